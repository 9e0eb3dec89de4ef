//! A point-cloud file as a source of frames: one scan, one frame (index 0), its points
//! turned into returns of a sensor model by [`super::returns`], for `run` to process as it
//! processes a capture's frames (issue 31, "Every stage works on these sources").
//!
//! The file is read and checked when the reader is opened, so a bad file is refused before
//! anything is written; the points are then dropped and read again when the frame is
//! needed, so a run over many files holds one scan at a time, not all of them. Labels
//! (given, or found beside the scan: [`crate::score::truth::labels_beside`]) are read and checked
//! against the scan when it is opened too, and kept as its ground truth.

use super::returns::{to_returns, ReturnsOptions, TimeField};
use super::{read_file, CloudPoint, Format, IntensityScale, ReadOptions};
use crate::error::{Error, Result};
use crate::frame::{Frame, FrameSource};
use crate::score::truth::{labels_beside, read_truth, CloudTruth, LabelsBeside};
use crate::sensor::SensorModel;
use serde::Serialize;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

/// How a point-cloud file is read.
#[derive(Clone, Debug)]
pub struct CloudOptions {
    /// The sensor that recorded the scan.
    pub sensor: &'static SensorModel,
    /// The format, when not detected from the file.
    pub format: Option<Format>,
    /// Rotation rate in Hz (the firing grid's size).
    pub rotation_hz: f64,
    /// A per-point label file (SemanticKITTI `.label`, nuScenes-lidarseg or -panoptic);
    /// `None` looks beside the scan.
    pub labels: Option<PathBuf>,
}

/// What a point-cloud source held, for the run's summary.json.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct CloudSummary {
    /// The file's format.
    pub format: &'static str,
    /// The sensor model the points were placed on.
    pub sensor: &'static str,
    /// Points in the file.
    pub points: usize,
    /// True when the lasers come from the file's ring field, false when from the elevation.
    pub ring_field: bool,
    /// How the stored intensity was scaled to the sensor's byte.
    pub intensity_scale: &'static str,
    /// Rotation rate of the firing grid, Hz.
    pub rotation_hz: f64,
    /// Firings in the turn.
    pub firings: u32,
    /// Points moved to a neighbouring firing because their own slot was taken.
    pub moved_to_neighbour_firing: usize,
    /// Points left sharing a firing slot with another (no free slot within reach).
    pub sharing_a_slot: usize,
    /// Points whose laser came from their elevation (no ring field).
    pub laser_from_elevation: usize,
    /// Of those, points between two beams of the table, whose laser is a guess.
    pub laser_ambiguous: usize,
    /// The time field that placed the points on their firings (kept to write their times
    /// back in it); `None` when they were placed by azimuth. Serialized as
    /// `placed_by_time`: its unit ("s", "ms", "us", "ns") or null.
    #[serde(rename = "placed_by_time", serialize_with = "time_unit")]
    pub time_field: Option<TimeField>,
}

/// Serializes a time field as its unit (null for none).
fn time_unit<S: serde::Serializer>(
    field: &Option<TimeField>,
    s: S,
) -> std::result::Result<S::Ok, S::Error> {
    serde::Serialize::serialize(&field.map(|f| f.unit), s)
}

/// One point-cloud file as a frame source.
pub struct CloudReader {
    path: PathBuf,
    /// Boxed, as the truth: `run` moves readers around in its jobs.
    options: Box<CloudOptions>,
    format: Format,
    summary: CloudSummary,
    done: bool,
    /// Input index of each return of the frame handed out (empty before).
    order: Vec<u32>,
    /// The points' times as stored, in input order, when a time field placed them.
    times: Vec<f64>,
    /// The scan's ground truth, when labels were given or found (boxed: a reader is moved
    /// around in `run`'s jobs).
    truth: Option<Box<CloudTruth>>,
}

impl CloudReader {
    /// Reads and checks `path` (every point must become a return of the sensor).
    pub fn open(path: &Path, options: &CloudOptions) -> Result<Self> {
        let (frame, format, summary, order, points) = load(path, options)?;
        drop(frame);
        let truth = truth_of(path, options, &points, &order)?.map(Box::new);
        Ok(CloudReader {
            path: path.to_path_buf(),
            options: Box::new(options.clone()),
            format,
            summary,
            done: false,
            order: Vec::new(),
            times: Vec::new(),
            truth,
        })
    }

    /// What the file held.
    pub fn summary(&self) -> &CloudSummary {
        &self.summary
    }

    /// The file's format.
    pub fn format(&self) -> Format {
        self.format
    }

    /// The input point index of each return of the frame handed out, in return order.
    pub fn order(&self) -> &[u32] {
        &self.order
    }

