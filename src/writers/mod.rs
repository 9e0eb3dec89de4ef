//! Output files: one module per format, all written atomically (see [`atomic`]).
//!
//! Every format implements [`Output`]: a document that knows its file extension and how
//! to serialise itself. [`write_file`] puts any such document on disk through a
//! temporary file, never overwriting an input of the run.

pub mod atomic;
pub mod csv;
pub mod figure;
pub mod html;
pub mod json;
pub mod las;
pub mod pcap;
pub mod ply;
pub mod scan;
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

/// File format of a frame's point cloud (`--format`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum FrameFormat {
    /// PLY (binary little-endian or ASCII), every field a vertex property.
    #[default]
    Ply,
    /// LAS 1.4, point format 6, extra fields as extra bytes.
    Las,
    /// LAZ: LAS compressed with LASzip.
    Laz,
}

impl FrameFormat {
    /// File extension, without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            FrameFormat::Ply => "ply",
            FrameFormat::Las => "las",
            FrameFormat::Laz => "laz",
        }
    }
}

/// How frames are written: the format and the PLY encoding.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrameOutput {
    /// File format.
    pub format: FrameFormat,
    /// PLY payload encoding (PLY only).
    pub encoding: ply::PlyEncoding,
    /// PLY property naming (PLY only).
    pub ply_style: ply::PlyStyle,
}

impl FrameOutput {
    /// File name of frame `index`: `frame_NNNNN.<extension>`.
    pub fn file_name(&self, index: u32) -> String {
        format!("frame_{index:05}.{}", self.format.extension())
    }

    /// The frame as a document of the chosen format.
    pub fn document<'a>(&self, mut frame: ply::PlyFrame<'a>) -> Box<dyn Output + 'a> {
        match self.format {
            FrameFormat::Ply => {
                frame.encoding = self.encoding;
                frame.style = self.ply_style;
                Box::new(frame)
            }
            FrameFormat::Las | FrameFormat::Laz => Box::new(las::LasFrame {
                frame,
                compressed: self.format == FrameFormat::Laz,
            }),
        }
    }
}
