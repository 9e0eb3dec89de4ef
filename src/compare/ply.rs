//! PLY point clouds: same elements and properties (names and types), value by value;
//! comments (provenance) are ignored. Binary little-endian and ASCII files with scalar
//! properties, the layouts this tool writes.

use super::Diffs;

/// A parsed PLY: its elements with their properties and values (as f64, exact for
/// every PLY scalar type but 64-bit doubles, which are f64 already).
#[derive(Debug, Default)]
pub struct PlyData {
    /// `format` line value, e.g. `binary_little_endian`.
    pub format: String,
    /// Elements in file order.
    pub elements: Vec<Element>,
}

/// One element of a PLY file.
#[derive(Debug, Default)]
pub struct Element {
    /// Element name (`vertex`).
    pub name: String,
    /// Number of items.
    pub count: usize,
    /// (type, name) of each property, in order.
    pub properties: Vec<(String, String)>,
    /// One column of values per property.
    pub columns: Vec<Vec<f64>>,
}

fn type_size(ty: &str) -> Option<usize> {
    Some(match ty {
        "char" | "uchar" | "int8" | "uint8" => 1,
        "short" | "ushort" | "int16" | "uint16" => 2,
        "int" | "uint" | "float" | "int32" | "uint32" | "float32" => 4,
        "double" | "float64" => 8,
        _ => return None,
    })
}

fn decode(ty: &str, b: &[u8]) -> f64 {
    let a4 = |b: &[u8]| [b[0], b[1], b[2], b[3]];
    match ty {
        "char" | "int8" => f64::from(b[0] as i8),
        "uchar" | "uint8" => f64::from(b[0]),
        "short" | "int16" => f64::from(i16::from_le_bytes([b[0], b[1]])),
        "ushort" | "uint16" => f64::from(u16::from_le_bytes([b[0], b[1]])),
        "int" | "int32" => f64::from(i32::from_le_bytes(a4(b))),
        "uint" | "uint32" => f64::from(u32::from_le_bytes(a4(b))),
        "float" | "float32" => f64::from(f32::from_le_bytes(a4(b))),
        _ => f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]),
    }
}

/// Parses a PLY file, or says what is wrong with it.
pub fn parse(bytes: &[u8]) -> Result<PlyData, String> {
    let end = b"end_header\n";
    let header_len = bytes
        .windows(end.len())
        .position(|w| w == end)
        .map(|p| p + end.len())
        .ok_or("no end_header line")?;
    let header = std::str::from_utf8(&bytes[..header_len]).map_err(|_| "header is not UTF-8")?;
    let mut data = PlyData::default();
    for line in header.lines() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("format") => data.format = words.next().unwrap_or("").to_string(),
            Some("element") => {
                let name = words.next().unwrap_or("").to_string();
                let count = words
                    .next()
                    .and_then(|c| c.parse().ok())
                    .ok_or_else(|| format!("bad element line `{line}`"))?;
                data.elements.push(Element {
                    name,
                    count,
                    ..Element::default()
                });
            }
            Some("property") => {
                let (ty, name) = (words.next().unwrap_or(""), words.next().unwrap_or(""));
                if type_size(ty).is_none() {
                    return Err(format!("unsupported property line `{line}`"));
                }
                let el = data
                    .elements
                    .last_mut()
                    .ok_or("a property before any element")?;
                el.properties.push((ty.to_string(), name.to_string()));
                el.columns.push(Vec::new());
            }
            _ => {}
        }
    }
    let body = &bytes[header_len..];
    match data.format.as_str() {
        "binary_little_endian" => {
            let mut at = 0;
            for el in &mut data.elements {
                let sizes: Vec<usize> = el
                    .properties
                    .iter()
                    .map(|(t, _)| type_size(t).unwrap_or(0))
                    .collect();
                let stride: usize = sizes.iter().sum();
                if body.len() < at + stride * el.count {
                    return Err(format!(
                        "element {} needs {} bytes, the file has {}",
                        el.name,
                        stride * el.count,
                        body.len() - at
                    ));
                }
                for _ in 0..el.count {
                    for ((ty, _), (col, size)) in
                        el.properties.iter().zip(el.columns.iter_mut().zip(&sizes))
                    {
                        col.push(decode(ty, &body[at..at + size]));
                        at += size;
                    }
                }
            }
        }
        "ascii" => {
            let text = std::str::from_utf8(body).map_err(|_| "ASCII body is not UTF-8")?;
            let mut lines = text.lines();
            for el in &mut data.elements {
                for i in 0..el.count {
                    let line = lines
                        .next()
                        .ok_or_else(|| format!("element {} ends after {i} lines", el.name))?;
                    let mut words = line.split_whitespace();
                    for ((ty, name), col) in el.properties.iter().zip(&mut el.columns) {
                        let w = words
                            .next()
                            .ok_or_else(|| format!("{} {i}: no {name}", el.name))?;
                        // Floats parse as their own width so that the value is the stored one.
                        let v = if ty.starts_with("float") && ty != "float64" {
                            w.parse::<f32>().map(f64::from).ok()
                        } else {
                            w.parse::<f64>().ok()
                        }
                        .ok_or_else(|| format!("{} {i} {name}: `{w}` is not a number", el.name))?;
                        col.push(v);
                    }
                }
            }
        }
        other => return Err(format!("unsupported PLY format `{other}`")),
    }
    Ok(data)
}

