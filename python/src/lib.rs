//! `lidar_noise._lidar_noise`: the compiled half of the Python package (issue 32).
//!
//! Only conversion lives here: numpy columns in, the library's types (`Return`,
//! `CloudPoint`, `Config`), the library's functions (`NoiseChain::process_returns`, the
//! pipeline's ground and clustering steps, `cloud::returns::to_returns`), numpy columns
//! out. The Python half (`lidar_noise/__init__.py`) checks shapes and dtypes and turns
//! these column dictionaries into structured arrays, so that this file never guesses
//! at a layout.
//!
//! Every entry point returns `PyResult`: library errors become `ValueError` (bad options,
//! bad points, malformed files) or `OSError` (files that cannot be read or written), and
//! the work runs with the GIL released (`Python::detach`).

use lidar_noise::cloud::guess::{sensor_by_name, SENSOR_NAMES};
use lidar_noise::cloud::{self, CloudPoint, IntensityScale};
use lidar_noise::config::Config;
use lidar_noise::error::Error;
use lidar_noise::frame::{Frame, Return, ReturnKind};
use lidar_noise::noise::{stage_rng, stage_tags, NoiseChain, NoisyFrame, Reported};
use lidar_noise::pipeline::Pipeline;
use lidar_noise::sensor::SensorModel;
use numpy::ndarray::Zip;
use numpy::{Element, PyArray1, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// The extension's allocator. `apply` allocates a few megabytes a call (the returns, the
/// noisy frame, the records); glibc's malloc hands blocks that large back to the kernel
/// when freed, so every call faulted its pages in again: a third of the time of an
/// `apply` without noise stages on a 35k-point scan went to page faults (perf). mimalloc
/// keeps freed memory for the next call. Only this module's Rust allocations use it;
/// Python and numpy keep their own.
#[global_allocator]
static ALLOC: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// A library error as the Python exception the package documents.
fn py_err(e: Error) -> PyErr {
    match &e {
        Error::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => {
            PyFileNotFoundError::new_err(e.to_string())
        }
        Error::Io { .. } => PyOSError::new_err(e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
    }
}

/// The sensor model a `sensor=` name means (the command line's `--sensor` names), or a
/// ValueError listing the names.
fn sensor_of(name: &str) -> PyResult<&'static SensorModel> {
    sensor_by_name(name).ok_or_else(|| {
        PyValueError::new_err(format!(
            "sensor {name:?}: not a sensor modelled here (give one of {SENSOR_NAMES})"
        ))
    })
}

/// A per-laser misfit of the noise chain (`for_lasers`'s message `e`) worded as `run`
/// words it: the sensor, then the stage and option.
fn misfit_message(sensor: &SensorModel, e: &str) -> String {
    format!("the {} ({} lasers): {e}", sensor.name, sensor.lasers)
}

/// A per-laser misfit of the noise chain as the ValueError the package documents.
fn misfit(sensor: &SensorModel, e: String) -> PyErr {
    PyValueError::new_err(misfit_message(sensor, &e))
}

/// Column `name` of `cols`, with one value per point.
fn column<'py, T: Element>(
    cols: &Bound<'py, PyDict>,
    name: &str,
    n: Option<usize>,
) -> PyResult<PyReadonlyArray1<'py, T>> {
    let item = cols
        .get_item(name)?
        .ok_or_else(|| PyValueError::new_err(format!("points: field `{name}` is missing")))?;
    let a: PyReadonlyArray1<'py, T> = item.extract().map_err(|_| {
        PyValueError::new_err(format!(
            "points: field `{name}` must be a 1-D array of {}",
            std::any::type_name::<T>()
        ))
    })?;
    if let Some(n) = n {
        if a.as_array().len() != n {
            return Err(PyValueError::new_err(format!(
                "points: field `{name}` has {} values for {n} points",
                a.as_array().len()
            )));
        }
    }
    Ok(a)
}

/// The returns of a column dictionary carrying every field of a `Return`, of a sensor
/// with `lasers` lasers (a laser id past them would index past the chain's firing slots).
fn returns_of(cols: &Bound<'_, PyDict>, lasers: usize) -> PyResult<Vec<Return>> {
    let x = column::<f32>(cols, "x", None)?;
    let n = x.as_array().len();
    let y = column::<f32>(cols, "y", Some(n))?;
    let z = column::<f32>(cols, "z", Some(n))?;
    let range = column::<f32>(cols, "range", Some(n))?;
    let azimuth = column::<f32>(cols, "azimuth", Some(n))?;
    let elevation = column::<f32>(cols, "elevation", Some(n))?;
    let time = column::<f64>(cols, "time", Some(n))?;
    let packet = column::<u32>(cols, "packet", Some(n))?;
    let raw = column::<u16>(cols, "raw_distance", Some(n))?;
    let intensity = column::<u8>(cols, "intensity", Some(n))?;
    let laser = column::<u8>(cols, "laser", Some(n))?;
    let ring = column::<u8>(cols, "ring", Some(n))?;
    let block = column::<u8>(cols, "block", Some(n))?;
    let kind = column::<u8>(cols, "kind", Some(n))?;
    let (x, y, z, range) = (x.as_array(), y.as_array(), z.as_array(), range.as_array());
    let (azimuth, elevation, time) = (azimuth.as_array(), elevation.as_array(), time.as_array());
    let (packet, raw, intensity) = (packet.as_array(), raw.as_array(), intensity.as_array());
    let (laser, ring, block, kind) = (
        laser.as_array(),
        ring.as_array(),
        block.as_array(),
        kind.as_array(),
    );
    let mut out = Vec::with_capacity(n + n / 8);
    for i in 0..n {
        let kind = match kind[i] {
            0 => ReturnKind::Strongest,
            1 => ReturnKind::Last,
            2 => ReturnKind::DualLast,
            3 => ReturnKind::DualStrongest,
            k => {
                return Err(PyValueError::new_err(format!(
                    "points: point {i} (0-based): kind {k} is not a return kind (0 strongest, \
                     1 last, 2 dual last, 3 dual strongest)"
                )))
            }
        };
        let r = Return {
            x: x[i],
            y: y[i],
            z: z[i],
            range: range[i],
            azimuth: azimuth[i],
            elevation: elevation[i],
            time: time[i],
            packet: packet[i],
            raw_distance: raw[i],
            intensity: intensity[i],
            laser: laser[i],
            ring: ring[i],
            block: block[i],
            kind,
        };
        let finite = [r.x, r.y, r.z, r.range, r.azimuth, r.elevation]
            .iter()
            .all(|v| v.is_finite())
            && r.time.is_finite();
        if !finite {
            let field = [
                ("x", r.x),
                ("y", r.y),
                ("z", r.z),
                ("range", r.range),
                ("azimuth", r.azimuth),
                ("elevation", r.elevation),
                ("time", r.time as f32),
            ]
            .into_iter()
            .find(|(_, v)| !v.is_finite())
            .map_or("time", |(f, _)| f);
            return Err(PyValueError::new_err(format!(
                "points: point {i} (0-based): {field} is not a finite number"
            )));
        }
        if usize::from(r.laser) >= lasers {
            return Err(PyValueError::new_err(format!(
                "points: point {i} (0-based): laser {} is out of range (0 to {})",
                r.laser,
                lasers - 1
            )));
        }
        out.push(r);
    }
    Ok(out)
}

