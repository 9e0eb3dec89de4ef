//! Ground-truth labels of a synthesized capture.
//!
//! Format (`<name>.labels.csv.gz`): a gzip-compressed CSV file, UTF-8, `\n` line
//! ends, with the header line `frame,firing,laser,label` and one row per emitted
//! return (raw distance != 0) in capture order:
//! - `frame`: zero-based rotation index (rotation k starts at the block whose
//!   azimuth wraps to 0 for the k-th time; the capture starts at azimuth 0.00).
//!   The frame is decided per block by the block azimuth, so a block just before
//!   the wrap belongs wholly to frame k even where its last lasers' interpolated
//!   azimuths pass 360°;
//! - `firing`: zero-based index of the firing (data block) within its frame, counting
//!   the frame's firings that emitted at least one return, in capture order. A firing
//!   that emitted nothing has no row and takes no index, so the key depends only on
//!   the frame's returns, not on how the capture file numbers its records: a label
//!   file survives re-encoding the capture (other packet sizes, position packets
//!   added or removed);
//! - `laser`: laser id 0..31 (firing order within the block) for the HDL-32E; the
//!   sensor's laser id (0..127) for captures of other sensors (`synth --sensor`),
//!   where `firing` counts firing sequences (a VLS-128 or HDL-64E sequence spans
//!   several bank blocks; the laser id tells the bank);
//! - `label`: 0 for the ground, k for object id k (see `<name>.objects.json`).
//!
//! `(frame, firing, laser)` identifies a return inside its capture. The synthesizer
//! writes single-return (strongest) captures; the format has no return-kind column,
//! so labels of dual-return captures are not defined.
//!
//! The reader also accepts the same CSV uncompressed, and the previous format
//! (`frame,packet,block,laser,label`, keyed by capture record and block), which it
//! converts to firings with [`Firings`].

use crate::error::{Error, Result};
use flate2::read::MultiGzDecoder;
use flate2::write::GzEncoder;
use flate2::Compression;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::Path;

/// Laser ids a labels file may name: 0..127 (the VLS-128's 128 lasers).
pub const MAX_LASERS: u8 = 128;

/// Header line of a labels file.
pub const HEADER: &str = "frame,firing,laser,label";
/// Header line of the previous format (record and block instead of firing), still read.
pub const OLD_HEADER: &str = "frame,packet,block,laser,label";
/// File name extension of a labels file (after `<name>.labels.`).
pub const EXTENSION: &str = "csv.gz";

/// One labelled return.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LabelRow {
    /// Zero-based rotation index.
    pub frame: u32,
    /// Zero-based index within the frame of the firing, among firings with a return.
    pub firing: u32,
    /// Laser id, 0..31 (0..127 for other sensors).
    pub laser: u8,
    /// 0 = ground, k = object id.
    pub label: u16,
}

/// Numbers firings within frames from returns given in capture order.
///
/// A firing is one data block (`packet`, `block`); the first firing seen in a frame is 0,
/// and the index grows by one each time the block changes within the frame.
#[derive(Clone, Copy, Debug, Default)]
pub struct Firings {
    last: Option<(u32, u32, u8)>,
    next: u32,
}

impl Firings {
    /// The firing index of a return of `frame` carried by record `packet`, block `block`.
    pub fn firing(&mut self, frame: u32, packet: u32, block: u8) -> u32 {
        match self.last {
            Some((f, p, b)) if f == frame => {
                if (p, b) != (packet, block) {
                    self.next += 1;
                }
            }
            _ => self.next = 0,
        }
        self.last = Some((frame, packet, block));
        self.next
    }
}

/// Streaming writer of a gzip-compressed labels file.
pub struct LabelWriter<W: Write> {
    out: GzEncoder<W>,
    line: String,
    firings: Firings,
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
            firings: Firings::default(),
        })
    }

    /// Appends one row.
    pub fn write(&mut self, row: &LabelRow) -> std::io::Result<()> {
        use std::fmt::Write as _;
        self.line.clear();
        // Writing to a String cannot fail.
        let _ = writeln!(
            self.line,
            "{},{},{},{}",
            row.frame, row.firing, row.laser, row.label
        );
        self.out.write_all(self.line.as_bytes())
    }

    /// Appends the row of a return given by its capture position (returns in capture order).
    pub fn write_return(
        &mut self,
        frame: u32,
        packet: u32,
        block: u8,
        laser: u8,
        label: u16,
    ) -> std::io::Result<()> {
        let firing = self.firings.firing(frame, packet, block);
        self.write(&LabelRow {
            frame,
            firing,
            laser,
            label,
        })
    }

    /// Finishes the gzip stream and returns the underlying writer.
    pub fn finish(self) -> std::io::Result<W> {
        self.out.finish()
    }
}

