//! `lidar-noise info`: what a capture contains (of an HDL-32E, or of another described
//! sensor, told by its packets' structure as `run` tells it).

use crate::cli::Global;
use crate::options::DecoderArgs;
use anyhow::Result;
use lidar_noise::frame::FrameSource;
use lidar_noise::sensor::frames::CaptureSummary;
use lidar_noise::sensor::frames::{CaptureFrames, ModelCaptureSummary};
use std::io::Write;
use std::path::PathBuf;

/// Arguments of `info`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Capture files (pcap or pcapng), `-` for standard input.
    #[arg(required = true, value_name = "CAPTURE")]
    pub captures: Vec<PathBuf>,
    /// Print JSON (one object per capture, one per line) instead of text.
    #[arg(long)]
    pub json: bool,
    /// Decoder settings shared by the commands that read captures.
    #[command(flatten)]
    pub decoder: DecoderArgs,
}

/// Reads each capture to the end and prints its summary.
pub fn run(args: Args, global: Global) -> Result<()> {
    super::check_stdin_once(&args.captures)?;
    let options = args.decoder.to_options()?;
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    for path in &args.captures {
        let mut reader = match lidar_noise::engine::inputs::open_any_capture(path, &options)? {
            CaptureFrames::Hdl32e(r) => r,
            CaptureFrames::Model(mut r) => {
                r.count_rest(&(0..=u32::MAX))?;
                write_model(&mut out, path, r.summary(), args.json)?;
                continue;
            }
        };
        for frame in reader.by_ref() {
            frame?;
        }
        let summary = reader.summary();
        super::warn_truncation(&global, path, &summary);
        if let Some(hint) = super::raw_intensity_hint(&summary) {
            global.warn(&format!("{}: {hint}", path.display()));
        }
        if args.json {
            let mut value = serde_json::to_value(&summary)?;
            value["file"] = serde_json::Value::from(path.display().to_string());
            value["dead_lasers"] = serde_json::to_value(summary.dead_lasers())?;
            writeln!(out, "{}", serde_json::to_string(&value)?)?;
        } else {
            write_text(&mut out, path, &summary)?;
        }
    }
    Ok(())
}

/// Prints the summary of another sensor's capture as text or one JSON line.
fn write_model(
    out: &mut impl Write,
    path: &std::path::Path,
    s: &ModelCaptureSummary,
    json: bool,
) -> Result<()> {
    let dead = s.dead_lasers();
    if json {
        let mut value = serde_json::to_value(s)?;
        value["file"] = serde_json::Value::from(path.display().to_string());
        value["dead_lasers"] = serde_json::to_value(&dead)?;
        writeln!(out, "{}", serde_json::to_string(&value)?)?;
        return Ok(());
    }
    writeln!(out, "{}", path.display())?;
    let mode = s
        .return_mode
        .map_or_else(|| "unknown".to_string(), |m| format!("{m:?}"));
    writeln!(
        out,
        "  sensor        {} (product id 0x{:02x}), return mode {mode}",
        s.sensor, s.product_id
    )?;
    if !s.note.is_empty() {
        writeln!(out, "  note          {}", s.note)?;
    }
    writeln!(
        out,
        "  packets       {} data, {} position, {} other UDP, {} bad data",
        s.data_packets, s.position_packets, s.other_udp, s.bad_data_packets
    )?;
    write_duplicates(out, s.duplicate_packets)?;
    write_dead(out, &dead)?;
    writeln!(out, "  calibration   {}", s.calibration)?;
    writeln!(out, "  packet period {:.0} us", s.packet_period_us)?;
    writeln!(out, "  rotation      {:.2} Hz", s.rotation_hz)?;
    writeln!(
        out,
        "  frames        {} full, {} partial",
        s.full_frames, s.partial_frames
    )?;
    writeln!(out, "  returns       {} in all", s.returns)?;
    Ok(())
}

/// The line counting the data packets dropped as copies, where there are any.
fn write_duplicates(out: &mut impl Write, duplicates: u64) -> Result<()> {
    if duplicates > 0 {
        writeln!(
            out,
            "  duplicates    {} data packet{} dropped (exact copies of one of the {} before)",
            duplicates,
            if duplicates == 1 { "" } else { "s" },
            lidar_noise::sensor::frames::DUPLICATE_WINDOW
        )?;
    }
    Ok(())
}

/// The line naming the lasers without a return, where there are any.
fn write_dead(out: &mut impl Write, dead: &[u8]) -> Result<()> {
    if !dead.is_empty() {
        writeln!(
            out,
            "  dead lasers   {} (no return over the capture)",
            super::join_ids(dead)
        )?;
    }
    Ok(())
}

fn write_text(out: &mut impl Write, path: &std::path::Path, s: &CaptureSummary) -> Result<()> {
    let ports: Vec<String> = s
        .data_ports
        .iter()
        .map(|(src, dst)| format!("{src}->{dst}"))
        .collect();
    writeln!(out, "{}", path.display())?;
    writeln!(
        out,
        "  format        {:?}, link type {} ({})",
        s.format, s.linktype, s.linktype_name
    )?;
    writeln!(
        out,
        "  sensor        {} (product id 0x{:02x}), return mode {:?}",
        s.product, s.product_id, s.return_mode
    )?;
    writeln!(
        out,
        "  packets       {} records: {} data, {} position, {} other UDP, {} bad data",
        s.capture.records, s.data_packets, s.position_packets, s.other_udp, s.bad_data_packets
    )?;
    writeln!(
        out,
        "  skipped       {} fragments, {} non-UDP, {} non-IPv4, {} malformed",
        s.capture.fragments, s.capture.not_udp, s.capture.not_ipv4, s.capture.malformed
    )?;
    writeln!(out, "  data ports    {}", ports.join(", "))?;
    write_dead(out, &s.dead_lasers())?;
    if let Some(p) = s.packet_period_us {
        writeln!(out, "  packet period {p:.0} us")?;
    }
    match s.rotation_hz {
        Some(hz) => writeln!(out, "  rotation      {hz:.2} Hz")?,
        None => writeln!(out, "  rotation      unknown")?,
    }
    writeln!(
        out,
        "  frames        {} full, {} partial",
        s.full_frames, s.partial_frames
    )?;
    writeln!(
        out,
        "  returns       {} in all, {} in full frames ({} empty slots)",
        s.returns, s.returns_in_full_frames, s.decode.zero_distance
    )?;
    writeln!(out, "  duration      {:.3} s", s.duration_s)?;
    if s.clock_backward_steps > 0 {
        writeln!(
            out,
            "  clock         not monotonic: {} data packet{} started before the previous one \
             ended (reordered or duplicated packets, or a reset clock); the duration is the \
             span from the earliest to the latest firing",
            s.clock_backward_steps,
            if s.clock_backward_steps == 1 { "" } else { "s" }
        )?;
    }
    write_duplicates(out, s.duplicate_packets)?;
    if s.short_frames > 0 {
        writeln!(
            out,
            "  short frames  {} between the first and the last cover under nine tenths of a \
             turn: the azimuths jump back (interleaved or reordered packets, two sensors)",
            s.short_frames
        )?;
    }
    match s.capture.truncated_at {
        Some(offset) => writeln!(out, "  truncated     at byte offset {offset}")?,
        None => writeln!(out, "  truncated     no")?,
    }
    Ok(())
}