/// A ring column as given: whole numbers as float32 (the fifth column of an (N, 5) array,
/// read in place and checked here, where numpy needed four passes and two temporary
/// arrays) or int64 (a structured array's field, checked by the Python side).
enum RingColumn<'py> {
    Float(PyReadonlyArray1<'py, f32>),
    Int(PyReadonlyArray1<'py, i64>),
}

/// Ring `v` of point `i` as the library's ring number. Whole and in range is one
/// round trip through an integer (NaN and infinities do not come back equal), without
/// the libm call `fract` makes on the wheel's baseline x86-64.
fn ring_of(i: usize, v: f32) -> PyResult<u16> {
    let out_of_range = || {
        PyValueError::new_err(format!(
            "points: point {i} (0-based): ring {v} is out of range"
        ))
    };
    if v.abs() > 65536.0 && v.is_finite() {
        return Err(out_of_range());
    }
    let k = v as i32;
    if k as f32 != v {
        return Err(PyValueError::new_err(format!(
            "points: point {i} (0-based): ring {v} is not a whole number"
        )));
    }
    u16::try_from(k).map_err(|_| out_of_range())
}

/// A float ring as a `u16`, and whether it is a ring: exactly when the saturating cast
/// gives it back (a whole number from 0 to 65535; NaN casts to 0). The points are built
/// with it, without a branch, and only a column with a bad ring is searched again
/// ([`first_bad_ring`]): a checking pass of its own was half of the conversion.
#[inline(always)]
fn cast_ring(v: f32) -> (u16, bool) {
    let ring = v as u16;
    (ring, f32::from(ring) == v)
}

/// The error [`ring_of`] gives the first of `rings` that is not a ring, if any.
fn first_bad_ring(rings: impl Iterator<Item = f32>) -> PyResult<()> {
    match rings.enumerate().find_map(|(i, v)| ring_of(i, v).err()) {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// Plain points (x y z intensity, optional ring and time) of a column dictionary.
fn cloud_points_of(cols: &Bound<'_, PyDict>) -> PyResult<Vec<CloudPoint>> {
    if let Some(rows) = cols.get_item("rows")? {
        return cloud_points_of_rows(&rows);
    }
    let x = column::<f32>(cols, "x", None)?;
    let n = x.as_array().len();
    let y = column::<f32>(cols, "y", Some(n))?;
    let z = column::<f32>(cols, "z", Some(n))?;
    let intensity = column::<f32>(cols, "intensity", Some(n))?;
    let ring = match cols.get_item("ring")? {
        Some(r) if r.extract::<PyReadonlyArray1<'_, f32>>().is_ok() => {
            Some(RingColumn::Float(column::<f32>(cols, "ring", Some(n))?))
        }
        Some(_) => Some(RingColumn::Int(column::<i64>(cols, "ring", Some(n))?)),
        None => None,
    };
    let (x, y, z, intensity) = (
        x.as_array(),
        y.as_array(),
        z.as_array(),
        intensity.as_array(),
    );
    // ndarray's Zip rather than indexing or zipped iterators: the columns are strided
    // views of the (N, 5) array, and Zip walks them with one stride each (an index per
    // value cost a bounds check and a stride multiply, zipped iterators about 140
    // instructions a point, callgrind). Rings are checked in a pass of their own first,
    // so that the loop that builds the points has no early exit.
    let point = |x, y, z, intensity, ring| CloudPoint {
        x,
        y,
        z,
        intensity,
        ring,
        time: None,
    };
    let mut out = Vec::with_capacity(n);
    let xyzi = Zip::from(&x).and(&y).and(&z).and(&intensity);
    match &ring {
        None => xyzi.for_each(|&x, &y, &z, &i| out.push(point(x, y, z, i, None))),
        Some(RingColumn::Float(r)) => {
            let r = r.as_array();
            let mut valid = true;
            xyzi.and(&r).for_each(|&x, &y, &z, &i, &r| {
                let (ring, ok) = cast_ring(r);
                valid &= ok;
                out.push(point(x, y, z, i, Some(ring)));
            });
            if !valid {
                first_bad_ring(r.iter().copied())?;
            }
        }
        Some(RingColumn::Int(r)) => {
            let r = r.as_array();
            for (i, &v) in r.iter().enumerate() {
                if u16::try_from(v).is_err() {
                    return Err(PyValueError::new_err(format!(
                        "points: point {i} (0-based): ring {v} is out of range"
                    )));
                }
            }
            xyzi.and(&r)
                .for_each(|&x, &y, &z, &i, &r| out.push(point(x, y, z, i, Some(r as u16))));
        }
    }
    // A time field places the points by time, as `run` places a file's (the conversion
    // refuses a time that is not a finite number, naming the point).
    if cols.get_item("time")?.is_some() {
        let time = column::<f64>(cols, "time", Some(n))?;
        for (p, &t) in out.iter_mut().zip(time.as_array()) {
            p.time = Some(t);
        }
    }
    Ok(out)
}

/// Plain points of a C-ordered float32 (N, 4) or (N, 5) array (x y z intensity [ring]),
/// read row by row from its one slice: the same points as its columns give, without five
/// strided walks (the package passes such an array whole).
fn cloud_points_of_rows(rows: &Bound<'_, PyAny>) -> PyResult<Vec<CloudPoint>> {
    let bad = || {
        PyValueError::new_err("points: `rows` must be a C-ordered float32 (N, 4) or (N, 5) array")
    };
    let a: PyReadonlyArray2<'_, f32> = rows.extract().map_err(|_| bad())?;
    let width = a.as_array().ncols();
    let flat = a.as_slice().map_err(|_| bad())?;
    let point = |r: &[f32], ring| CloudPoint {
        x: r[0],
        y: r[1],
        z: r[2],
        intensity: r[3],
        ring,
        time: None,
    };
    match width {
        4 => Ok(flat.chunks_exact(4).map(|r| point(r, None)).collect()),
        5 => {
            let mut valid = true;
            let out = flat
                .chunks_exact(5)
                .map(|r| {
                    let (ring, ok) = cast_ring(r[4]);
                    valid &= ok;
                    point(r, Some(ring))
                })
                .collect();
            if !valid {
                first_bad_ring(flat.chunks_exact(5).map(|r| r[4]))?;
            }
            Ok(out)
        }
        _ => Err(bad()),
    }
}

/// Columns of returns (the fields of `Return`), in the given order of indices.
struct ReturnColumns {
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    range: Vec<f32>,
    azimuth: Vec<f32>,
    elevation: Vec<f32>,
    time: Vec<f64>,
    packet: Vec<u32>,
    raw_distance: Vec<u16>,
    intensity: Vec<u8>,
    laser: Vec<u8>,
    ring: Vec<u8>,
    block: Vec<u8>,
    kind: Vec<u8>,
}

impl ReturnColumns {
    fn of<'a>(returns: impl ExactSizeIterator<Item = &'a Return>) -> Self {
        let n = returns.len();
        let mut c = ReturnColumns {
            x: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            z: Vec::with_capacity(n),
            range: Vec::with_capacity(n),
            azimuth: Vec::with_capacity(n),
            elevation: Vec::with_capacity(n),
            time: Vec::with_capacity(n),
            packet: Vec::with_capacity(n),
            raw_distance: Vec::with_capacity(n),
            intensity: Vec::with_capacity(n),
            laser: Vec::with_capacity(n),
            ring: Vec::with_capacity(n),
            block: Vec::with_capacity(n),
            kind: Vec::with_capacity(n),
        };
        for r in returns {
            c.x.push(r.x);
            c.y.push(r.y);
            c.z.push(r.z);
            c.range.push(r.range);
            c.azimuth.push(r.azimuth);
            c.elevation.push(r.elevation);
            c.time.push(r.time);
            c.packet.push(r.packet);
            c.raw_distance.push(r.raw_distance);
            c.intensity.push(r.intensity);
            c.laser.push(r.laser);
            c.ring.push(r.ring);
            c.block.push(r.block);
            c.kind.push(r.kind as u8);
        }
        c
    }

    fn into_dict<'py>(self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("x", PyArray1::from_vec(py, self.x))?;
        d.set_item("y", PyArray1::from_vec(py, self.y))?;
        d.set_item("z", PyArray1::from_vec(py, self.z))?;
        d.set_item("range", PyArray1::from_vec(py, self.range))?;
        d.set_item("azimuth", PyArray1::from_vec(py, self.azimuth))?;
        d.set_item("elevation", PyArray1::from_vec(py, self.elevation))?;
        d.set_item("time", PyArray1::from_vec(py, self.time))?;
        d.set_item("packet", PyArray1::from_vec(py, self.packet))?;
        d.set_item("raw_distance", PyArray1::from_vec(py, self.raw_distance))?;
        d.set_item("intensity", PyArray1::from_vec(py, self.intensity))?;
        d.set_item("laser", PyArray1::from_vec(py, self.laser))?;
        d.set_item("ring", PyArray1::from_vec(py, self.ring))?;
        d.set_item("block", PyArray1::from_vec(py, self.block))?;
        d.set_item("kind", PyArray1::from_vec(py, self.kind))?;
        Ok(d)
    }
}