/// Longest line of a labels file read (bytes): a row is about 20 bytes; a file with no
/// line break (`/dev/zero`) is refused here instead of read into one line until memory
/// runs out.
const MAX_LINE_BYTES: u64 = 4096;

/// The lines of `reader` without their line break, each at most [`MAX_LINE_BYTES`] long
/// (a longer one is an `InvalidData` error, and the iteration ends after it).
fn bounded_lines(mut reader: impl BufRead) -> impl Iterator<Item = std::io::Result<String>> {
    let mut done = false;
    std::iter::from_fn(move || {
        if done {
            return None;
        }
        let mut line = String::new();
        match reader.by_ref().take(MAX_LINE_BYTES).read_line(&mut line) {
            Ok(0) => None,
            Ok(n) if n as u64 == MAX_LINE_BYTES && !line.ends_with('\n') => {
                done = true;
                Some(Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidData,
                    format!("a line longer than {MAX_LINE_BYTES} bytes: not a labels file"),
                )))
            }
            Ok(_) => {
                if line.ends_with('\n') {
                    line.pop();
                    if line.ends_with('\r') {
                        line.pop();
                    }
                }
                Some(Ok(line))
            }
            Err(e) => {
                done = true;
                Some(Err(e))
            }
        }
    })
}

/// Reads a labels file (gzip-compressed or plain CSV); `origin` names it in errors.
pub fn read_labels<R: Read>(input: R, origin: &Path) -> Result<Vec<LabelRow>> {
    LabelRows::new(input, origin)?.collect()
}

/// The rows of a labels file read one at a time, in file order (memory does not grow
/// with the file): the reader of [`read_labels`]. After an error it ends.
pub struct LabelRows<'a> {
    lines: std::iter::Enumerate<Box<dyn Iterator<Item = std::io::Result<String>> + 'a>>,
    origin: std::path::PathBuf,
    old: bool,
    firings: Firings,
    done: bool,
}

impl<'a> LabelRows<'a> {
    /// Starts reading `input` (gzip-compressed or plain CSV): checks the header line.
    pub fn new<R: Read + 'a>(input: R, origin: &Path) -> Result<Self> {
        let mut reader = BufReader::new(input);
        let gz = reader
            .fill_buf()
            .map_err(|e| Error::io(origin, e))?
            .starts_with(&[0x1f, 0x8b]);
        let reader: Box<dyn BufRead + 'a> = if gz {
            Box::new(BufReader::new(MultiGzDecoder::new(reader)))
        } else {
            Box::new(reader)
        };
        let lines: Box<dyn Iterator<Item = std::io::Result<String>> + 'a> =
            Box::new(bounded_lines(reader));
        let mut rows = LabelRows {
            lines: lines.enumerate(),
            origin: origin.to_path_buf(),
            old: false,
            firings: Firings::default(),
            done: false,
        };
        rows.old = match rows.lines.next() {
            None => return Err(rows.bad(1, format!("empty file: expected the header `{HEADER}`"))),
            Some((_, line)) => match line.map_err(|e| Error::io(origin, e))?.trim_end() {
                HEADER => false,
                OLD_HEADER => true,
                _ => return Err(rows.bad(1, format!("expected the header `{HEADER}`"))),
            },
        };
        Ok(rows)
    }

    fn bad(&self, line: usize, message: String) -> Error {
        Error::Invalid(format!("{}: line {line}: {message}", self.origin.display()))
    }

    fn row(&mut self, n: usize, line: &str) -> Result<LabelRow> {
        let fields: Vec<&str> = line.trim_end().split(',').collect();
        let width = if self.old { 5 } else { 4 };
        if fields.len() != width {
            return Err(self.bad(
                n,
                format!("expected {width} fields, found {}", fields.len()),
            ));
        }
        fn num<T: std::str::FromStr>(s: &str) -> Option<T> {
            s.parse().ok()
        }
        let firings = &mut self.firings;
        if self.old {
            (|| {
                let frame = num(fields[0])?;
                let packet = num(fields[1])?;
                let block = num(fields[2]).filter(|&b: &u8| b < 12)?;
                Some(LabelRow {
                    frame,
                    firing: firings.firing(frame, packet, block),
                    laser: num(fields[3]).filter(|&l: &u8| l < MAX_LASERS)?,
                    label: num(fields[4])?,
                })
            })()
        } else {
            (|| {
                Some(LabelRow {
                    frame: num(fields[0])?,
                    firing: num(fields[1])?,
                    laser: num(fields[2]).filter(|&l: &u8| l < MAX_LASERS)?,
                    label: num(fields[3])?,
                })
            })()
        }
        .ok_or_else(|| self.bad(n, format!("invalid row `{line}`")))
    }
}

