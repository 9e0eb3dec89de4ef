//! `Chain`: a configuration's noise chain and pipeline applied to numpy columns.

use crate::*;

/// What `apply` hands back: the returns after the chain, each at its noisy position when
/// the sensor still reports it and at its recorded one when dropped (as `run
/// --keep-dropped` writes them), with fate, cause, clean range and power.
pub(crate) struct Applied {
    returns: ReturnColumns,
    range_clean: Vec<f32>,
    power: Vec<f64>,
    fate: Vec<u8>,
    cause: Vec<u8>,
    kept: Vec<bool>,
}

impl Applied {
    /// Rows in `rows` order (indices into the noisy frame).
    pub(crate) fn of(noisy: &NoisyFrame, rows: &[u32]) -> Self {
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

    pub(crate) fn into_dict<'py>(self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
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
pub(crate) fn on_threads<T: Send>(
    threads: Option<usize>,
    work: impl FnOnce() -> T + Send,
) -> PyResult<T> {
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
pub(crate) struct Chain {
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
    pub(crate) fn new(
        config: Config,
        warnings: Vec<String>,
        sensor: &'static SensorModel,
    ) -> PyResult<Self> {
        let chain = Arc::new(build_chain(&config, sensor)?);
        Ok(Chain {
            chains: Mutex::new(vec![(config.seed, chain)]),
            config,
            warnings,
            sensor,
        })
    }

    pub(crate) fn chain(&self, seed: Option<u64>) -> PyResult<Arc<NoiseChain>> {
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
    pub(crate) fn config_with(&self, seed: Option<u64>) -> Config {
        let mut config = self.config.clone();
        if let Some(s) = seed {
            config.seed = s;
        }
        config
    }
}

/// The noise chain of `config` for frames of `sensor` (as `run` builds it per sensor).
pub(crate) fn build_chain(config: &Config, sensor: &SensorModel) -> PyResult<NoiseChain> {
    NoiseChain::new(config)
        .for_sensor(sensor)
        .map_err(|e| misfit(sensor, e))
}

/// Config text `text` named `name` (a path or a label), validated as `run -c` does, for
/// frames of the sensor named `sensor`.
pub(crate) fn load(
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
pub(crate) fn to_toml(v: &Bound<'_, PyAny>, key: &str) -> PyResult<toml::Value> {
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
    pub(crate) fn from_text(
        text: &str,
        name: &str,
        sets: Vec<String>,
        sensor: &str,
    ) -> PyResult<Self> {
        load(Some(text), None, name, &sets, sensor)
    }

    /// Reads a configuration file for frames of `sensor`.
    #[staticmethod]
    #[pyo3(signature = (path, sets=Vec::new(), sensor="hdl32e"))]
    pub(crate) fn from_path(path: PathBuf, sets: Vec<String>, sensor: &str) -> PyResult<Self> {
        let name = path.display().to_string();
        load(None, Some(&path), &name, &sets, sensor)
    }

    /// Builds a configuration from a dict laid out as the TOML file, for frames of
    /// `sensor`.
    #[staticmethod]
    #[pyo3(signature = (table, sets=Vec::new(), sensor="hdl32e"))]
    pub(crate) fn from_table(
        table: &Bound<'_, PyDict>,
        sets: Vec<String>,
        sensor: &str,
    ) -> PyResult<Self> {
        let value = to_toml(table.as_any(), "")?;
        let text = toml::to_string(&value)
            .map_err(|e| PyValueError::new_err(format!("config dict: {e}")))?;
        load(Some(&text), None, "<dict>", &sets, sensor)
    }

    /// The model name of the sensor the chain is for ("HDL-32E", "HDL-64E S2").
    #[getter]
    pub(crate) fn sensor(&self) -> &'static str {
        self.sensor.name
    }

    /// Lasers of the sensor the chain is for.
    #[getter]
    pub(crate) fn lasers(&self) -> usize {
        self.sensor.lasers
    }

    /// Warnings the configuration gave (as `run` prints them).
    #[getter]
    pub(crate) fn warnings(&self) -> Vec<String> {
        self.warnings.clone()
    }

    /// The configuration's seed.
    #[getter]
    pub(crate) fn seed(&self) -> u64 {
        self.config.seed
    }

    /// The effective configuration as TOML (defaults filled in).
    #[getter]
    pub(crate) fn effective_toml(&self) -> String {
        self.config.effective_toml()
    }

    /// The noise stages' types in chain order.
    #[getter]
    pub(crate) fn stages(&self) -> Vec<String> {
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
    pub(crate) fn apply_returns<'py>(
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
    pub(crate) fn apply_points<'py>(
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
    pub(crate) fn ground<'py>(
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
    pub(crate) fn cluster<'py>(
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
    pub(crate) fn detect<'py>(
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