/// Range of return `i` before noise: 0 for a return a stage added.
fn clean_range(noisy: &NoisyFrame, i: usize) -> f32 {
    if i < noisy.clean_len {
        noisy.clean[i].range
    } else {
        0.0
    }
}

/// The fields of a record of `apply`'s result (the package's `APPLIED_DTYPE`) with their
/// sizes in bytes, in the order [`RecordLayout::records`] writes them.
const RECORD_FIELDS: [(&str, usize); 19] = [
    ("x", 4),
    ("y", 4),
    ("z", 4),
    ("range", 4),
    ("azimuth", 4),
    ("elevation", 4),
    ("time", 8),
    ("packet", 4),
    ("raw_distance", 2),
    ("intensity", 1),
    ("laser", 1),
    ("ring", 1),
    ("block", 1),
    ("kind", 1),
    ("range_clean", 4),
    ("power", 8),
    ("fate", 1),
    ("cause", 1),
    ("kept", 1),
];

/// Where each of [`RECORD_FIELDS`] sits in a record of `itemsize` bytes (given by the
/// Python side from its dtype, so that the two cannot disagree).
struct RecordLayout {
    itemsize: usize,
    at: [usize; 19],
}

impl RecordLayout {
    /// From a dict of field offsets plus `__itemsize__`; every field must fit.
    fn of(d: &Bound<'_, PyDict>) -> PyResult<Self> {
        let get = |k: &str| -> PyResult<usize> {
            d.get_item(k)?
                .ok_or_else(|| PyValueError::new_err(format!("record layout: no `{k}`")))?
                .extract()
        };
        let itemsize = get("__itemsize__")?;
        let mut at = [0usize; 19];
        for (j, (name, size)) in RECORD_FIELDS.iter().enumerate() {
            at[j] = get(name)?;
            if at[j] + size > itemsize {
                return Err(PyValueError::new_err(format!(
                    "record layout: `{name}` at byte {} does not fit {itemsize} bytes",
                    at[j]
                )));
            }
        }
        Ok(RecordLayout { itemsize, at })
    }

