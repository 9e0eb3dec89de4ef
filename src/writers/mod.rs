//! Output files: one module per format, all written atomically (see [`atomic`]).
//!
//! Every format implements [`Output`]: a document that knows its file extension and how
//! to serialise itself. [`write_file`] puts any such document on disk through a
//! temporary file, never overwriting an input of the run.

pub mod atomic;
pub mod csv;
pub mod html;
pub mod json;
pub mod ply;
pub mod png;
pub mod staging;

use crate::error::Result;
use std::io::Write;
use std::path::Path;

/// A document that can be written as one output file.
pub trait Output {
    /// Conventional file extension, without the dot (e.g. `"ply"`).
    fn extension(&self) -> &'static str;

    /// Serialises the whole document into `out`.
    ///
    /// `out` is already buffered by [`write_file`]; implementations need not buffer again.
    fn write_to(&self, out: &mut dyn Write) -> std::io::Result<()>;
}

/// Writes `doc` to `path` atomically, refusing to overwrite any of `protected_inputs`.
pub fn write_file(doc: &dyn Output, path: &Path, protected_inputs: &[&Path]) -> Result<()> {
    atomic::write_atomically(path, protected_inputs, |out| doc.write_to(out))
}
