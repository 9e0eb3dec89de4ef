//! Typed reading of a parsed TOML document with errors that name the dotted key and the
//! place it came from (a line of the file or a `--set` argument).

use crate::error::Error;
use std::cell::RefCell;
use std::collections::{BTreeSet, HashMap};
use std::path::PathBuf;
use toml::{Table, Value};

/// Where each key of the document came from: used to point errors at a line or a `--set`.
#[derive(Clone, Debug, Default)]
pub struct Locator {
    /// The file name used in errors (a path, or a label for the built-in default).
    pub(crate) file: PathBuf,
    /// Line and column (1-based) of each dotted key path as written in the file.
    pub(crate) spans: HashMap<String, (usize, usize)>,
    /// Dotted key paths replaced by `--set`, with the argument that replaced them.
    pub(crate) sets: Vec<(String, String)>,
}

impl Locator {
    /// Describes where `path` came from: " (--set ARG)", " (line L, column C)" or "".
    pub fn origin(&self, path: &str) -> String {
        // The latest --set wins, as it does when the overrides are applied.
        for (set_path, arg) in self.sets.iter().rev() {
            if is_prefix_path(set_path, path) {
                return format!(" (from --set {arg})");
            }
        }
        let mut probe = path.to_string();
        loop {
            if let Some(&(line, column)) = self.spans.get(&probe) {
                return format!(" (line {line}, column {column})");
            }
            // A table the file does not have but a --set wrote into came from that --set
            // (not from the line of the array it was appended to).
            if probe != path {
                if let Some((_, arg)) = self
                    .sets
                    .iter()
                    .rev()
                    .find(|(set_path, _)| is_prefix_path(&probe, set_path))
                {
                    return format!(" (in {probe}, created by --set {arg})");
                }
            }
            match parent_path(&probe) {
                Some(parent) => probe = parent,
                None => return String::new(),
            }
        }
    }

    /// Builds the configuration error for `path` with its origin.
    pub fn error(&self, path: &str, message: impl std::fmt::Display) -> Error {
        let name = if path.is_empty() { "(top level)" } else { path };
        Error::Config {
            path: self.file.clone(),
            message: format!("{name}{}: {message}", self.origin(path)),
        }
    }
}

/// True if `prefix` equals `path` or is one of its ancestors (`a` of `a.b` or `a[1]`).
fn is_prefix_path(prefix: &str, path: &str) -> bool {
    path == prefix
        || (path.starts_with(prefix)
            && matches!(path.as_bytes().get(prefix.len()), Some(b'.') | Some(b'[')))
}

/// The dotted path one level up (`noise[1].rate` -> `noise[1]` -> `noise`), if any.
fn parent_path(path: &str) -> Option<String> {
    let cut = path.rfind(['.', '['])?;
    Some(path[..cut].to_string())
}

/// Shared state of one configuration read: the locator and the collected warnings.
#[derive(Debug)]
pub struct ReadContext {
    /// Origins of keys.
    pub locator: Locator,
    /// Warnings collected so far, already prefixed with key and origin.
    pub warnings: RefCell<Vec<String>>,
}

/// One table of the document being read; remembers which keys were used so that any
/// other key can be reported as unknown.
pub struct Section<'a> {
    table: &'a Table,
    path: String,
    ctx: &'a ReadContext,
    seen: RefCell<BTreeSet<String>>,
}

impl<'a> Section<'a> {
    /// Starts reading `table`, found at dotted `path` ("" for the document root).
    pub fn new(table: &'a Table, path: impl Into<String>, ctx: &'a ReadContext) -> Self {
        Section {
            table,
            path: path.into(),
            ctx,
            seen: RefCell::new(BTreeSet::new()),
        }
    }