    /// The records of `rows` (indices into the noisy frame), written straight into the
    /// bytes numpy will view as the structured array (no column copies). Each row's
    /// return is as `run --keep-dropped` writes it ([`NoisyFrame::reported`]), built per
    /// row rather than from the survivors collected first.
    fn records(&self, noisy: &NoisyFrame, rows: &[u32]) -> Vec<u8> {
        let reported = noisy.reported();
        let mut buf = vec![0u8; rows.len() * self.itemsize];
        if self.itemsize == ALIGNED_ITEMSIZE && self.at == ALIGNED_AT {
            // numpy's aligned layout of APPLIED_DTYPE (what the package passes): offsets
            // known at compile time. Written in place: a record built on the stack and
            // then appended was read back in wide loads right after its narrow stores,
            // which stalled on every record (store forwarding).
            for (rec, &i) in buf.chunks_exact_mut(ALIGNED_ITEMSIZE).zip(rows) {
                let rec: &mut [u8; ALIGNED_ITEMSIZE] = rec.try_into().expect("chunks are exact");
                fill_record(rec, &ALIGNED_AT, noisy, &reported, i as usize);
            }
            return buf;
        }
        for (rec, &i) in buf.chunks_exact_mut(self.itemsize).zip(rows) {
            fill_record(rec, &self.at, noisy, &reported, i as usize);
        }
        buf
    }
}

/// Offsets of [`RECORD_FIELDS`] in numpy's aligned layout of `APPLIED_DTYPE`.
const ALIGNED_AT: [usize; 19] = [
    0, 4, 8, 12, 16, 20, 24, 32, 36, 38, 39, 40, 41, 42, 44, 48, 56, 57, 58,
];
/// Size of a record in numpy's aligned layout of `APPLIED_DTYPE`.
const ALIGNED_ITEMSIZE: usize = 64;

/// Writes the record of return `i` into `rec`, field j at byte `at[j]` (little-endian).
#[inline(always)]
fn fill_record(
    rec: &mut [u8],
    at: &[usize; 19],
    noisy: &NoisyFrame,
    reported: &Reported<'_>,
    i: usize,
) {
    let r = reported.of(i);
    let mut put = |j: usize, b: &[u8]| rec[at[j]..at[j] + b.len()].copy_from_slice(b);
    put(0, &r.x.to_le_bytes());
    put(1, &r.y.to_le_bytes());
    put(2, &r.z.to_le_bytes());
    put(3, &r.range.to_le_bytes());
    put(4, &r.azimuth.to_le_bytes());
    put(5, &r.elevation.to_le_bytes());
    put(6, &r.time.to_le_bytes());
    put(7, &r.packet.to_le_bytes());
    put(8, &r.raw_distance.to_le_bytes());
    put(9, &[r.intensity]);
    put(10, &[r.laser]);
    put(11, &[r.ring]);
    put(12, &[r.block]);
    put(13, &[r.kind as u8]);
    put(14, &clean_range(noisy, i).to_le_bytes());
    put(15, &noisy.power[i].to_le_bytes());
    put(16, &[noisy.fate[i] as u8]);
    put(17, &[noisy.cause[i]]);
    put(18, &[u8::from(noisy.fate[i].is_alive())]);
}

/// What `apply` hands back: the returns after the chain, each at its noisy position when
/// the sensor still reports it and at its recorded one when dropped (as `run
/// --keep-dropped` writes them), with fate, cause, clean range and power.
struct Applied {
    returns: ReturnColumns,
    range_clean: Vec<f32>,
    power: Vec<f64>,
    fate: Vec<u8>,
    cause: Vec<u8>,
    kept: Vec<bool>,
}

impl Applied {
    /// Rows in `rows` order (indices into the noisy frame).
    fn of(noisy: &NoisyFrame, rows: &[u32]) -> Self {
        let reported = noisy.reported();
        let all: Vec<Return> = rows.iter().map(|&i| reported.of(i as usize)).collect();
        let clean_range = |i: usize| clean_range(noisy, i);
        Applied {
            returns: ReturnColumns::of(all.iter()),
            range_clean: rows.iter().map(|&i| clean_range(i as usize)).collect(),
            power: rows.iter().map(|&i| noisy.power[i as usize]).collect(),
            fate: rows.iter().map(|&i| noisy.fate[i as usize] as u8).collect(),
            cause: rows.iter().map(|&i| noisy.cause[i as usize]).collect(),
            kept: rows
                .iter()
                .map(|&i| noisy.fate[i as usize].is_alive())
                .collect(),
        }
    }

    fn into_dict<'py>(self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = self.returns.into_dict(py)?;
        d.set_item("range_clean", PyArray1::from_vec(py, self.range_clean))?;
        d.set_item("power", PyArray1::from_vec(py, self.power))?;
        d.set_item("fate", PyArray1::from_vec(py, self.fate))?;
        d.set_item("cause", PyArray1::from_vec(py, self.cause))?;
        d.set_item("kept", PyArray1::from_vec(py, self.kept))?;
        Ok(d)
    }
}

/// Runs `work` on a pool of `threads` threads (rayon's global pool when `None`). Pools
/// are kept by size: a data loader calls `apply` per scan, and starting threads each time
/// cost more than a small frame's work. One thread is the calling thread itself: `work`
/// is one frame's, whose forks are `par::join`s (the library's rule for work inside a
/// frame), and those run in turn off a pool's threads; handing the frame to a pool's
/// thread and waiting for it cost up to a tenth of a millisecond a call (a thirtieth of a
/// weather chain's `apply` on a nuScenes sweep) for the same result.
fn on_threads<T: Send>(threads: Option<usize>, work: impl FnOnce() -> T + Send) -> PyResult<T> {
    static POOLS: Mutex<Vec<(usize, Arc<rayon::ThreadPool>)>> = Mutex::new(Vec::new());
    let n = match threads {
        None => return Ok(work()),
        Some(n) if !(1..=1024).contains(&n) => {
            return Err(PyValueError::new_err(format!(
                "threads {n}: give 1 to 1024 (or None for rayon's pool)"
            )))
        }
        Some(1) => return Ok(work()),
        Some(n) => n,
    };
    let pool = {
        let mut pools = POOLS
            .lock()
            .map_err(|_| PyOSError::new_err("thread pools: lock poisoned"))?;
        match pools.iter().find(|(k, _)| *k == n) {
            Some((_, p)) => Arc::clone(p),
            None => {
                let p = Arc::new(
                    rayon::ThreadPoolBuilder::new()
                        .num_threads(n)
                        .build()
                        .map_err(|e| PyOSError::new_err(format!("threads {n}: {e}")))?,
                );
                pools.push((n, Arc::clone(&p)));
                p
            }
        }
    };
    Ok(pool.install(work))
}

