//! Cell files and the tidy JSON table written and read a frame at a time, so that a
//! sweep's memory does not grow with the length of its captures (issue 30: peak RSS grew
//! from 65 to 77 MB between 1x and 30x a capture while `run` stays flat).
//!
//! Both files are pretty-printed JSON documents holding one long array under a top-level
//! key (a cell's `frames`, the table's `rows`). [`ArrayWriter`] writes the document
//! around the array with serde_json and each element as it comes, byte for byte as
//! `serde_json::to_vec_pretty` of the whole document: an element is the pretty text of
//! the value with every line indented by two levels (JSON strings hold no raw line
//! break, so the lines of the text are the lines of the value). [`scan_cell`] parses a
//! cell file from a reader, handing each frame to a callback, and checks its checksum
//! in a second streamed pass.

use crate::score::metrics::FrameMetrics;
use serde::de::{self, DeserializeSeed, MapAccess, SeqAccess, Visitor};
use serde::Serialize;
use std::io::{BufReader, Read, Seek, SeekFrom, Write};
use std::path::Path;

/// Indentation of an element of a top-level array in serde_json's pretty output.
const ELEMENT_INDENT: &str = "    ";

/// What a cell file's `checksum` holds while the checksum is computed.
pub const CHECKSUM_PLACEHOLDER: &str = "0000000000000000";

/// Writes a pretty-printed JSON document whose top-level `key` holds an array, the
/// array's elements one at a time; the xxh3-64 of every byte written is kept.
pub struct ArrayWriter<W: Write> {
    out: W,
    /// The document after the array's `[`: `]` and the keys that follow.
    after: String,
    elements: u64,
    hasher: xxhash_rust::xxh3::Xxh3,
}

impl<W: Write> ArrayWriter<W> {
    /// Writes `doc` (whose top-level `key` must hold an empty array) up to the array's
    /// `[`.
    pub fn start(out: W, doc: &impl Serialize, key: &str) -> std::io::Result<Self> {
        let text = serde_json::to_string_pretty(doc)?;
        let marker = format!("\n  \"{key}\": []");
        let at = text.rfind(&marker).ok_or_else(|| {
            std::io::Error::other(format!("internal: the document has no empty `{key}`"))
        })? + marker.len()
            - 1;
        let mut w = ArrayWriter {
            out,
            after: text[at..].to_string(),
            elements: 0,
            hasher: xxhash_rust::xxh3::Xxh3::new(),
        };
        w.put(&text.as_bytes()[..at])?;
        Ok(w)
    }

    fn put(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.hasher.update(bytes);
        self.out.write_all(bytes)
    }

    /// Flushes the output.
    pub fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }

    /// Appends one element.
    pub fn push(&mut self, value: &impl Serialize) -> std::io::Result<()> {
        let text = serde_json::to_string_pretty(value)?;
        let mut s = String::with_capacity(text.len() + text.len() / 8 + 8);
        for (i, line) in text.split('\n').enumerate() {
            if i > 0 {
                s.push('\n');
            }
            s.push_str(ELEMENT_INDENT);
            s.push_str(line);
        }
        self.push_indented(&s, 1)
    }

    /// Appends `n` elements given as their indented text, separated by `,\n` (as they
    /// stand between the brackets of a file this writer wrote).
    pub fn push_indented(&mut self, text: &str, n: u64) -> std::io::Result<()> {
        if n == 0 {
            return Ok(());
        }
        self.put(if self.elements == 0 { b"\n" } else { b",\n" })?;
        self.put(text.as_bytes())?;
        self.elements += n;
        Ok(())
    }

    /// The rest of the document (closing the array) and the writer, unwritten, with the
    /// hash of the bytes written so far.
    pub fn into_tail(self) -> (W, String, xxhash_rust::xxh3::Xxh3) {
        let tail = if self.elements == 0 {
            self.after
        } else {
            format!("\n  {}", self.after)
        };
        (self.out, tail, self.hasher)
    }

    /// Writes the rest of the document; returns the writer.
    pub fn finish(self) -> std::io::Result<W> {
        let (mut out, tail, _) = self.into_tail();
        out.write_all(tail.as_bytes())?;
        Ok(out)
    }
}

/// A cell file read by [`scan_cell`], without its frames (they went to the callback).
#[derive(Clone, Debug, PartialEq)]
pub struct CellHead {
    /// The writer (`lidar-noise <version>`).
    pub tool: String,
    /// The settings that produced the frames.
    pub settings: serde_json::Value,
    /// Frames in the file.
    pub frames: usize,
    /// Index of its first frame.
    pub first: Option<u32>,
    /// Index of its last frame.
    pub last: Option<u32>,
}

