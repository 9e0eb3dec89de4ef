//! LAS and LAZ point clouds: point format, count, and every point's coordinates, intensity,
//! classification, GPS time and extra-bytes dimensions (by their descriptor names);
//! VLRs other than the Extra Bytes descriptors, dates and software names are provenance.

use super::Diffs;
use std::io::Cursor;
use std::path::Path;

/// Points decoded per batch: memory follows the points the file holds, not the count its
/// header claims.
const BATCH_POINTS: u64 = 1 << 16;

/// One file's points as named columns.
struct Columns {
    format: u8,
    names: Vec<String>,
    columns: Vec<Vec<f64>>,
}

/// Value of an extra-bytes field of LAS data type `ty` (1-10), little-endian.
fn extra_value(ty: u8, b: &[u8]) -> Option<(f64, usize)> {
    let get = |n: usize| b.get(..n);
    Some(match ty {
        1 => (f64::from(*b.first()?), 1),
        2 => (f64::from(*b.first()? as i8), 1),
        3 => (f64::from(u16::from_le_bytes(get(2)?.try_into().ok()?)), 2),
        4 => (f64::from(i16::from_le_bytes(get(2)?.try_into().ok()?)), 2),
        5 => (f64::from(u32::from_le_bytes(get(4)?.try_into().ok()?)), 4),
        6 => (f64::from(i32::from_le_bytes(get(4)?.try_into().ok()?)), 4),
        7 => (u64::from_le_bytes(get(8)?.try_into().ok()?) as f64, 8),
        8 => (i64::from_le_bytes(get(8)?.try_into().ok()?) as f64, 8),
        9 => (f64::from(f32::from_le_bytes(get(4)?.try_into().ok()?)), 4),
        10 => (f64::from_le_bytes(get(8)?.try_into().ok()?), 8),
        _ => return None,
    })
}

fn read(bytes: &[u8]) -> Result<Columns, String> {
    check_point_count(bytes)?;
    let mut reader =
        las::Reader::new(Cursor::new(bytes.to_vec())).map_err(|e| format!("not LAS/LAZ: {e}"))?;
    let header = reader.header().clone();
    let points = header.number_of_points();
    let mut extra: Vec<(String, u8)> = Vec::new();
    if let Some(vlr) = header
        .vlrs()
        .iter()
        .find(|v| v.user_id == "LASF_Spec" && v.record_id == 4)
    {
        for d in vlr.data.chunks_exact(192) {
            let name: String = d[4..36]
                .iter()
                .take_while(|&&b| b != 0)
                .map(|&b| b as char)
                .collect();
            extra.push((name, d[2]));
        }
    }
    let mut names: Vec<String> = ["x", "y", "z", "intensity", "classification", "gps_time"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    names.extend(extra.iter().map(|(n, _)| n.clone()));
    let mut columns = vec![Vec::new(); names.len()];
    let mut data = las::PointDataBuilder::new().for_header(&header).build();
    let mut read = 0u64;
    while read < points {
        let got = reader
            .fill_points((points - read).min(BATCH_POINTS), &mut data)
            .map_err(|e| format!("point {read}: {e}"))?;
        if got == 0 {
            return Err(format!(
                "the header claims {points} points, but the point data ends after {read}: \
                 the file is truncated or its header is corrupt; write it again"
            ));
        }
        for (k, p) in data.points().enumerate() {
            let i = read + k as u64;
            let p = p.map_err(|e| format!("point {i}: {e}"))?;
            let base = [
                p.x,
                p.y,
                p.z,
                f64::from(p.intensity),
                f64::from(u8::from(p.classification)),
                p.gps_time.unwrap_or(f64::NAN),
            ];
            for (c, v) in columns.iter_mut().zip(base) {
                c.push(v);
            }
            let mut at = 0;
            for (k, (name, ty)) in extra.iter().enumerate() {
                let (v, n) = extra_value(*ty, &p.extra_bytes[at.min(p.extra_bytes.len())..])
                    .ok_or_else(|| format!("point {i}: cannot decode extra dimension {name}"))?;
                columns[6 + k].push(v);
                at += n;
            }
        }
        read += got;
    }
    Ok(Columns {
        format: header.point_format().to_u8().unwrap_or(0),
        names,
        columns,
    })
}

/// Checks the header's point count against the file's size before the las crate sees it:
/// it sizes its buffer by the count (a header claiming 2^63 points filled the memory) and
/// computes the end of the points by an unchecked product. Uncompressed records must fit
/// in the file; compressed ones are read in batches (see [`BATCH_POINTS`]), so a false
/// count ends at the data's end, once the end it implies is a number.
fn check_point_count(bytes: &[u8]) -> Result<(), String> {
    let raw =
        las::raw::Header::read_from(Cursor::new(bytes)).map_err(|e| format!("not LAS/LAZ: {e}"))?;
    // As the las crate reads it: the legacy 32-bit count unless it is 0.
    let points = match (raw.number_of_point_records, raw.large_file) {
        (0, Some(large)) => large.number_of_point_records,
        (n, _) => u64::from(n),
    };
    let record = u64::from(raw.point_data_record_length);
    let start = u64::from(raw.offset_to_point_data);
    let compressed = raw.point_data_record_format & 0x80 != 0;
    let room = (bytes.len() as u64).saturating_sub(start);
    let claimed = points
        .checked_mul(record)
        .filter(|&n| start.checked_add(n).is_some());
    match claimed {
        Some(n) if compressed || n <= room => Ok(()),
        _ => Err(format!(
            "the header claims {points} points of {record} bytes, but the file holds {room} \
             bytes of point data (from byte offset {start} to its end at {}): the file is \
             truncated or its header is corrupt; write it again",
            bytes.len()
        )),
    }
}

/// Compares two LAS or LAZ files, each given by its path (for messages) and its bytes.
pub fn compare(
    (expected_path, expected): (&Path, &[u8]),
    (actual_path, actual): (&Path, &[u8]),
    diffs: &mut Diffs<'_>,
) -> Result<(), String> {
    let e = read(expected)
        .map_err(|m| format!("the expected file {}: {m}", expected_path.display()))?;
    let a = read(actual).map_err(|m| format!("the actual file {}: {m}", actual_path.display()))?;
    if e.format != a.format {
        diffs.push(format!(
            "point format: expected {}, actual {}",
            e.format, a.format
        ));
    }
    if e.names != a.names {
        diffs.push(format!(
            "dimensions: expected {}, actual {}",
            e.names.join(" "),
            a.names.join(" ")
        ));
        return Ok(());
    }
    let (en, an) = (e.columns[0].len(), a.columns[0].len());
    if en != an {
        diffs.push(format!("points: expected {en}, actual {an}"));
        return Ok(());
    }
    for (name, (ec, ac)) in e.names.iter().zip(e.columns.iter().zip(&a.columns)) {
        diffs.column("points", name, ec, ac);
    }
    Ok(())
}