/// A validated configuration and its noise chain for one sensor (built again for
/// another seed: stages draw per-configuration values from the seed's streams when
/// built).
#[pyclass(module = "lidar_noise._lidar_noise", frozen)]
struct Chain {
    config: Config,
    warnings: Vec<String>,
    /// The sensor the frames are of: its lasers size the chain's firing slots and bound
    /// the per-laser options, and plain points are placed on its firings.
    sensor: &'static SensorModel,
    /// Chains built so far by seed (a handful: the configuration's and the last asked).
    chains: Mutex<Vec<(u64, Arc<NoiseChain>)>>,
}

impl Chain {
    /// The chain of `config` for `sensor`; a ValueError naming the stage and option when
    /// a per-laser option does not fit the sensor (checked once here: the fit depends on
    /// the options, not on the seed).
    fn new(config: Config, warnings: Vec<String>, sensor: &'static SensorModel) -> PyResult<Self> {
        let chain = Arc::new(build_chain(&config, sensor)?);
        Ok(Chain {
            chains: Mutex::new(vec![(config.seed, chain)]),
            config,
            warnings,
            sensor,
        })
    }

    fn chain(&self, seed: Option<u64>) -> PyResult<Arc<NoiseChain>> {
        let seed = seed.unwrap_or(self.config.seed);
        if i64::try_from(seed).is_err() {
            return Err(PyValueError::new_err(format!(
                "seed {seed}: must be at most {} (TOML integers are 64-bit signed)",
                i64::MAX
            )));
        }
        let mut chains = self
            .chains
            .lock()
            .map_err(|_| PyValueError::new_err("chain cache poisoned"))?;
        if let Some((_, c)) = chains.iter().find(|(s, _)| *s == seed) {
            return Ok(Arc::clone(c));
        }
        let mut config = self.config.clone();
        config.seed = seed;
        let c = Arc::new(build_chain(&config, self.sensor)?);
        if chains.len() >= 4 {
            chains.remove(1);
        }
        chains.push((seed, Arc::clone(&c)));
        Ok(c)
    }

    /// The configuration with `seed`.
    fn config_with(&self, seed: Option<u64>) -> Config {
        let mut config = self.config.clone();
        if let Some(s) = seed {
            config.seed = s;
        }
        config
    }
}

/// The noise chain of `config` for frames of `sensor` (as `run` builds it per sensor).
fn build_chain(config: &Config, sensor: &SensorModel) -> PyResult<NoiseChain> {
    NoiseChain::new(config)
        .for_sensor(sensor)
        .map_err(|e| misfit(sensor, e))
}

/// Config text `text` named `name` (a path or a label), validated as `run -c` does, for
/// frames of the sensor named `sensor`.
fn load(
    text: Option<&str>,
    path: Option<&Path>,
    name: &str,
    sets: &[String],
    sensor: &str,
) -> PyResult<Chain> {
    let sensor = sensor_of(sensor)?;
    let (config, warnings) = match (text, path) {
        (Some(t), _) => Config::from_toml_str(t, Path::new(name), sets, None),
        (None, p) => Config::load(p, sets, None),
    }
    .map_err(py_err)?;
    Chain::new(config, warnings, sensor)
}

/// A Python value as a TOML value (dicts, lists, str, bool, int, float); `key` names it.
fn to_toml(v: &Bound<'_, PyAny>, key: &str) -> PyResult<toml::Value> {
    use pyo3::types::{PyBool, PyFloat, PyInt, PyString, PyTuple};
    if v.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(v.extract()?));
    }
    if v.is_instance_of::<PyInt>() {
        let i: i64 = v.extract().map_err(|_| {
            PyValueError::new_err(format!("{key}: {v} does not fit a 64-bit TOML integer"))
        })?;
        return Ok(toml::Value::Integer(i));
    }
    if v.is_instance_of::<PyFloat>() {
        return Ok(toml::Value::Float(v.extract()?));
    }
    if v.is_instance_of::<PyString>() {
        return Ok(toml::Value::String(v.extract()?));
    }
    if let Ok(d) = v.cast::<PyDict>() {
        let mut t = toml::Table::new();
        for (k, val) in d.iter() {
            let k: String = k
                .extract()
                .map_err(|_| PyValueError::new_err(format!("{key}: keys must be strings")))?;
            let path = if key.is_empty() {
                k.clone()
            } else {
                format!("{key}.{k}")
            };
            if val.is_none() {
                continue;
            }
            t.insert(k, to_toml(&val, &path)?);
        }
        return Ok(toml::Value::Table(t));
    }
    if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() {
        let mut out = Vec::new();
        for (i, item) in v.try_iter()?.enumerate() {
            out.push(to_toml(&item?, &format!("{key}[{i}]"))?);
        }
        return Ok(toml::Value::Array(out));
    }
    // numpy scalars and other numbers: as float or int through Python's own protocols.
    if let Ok(i) = v.call_method0("__index__").and_then(|i| i.extract::<i64>()) {
        return Ok(toml::Value::Integer(i));
    }
    if let Ok(f) = v.call_method0("__float__").and_then(|f| f.extract::<f64>()) {
        return Ok(toml::Value::Float(f));
    }
    Err(PyValueError::new_err(format!(
        "{key}: a {} is not a TOML value (give a dict, list, str, bool, int or float)",
        v.get_type().name()?
    )))
}

#[pymethods]
impl Chain {
    /// Reads a configuration from TOML text for frames of `sensor` (a `--sensor` name);
    /// `name` names it in errors.
    #[staticmethod]
    #[pyo3(signature = (text, name="<string>", sets=Vec::new(), sensor="hdl32e"))]
    fn from_text(text: &str, name: &str, sets: Vec<String>, sensor: &str) -> PyResult<Self> {
        load(Some(text), None, name, &sets, sensor)
    }

    /// Reads a configuration file for frames of `sensor`.
    #[staticmethod]
    #[pyo3(signature = (path, sets=Vec::new(), sensor="hdl32e"))]
    fn from_path(path: PathBuf, sets: Vec<String>, sensor: &str) -> PyResult<Self> {
        let name = path.display().to_string();
        load(None, Some(&path), &name, &sets, sensor)
    }