/// Compares two PLY files.
pub fn compare(expected: &[u8], actual: &[u8], diffs: &mut Diffs<'_>) -> Result<(), String> {
    let e = parse(expected).map_err(|m| format!("the expected file: {m}"))?;
    let a = parse(actual).map_err(|m| format!("the actual file: {m}"))?;
    diffs.text("format", &e.format, &a.format);
    let names = |d: &PlyData| -> Vec<String> {
        d.elements
            .iter()
            .map(|el| format!("{} {}", el.name, el.count))
            .collect()
    };
    if names(&e) != names(&a) {
        diffs.push(format!(
            "elements: expected {}, actual {}",
            names(&e).join(", "),
            names(&a).join(", ")
        ));
        return Ok(());
    }
    for (ee, ae) in e.elements.iter().zip(&a.elements) {
        if ee.properties != ae.properties {
            let list = |el: &Element| -> String {
                el.properties
                    .iter()
                    .map(|(t, n)| format!("{t} {n}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            diffs.push(format!(
                "{} properties: expected {}, actual {}",
                ee.name,
                list(ee),
                list(ae)
            ));
            continue;
        }
        for ((_, name), (ec, ac)) in ee.properties.iter().zip(ee.columns.iter().zip(&ae.columns)) {
            diffs.column(&ee.name, name, ec, ac);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::Tolerances;
    use super::*;

    #[test]
    fn ascii_and_binary_parse_to_the_same_values() {
        let ascii = b"ply\nformat ascii 1.0\ncomment x\nelement vertex 2\nproperty float x\nproperty uchar r\nend_header\n0.1 7\n-2.5 255\n";
        let mut bin = b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty uchar r\nend_header\n".to_vec();
        for (x, r) in [(0.1f32, 7u8), (-2.5, 255)] {
            bin.extend_from_slice(&x.to_le_bytes());
            bin.push(r);
        }
        let (a, b) = (parse(ascii).unwrap(), parse(&bin).unwrap());
        assert_eq!(a.elements[0].columns, b.elements[0].columns);
        assert_eq!(a.elements[0].columns[0][0], f64::from(0.1f32));
        assert!(parse(&bin[..bin.len() - 1]).is_err());
        let t = Tolerances::default();
        let mut d = Diffs::new(&t);
        let changed = String::from_utf8(ascii.to_vec())
            .unwrap()
            .replace("-2.5 255", "-2.5 254");
        compare(ascii, changed.as_bytes(), &mut d).unwrap();
        assert_eq!(
            d.listed,
            ["r: 1 of 2 vertex differ, largest by 1; first vertex 1: expected 255, actual 254"]
        );
    }
}
