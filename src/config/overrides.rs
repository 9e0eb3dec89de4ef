//! Key positions of a TOML file and `--set key=value` overrides of the parsed document.

use crate::config::reader::Locator;
use std::collections::HashMap;
use toml::de::{DeTable, DeValue};
use toml::{Spanned, Table, Value};

/// Converts a byte offset of `text` to a 1-based (line, column in characters).
pub fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = before[line_start..].chars().count() + 1;
    (line, column)
}

/// Line and column of every key and array element of the document, by dotted path.
pub fn key_positions(text: &str, root: &Spanned<DeTable<'_>>) -> HashMap<String, (usize, usize)> {
    let mut spans = HashMap::new();
    walk_table(text, root.get_ref(), "", &mut spans);
    spans
}

fn walk_table(
    text: &str,
    table: &DeTable<'_>,
    prefix: &str,
    spans: &mut HashMap<String, (usize, usize)>,
) {
    for (key, value) in table.iter() {
        let path = if prefix.is_empty() {
            key.get_ref().to_string()
        } else {
            format!("{prefix}.{}", key.get_ref())
        };
        // The key's own position: that is the line a user looks for.
        spans
            .entry(path.clone())
            .or_insert_with(|| line_column(text, key.span().start));
        walk_value(text, value, &path, spans);
    }
}

fn walk_value(
    text: &str,
    value: &Spanned<DeValue<'_>>,
    path: &str,
    spans: &mut HashMap<String, (usize, usize)>,
) {
    match value.get_ref() {
        DeValue::Table(t) => walk_table(text, t, path, spans),
        DeValue::Array(items) => {
            for (i, item) in items.iter().enumerate() {
                let elem = format!("{path}[{i}]");
                spans.insert(elem.clone(), line_column(text, item.span().start));
                walk_value(text, item, &elem, spans);
            }
        }
        _ => {}
    }
}

/// One step of a dotted override path.
#[derive(Debug, PartialEq)]
enum Segment {
    Key(String),
    Index(usize),
}

/// Splits `noise[1].rate_mm_h` into keys and indices, or explains what is wrong.
fn parse_path(path: &str) -> Result<Vec<Segment>, String> {
    let mut out = Vec::new();
    for part in path.split('.') {
        let (name, mut rest) = match part.find('[') {
            Some(i) => (&part[..i], &part[i..]),
            None => (part, ""),
        };
        if name.is_empty()
            || !name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            return Err(format!("\"{part}\" is not a key name"));
        }
        out.push(Segment::Key(name.to_string()));
        while !rest.is_empty() {
            let close = rest
                .find(']')
                .filter(|_| rest.starts_with('['))
                .ok_or_else(|| format!("malformed index in \"{part}\""))?;
            let index: usize = rest[1..close]
                .parse()
                .map_err(|_| format!("\"{}\" is not an index", &rest[1..close]))?;
            out.push(Segment::Index(index));
            rest = &rest[close + 1..];
        }
    }
    Ok(out)
}

/// The dotted path in canonical form (as used in error messages).
fn canonical(segments: &[Segment]) -> String {
    let mut s = String::new();
    for seg in segments {
        match seg {
            Segment::Key(k) => {
                if !s.is_empty() {
                    s.push('.');
                }
                s.push_str(k);
            }
            Segment::Index(i) => s.push_str(&format!("[{i}]")),
        }
    }
    s
}