    /// Builds a configuration from a dict laid out as the TOML file, for frames of
    /// `sensor`.
    #[staticmethod]
    #[pyo3(signature = (table, sets=Vec::new(), sensor="hdl32e"))]
    fn from_table(table: &Bound<'_, PyDict>, sets: Vec<String>, sensor: &str) -> PyResult<Self> {
        let value = to_toml(table.as_any(), "")?;
        let text = toml::to_string(&value)
            .map_err(|e| PyValueError::new_err(format!("config dict: {e}")))?;
        load(Some(&text), None, "<dict>", &sets, sensor)
    }

    /// The model name of the sensor the chain is for ("HDL-32E", "HDL-64E S2").
    #[getter]
    fn sensor(&self) -> &'static str {
        self.sensor.name
    }

    /// Lasers of the sensor the chain is for.
    #[getter]
    fn lasers(&self) -> usize {
        self.sensor.lasers
    }

    /// Warnings the configuration gave (as `run` prints them).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.warnings.clone()
    }

    /// The configuration's seed.
    #[getter]
    fn seed(&self) -> u64 {
        self.config.seed
    }

    /// The effective configuration as TOML (defaults filled in).
    #[getter]
    fn effective_toml(&self) -> String {
        self.config.effective_toml()
    }

    /// The noise stages' types in chain order.
    #[getter]
    fn stages(&self) -> Vec<String> {
        self.config
            .noise
            .iter()
            .map(|s| s.kind().to_string())
            .collect()
    }

    /// Runs the chain on full returns (the fields of `read`'s arrays), rows in input order
    /// then the added returns.
    ///
    /// With `layout` (field offsets of the package's `APPLIED_DTYPE`), the result is the
    /// records' bytes, for numpy to view as that dtype; else a dict of columns.
    #[pyo3(signature = (cols, seed=None, frame=0, threads=None, layout=None))]
    fn apply_returns<'py>(
        &self,
        py: Python<'py>,
        cols: &Bound<'py, PyDict>,
        seed: Option<u64>,
        frame: u32,
        threads: Option<usize>,
        layout: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let returns = returns_of(cols, self.sensor.lasers)?;
        let layout = layout.map(RecordLayout::of).transpose()?;
        let chain = self.chain(seed)?;
        let out = py.detach(|| {
            on_threads(threads, || {
                let noisy = chain.process_returns(frame, returns);
                let rows: Vec<u32> = (0..noisy.len() as u32).collect();
                match &layout {
                    Some(l) => Ok(l.records(&noisy, &rows)),
                    None => Err(Box::new(Applied::of(&noisy, &rows))),
                }
            })
        })?;
        match out {
            Ok(bytes) => Ok(PyArray1::from_vec(py, bytes).into_any()),
            Err(applied) => Ok(applied.into_dict(py)?.into_any()),
        }
    }

    /// Runs the chain on plain points (x y z intensity, optional ring) made returns of the
    /// chain's sensor (`cloud::returns`); rows in input order then the added returns.
    /// `layout` as for `apply_returns`.
    #[pyo3(signature = (cols, seed=None, frame=0, rotation_hz=10.0, intensity_scale="byte", threads=None, layout=None))]
    #[allow(clippy::too_many_arguments)]
    fn apply_points<'py>(
        &self,
        py: Python<'py>,
        cols: &Bound<'py, PyDict>,
        seed: Option<u64>,
        frame: u32,
        rotation_hz: f64,
        intensity_scale: &str,
        threads: Option<usize>,
        layout: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let points = cloud_points_of(cols)?;
        let scale = intensity_scale_of(intensity_scale)?;
        let layout = layout.map(RecordLayout::of).transpose()?;
        let chain = self.chain(seed)?;
        let sensor = self.sensor;
        let out = py
            .detach(|| {
                on_threads(
                    threads,
                    || -> Result<Result<Vec<u8>, Box<Applied>>, Error> {
                        let placed = points_as_returns(&points, sensor, rotation_hz, scale)?;
                        let n = placed.order.len();
                        let noisy = chain.process_returns(frame, placed.returns);
                        // Back to input order: row r of the output is the return of point r.
                        let mut rows = vec![0u32; n];
                        for (j, &i) in placed.order.iter().enumerate() {
                            rows[i as usize] = j as u32;
                        }
                        rows.extend(n as u32..noisy.len() as u32);
                        Ok(match &layout {
                            Some(l) => Ok(l.records(&noisy, &rows)),
                            None => Err(Box::new(Applied::of(&noisy, &rows))),
                        })
                    },
                )
            })?
            .map_err(py_err)?;
        match out {
            Ok(bytes) => Ok(PyArray1::from_vec(py, bytes).into_any()),
            Err(applied) => Ok(applied.into_dict(py)?.into_any()),
        }
    }

    /// Ground labels of returns by the configuration's `[ground]` (the pipeline's stream
    /// for frame `frame`).
    #[pyo3(signature = (cols, seed=None, frame=0))]
    fn ground<'py>(
        &self,
        py: Python<'py>,
        cols: &Bound<'py, PyDict>,
        seed: Option<u64>,
        frame: u32,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let returns = returns_of(cols, self.sensor.lasers)?;
        let config = self.config_with(seed);
        let labels = py.detach(|| {
            let tag = stage_tags(&["ground"])[0];
            let mut rng = stage_rng(config.seed, frame, tag);
            lidar_noise::ground::segment(&returns, &config.ground, &mut rng)
        });
        Ok(PyArray1::from_vec(py, labels))
    }

    /// Cluster labels (-1 noise) of points by the configuration's `[cluster]`.
    fn cluster<'py>(
        &self,
        py: Python<'py>,
        cols: &Bound<'py, PyDict>,
    ) -> PyResult<(Bound<'py, PyArray1<i32>>, usize)> {
        let x = column::<f32>(cols, "x", None)?;
        let n = x.as_array().len();
        let y = column::<f32>(cols, "y", Some(n))?;
        let z = column::<f32>(cols, "z", Some(n))?;
        let (x, y, z) = (x.as_array(), y.as_array(), z.as_array());
        let mut points = Vec::with_capacity(n);
        for i in 0..n {
            let p = [x[i], y[i], z[i]];
            if !p.iter().all(|v| v.is_finite()) {
                return Err(PyValueError::new_err(format!(
                    "points: point {i} (0-based): a coordinate is not a finite number"
                )));
            }
            points.push(p);
        }
        let opts = self.config.cluster;
        let c = py
            .detach(|| lidar_noise::cluster::cluster(&points, &opts))
            .map_err(py_err)?;
        Ok((PyArray1::from_vec(py, c.labels), c.n_clusters))
    }

    /// The whole per-frame pipeline on returns: noise (unless `noise` is false), ground,
    /// clusters and objects. Gives the applied columns plus `ground` and `cluster` per
    /// row, and the clusters as JSON text (as clusters.json describes them).
    #[pyo3(signature = (cols, seed=None, frame=0, noise=true))]
    fn detect<'py>(
        &self,
        py: Python<'py>,
        cols: &Bound<'py, PyDict>,
        seed: Option<u64>,
        frame: u32,
        noise: bool,
    ) -> PyResult<(Bound<'py, PyDict>, String)> {
        let returns = returns_of(cols, self.sensor.lasers)?;
        let mut config = self.config_with(seed);
        if !noise {
            config.noise.clear();
        }
        let sensor = self.sensor;
        let (applied, ground, labels, clusters) = py
            .detach(|| -> Result<_, Error> {
                let pipeline = Pipeline::new(&config)
                    .for_sensor(sensor)
                    .map_err(|e| Error::Invalid(misfit_message(sensor, &e)))?;
                let r = pipeline.process(Frame {
                    index: frame,
                    partial: false,
                    returns,
                })?;
                let rows: Vec<u32> = (0..r.noisy.len() as u32).collect();
                let mut ground = vec![false; rows.len()];
                let mut labels = vec![-1i32; rows.len()];
                for (s, &k) in r.kept.iter().enumerate() {
                    ground[k as usize] = r.ground[s];
                    labels[k as usize] = r.labels[s];
                }
                let clusters = serde_json::to_string(&r.clusters)
                    .map_err(|e| Error::Invalid(format!("clusters: {e}")))?;
                Ok((Applied::of(&r.noisy, &rows), ground, labels, clusters))
            })
            .map_err(py_err)?;
        let d = applied.into_dict(py)?;
        d.set_item("ground", PyArray1::from_vec(py, ground))?;
        d.set_item("cluster", PyArray1::from_vec(py, labels))?;
        Ok((d, clusters))
    }
}

