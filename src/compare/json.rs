//! JSON reports: compared value by value; provenance keys are skipped.

use super::{Diffs, PROVENANCE_KEYS};
use serde_json::Value;

/// Compares two JSON documents.
pub fn compare(expected: &[u8], actual: &[u8], diffs: &mut Diffs<'_>) -> Result<(), String> {
    let parse = |b: &[u8], which: &str| {
        serde_json::from_slice::<Value>(b).map_err(|e| format!("the {which} file is not JSON: {e}"))
    };
    let (e, a) = (parse(expected, "expected")?, parse(actual, "actual")?);
    walk(&e, &a, "", "", diffs);
    Ok(())
}

fn join(path: &str, key: &str) -> String {
    if path.is_empty() {
        key.to_string()
    } else {
        format!("{path}.{key}")
    }
}

/// Compares `e` and `a` at `path`; `name` is the last key above it (for tolerances).
fn walk(e: &Value, a: &Value, path: &str, name: &str, diffs: &mut Diffs<'_>) {
    let shown = if path.is_empty() { "(document)" } else { path };
    match (e, a) {
        (Value::Object(eo), Value::Object(ao)) => {
            for (k, ev) in eo {
                if PROVENANCE_KEYS.contains(&k.as_str()) {
                    continue;
                }
                let p = join(path, k);
                match ao.get(k) {
                    Some(av) => walk(ev, av, &p, k, diffs),
                    None => diffs.push(format!("{p}: missing from the actual file")),
                }
            }
            for k in ao.keys() {
                if !eo.contains_key(k) && !PROVENANCE_KEYS.contains(&k.as_str()) {
                    diffs.push(format!("{}: not in the expected file", join(path, k)));
                }
            }
        }
        (Value::Array(ea), Value::Array(aa)) => {
            if ea.len() != aa.len() {
                diffs.push(format!(
                    "{shown}: expected {} entries, actual {}",
                    ea.len(),
                    aa.len()
                ));
            }
            for (i, (ev, av)) in ea.iter().zip(aa).enumerate() {
                walk(ev, av, &format!("{path}[{i}]"), name, diffs);
            }
        }
        (Value::Number(en), Value::Number(an)) => {
            // Integers compare exactly as integers (u64 beyond 2^53 would round in f64).
            if en == an {
                return;
            }
            match (en.as_f64(), an.as_f64()) {
                (Some(x), Some(y)) => diffs.number(shown, name, x, y),
                _ => diffs.text(shown, &en.to_string(), &an.to_string()),
            }
        }
        _ => {
            if e != a {
                diffs.push(format!("{shown}: expected {e}, actual {a}"));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::Tolerances;
    use super::*;

    #[test]
    fn numbers_keys_and_provenance() {
        let t = Tolerances::parse(&["mean=0.1".into()]).unwrap();
        let mut d = Diffs::new(&t);
        let e = br#"{"version":"1","a":{"n":[1,2,3],"mean":1.0,"s":"x"},"gone":1}"#;
        let a = br#"{"version":"2","a":{"n":[1,2,4],"mean":1.05,"s":"y"},"new":1}"#;
        compare(e, a, &mut d).unwrap();
        assert_eq!(d.count, 4, "{:?}", d.listed);
        let all = d.listed.join("\n");
        assert!(all.contains("a.n[2]: expected 3, actual 4"), "{all}");
        assert!(all.contains("a.s:"), "{all}");
        assert!(all.contains("gone: missing"), "{all}");
        assert!(all.contains("new: not in the expected"), "{all}");
        assert!(!all.contains("version"), "{all}");
    }
}