/// Reads the cell file at `path` a frame at a time, giving each frame to `on_frame`,
/// then checks its checksum: None when the file cannot be opened, Err(why) when it
/// cannot be parsed or does not verify (`on_frame` may have seen some of its frames).
pub fn scan_cell(
    path: &Path,
    on_frame: &mut dyn FnMut(FrameMetrics),
) -> Option<std::result::Result<CellHead, String>> {
    let file = std::fs::File::open(path).ok()?;
    if !file.metadata().ok()?.is_file() {
        return None;
    }
    Some(scan_open(file, on_frame))
}

fn scan_open(
    mut file: std::fs::File,
    on_frame: &mut dyn FnMut(FrameMetrics),
) -> std::result::Result<CellHead, String> {
    let unreadable = |e: serde_json::Error| format!("the cell file cannot be read ({e})");
    let (head, checksum) = {
        let mut de = serde_json::Deserializer::from_reader(BufReader::new(&mut file));
        let parsed = CellSeed(on_frame)
            .deserialize(&mut de)
            .map_err(unreadable)?;
        de.end().map_err(unreadable)?;
        parsed
    };
    verify_checksum(&mut file, &checksum)?;
    Ok(head)
}

/// Checks the checksum of a cell file: the xxh3-64 of its bytes with the value of its
/// last `"checksum": "<checksum>"` field written as 16 zeros. As written, the field closes
/// the file; it is looked for in the file's last 4 KiB (a file rewritten with it earlier
/// has other bytes and would not verify anyway).
fn verify_checksum(file: &mut std::fs::File, checksum: &str) -> std::result::Result<(), String> {
    const TAIL: u64 = 4096;
    let io = |e: std::io::Error| format!("the cell file cannot be read ({e})");
    let no_checksum = || "the cell file has no checksum".to_string();
    if checksum.len() != CHECKSUM_PLACEHOLDER.len() {
        return Err(no_checksum());
    }
    let len = file.metadata().map_err(io)?.len();
    let from = len.saturating_sub(TAIL);
    file.seek(SeekFrom::Start(from)).map_err(io)?;
    let mut tail = Vec::new();
    Read::read_to_end(file, &mut tail).map_err(io)?;
    let field = format!("\"checksum\": \"{checksum}\"");
    let at = tail
        .windows(field.len())
        .rposition(|w| w == field.as_bytes())
        .ok_or_else(no_checksum)?;
    let value_at = from + (at + field.len() - 1 - checksum.len()) as u64;
    file.seek(SeekFrom::Start(0)).map_err(io)?;
    let mut hasher = xxhash_rust::xxh3::Xxh3::new();
    let mut buf = vec![0u8; 1 << 16];
    hash_bytes(file, value_at, &mut buf, &mut hasher).map_err(io)?;
    // The zeros go in the value's place.
    hasher.update(CHECKSUM_PLACEHOLDER.as_bytes());
    file.seek(SeekFrom::Current(checksum.len() as i64))
        .map_err(io)?;
    let rest = len - value_at - checksum.len() as u64;
    hash_bytes(file, rest, &mut buf, &mut hasher).map_err(io)?;
    let sum = format!("{:016x}", hasher.digest());
    if sum != checksum {
        return Err(format!(
            "the cell file was changed after it was written (checksum {sum}, recorded {checksum})"
        ));
    }
    Ok(())
}

/// Hashes the next `n` bytes of `file`, a buffer at a time.
fn hash_bytes(
    file: &mut std::fs::File,
    mut n: u64,
    buf: &mut [u8],
    hasher: &mut xxhash_rust::xxh3::Xxh3,
) -> std::io::Result<()> {
    while n > 0 {
        let want = n.min(buf.len() as u64) as usize;
        let got = file.read(&mut buf[..want])?;
        if got == 0 {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
        hasher.update(&buf[..got]);
        n -= got as u64;
    }
    Ok(())
}

/// Parses a cell file's object, frames to the callback (fields as the derived
/// deserializer of the file's struct reads them: unknown keys ignored, `checksum`
/// optional).
struct CellSeed<'a>(&'a mut dyn FnMut(FrameMetrics));

impl<'de> DeserializeSeed<'de> for CellSeed<'_> {
    type Value = (CellHead, String);
    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_map(self)
    }
}

impl<'de> Visitor<'de> for CellSeed<'_> {
    type Value = (CellHead, String);
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a cell file")
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
        let mut tool: Option<String> = None;
        let mut settings: Option<serde_json::Value> = None;
        let mut frames: Option<(usize, Option<u32>, Option<u32>)> = None;
        let mut checksum: Option<String> = None;
        while let Some(key) = map.next_key::<String>()? {
            match key.as_str() {
                "tool" if tool.is_some() => return Err(de::Error::duplicate_field("tool")),
                "tool" => tool = Some(map.next_value()?),
                "settings" if settings.is_some() => {
                    return Err(de::Error::duplicate_field("settings"))
                }
                "settings" => settings = Some(map.next_value()?),
                "frames" if frames.is_some() => return Err(de::Error::duplicate_field("frames")),
                "frames" => frames = Some(map.next_value_seed(FramesSeed(&mut *self.0))?),
                "checksum" if checksum.is_some() => {
                    return Err(de::Error::duplicate_field("checksum"))
                }
                "checksum" => checksum = Some(map.next_value()?),
                _ => {
                    map.next_value::<de::IgnoredAny>()?;
                }
            }
        }
        let tool = tool.ok_or_else(|| de::Error::missing_field("tool"))?;
        let settings = settings.ok_or_else(|| de::Error::missing_field("settings"))?;
        let (frames, first, last) = frames.ok_or_else(|| de::Error::missing_field("frames"))?;
        Ok((
            CellHead {
                tool,
                settings,
                frames,
                first,
                last,
            },
            checksum.unwrap_or_default(),
        ))
    }
}