fn intensity_scale_of(name: &str) -> PyResult<IntensityScale> {
    match name {
        "byte" => Ok(IntensityScale::Byte),
        "unit" => Ok(IntensityScale::Unit),
        other => Err(PyValueError::new_err(format!(
            "intensity_scale {other:?}: give \"byte\" (0-255, nuScenes) or \"unit\" (0-1, KITTI)"
        ))),
    }
}

/// Plain points as returns of `sensor` (the library's conversion).
fn points_as_returns(
    points: &[CloudPoint],
    sensor: &SensorModel,
    rotation_hz: f64,
    intensity_scale: IntensityScale,
) -> Result<cloud::returns::CloudReturns, Error> {
    let options = cloud::returns::ReturnsOptions {
        rotation_hz,
        intensity_scale,
        start_time: 0.0,
    };
    cloud::returns::to_returns(points, sensor, &options, "points")
}

/// Plain points as returns of the sensor named `sensor`, as the columns of `read`'s
/// arrays in firing order, with the input index of each.
#[pyfunction]
#[pyo3(signature = (cols, rotation_hz=10.0, intensity_scale="byte", sensor="hdl32e"))]
fn points_to_returns<'py>(
    py: Python<'py>,
    cols: &Bound<'py, PyDict>,
    rotation_hz: f64,
    intensity_scale: &str,
    sensor: &str,
) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyArray1<u32>>)> {
    let sensor = sensor_of(sensor)?;
    let points = cloud_points_of(cols)?;
    let scale = intensity_scale_of(intensity_scale)?;
    let placed = py
        .detach(|| points_as_returns(&points, sensor, rotation_hz, scale))
        .map_err(py_err)?;
    let d = ReturnColumns::of(placed.returns.iter()).into_dict(py)?;
    d.set_item("moved", placed.moved)?;
    d.set_item("shared", placed.shared)?;
    Ok((d, PyArray1::from_vec(py, placed.order)))
}

/// The sensor model a `sensor=` name means: its model name, laser count and the
/// elevation of each laser id in degrees (the model's built-in table); a ValueError
/// listing the names for one not modelled.
#[pyfunction]
fn sensor_model(name: &str) -> PyResult<(&'static str, usize, Vec<f64>)> {
    let model = sensor_of(name)?;
    Ok((model.name, model.lasers, model.elevation_deg.to_vec()))
}

/// The frames of a capture as return columns, with each frame's index and partial flag,
/// decoded with the command line's defaults (`keep_partial` as `--keep-partial`), and
/// the name of the sensor: an HDL-32E, or another described sensor told by its packets'
/// structure, as `run` reads them.
#[pyfunction]
#[pyo3(signature = (path, keep_partial=false))]
#[allow(clippy::type_complexity)]
fn read_capture<'py>(
    py: Python<'py>,
    path: PathBuf,
    keep_partial: bool,
) -> PyResult<(&'static str, Vec<(u32, bool, Bound<'py, PyDict>)>)> {
    use lidar_noise::frame::FrameSource;
    use lidar_noise::sensor::frames::CaptureFrames;
    let (sensor, frames) = py
        .detach(|| -> Result<(&'static str, Vec<Frame>), Error> {
            let options = lidar_noise::sensor::frames::DecoderOptions {
                keep_partial,
                ..Default::default()
            };
            // The reader `run` uses: the HDL-32E's, or another described sensor's.
            match lidar_noise::sensor::frames::open_capture(&path, &options)? {
                CaptureFrames::Hdl32e(mut r) => Ok((
                    lidar_noise::sensor::HDL32E.name,
                    r.read_rest(&(0..=u32::MAX))?,
                )),
                CaptureFrames::Model(mut r) => {
                    let frames = r.read_rest(&(0..=u32::MAX))?;
                    Ok((r.model().name, frames))
                }
            }
        })
        .map_err(py_err)?;
    let frames = frames
        .into_iter()
        .map(|f| {
            let d = ReturnColumns::of(f.returns.iter()).into_dict(py)?;
            Ok((f.index, f.partial, d))
        })
        .collect::<PyResult<Vec<_>>>()?;
    Ok((sensor, frames))
}

