//! Ground-truth labels of a synthesized capture.
//!
//! Format (`<name>.labels.csv.gz`): a gzip-compressed CSV file, UTF-8, `\n` line
//! ends, with the header line `frame,packet,block,laser,label` and one row per
//! emitted return (raw distance != 0) in capture order:
//! - `frame`: zero-based rotation index (rotation k starts at the block whose
//!   azimuth wraps to 0 for the k-th time; the capture starts at azimuth 0.00).
//!   The frame is decided per block by the block azimuth, so a block just before
//!   the wrap belongs wholly to frame k even where its last lasers' interpolated
//!   azimuths pass 360°;
//! - `packet`: zero-based index of the record in the pcap, position packets counted
//!   (the decoder's `Return::packet`);
//! - `block`: 0..11 within the packet; `laser`: laser id 0..31;
//! - `label`: 0 for the ground, k for object id k (see `<name>.objects.json`).
//!
//! The reader also accepts the same CSV uncompressed.

use crate::error::{Error, Result};
use flate2::read::MultiGzDecoder;
use flate2::write::GzEncoder;
use flate2::Compression;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::Path;

/// Header line of a labels file.
pub const HEADER: &str = "frame,packet,block,laser,label";
/// File name extension of a labels file (after `<name>.labels.`).
pub const EXTENSION: &str = "csv.gz";

/// One labelled return.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LabelRow {
    /// Zero-based rotation index.
    pub frame: u32,
    /// Zero-based capture record index (position packets counted).
    pub packet: u32,
    /// Block within the packet, 0..11.
    pub block: u8,
    /// Laser id, 0..31.
    pub laser: u8,
    /// 0 = ground, k = object id.
    pub label: u16,
}

/// Streaming writer of a gzip-compressed labels file.
pub struct LabelWriter<W: Write> {
    out: GzEncoder<W>,
    line: String,
}

impl<W: Write> LabelWriter<W> {
    /// Starts a labels file: writes the gzip header and the CSV header line.
    pub fn new(out: W) -> std::io::Result<Self> {
        let mut out = GzEncoder::new(out, Compression::best());
        out.write_all(HEADER.as_bytes())?;
        out.write_all(b"\n")?;
        Ok(LabelWriter {
            out,
            line: String::with_capacity(32),
        })
    }

    /// Appends one row.
    pub fn write(&mut self, row: &LabelRow) -> std::io::Result<()> {
        use std::fmt::Write as _;
        self.line.clear();
        // Writing to a String cannot fail.
        let _ = writeln!(
            self.line,
            "{},{},{},{},{}",
            row.frame, row.packet, row.block, row.laser, row.label
        );
        self.out.write_all(self.line.as_bytes())
    }

    /// Finishes the gzip stream and returns the underlying writer.
    pub fn finish(self) -> std::io::Result<W> {
        self.out.finish()
    }
}

/// Reads a labels file (gzip-compressed or plain CSV); `origin` names it in errors.
pub fn read_labels<R: Read>(input: R, origin: &Path) -> Result<Vec<LabelRow>> {
    let mut reader = BufReader::new(input);
    let gz = reader
        .fill_buf()
        .map_err(|e| Error::io(origin, e))?
        .starts_with(&[0x1f, 0x8b]);
    let reader: Box<dyn BufRead> = if gz {
        Box::new(BufReader::new(MultiGzDecoder::new(reader)))
    } else {
        Box::new(reader)
    };
    let bad = |line: usize, message: String| {
        Error::Invalid(format!("{}: line {line}: {message}", origin.display()))
    };
    let mut rows = Vec::new();
    let mut saw_header = false;
    for (i, line) in reader.lines().enumerate() {
        let line = line.map_err(|e| Error::io(origin, e))?;
        let n = i + 1;
        if n == 1 {
            if line.trim_end() != HEADER {
                return Err(bad(n, format!("expected the header `{HEADER}`")));
            }
            saw_header = true;
            continue;
        }
        if line.is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.trim_end().split(',').collect();
        if fields.len() != 5 {
            return Err(bad(n, format!("expected 5 fields, found {}", fields.len())));
        }
        fn num<T: std::str::FromStr>(s: &str) -> Option<T> {
            s.parse().ok()
        }
        let row = (|| {
            Some(LabelRow {
                frame: num(fields[0])?,
                packet: num(fields[1])?,
                block: num(fields[2]).filter(|&b: &u8| b < 12)?,
                laser: num(fields[3]).filter(|&l: &u8| l < 32)?,
                label: num(fields[4])?,
            })
        })()
        .ok_or_else(|| bad(n, format!("invalid row `{line}`")))?;
        rows.push(row);
    }
    if !saw_header {
        return Err(bad(
            1,
            format!("empty file: expected the header `{HEADER}`"),
        ));
    }
    Ok(rows)
}

/// Reads a labels file from disk.
pub fn read_labels_file(path: &Path) -> Result<Vec<LabelRow>> {
    let f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    read_labels(f, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_rows() {
        let p = Path::new("x.csv");
        assert!(read_labels(&b"frame,packet,block,laser,label\n0,1,12,0,0\n"[..], p).is_err());
        assert!(read_labels(&b"nope\n"[..], p).is_err());
        let rows = read_labels(&b"frame,packet,block,laser,label\n0,1,11,31,2\n"[..], p).unwrap();
        assert_eq!(
            rows,
            vec![LabelRow {
                frame: 0,
                packet: 1,
                block: 11,
                laser: 31,
                label: 2
            }]
        );
    }
}