/// A cell's `frames` array: each frame to the callback; count, first and last index.
struct FramesSeed<'a>(&'a mut dyn FnMut(FrameMetrics));

impl<'de> DeserializeSeed<'de> for FramesSeed<'_> {
    type Value = (usize, Option<u32>, Option<u32>);
    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for FramesSeed<'_> {
    type Value = (usize, Option<u32>, Option<u32>);
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a sequence of frames")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let (mut n, mut first, mut last) = (0usize, None, None);
        while let Some(m) = seq.next_element::<FrameMetrics>()? {
            n += 1;
            first.get_or_insert(m.frame);
            last = Some(m.frame);
            (self.0)(m);
        }
        Ok((n, first, last))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Serialize)]
    struct Doc<'a> {
        tool: &'a str,
        settings: serde_json::Value,
        frames: Vec<FrameMetrics>,
        checksum: &'a str,
    }

    fn frames(n: u32) -> Vec<FrameMetrics> {
        (0..n)
            .map(|i| FrameMetrics {
                frame: 10 + i,
                kept: u64::from(i) * 7,
                range_change_rms_m: 0.1 * f64::from(i) + 1e-17,
                object_survival: (i % 2 == 0).then_some(1.0 / 3.0),
                ..FrameMetrics::default()
            })
            .collect()
    }

    /// The streamed document equals serde_json's pretty output of the whole document,
    /// for no, one and several elements.
    #[test]
    fn streamed_arrays_equal_the_whole_document() {
        for n in [0, 1, 3] {
            let settings = serde_json::json!({"frames": [0, 5], "deep": {"list": [1, 2], "e": []}});
            let doc = Doc {
                tool: "t",
                settings: settings.clone(),
                frames: frames(n),
                checksum: CHECKSUM_PLACEHOLDER,
            };
            let whole = serde_json::to_string_pretty(&doc).unwrap();
            let empty = Doc {
                frames: Vec::new(),
                ..doc
            };
            let mut w = ArrayWriter::start(Vec::new(), &empty, "frames").unwrap();
            for f in frames(n) {
                w.push(&f).unwrap();
            }
            let out = w.finish().unwrap();
            assert_eq!(String::from_utf8(out).unwrap(), whole, "{n} elements");
        }
    }

    /// A file written whole (with its checksum) is read back frame by frame; an edited
    /// byte or a missing checksum is refused.
    #[test]
    fn scanned_cells_verify() {
        let dir = tempfile::tempdir().unwrap();
        let doc = Doc {
            tool: "lidar-noise x",
            settings: serde_json::json!({"a": 1}),
            frames: frames(4),
            checksum: CHECKSUM_PLACEHOLDER,
        };
        let mut bytes = serde_json::to_vec_pretty(&doc).unwrap();
        bytes.push(b'\n');
        let sum = format!("{:016x}", xxhash_rust::xxh3::xxh3_64(&bytes));
        let text = String::from_utf8(bytes)
            .unwrap()
            .replace(CHECKSUM_PLACEHOLDER, &sum);
        let path = dir.path().join("c.json");
        std::fs::write(&path, &text).unwrap();
        let mut seen = Vec::new();
        let head = scan_cell(&path, &mut |m| seen.push(m)).unwrap().unwrap();
        assert_eq!(seen, frames(4));
        assert_eq!(
            (head.frames, head.first, head.last),
            (4, Some(10), Some(13))
        );
        assert_eq!(head.settings, serde_json::json!({"a": 1}));

        std::fs::write(&path, text.replace("\"kept\": 7", "\"kept\": 8")).unwrap();
        let e = scan_cell(&path, &mut |_| ()).unwrap().unwrap_err();
        assert!(e.contains("changed after it was written"), "{e}");
        std::fs::write(&path, text.replace(&sum, "00")).unwrap();
        let e = scan_cell(&path, &mut |_| ()).unwrap().unwrap_err();
        assert!(e.contains("no checksum"), "{e}");
        std::fs::write(&path, &text[..text.len() / 2]).unwrap();
        let e = scan_cell(&path, &mut |_| ()).unwrap().unwrap_err();
        assert!(e.contains("cannot be read"), "{e}");
        assert!(scan_cell(&dir.path().join("none.json"), &mut |_| ()).is_none());
    }
}
