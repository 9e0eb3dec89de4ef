//! Ground truth of a sweep's capture: the label rows of its frames (read a frame at a
//! time when the file is in frame order) and the object classes beside them.

use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::synth::labels::{check_frame, read_labels_file, LabelRow, LabelRows};
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

/// Ground truth of one frame, per clean return.
pub(super) struct Truth {
    pub(super) ground: Vec<bool>,
    pub(super) objects: Vec<i32>,
}

/// Ground-truth labels of a capture: where its rows come from and object classes by id.
pub(super) struct Labels {
    rows: LabelSource,
    pub(super) classes: BTreeMap<i32, String>,
}

/// The label rows of a capture's frames.
enum LabelSource {
    /// A file in frame order (as the synthesizer writes it: capture order), read again
    /// a frame at a time by every pass over the capture: memory does not grow with it.
    InOrder(PathBuf),
    /// Rows of a file not in frame order, grouped by frame (held whole).
    Grouped(HashMap<u32, Vec<LabelRow>>),
}

impl Labels {
    /// Reads (checks) the labels file `path`; its rows are held only when they are not
    /// in frame order.
    pub(super) fn open(path: &Path) -> Result<Labels> {
        let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        let mut last = 0u32;
        let mut in_order = true;
        for row in LabelRows::new(file, path)? {
            let row = row?;
            in_order &= row.frame >= last;
            last = row.frame;
        }
        let rows = if in_order {
            LabelSource::InOrder(path.to_path_buf())
        } else {
            LabelSource::Grouped(group_labels(read_labels_file(path)?))
        };
        Ok(Labels {
            rows,
            classes: read_classes(path)?,
        })
    }

    /// A reader of the rows of frames asked for in increasing order.
    pub(super) fn cursor(&self) -> Result<LabelCursor<'_>> {
        Ok(match &self.rows {
            LabelSource::InOrder(path) => {
                let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
                LabelCursor::Stream {
                    rows: LabelRows::new(file, path)?,
                    next: None,
                }
            }
            LabelSource::Grouped(frames) => LabelCursor::Grouped(frames),
        })
    }
}

/// The label rows of one frame after another (see [`Labels::cursor`]).
pub(super) enum LabelCursor<'a> {
    Stream {
        rows: LabelRows<'static>,
        /// The first row of a later frame, read ahead.
        next: Option<LabelRow>,
    },
    Grouped(&'a HashMap<u32, Vec<LabelRow>>),
}

impl LabelCursor<'_> {
    /// The rows of frame `index` (frames asked for in increasing order).
    pub(super) fn frame(&mut self, index: u32) -> Result<Vec<LabelRow>> {
        match self {
            LabelCursor::Grouped(frames) => Ok(frames.get(&index).cloned().unwrap_or_default()),
            LabelCursor::Stream { rows, next } => {
                let mut out = Vec::new();
                loop {
                    let row = match next.take() {
                        Some(r) => r,
                        None => match rows.next() {
                            Some(r) => r?,
                            None => return Ok(out),
                        },
                    };
                    if row.frame > index {
                        *next = Some(row);
                        return Ok(out);
                    }
                    if row.frame == index {
                        out.push(row);
                    }
                }
            }
        }
    }
}

fn group_labels(rows: Vec<LabelRow>) -> HashMap<u32, Vec<LabelRow>> {
    let mut out: HashMap<u32, Vec<LabelRow>> = HashMap::new();
    for r in rows {
        out.entry(r.frame).or_default().push(r);
    }
    out
}

/// Object classes (`kind` by `id`) of `<name>.objects.json` beside `<name>.labels.csv.gz`;
/// empty when there is no such file.
fn read_classes(labels: &Path) -> Result<BTreeMap<i32, String>> {
    let name = labels.file_name().unwrap_or_default().to_string_lossy();
    let Some(stem) = name.split(".labels.").next().filter(|s| *s != name) else {
        return Ok(BTreeMap::new());
    };
    let path = labels.with_file_name(format!("{stem}.objects.json"));
    let Ok(text) = std::fs::read(&path) else {
        return Ok(BTreeMap::new());
    };
    let value: serde_json::Value = serde_json::from_slice(&text)
        .map_err(|e| Error::Invalid(format!("{}: {e}", path.display())))?;
    let mut out = BTreeMap::new();
    for o in value["objects"].as_array().map_or(&[][..], Vec::as_slice) {
        if let (Some(id), Some(kind)) = (o["id"].as_i64(), o["kind"].as_str()) {
            out.insert(id as i32, kind.to_string());
        }
    }
    Ok(out)
}

pub(super) fn truth_of(frame: &Frame, rows: &[LabelRow], origin: &Path) -> Result<Truth> {
    check_frame(rows, frame, origin)?;
    Ok(Truth {
        ground: rows.iter().map(|l| l.label == 0).collect(),
        objects: rows
            .iter()
            .map(|l| if l.label == 0 { -1 } else { i32::from(l.label) })
            .collect(),
    })
}
