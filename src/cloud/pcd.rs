//! PCD files (Point Cloud Library format, version 0.7): a text header, then the points as
//! `ascii` (one point a line), `binary` (packed records, point after point) or
//! `binary_compressed` (a u32 compressed size, a u32 uncompressed size, then LZF data
//! that holds the fields one after the other: all x, then all y, ...).
//!
//! Source: PCL documentation, "The PCD (Point Cloud Data) file format" (header entries
//! VERSION, FIELDS, SIZE, TYPE, COUNT, WIDTH, HEIGHT, VIEWPOINT, POINTS, DATA); PCL
//! `io/src/pcd_io.cpp` (`readHeader`, `readBodyBinary`: the compressed layout, one block
//! per field); LZF as in liblzf (Marc Lehmann), decoded by the `lzf` crate. Binary values
//! are stored in the writer's byte order, little-endian on every machine PCL runs on; they
//! are read as little-endian.
//!
//! Read: x y z (required), intensity (aliases i, reflectance, remission), ring (ring_index),
//! time (t, timestamp); of a field with COUNT above 1 the first element. Every other field
//! is skipped. TYPE F with SIZE 4 or 8, U and I with SIZE 1, 2, 4 or 8.

use super::{invalid, ring_from_f64, CloudPoint, Fields};
use crate::error::Result;
use std::path::Path;

/// Largest header read (bytes) before its `DATA` line: real headers are a few hundred.
const MAX_HEADER_BYTES: usize = 64 << 10;

/// Whether `head` (a file's first bytes) starts like a PCD header.
pub fn looks_like(head: &[u8]) -> bool {
    head.starts_with(b"# .PCD") || head.starts_with(b"VERSION") || head.starts_with(b"FIELDS")
}

/// One field of the header.
#[derive(Clone, Debug)]
struct Field {
    name: String,
    size: usize,
    kind: u8,
    count: usize,
    /// Bytes before it in a packed point record.
    offset: usize,
}

/// How the points are stored after the header.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Data {
    Ascii,
    Binary,
    Compressed,
}

/// The parsed header.
struct Header {
    fields: Vec<Field>,
    points: usize,
    data: Data,
    /// Byte offset of the first byte after the DATA line.
    start: usize,
    /// Bytes a packed point.
    point_size: usize,
}

/// Parses a PCD file (`path` is named in errors).
pub fn parse(bytes: &[u8], path: &Path) -> Result<(Vec<CloudPoint>, Fields)> {
    let header = parse_header(bytes, path)?;
    let find = |names: &[&str]| {
        header
            .fields
            .iter()
            .position(|f| names.iter().any(|n| f.name.eq_ignore_ascii_case(n)))
    };
    let need = |name: &str| {
        find(&[name]).ok_or_else(|| {
            let present: Vec<&str> = header.fields.iter().map(|f| f.name.as_str()).collect();
            invalid(
                path,
                format!(
                    "PCD header: required field {name} is missing (FIELDS {})",
                    present.join(" ")
                ),
            )
        })
    };
    let x = need("x")?;
    let y = need("y")?;
    let z = need("z")?;
    let intensity = find(&["intensity", "i", "reflectance", "remission"]);
    let ring = find(&["ring", "ring_index"]);
    let time = find(&["time", "t", "timestamp"]);
    let fields = Fields {
        intensity: intensity.is_some(),
        ring: ring.is_some(),
        time: time.is_some(),
    };
    let wanted = Wanted {
        x,
        y,
        z,
        intensity,
        ring,
        time,
    };
    let points = match header.data {
        Data::Ascii => ascii(bytes, &header, &wanted, path)?,
        Data::Binary => {
            let data = exact_data(bytes, &header, path)?;
            let ps = header.point_size;
            collect(&header, &wanted, path, |i, f: &Field| {
                value(&data[i * ps + f.offset..], f)
            })?
        }
        Data::Compressed => {
            let data = decompress(bytes, &header, path)?;
            let n = header.points;
            // Field f's block starts at n * f.offset; point i's element at i * size * count.
            collect(&header, &wanted, path, |i, f: &Field| {
                value(&data[n * f.offset + i * f.size * f.count..], f)
            })?
        }
    };
    Ok((points, fields))
}

/// Indices (into the header's fields) of the fields read.
struct Wanted {
    x: usize,
    y: usize,
    z: usize,
    intensity: Option<usize>,
    ring: Option<usize>,
    time: Option<usize>,
}