/// The points of a point-cloud file as columns (x y z intensity, ring and time where the
/// file has them), with its format name and intensity scale.
#[pyfunction]
fn read_cloud<'py>(
    py: Python<'py>,
    path: PathBuf,
) -> PyResult<(Bound<'py, PyDict>, String, String)> {
    let cloud = py
        .detach(|| cloud::read_file(&path, &cloud::ReadOptions::default()))
        .map_err(py_err)?;
    let d = PyDict::new(py);
    let p = &cloud.points;
    d.set_item("x", PyArray1::from_vec(py, p.iter().map(|p| p.x).collect()))?;
    d.set_item("y", PyArray1::from_vec(py, p.iter().map(|p| p.y).collect()))?;
    d.set_item("z", PyArray1::from_vec(py, p.iter().map(|p| p.z).collect()))?;
    d.set_item(
        "intensity",
        PyArray1::from_vec(py, p.iter().map(|p| p.intensity).collect()),
    )?;
    if cloud.info.fields.ring {
        let ring: Vec<i64> = p.iter().map(|p| p.ring.map_or(-1, i64::from)).collect();
        d.set_item("ring", PyArray1::from_vec(py, ring))?;
    }
    if cloud.info.fields.time {
        let t: Vec<f64> = p.iter().map(|p| p.time.unwrap_or(f64::NAN)).collect();
        d.set_item("time", PyArray1::from_vec(py, t))?;
    }
    let scale = match cloud.info.intensity_scale {
        IntensityScale::Unit => "unit",
        IntensityScale::Byte => "byte",
        IntensityScale::Unstated => "unstated",
    };
    Ok((d, cloud.info.format.name().to_string(), scale.to_string()))
}

/// Writes returns (and the optional columns of `apply`) as a binary PLY frame with the
/// library's writer, atomically.
#[pyfunction]
#[pyo3(signature = (path, cols, frame=0))]
fn write_ply(path: PathBuf, cols: &Bound<'_, PyDict>, frame: u32) -> PyResult<()> {
    use lidar_noise::writers::ply::{PlyColumns, PlyFrame};
    // Returns of any modelled sensor: the writer keeps the laser ids as they are.
    let returns = returns_of(cols, lidar_noise::noise::spurious::MAX_LASERS)?;
    let n = returns.len();
    let opt_f32 = |name: &str| -> PyResult<Option<Vec<f32>>> {
        match cols.get_item(name)? {
            Some(_) => Ok(Some(
                column::<f32>(cols, name, Some(n))?.as_array().to_vec(),
            )),
            None => Ok(None),
        }
    };
    let opt_u8 = |name: &str| -> PyResult<Option<Vec<u8>>> {
        match cols.get_item(name)? {
            Some(_) => Ok(Some(column::<u8>(cols, name, Some(n))?.as_array().to_vec())),
            None => Ok(None),
        }
    };
    let range_clean = opt_f32("range_clean")?;
    // The power is kept as f64 by `apply`; the PLY column is float, as `run` writes it.
    let power = match cols.get_item("power")? {
        Some(_) => Some(
            column::<f64>(cols, "power", Some(n))?
                .as_array()
                .iter()
                .map(|&p| p as f32)
                .collect::<Vec<f32>>(),
        ),
        None => None,
    };
    let fate = opt_u8("fate")?;
    let cause = opt_u8("cause")?;
    let start = returns.first().map_or(0.0, |r| r.time);
    let source = path.display().to_string();
    let ply = PlyFrame {
        columns: PlyColumns {
            range_clean: range_clean.as_deref(),
            power: power.as_deref(),
            fate: fate.as_deref(),
            cause: cause.as_deref(),
            ..PlyColumns::default()
        },
        ..PlyFrame::new(&returns, &source, frame, start)
    };
    ply.check().map_err(py_err)?;
    lidar_noise::writers::atomic::write_atomically(&path, &[], |out| ply.write(out)).map_err(py_err)
}

/// Runs the library's sweep (what `lidar-noise sweep` runs, silently) of `captures` into
/// `output`, where its tidy table then is: `varies` are `KEY=V1,V2,...`, `sets`
/// `KEY=VALUE`, `seeds` and `frames` as the command's options. ValueError for bad options,
/// OSError for files. The GIL is released while it runs.
#[pyfunction]
#[pyo3(signature = (captures, output, config=None, varies=Vec::new(), sets=Vec::new(), seeds=None, frames=None))]
#[allow(clippy::too_many_arguments)]
fn sweep(
    py: Python<'_>,
    captures: Vec<PathBuf>,
    output: PathBuf,
    config: Option<PathBuf>,
    varies: Vec<String>,
    sets: Vec<String>,
    seeds: Option<String>,
    frames: Option<String>,
) -> PyResult<()> {
    use lidar_noise::sweep::folder::SweepRequest;
    use lidar_noise::sweep::plan::{parse_seeds, Vary};
    let request = (|| -> Result<SweepRequest, Error> {
        Ok(SweepRequest {
            config,
            sets,
            varies: varies
                .iter()
                .map(|v| Vary::parse(v))
                .collect::<Result<_, _>>()?,
            seeds: seeds.as_deref().map(parse_seeds).transpose()?,
            frames: match &frames {
                Some(text) => lidar_noise::range::parse_range("--frames", text)?,
                None => lidar_noise::range::ALL_FRAMES,
            },
            ..SweepRequest::new(captures, output)
        })
    })()
    .map_err(py_err)?;
    py.detach(|| lidar_noise::sweep::folder::sweep(&request, &lidar_noise::observe::Silent))
        .map_err(|e| {
            let message = lidar_noise::error::message_of(&e);
            let io = e.chain().any(|c| {
                matches!(c.downcast_ref::<Error>(), Some(Error::Io { .. }))
                    || c.downcast_ref::<std::io::Error>().is_some()
            });
            if io {
                PyOSError::new_err(message)
            } else {
                PyValueError::new_err(message)
            }
        })
}

/// The compiled module.
#[pymodule]
fn _lidar_noise(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Chain>()?;
    m.add_function(wrap_pyfunction!(points_to_returns, m)?)?;
    m.add_function(wrap_pyfunction!(sensor_model, m)?)?;
    m.add_function(wrap_pyfunction!(read_capture, m)?)?;
    m.add_function(wrap_pyfunction!(read_cloud, m)?)?;
    m.add_function(wrap_pyfunction!(write_ply, m)?)?;
    m.add_function(wrap_pyfunction!(sweep, m)?)?;
    m.add("VERSION", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