    /// The table being read, as written.
    pub fn raw(&self) -> &'a Table {
        self.table
    }

    /// The dotted path of this table.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// The dotted path of `key` in this table.
    pub fn key_path(&self, key: &str) -> String {
        if self.path.is_empty() {
            key.to_string()
        } else {
            format!("{}.{key}", self.path)
        }
    }

    /// An error about `key` of this table (or about the table itself when `key` is "").
    pub fn error(&self, key: &str, message: impl std::fmt::Display) -> Error {
        let path = if key.is_empty() {
            self.path.clone()
        } else {
            self.key_path(key)
        };
        self.ctx.locator.error(&path, message)
    }

    /// Records a warning about `key`; the loader returns warnings to the caller.
    pub fn warn(&self, key: &str, message: impl std::fmt::Display) {
        let path = self.key_path(key);
        let origin = self.ctx.locator.origin(&path);
        self.ctx
            .warnings
            .borrow_mut()
            .push(format!("{path}{origin}: {message}"));
    }

    /// The raw value of `key`, marking it used.
    pub fn value(&self, key: &str) -> Option<&'a Value> {
        self.seen.borrow_mut().insert(key.to_string());
        self.table.get(key)
    }

    /// True if the table has `key` (does not mark it used).
    pub fn has(&self, key: &str) -> bool {
        self.table.contains_key(key)
    }

    /// A finite number (integer or float) at `key`.
    pub fn f64(&self, key: &str) -> crate::error::Result<Option<f64>> {
        self.value(key)
            .map(|v| number(v).ok_or_else(|| self.error(key, expected("a number", v))))
            .transpose()
    }

    /// An integer at `key`.
    pub fn i64(&self, key: &str) -> crate::error::Result<Option<i64>> {
        self.value(key)
            .map(|v| match v {
                Value::Integer(i) => Ok(*i),
                _ => Err(self.error(key, expected("an integer", v))),
            })
            .transpose()
    }

    /// A string at `key`.
    pub fn str(&self, key: &str) -> crate::error::Result<Option<&'a str>> {
        self.value(key)
            .map(|v| match v {
                Value::String(s) => Ok(s.as_str()),
                _ => Err(self.error(key, expected("a string", v))),
            })
            .transpose()
    }

    /// A string at `key` that must be one of `choices`.
    pub fn choice(&self, key: &str, choices: &[&str]) -> crate::error::Result<Option<&'a str>> {
        match self.str(key)? {
            None => Ok(None),
            Some(s) if choices.contains(&s) => Ok(Some(s)),
            Some(s) => Err(self.error(
                key,
                format!(
                    "unknown value \"{s}\" (expected one of: {})",
                    choices.join(", ")
                ),
            )),
        }
    }

    /// A non-empty array of integers in `0..=max` at `key`; errors name the element.
    pub fn id_list(&self, key: &str, max: u8) -> crate::error::Result<Option<Vec<u8>>> {
        let Some(v) = self.value(key) else {
            return Ok(None);
        };
        let Value::Array(items) = v else {
            return Err(self.error(key, expected("an array of integers", v)));
        };
        if items.is_empty() {
            return Err(self.error(key, "the list is empty: name at least one"));
        }
        let mut out = Vec::with_capacity(items.len());
        for (i, item) in items.iter().enumerate() {
            let elem = format!("{key}[{i}]");
            match item {
                Value::Integer(n) if (0..=i64::from(max)).contains(n) => out.push(*n as u8),
                Value::Integer(n) => {
                    return Err(self.error(&elem, format!("{n} is out of range 0..={max}")))
                }
                _ => return Err(self.error(&elem, expected("an integer", item))),
            }
        }
        Ok(Some(out))
    }

    /// A two-number array `[a, b]` at `key`.
    pub fn pair(&self, key: &str) -> crate::error::Result<Option<[f64; 2]>> {
        let Some(v) = self.value(key) else {
            return Ok(None);
        };
        match v {
            Value::Array(items) if items.len() == 2 => {
                let mut out = [0.0; 2];
                for (i, item) in items.iter().enumerate() {
                    out[i] = number(item).ok_or_else(|| {
                        self.error(&format!("{key}[{i}]"), expected("a number", item))
                    })?;
                }
                Ok(Some(out))
            }
            _ => Err(self.error(key, expected("an array of two numbers", v))),
        }
    }

    /// The sub-table at `key`, to read further.
    pub fn table(&self, key: &str) -> crate::error::Result<Option<Section<'a>>> {
        self.value(key)
            .map(|v| match v {
                Value::Table(t) => Ok(Section::new(t, self.key_path(key), self.ctx)),
                _ => Err(self.error(key, expected("a table", v))),
            })
            .transpose()
    }

    /// The sub-table at `key` taken as an opaque table (validated elsewhere).
    pub fn raw_table(&self, key: &str) -> crate::error::Result<Option<Table>> {
        self.value(key)
            .map(|v| match v {
                Value::Table(t) => Ok(t.clone()),
                _ => Err(self.error(key, expected("a table", v))),
            })
            .transpose()
    }

    /// The array of tables at `key` (`[[key]]`), each to read further.
    pub fn table_array(&self, key: &str) -> crate::error::Result<Vec<Section<'a>>> {
        let Some(v) = self.value(key) else {
            return Ok(Vec::new());
        };
        let Value::Array(items) = v else {
            return Err(self.error(key, expected("an array of tables ([[...]])", v)));
        };
        items
            .iter()
            .enumerate()
            .map(|(i, item)| match item {
                Value::Table(t) => Ok(Section::new(
                    t,
                    format!("{}[{i}]", self.key_path(key)),
                    self.ctx,
                )),
                _ => Err(self.error(&format!("{key}[{i}]"), expected("a table", item))),
            })
            .collect()
    }

    /// An error for a required key that is missing.
    pub fn missing(&self, key: &str) -> Error {
        let here = if self.path.is_empty() {
            "the top level".to_string()
        } else {
            self.path.clone()
        };
        // Point at the table: the key itself has no line.
        self.ctx.locator.error(
            &self.key_path(key),
            format!("required key missing in {here}"),
        )
    }

    /// Fails on the first key of this table that was never asked for.
    pub fn finish(&self) -> crate::error::Result<()> {
        let seen: Vec<String> = self.seen.borrow().iter().cloned().collect();
        let known: Vec<&str> = seen.iter().map(String::as_str).collect();
        self.finish_listing(&known)
    }

    /// [`Section::finish`] naming `options` (every key the table may hold) in the error,
    /// with the one closest to the unknown key.
    pub fn finish_listing(&self, options: &[&str]) -> crate::error::Result<()> {
        match self
            .unknown_keys(|k| self.seen.borrow().contains(k))
            .first()
        {
            None => Ok(()),
            Some(key) => Err(self.unknown_key_error(key, options)),
        }
    }

    /// The keys of this table for which `known` is false, the first in the file first
    /// (which is what a reader scanning the file expects); keys without a line (from
    /// --set) come last.
    pub fn unknown_keys(&self, known: impl Fn(&str) -> bool) -> Vec<String> {
        let mut unknown: Vec<(usize, usize, &String)> = self
            .table
            .keys()
            .filter(|k| !known(k))
            .map(|k| {
                let (line, col) = self
                    .ctx
                    .locator
                    .spans
                    .get(&self.key_path(k))
                    .copied()
                    .unwrap_or((usize::MAX, 0));
                (line, col, k)
            })
            .collect();
        unknown.sort();
        unknown.into_iter().map(|(_, _, k)| k.clone()).collect()
    }

    /// The error for an unknown `key`: the closest of `options` when one is near, and
    /// the whole list.
    pub fn unknown_key_error(&self, key: &str, options: &[&str]) -> Error {
        let hint = closest(key, options)
            .map(|c| format!("did you mean `{c}`? "))
            .unwrap_or_default();
        self.error(
            key,
            format!(
                "unknown key ({hint}known keys here: {})",
                options.join(", ")
            ),
        )
    }
}