impl Iterator for LabelRows<'_> {
    type Item = Result<LabelRow>;
    fn next(&mut self) -> Option<Result<LabelRow>> {
        if self.done {
            return None;
        }
        loop {
            let (i, line) = self.lines.next()?;
            let line = match line {
                Ok(l) => l,
                Err(e) => {
                    self.done = true;
                    return Some(Err(Error::io(&self.origin, e)));
                }
            };
            if line.is_empty() {
                continue;
            }
            let row = self.row(i + 1, &line);
            self.done = row.is_err();
            return Some(row);
        }
    }
}

/// Reads a labels file from disk.
pub fn read_labels_file(path: &Path) -> Result<Vec<LabelRow>> {
    let f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    read_labels(f, path)
}

/// The `(firing, laser)` key of every return of a decoded frame, in order.
pub fn frame_keys(frame: &crate::frame::Frame) -> Vec<(u32, u8)> {
    let mut firings = Firings::default();
    frame
        .returns
        .iter()
        .map(|r| (firings.firing(frame.index, r.packet, r.block), r.laser))
        .collect()
}

/// Checks that `rows` (the labels of one frame) line up with the frame's decoded returns,
/// and says where they first differ otherwise; `origin` names the labels file.
pub fn check_frame(rows: &[LabelRow], frame: &crate::frame::Frame, origin: &Path) -> Result<()> {
    let keys = frame_keys(frame);
    let head = || {
        format!(
            "{}: the labels of frame {} do not line up with the decoded capture",
            origin.display(),
            frame.index
        )
    };
    for (k, (row, key)) in rows.iter().zip(&keys).enumerate() {
        if (row.firing, row.laser) != *key {
            return Err(Error::Invalid(format!(
                "{}: return {k} of the frame: expected firing {} laser {} (decoded), found firing {} laser {} (labels)",
                head(),
                key.0,
                key.1,
                row.firing,
                row.laser
            )));
        }
    }
    if rows.len() != keys.len() {
        return Err(Error::Invalid(format!(
            "{}: {} label rows but {} decoded returns (the first {} agree)",
            head(),
            rows.len(),
            keys.len(),
            rows.len().min(keys.len())
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_rows() {
        let p = Path::new("x.csv");
        assert!(read_labels(&b"frame,firing,laser,label\n0,1,128,0\n"[..], p).is_err());
        assert!(read_labels(&b"nope\n"[..], p).is_err());
        let rows = read_labels(&b"frame,firing,laser,label\n0,1,31,2\n"[..], p).unwrap();
        assert_eq!(
            rows,
            vec![LabelRow {
                frame: 0,
                firing: 1,
                laser: 31,
                label: 2
            }]
        );
    }

    #[test]
    fn old_format_is_converted_to_firings() {
        let p = Path::new("x.csv");
        let text = b"frame,packet,block,laser,label\n0,3,4,0,0\n0,3,4,1,1\n0,3,6,0,0\n0,5,0,2,2\n1,5,1,0,0\n";
        let rows = read_labels(&text[..], p).unwrap();
        let keys: Vec<(u32, u32, u8)> = rows.iter().map(|r| (r.frame, r.firing, r.laser)).collect();
        assert_eq!(
            keys,
            vec![(0, 0, 0), (0, 0, 1), (0, 1, 0), (0, 2, 2), (1, 0, 0)]
        );
    }
}
