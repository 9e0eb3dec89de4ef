//! Writes a capture made of N back-to-back copies of another, with the capture and sensor
//! clocks continuing across copies (the sensor's wrapping at the hour), for the memory
//! benchmark (`benches/memory.sh`).
//!
//! Usage: `repeat_capture IN.pcap N OUT.pcap`

use lidar_noise::capture::writer::PcapWriter;
use lidar_noise::capture::CaptureReader;
use std::io::BufWriter;
use std::path::Path;

const HOUR_US: u64 = 3_600_000_000;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 4 {
        return Err("usage: repeat_capture IN.pcap N OUT.pcap".into());
    }
    let copies: u64 = args[2].parse()?;
    let mut records = Vec::new();
    let mut reader = CaptureReader::open(Path::new(&args[1]))?;
    while let Some(d) = reader.next_datagram()? {
        records.push((d.ts_ns / 1000, d.src_port, d.dst_port, d.payload.to_vec()));
    }
    let (first, last) = match (records.first(), records.last()) {
        (Some(f), Some(l)) => (f.0, l.0),
        _ => return Err("the capture has no UDP datagram".into()),
    };
    // One copy lasts the capture's span plus one typical packet gap.
    let span = last - first + 553;
    let out = BufWriter::new(std::fs::File::create(&args[3])?);
    let mut w = PcapWriter::new(out)?;
    for copy in 0..copies {
        let shift = copy * span;
        for (ts, src, dst, payload) in &records {
            let mut p = payload.clone();
            if p.len() >= 1204 {
                let sensor = u64::from(u32::from_le_bytes([p[1200], p[1201], p[1202], p[1203]]));
                let moved = ((sensor + shift) % HOUR_US) as u32;
                p[1200..1204].copy_from_slice(&moved.to_le_bytes());
            }
            w.write_udp(ts + shift, *src, *dst, &p)?;
        }
    }
    w.into_inner()?;
    Ok(())
}