/// The option nearest to a misspelt `key` (edit distance at most a third of its length,
/// at least 2; case ignored), else the only option it begins (`rate` for `rate_mm_h`).
pub fn closest<'o>(key: &str, options: &[&'o str]) -> Option<&'o str> {
    let key = key.to_lowercase();
    let limit = (key.chars().count() / 3).max(2);
    let near = options
        .iter()
        .map(|o| (edit_distance(&key, &o.to_lowercase()), *o))
        .filter(|(d, _)| *d <= limit)
        .min_by_key(|(d, _)| *d)
        .map(|(_, o)| o);
    near.or_else(|| {
        let mut starting = options
            .iter()
            .filter(|o| key.len() >= 3 && o.to_lowercase().starts_with(&key));
        match (starting.next(), starting.next()) {
            (Some(o), None) => Some(*o),
            _ => None,
        }
    })
}

/// Levenshtein distance between two short strings (keys), by characters.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diag = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let next = (diag + usize::from(ca != cb))
                .min(row[j] + 1)
                .min(row[j + 1] + 1);
            diag = row[j + 1];
            row[j + 1] = next;
        }
    }
    row[b.len()]
}

/// A finite number from an integer or float value.
fn number(v: &Value) -> Option<f64> {
    match v {
        Value::Integer(i) => Some(*i as f64),
        Value::Float(f) if f.is_finite() => Some(*f),
        _ => None,
    }
}

/// "expected X, found Y" with the TOML type and value of what was found.
fn expected(what: &str, found: &Value) -> String {
    let shown = match found {
        Value::Table(_) => "a table".to_string(),
        Value::Array(_) => format!("an array {found}"),
        _ => format!("{} {found}", found.type_str()),
    };
    format!("expected {what}, found {shown}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edit_distance_by_hand() {
        assert_eq!(edit_distance("", ""), 0);
        assert_eq!(edit_distance("rate_mmh", "rate_mm_h"), 1);
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        assert_eq!(edit_distance("abc", ""), 3);
        assert_eq!(edit_distance("flaw", "lawn"), 2);
    }

    #[test]
    fn closest_option_by_distance_then_by_prefix() {
        let o = ["rate_mm_h", "range_noise", "backscatter", "model"];
        assert_eq!(closest("rate_mmh", &o), Some("rate_mm_h"));
        assert_eq!(closest("BACKSCATER", &o), Some("backscatter"));
        assert_eq!(closest("rate", &o), Some("rate_mm_h"));
        // "ra" begins two options and is too short: no guess.
        assert_eq!(closest("ra", &o), None);
        assert_eq!(closest("zzzzzz", &o), None);
    }
}
