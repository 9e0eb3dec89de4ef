//! LAS and LAZ point clouds: point format, count, and every point's coordinates, intensity,
//! classification, GPS time and extra-bytes dimensions (by their descriptor names);
//! VLRs other than the Extra Bytes descriptors, dates and software names are provenance.

use super::Diffs;
use std::io::Cursor;

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
    let mut reader =
        las::Reader::new(Cursor::new(bytes.to_vec())).map_err(|e| format!("not LAS/LAZ: {e}"))?;
    let header = reader.header().clone();
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
    let data = reader.read_all().map_err(|e| format!("points: {e}"))?;
    for (i, p) in data.points().enumerate() {
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
    Ok(Columns {
        format: header.point_format().to_u8().unwrap_or(0),
        names,
        columns,
    })
}

/// Compares two LAS or LAZ files.
pub fn compare(expected: &[u8], actual: &[u8], diffs: &mut Diffs<'_>) -> Result<(), String> {
    let e = read(expected).map_err(|m| format!("the expected file: {m}"))?;
    let a = read(actual).map_err(|m| format!("the actual file: {m}"))?;
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