fn parse_header(bytes: &[u8], path: &Path) -> Result<Header> {
    let mut fields: Vec<Field> = Vec::new();
    let mut sizes: Option<(usize, Vec<usize>)> = None;
    let mut types: Option<(usize, Vec<u8>)> = None;
    let mut counts: Option<(usize, Vec<usize>)> = None;
    let mut width: Option<usize> = None;
    let mut height: Option<usize> = None;
    let mut points: Option<usize> = None;
    let mut pos = 0usize;
    let mut line_no = 0usize;
    let data = loop {
        line_no += 1;
        if pos >= bytes.len() || pos > MAX_HEADER_BYTES {
            return Err(invalid(
                path,
                format!("PCD header: no DATA line (read up to line {line_no}, byte offset {pos})"),
            ));
        }
        let end = bytes[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |e| pos + e);
        let raw = &bytes[pos..end];
        pos = (end + 1).min(bytes.len());
        let text = std::str::from_utf8(raw)
            .map_err(|_| invalid(path, format!("PCD header line {line_no}: not ASCII text")))?;
        let text = text.trim();
        if text.is_empty() || text.starts_with('#') {
            continue;
        }
        let mut words = text.split_whitespace();
        let key = words.next().unwrap_or("");
        let rest: Vec<&str> = words.collect();
        let at = |m: String| invalid(path, format!("PCD header line {line_no} ({key}): {m}"));
        let one_number = |rest: &[&str]| -> Result<usize> {
            match rest {
                [v] => v
                    .parse::<usize>()
                    .map_err(|_| at(format!("{v:?} is not a whole number"))),
                _ => Err(at("expected one whole number".into())),
            }
        };
        match key.to_ascii_uppercase().as_str() {
            "VERSION" => match rest.as_slice() {
                ["0.7"] | [".7"] => {}
                _ => {
                    return Err(at(format!(
                        "version {} is not read here (PCD 0.7 only)",
                        rest.join(" ")
                    )))
                }
            },
            "FIELDS" | "COLUMNS" => {
                fields = rest
                    .iter()
                    .map(|n| Field {
                        name: n.to_string(),
                        size: 0,
                        kind: 0,
                        count: 1,
                        offset: 0,
                    })
                    .collect();
            }
            "SIZE" => {
                let v = rest
                    .iter()
                    .map(|s| {
                        s.parse::<usize>()
                            .map_err(|_| at(format!("{s:?} is not a size")))
                    })
                    .collect::<Result<Vec<_>>>()?;
                sizes = Some((line_no, v));
            }
            "TYPE" => {
                let v = rest
                    .iter()
                    .map(|s| match s.as_bytes() {
                        [k @ (b'F' | b'U' | b'I')] => Ok(*k),
                        _ => Err(at(format!("{s:?} is not a type (F, U or I)"))),
                    })
                    .collect::<Result<Vec<_>>>()?;
                types = Some((line_no, v));
            }
            "COUNT" => {
                let v = rest
                    .iter()
                    .map(|s| match s.parse::<usize>() {
                        Ok(c) if c >= 1 => Ok(c),
                        _ => Err(at(format!("{s:?} is not a count of at least 1"))),
                    })
                    .collect::<Result<Vec<_>>>()?;
                counts = Some((line_no, v));
            }
            "WIDTH" => width = Some(one_number(&rest)?),
            "HEIGHT" => height = Some(one_number(&rest)?),
            "POINTS" => points = Some(one_number(&rest)?),
            "VIEWPOINT" => {}
            "DATA" => match rest.as_slice() {
                [d] if d.eq_ignore_ascii_case("ascii") => break Data::Ascii,
                [d] if d.eq_ignore_ascii_case("binary") => break Data::Binary,
                [d] if d.eq_ignore_ascii_case("binary_compressed") => break Data::Compressed,
                _ => {
                    return Err(at(format!(
                        "{:?} is not ascii, binary or binary_compressed",
                        rest.join(" ")
                    )))
                }
            },
            _ => return Err(at("unknown header entry".into())),
        }
    };
    let n = fields.len();
    if n == 0 {
        return Err(invalid(path, "PCD header: no FIELDS line"));
    }
    let check_len = |what: &str, entry: Option<(usize, usize)>| -> Result<()> {
        match entry {
            None => Err(invalid(path, format!("PCD header: no {what} line"))),
            Some((line, len)) if len != n => Err(invalid(
                path,
                format!("PCD header line {line} ({what}): {len} entries for {n} FIELDS"),
            )),
            Some(_) => Ok(()),
        }
    };
    check_len("SIZE", sizes.as_ref().map(|(l, v)| (*l, v.len())))?;
    check_len("TYPE", types.as_ref().map(|(l, v)| (*l, v.len())))?;
    if counts.is_some() {
        check_len("COUNT", counts.as_ref().map(|(l, v)| (*l, v.len())))?;
    }
    let (size_line, sizes) = sizes.unwrap_or_default();
    let types = types.map(|(_, v)| v).unwrap_or_default();
    let counts = counts.map(|(_, v)| v).unwrap_or_else(|| vec![1; n]);
    let mut offset = 0usize;
    for (i, f) in fields.iter_mut().enumerate() {
        f.size = sizes[i];
        f.kind = types[i];
        f.count = counts[i];
        let ok = match f.kind {
            b'F' => matches!(f.size, 4 | 8),
            _ => matches!(f.size, 1 | 2 | 4 | 8),
        };
        if !ok {
            return Err(invalid(
                path,
                format!(
                    "PCD header line {size_line}: field {} has TYPE {} with SIZE {} (F takes \
                     4 or 8, U and I 1, 2, 4 or 8)",
                    f.name, f.kind as char, f.size
                ),
            ));
        }
        f.offset = offset;
        offset = f
            .size
            .checked_mul(f.count)
            .and_then(|b| offset.checked_add(b))
            .filter(|&o| o <= MAX_HEADER_BYTES)
            .ok_or_else(|| {
                invalid(
                    path,
                    format!(
                        "PCD header: field {} makes a point record absurdly large",
                        f.name
                    ),
                )
            })?;
    }
    let points = match (points, width, height) {
        (Some(p), Some(w), Some(h)) if w.checked_mul(h) != Some(p) => {
            return Err(invalid(
                path,
                format!("PCD header: POINTS {p} is not WIDTH {w} x HEIGHT {h}"),
            ))
        }
        (Some(p), _, _) => p,
        (None, Some(w), h) => w
            .checked_mul(h.unwrap_or(1))
            .ok_or_else(|| invalid(path, "PCD header: WIDTH x HEIGHT overflows"))?,
        (None, None, _) => return Err(invalid(path, "PCD header: neither POINTS nor WIDTH")),
    };
    Ok(Header {
        fields,
        points,
        data,
        start: pos,
        point_size: offset,
    })
}