/// Parses the value of a `--set` as a TOML value, or takes it as a string.
fn parse_value(text: &str) -> Value {
    toml::from_str::<Table>(&format!("v = {text}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| Value::String(text.to_string()))
}

/// Resolves the stage shorthand `<stage type>.<option>` (e.g. `rain.rate_mm_h`) to the
/// path of that option in the first stage of that type, `noise[i].<option>`, appending a
/// stage of that type when the configuration has none. Any other key gives `None`.
/// `--set` and `sweep --vary` share it.
pub fn stage_shorthand(root: &mut Table, key: &str) -> Option<String> {
    let (stage, option) = key.split_once('.')?;
    let is_stage = super::STAGE_TYPES.contains(&stage);
    if !is_stage || option.is_empty() || option.contains(['.', '[']) {
        return None;
    }
    let Value::Array(items) = root
        .entry("noise")
        .or_insert_with(|| Value::Array(Vec::new()))
    else {
        // `noise` is not an array: the plain path reports that.
        return None;
    };
    let of_type = |v: &Value| v.get("type").and_then(Value::as_str) == Some(stage);
    let i = match items.iter().position(of_type) {
        Some(i) => i,
        None => {
            let mut t = Table::new();
            t.insert("type".into(), Value::String(stage.into()));
            items.push(Value::Table(t));
            items.len() - 1
        }
    };
    Some(format!("noise[{i}].{option}"))
}

/// Applies one `key=value` override to `root`, recording its path in `locator`.
///
/// Intermediate tables are created when missing; an array index may be one past the end
/// to append a new table (e.g. a new `[[noise]]` stage). The key may be the stage
/// shorthand of [`stage_shorthand`].
pub fn apply_set(root: &mut Table, arg: &str, locator: &mut Locator) -> Result<(), String> {
    // A value is parsed as the TOML line `v = VALUE`: a line break would let the rest of
    // the argument be read as other keys and silently dropped.
    if arg.contains(['\n', '\r']) {
        return Err(
            "holds a line break: give one key=value per --set (repeat --set for more)".into(),
        );
    }
    let (path, text) = arg
        .split_once('=')
        .ok_or_else(|| "expected key=value".to_string())?;
    let expanded = stage_shorthand(root, path.trim());
    let segments = parse_path(expanded.as_deref().unwrap_or(path.trim()))?;
    let value = parse_value(text.trim());
    let mut cur: &mut Value = {
        let Some(Segment::Key(first)) = segments.first() else {
            return Err("empty key".into());
        };
        if segments.len() == 1 {
            root.insert(first.clone(), value);
            locator.sets.push((canonical(&segments), arg.to_string()));
            return Ok(());
        }
        root.entry(first.clone())
            .or_insert_with(|| empty_for(&segments[1]))
    };
    for (i, seg) in segments.iter().enumerate().skip(1) {
        let last = i + 1 == segments.len();
        let here = canonical(&segments[..i]);
        cur = match seg {
            Segment::Key(k) => {
                let Value::Table(t) = cur else {
                    return Err(format!("{here} is not a table"));
                };
                if last {
                    t.insert(k.clone(), value);
                    break;
                }
                t.entry(k.clone())
                    .or_insert_with(|| empty_for(&segments[i + 1]))
            }
            Segment::Index(n) => {
                let Value::Array(items) = cur else {
                    return Err(format!("{here} is not an array"));
                };
                if *n == items.len() && !last {
                    items.push(empty_for(&segments[i + 1]));
                }
                let len = items.len();
                let slot = items.get_mut(*n).ok_or_else(|| {
                    format!("index {n} is out of range: {here} has {len} entries")
                })?;
                if last {
                    *slot = value;
                    break;
                }
                slot
            }
        };
    }
    locator.sets.push((canonical(&segments), arg.to_string()));
    Ok(())
}

/// The empty container a path segment needs to step into.
fn empty_for(next: &Segment) -> Value {
    match next {
        Segment::Key(_) => Value::Table(Table::new()),
        Segment::Index(_) => Value::Array(Vec::new()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_parse() {
        assert_eq!(
            parse_path("noise[1].rate_mm_h").unwrap(),
            vec![
                Segment::Key("noise".into()),
                Segment::Index(1),
                Segment::Key("rate_mm_h".into())
            ]
        );
        assert!(parse_path("noise[x]").is_err());
        assert!(parse_path("a..b").is_err());
    }

    #[test]
    fn stage_shorthand_finds_or_appends_the_stage() {
        let mut root: Table =
            toml::from_str("[[noise]]\ntype = \"occlusion\"\n[[noise]]\ntype = \"rain\"\n")
                .unwrap();
        let mut loc = Locator::default();
        apply_set(&mut root, "rain.rate_mm_h=3", &mut loc).unwrap();
        assert_eq!(root["noise"][1]["rate_mm_h"].as_integer(), Some(3));
        assert_eq!(loc.sets[0].0, "noise[1].rate_mm_h");
        let mut empty = Table::new();
        apply_set(&mut empty, "rain.rate_mm_h=2", &mut loc).unwrap();
        assert_eq!(empty["noise"][0]["type"].as_str(), Some("rain"));
        assert_eq!(stage_shorthand(&mut empty, "detection.min_power"), None);
        assert_eq!(stage_shorthand(&mut empty, "rain.a.b"), None);
    }

    #[test]
    fn line_columns_count_from_one() {
        assert_eq!(line_column("a\nbc = 1", 3), (2, 2));
        assert_eq!(line_column("x", 0), (1, 1));
    }
}
