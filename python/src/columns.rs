//! numpy columns to the library's returns and points, and noisy frames back to columns
//! and records.

use crate::*;

/// Column `name` of `cols`, with one value per point.
pub(crate) fn column<'py, T: Element>(
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
pub(crate) fn returns_of(cols: &Bound<'_, PyDict>, lasers: usize) -> PyResult<Vec<Return>> {
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
pub(crate) enum RingColumn<'py> {
    Float(PyReadonlyArray1<'py, f32>),
    Int(PyReadonlyArray1<'py, i64>),
}

/// Ring `v` of point `i` as the library's ring number. Whole and in range is one
/// round trip through an integer (NaN and infinities do not come back equal), without
/// the libm call `fract` makes on the wheel's baseline x86-64.
pub(crate) fn ring_of(i: usize, v: f32) -> PyResult<u16> {
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
pub(crate) fn cast_ring(v: f32) -> (u16, bool) {
    let ring = v as u16;
    (ring, f32::from(ring) == v)
}

/// The error [`ring_of`] gives the first of `rings` that is not a ring, if any.
pub(crate) fn first_bad_ring(rings: impl Iterator<Item = f32>) -> PyResult<()> {
    match rings.enumerate().find_map(|(i, v)| ring_of(i, v).err()) {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// Plain points (x y z intensity, optional ring and time) of a column dictionary.
pub(crate) fn cloud_points_of(cols: &Bound<'_, PyDict>) -> PyResult<Vec<CloudPoint>> {
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
pub(crate) fn cloud_points_of_rows(rows: &Bound<'_, PyAny>) -> PyResult<Vec<CloudPoint>> {
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
pub(crate) struct ReturnColumns {
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
    pub(crate) fn of<'a>(returns: impl ExactSizeIterator<Item = &'a Return>) -> Self {
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

    pub(crate) fn into_dict<'py>(self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
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
pub(crate) fn clean_range(noisy: &NoisyFrame, i: usize) -> f32 {
    if i < noisy.clean_len {
        noisy.clean[i].range
    } else {
        0.0
    }
}

/// The fields of a record of `apply`'s result (the package's `APPLIED_DTYPE`) with their
/// sizes in bytes, in the order [`RecordLayout::records`] writes them.
pub(crate) const RECORD_FIELDS: [(&str, usize); 19] = [
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
pub(crate) struct RecordLayout {
    itemsize: usize,
    at: [usize; 19],
}

impl RecordLayout {
    /// From a dict of field offsets plus `__itemsize__`; every field must fit.
    pub(crate) fn of(d: &Bound<'_, PyDict>) -> PyResult<Self> {
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
    pub(crate) fn records(&self, noisy: &NoisyFrame, rows: &[u32]) -> Vec<u8> {
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
pub(crate) const ALIGNED_AT: [usize; 19] = [
    0, 4, 8, 12, 16, 20, 24, 32, 36, 38, 39, 40, 41, 42, 44, 48, 56, 57, 58,
];
/// Size of a record in numpy's aligned layout of `APPLIED_DTYPE`.
pub(crate) const ALIGNED_ITEMSIZE: usize = 64;

/// Writes the record of return `i` into `rec`, field j at byte `at[j]` (little-endian).
#[inline(always)]
pub(crate) fn fill_record(
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
