//! JSON documents (pretty-printed, newline-terminated).

use super::Output;
use serde::Serialize;
use std::io::Write;

/// Any serialisable value written as one JSON document.
pub struct JsonDoc<'a, T: Serialize>(pub &'a T);

impl<T: Serialize> Output for JsonDoc<'_, T> {
    fn extension(&self) -> &'static str {
        "json"
    }

    fn write_to(&self, out: &mut dyn Write) -> std::io::Result<()> {
        serde_json::to_writer_pretty(&mut *out, self.0)?;
        out.write_all(b"\n")
    }
}
