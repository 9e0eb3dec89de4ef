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

mod chain;
mod columns;
mod files;
mod sweep;

use chain::*;
use columns::*;
use files::*;

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
pub(crate) fn py_err(e: Error) -> PyErr {
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
pub(crate) fn sensor_of(name: &str) -> PyResult<&'static SensorModel> {
    sensor_by_name(name).ok_or_else(|| {
        PyValueError::new_err(format!(
            "sensor {name:?}: not a sensor modelled here (give one of {SENSOR_NAMES})"
        ))
    })
}

/// A per-laser misfit of the noise chain (`for_lasers`'s message `e`) worded as `run`
/// words it: the sensor, then the stage and option.
pub(crate) fn misfit_message(sensor: &SensorModel, e: &str) -> String {
    format!("the {} ({} lasers): {e}", sensor.name, sensor.lasers)
}

/// A per-laser misfit of the noise chain as the ValueError the package documents.
pub(crate) fn misfit(sensor: &SensorModel, e: String) -> PyErr {
    PyValueError::new_err(misfit_message(sensor, &e))
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
    m.add_function(wrap_pyfunction!(sweep::sweep, m)?)?;
    m.add("VERSION", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