    /// The time field that placed the points of the frame handed out, and their times
    /// as stored (input order); `None` when they were placed by azimuth.
    pub fn times(&self) -> Option<(&TimeField, &[f64])> {
        self.summary
            .time_field
            .as_ref()
            .map(|f| (f, &self.times[..]))
    }

    /// The scan's ground truth (labels given or found beside it), taken out of the reader.
    pub fn take_truth(&mut self) -> Option<CloudTruth> {
        self.truth.take().map(|t| *t)
    }
}

/// Reads `path` as one frame at once (where [`CloudReader`] reads it twice, to check it
/// before a run writes anything and then when the frame is needed): the frame (index 0),
/// the file's format, what it held, and the input index of each return, in return order.
/// A dataset run, which checks and processes each file in one go, reads it once.
/// Also gives the scan's ground truth, when labels were given or found beside it.
pub fn read_frame(path: &Path, options: &CloudOptions) -> Result<ReadFrame> {
    let (frame, format, summary, order, points) = load(path, options)?;
    let truth = truth_of(path, options, &points, &order)?;
    Ok((frame, format, summary, order, truth))
}

/// The ground truth of the scan at `path` from its labels (given in `options`, else found
/// beside it), checked against its points; `order` is the input index of each return.
fn truth_of(
    path: &Path,
    options: &CloudOptions,
    points: &[CloudPoint],
    order: &[u32],
) -> Result<Option<CloudTruth>> {
    let found = match &options.labels {
        Some(p) => Some(LabelsBeside::PerPoint(p.clone())),
        None => labels_beside(path),
    };
    Ok(match found {
        Some(labels) => Some(CloudTruth {
            truth: read_truth(&labels, points)?,
            labels: labels.shown(),
            // A copy only when the scan has labels.
            order: order.to_vec(),
        }),
        None => None,
    })
}

/// What [`read_frame`] gives: the frame, the format, the summary, the input index of each
/// return, the ground truth.
pub type ReadFrame = (Frame, Format, CloudSummary, Vec<u32>, Option<CloudTruth>);

/// What [`load`] gives: the frame, the format, the summary, the input index of each
/// return, the points.
type Loaded = (Frame, Format, CloudSummary, Vec<u32>, Vec<CloudPoint>);

/// The file's frame, format and summary.
fn load(path: &Path, options: &CloudOptions) -> Result<Loaded> {
    let cloud = read_file(
        path,
        &ReadOptions {
            format: options.format,
            lasers: Some(options.sensor.lasers as u16),
        },
    )?;
    let shown = path.display().to_string();
    let placed = to_returns(
        &cloud.points,
        options.sensor,
        &ReturnsOptions {
            rotation_hz: options.rotation_hz,
            intensity_scale: cloud.info.intensity_scale,
            start_time: 0.0,
        },
        &shown,
    )?;
    let summary = CloudSummary {
        format: cloud.info.format.name(),
        sensor: options.sensor.name,
        points: cloud.points.len(),
        ring_field: cloud.info.fields.ring,
        intensity_scale: match cloud.info.intensity_scale {
            IntensityScale::Unit => "0-1, times 255",
            IntensityScale::Byte => "0-255, as stored",
            IntensityScale::Unstated => "unstated, as stored (clamped to 0-255)",
        },
        rotation_hz: options.rotation_hz,
        firings: placed.firings,
        moved_to_neighbour_firing: placed.moved,
        sharing_a_slot: placed.shared,
        laser_from_elevation: placed.from_elevation,
        laser_ambiguous: placed.ambiguous,
        time_field: placed.time,
    };
    if placed.returns.is_empty() {
        return Err(Error::Invalid(format!("{shown}: the file holds no point")));
    }
    let frame = Frame {
        index: 0,
        partial: false,
        returns: placed.returns,
    };
    Ok((
        frame,
        cloud.info.format,
        summary,
        placed.order,
        cloud.points,
    ))
}

impl FrameSource for CloudReader {
    fn next_batch(&mut self, max: usize, frames: &RangeInclusive<u32>) -> Result<Vec<Frame>> {
        if self.done || max == 0 {
            return Ok(Vec::new());
        }
        self.done = true;
        if !frames.contains(&0) {
            return Ok(Vec::new());
        }
        let (frame, _, summary, order, points) = load(&self.path, &self.options)?;
        if summary != self.summary {
            return Err(Error::Invalid(format!(
                "{}: the file changed while it was being processed",
                self.path.display()
            )));
        }
        self.order = order;
        if let Some(f) = &summary.time_field {
            self.times = points.iter().map(|p| p.time.unwrap_or(f.t0)).collect();
        }
        Ok(vec![frame])
    }

    fn recycle(&mut self, _frame: Frame) {}
}
