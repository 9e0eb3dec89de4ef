//! Reading captures and point clouds into columns, and writing a PLY.

use crate::*;

pub(crate) fn intensity_scale_of(name: &str) -> PyResult<IntensityScale> {
    match name {
        "byte" => Ok(IntensityScale::Byte),
        "unit" => Ok(IntensityScale::Unit),
        other => Err(PyValueError::new_err(format!(
            "intensity_scale {other:?}: give \"byte\" (0-255, nuScenes) or \"unit\" (0-1, KITTI)"
        ))),
    }
}

/// Plain points as returns of `sensor` (the library's conversion).
pub(crate) fn points_as_returns(
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
pub(crate) fn points_to_returns<'py>(
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
pub(crate) fn sensor_model(name: &str) -> PyResult<(&'static str, usize, Vec<f64>)> {
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
pub(crate) fn read_capture<'py>(
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
pub(crate) fn read_cloud<'py>(
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
pub(crate) fn write_ply(path: PathBuf, cols: &Bound<'_, PyDict>, frame: u32) -> PyResult<()> {
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