/// The header's points x point size, checked.
fn data_bytes(header: &Header, path: &Path) -> Result<usize> {
    header.points.checked_mul(header.point_size).ok_or_else(|| {
        invalid(
            path,
            format!(
                "PCD header: {} points of {} bytes overflow",
                header.points, header.point_size
            ),
        )
    })
}

/// The binary data, exactly as long as the header says.
fn exact_data<'a>(bytes: &'a [u8], header: &Header, path: &Path) -> Result<&'a [u8]> {
    let need = data_bytes(header, path)?;
    let have = bytes.len() - header.start;
    if need != have {
        return Err(invalid(
            path,
            format!(
                "PCD header says {} points of {} bytes ({need} bytes of binary data) but the \
                 file has {have} bytes after the header (from byte offset {})",
                header.points, header.point_size, header.start
            ),
        ));
    }
    Ok(&bytes[header.start..])
}

/// The binary_compressed data, decompressed and checked against the header.
fn decompress(bytes: &[u8], header: &Header, path: &Path) -> Result<Vec<u8>> {
    let start = header.start;
    let word = |at: usize| -> Option<usize> {
        bytes
            .get(at..at + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
    };
    let (Some(compressed), Some(uncompressed)) = (word(start), word(start + 4)) else {
        return Err(invalid(
            path,
            format!("PCD binary_compressed: the two sizes at byte offset {start} are cut off"),
        ));
    };
    let need = data_bytes(header, path)?;
    if uncompressed != need {
        return Err(invalid(
            path,
            format!(
                "PCD binary_compressed: uncompressed size {uncompressed} (byte offset {}) is \
                 not the header's {} points of {} bytes ({need})",
                start + 4,
                header.points,
                header.point_size
            ),
        ));
    }
    let body = &bytes[start + 8..];
    if compressed != body.len() {
        return Err(invalid(
            path,
            format!(
                "PCD binary_compressed: compressed size {compressed} (byte offset {start}) but \
                 {} bytes follow (from byte offset {})",
                body.len(),
                start + 8
            ),
        ));
    }
    if need == 0 {
        return Ok(Vec::new());
    }
    // One LZF back reference (3 bytes) yields at most 264 bytes: a larger claim cannot be
    // true, and is refused before the output is allocated.
    if need / 88 > compressed + 1 {
        return Err(invalid(
            path,
            format!(
                "PCD binary_compressed: {need} bytes cannot come from {compressed} bytes of \
                 LZF data (byte offset {})",
                start + 8
            ),
        ));
    }
    let data = lzf::decompress(body, need).map_err(|e| {
        invalid(
            path,
            format!(
                "PCD binary_compressed: LZF data from byte offset {} is corrupt ({e:?})",
                start + 8
            ),
        )
    })?;
    if data.len() != need {
        return Err(invalid(
            path,
            format!(
                "PCD binary_compressed: LZF data from byte offset {} gives {} bytes, the \
                 header says {need}",
                start + 8,
                data.len()
            ),
        ));
    }
    Ok(data)
}

/// The first element of field `f` at the start of `b` (little-endian), as f64.
fn value(b: &[u8], f: &Field) -> f64 {
    let mut w = [0u8; 8];
    w[..f.size].copy_from_slice(&b[..f.size]);
    match (f.kind, f.size) {
        (b'F', 4) => f64::from(f32::from_le_bytes([w[0], w[1], w[2], w[3]])),
        (b'F', _) => f64::from_le_bytes(w),
        (b'U', _) => u64::from_le_bytes(w) as f64,
        // Sign-extend from the field's width.
        (_, s) => ((i64::from_le_bytes(w) << (64 - 8 * s)) >> (64 - 8 * s)) as f64,
    }
}

/// The points of a binary layout, `get(i, field)` giving field's first element of point i.
fn collect(
    header: &Header,
    w: &Wanted,
    path: &Path,
    get: impl Fn(usize, &Field) -> f64,
) -> Result<Vec<CloudPoint>> {
    let f = &header.fields;
    let mut points = Vec::with_capacity(header.points);
    for i in 0..header.points {
        points.push(CloudPoint {
            x: get(i, &f[w.x]) as f32,
            y: get(i, &f[w.y]) as f32,
            z: get(i, &f[w.z]) as f32,
            intensity: w.intensity.map_or(0.0, |k| get(i, &f[k]) as f32),
            ring: match w.ring {
                Some(k) => Some(ring_from_f64(get(i, &f[k]), i, path)?),
                None => None,
            },
            time: w.time.map(|k| get(i, &f[k])),
        });
    }
    Ok(points)
}

/// The points of `DATA ascii`: one line a point, the values of every field (COUNT each)
/// separated by white space.
fn ascii(bytes: &[u8], header: &Header, w: &Wanted, path: &Path) -> Result<Vec<CloudPoint>> {
    let body = &bytes[header.start..];
    let text = std::str::from_utf8(body).map_err(|e| {
        invalid(
            path,
            format!(
                "PCD ascii data: not text at byte offset {}",
                header.start + e.valid_up_to()
            ),
        )
    })?;
    // Header lines before the data: for file line numbers in messages.
    let first_line = bytes[..header.start]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1;
    // Where each field's first value sits among a line's values.
    let mut column = Vec::with_capacity(header.fields.len());
    let mut values = 0usize;
    for f in &header.fields {
        column.push(values);
        values = values.saturating_add(f.count);
    }
    let fields = &header.fields;
    // At most one point per 2 bytes: the claim is never trusted for the allocation.
    let mut points = Vec::with_capacity(header.points.min(body.len() / 2 + 1));
    let mut tokens: Vec<&str> = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let line_no = first_line + k;
        if line.trim().is_empty() {
            continue;
        }
        let i = points.len();
        if i == header.points {
            return Err(invalid(
                path,
                format!(
                    "PCD ascii data, line {line_no}: more points than the header's POINTS {}",
                    header.points
                ),
            ));
        }
        tokens.clear();
        tokens.extend(line.split_whitespace());
        if tokens.len() != values {
            return Err(invalid(
                path,
                format!(
                    "PCD ascii data, line {line_no} (point {i}): {} values, the header's \
                     fields take {values}",
                    tokens.len()
                ),
            ));
        }
        let get = |k: usize| -> Result<f64> {
            let tok = tokens[column[k]];
            tok.parse::<f64>().map_err(|_| {
                invalid(
                    path,
                    format!(
                        "PCD ascii data, line {line_no} (point {i}), field {}: {tok:?} is not \
                         a number",
                        fields[k].name
                    ),
                )
            })
        };
        points.push(CloudPoint {
            x: get(w.x)? as f32,
            y: get(w.y)? as f32,
            z: get(w.z)? as f32,
            intensity: match w.intensity {
                Some(k) => get(k)? as f32,
                None => 0.0,
            },
            ring: match w.ring {
                Some(k) => Some(ring_from_f64(get(k)?, i, path)?),
                None => None,
            },
            time: match w.time {
                Some(k) => Some(get(k)?),
                None => None,
            },
        });
    }
    if points.len() != header.points {
        return Err(invalid(
            path,
            format!(
                "PCD ascii data: {} points, the header says {}",
                points.len(),
                header.points
            ),
        ));
    }
    Ok(points)
}
