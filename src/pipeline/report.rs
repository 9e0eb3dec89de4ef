//! Reports of a run: the per-capture summary and the cluster report (JSON and CSV).

use super::{FrameResult, StageCounts};
use crate::cluster::ClusterInfo;
use crate::noise::NoiseSummary;
use crate::writers::csv::CsvTable;
use serde::Serialize;

/// Meaning of the PLY `fate` codes, in code order.
pub const FATE_CODES: [&str; 6] = [
    "kept",
    "occluded",
    "below_power",
    "below_min_range",
    "replaced",
    "added",
];

/// One frame's line in the summary.
#[derive(Clone, Debug, Serialize)]
pub struct FrameReport {
    /// Sweep index in the capture.
    pub index: u32,
    /// What the noise chain and the filters did.
    pub noise: NoiseSummary,
    /// Counts after ground removal and clustering.
    pub stages: StageCounts,
    /// Share of kept returns labelled ground.
    pub ground_fraction: f64,
}

impl FrameReport {
    /// Summarises a processed frame.
    pub fn of(result: &FrameResult) -> Self {
        FrameReport {
            index: result.noisy.index,
            noise: result.noise.clone(),
            stages: result.counts.clone(),
            ground_fraction: result.counts.ground_fraction(),
        }
    }
}

/// Totals over the frames of a capture.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Totals {
    /// Merged noise summaries.
    pub noise: NoiseSummary,
    /// Summed stage counts.
    pub stages: StageCounts,
    /// Share of kept returns labelled ground.
    pub ground_fraction: f64,
}

impl Totals {
    /// Adds up frame reports.
    pub fn of(frames: &[FrameReport]) -> Self {
        let mut t = Totals::default();
        for f in frames {
            t.add(f);
        }
        t
    }

    /// Adds one frame report (the running form of `of`, for streamed reports).
    pub fn add(&mut self, f: &FrameReport) {
        self.noise.merge(&f.noise);
        self.stages.merge(&f.stages);
        self.ground_fraction = self.stages.ground_fraction();
    }
}

/// One frame's clusters in the cluster report.
#[derive(Clone, Debug, Serialize)]
pub struct FrameClusters {
    /// Sweep index in the capture.
    pub index: u32,
    /// Objects, sorted by id.
    pub clusters: Vec<ClusterInfo>,
}

/// Columns of the cluster CSV.
pub const CLUSTER_COLUMNS: [&str; 27] = [
    "frame",
    "cluster",
    "object",
    "points",
    "centroid_x",
    "centroid_y",
    "centroid_z",
    "min_x",
    "min_y",
    "min_z",
    "max_x",
    "max_y",
    "max_z",
    "extent_x",
    "extent_y",
    "extent_z",
    "box_center_x",
    "box_center_y",
    "box_length",
    "box_width",
    "box_yaw_deg",
    "box_z_min",
    "box_z_max",
    "min_range",
    "mean_range",
    "mean_intensity",
    "lasers",
];

/// `format!("{v:.4}")`, byte for byte, without the exact big-number formatting for
/// ordinary values. `{:.4}` rounds the exact binary value to 4 decimals; for `|v| < 1e6`,
/// `v * 1e4` is within 1e-6 of the exact scaled value, so rounding it gives the same
/// digits unless its fraction lies within 1e-3 of one half (ties and near-ties, including
/// exact ties such as 1/32, go to `format!`, which decides them exactly). Negative values
/// that round to zero (printed `-0.0000`), NaN, infinities and large values also go to
/// `format!`. Profiling showed `{:.4}` (Grisu with Dragon fallback) at about 4 % of a run.
pub(crate) fn fixed4(v: f64) -> String {
    let a = v.abs();
    if a < 1e6 {
        let s = a * 1e4;
        let whole = s as u64;
        let frac = s - whole as f64;
        if (frac - 0.5).abs() > 1e-3 {
            let n = whole + u64::from(frac > 0.5);
            if n > 0 || !v.is_sign_negative() {
                let sign = if v.is_sign_negative() { "-" } else { "" };
                return format!("{sign}{}.{:04}", n / 10_000, n % 10_000);
            }
        }
    }
    format!("{v:.4}")
}

/// Appends `format!("{v:.4}")` to `out`, byte for byte (the digits of [`fixed4`] without
/// a `String` per value).
pub(crate) fn push_fixed4(out: &mut Vec<u8>, v: f64) {
    use std::io::Write as _;
    let a = v.abs();
    if a < 1e6 {
        let s = a * 1e4;
        let whole = s as u64;
        let frac = s - whole as f64;
        if (frac - 0.5).abs() > 1e-3 {
            let n = whole + u64::from(frac > 0.5);
            if n > 0 || !v.is_sign_negative() {
                if v.is_sign_negative() {
                    out.push(b'-');
                }
                push_u64(out, n / 10_000);
                let f = n % 10_000;
                out.extend_from_slice(&[
                    b'.',
                    b'0' + (f / 1000) as u8,
                    b'0' + (f / 100 % 10) as u8,
                    b'0' + (f / 10 % 10) as u8,
                    b'0' + (f % 10) as u8,
                ]);
                return;
            }
        }
    }
    let _ = write!(out, "{v:.4}");
}

/// Appends the decimal digits of `n` (as `{}` prints it).
fn push_u64(out: &mut Vec<u8>, mut n: u64) {
    let mut digits = [0u8; 20];
    let mut at = digits.len();
    loop {
        at -= 1;
        digits[at] = b'0' + (n % 10) as u8;
        n /= 10;
        if n == 0 {
            break;
        }
    }
    out.extend_from_slice(&digits[at..]);
}

/// Appends `n` as `{}` prints it.
fn push_i64(out: &mut Vec<u8>, n: i64) {
    if n < 0 {
        out.push(b'-');
    }
    push_u64(out, n.unsigned_abs());
}

/// Appends the cluster CSV of `frames` (header line, then one row per cluster): the bytes
/// `cluster_table(frames).write_to` writes, without a table of strings in between. No
/// cell needs quotes (numbers, and laser ids separated by spaces), so the CSV writer
/// would add none.
pub fn write_cluster_csv(out: &mut Vec<u8>, frames: &[FrameClusters]) {
    out.extend_from_slice(CLUSTER_COLUMNS.join(",").as_bytes());
    out.push(b'\n');
    for frame in frames {
        for c in &frame.clusters {
            let b = &c.oriented_box;
            push_u64(out, u64::from(frame.index));
            out.push(b',');
            push_i64(out, i64::from(c.id));
            out.push(b',');
            push_u64(out, u64::from(c.object));
            out.push(b',');
            push_u64(out, c.n_points as u64);
            for v in [
                c.centroid[0],
                c.centroid[1],
                c.centroid[2],
                c.aabb_min[0],
                c.aabb_min[1],
                c.aabb_min[2],
                c.aabb_max[0],
                c.aabb_max[1],
                c.aabb_max[2],
                c.extent[0],
                c.extent[1],
                c.extent[2],
                b.center[0],
                b.center[1],
                b.length,
                b.width,
                b.yaw_deg,
                b.z_min,
                b.z_max,
                c.min_range,
                c.mean_range,
                c.mean_intensity,
            ] {
                out.push(b',');
                push_fixed4(out, v);
            }
            out.push(b',');
            for (i, &l) in c.lasers.iter().enumerate() {
                if i > 0 {
                    out.push(b' ');
                }
                push_u64(out, u64::from(l));
            }
            out.push(b'\n');
        }
    }
}

/// Appends `frame` as [`write_pretty_nested`] writes it `level` levels deep, byte for
/// byte, without serde: the cluster report is most of a run's JSON, and serde_json spent
/// about 13,000 instructions per cluster (one `io::Write` call per token, the key
/// escaping scan, the indentation written space by space). Numbers go through
/// serde_json's own formatter, and NaN and infinities become `null` as serde_json writes
/// them.
pub fn write_frame_clusters_json(out: &mut Vec<u8>, level: usize, frame: &FrameClusters) {
    let mut j = PrettyJson { out, level };
    j.open(b'{');
    j.key(true, "\"index\": ");
    j.uint(u64::from(frame.index));
    j.key(false, "\"clusters\": ");
    if frame.clusters.is_empty() {
        j.out.extend_from_slice(b"[]");
    } else {
        j.open(b'[');
        for (i, c) in frame.clusters.iter().enumerate() {
            j.element(i == 0);
            j.cluster(c);
        }
        j.close(b']');
    }
    j.close(b'}');
}

/// serde_json's pretty layout (two-space indent) written straight into a byte buffer.
struct PrettyJson<'a> {
    out: &'a mut Vec<u8>,
    level: usize,
}

/// `,` and a line break, then the indentation of up to 64 levels.
const PAD: [u8; 130] = {
    let mut pad = [b' '; 130];
    pad[0] = b',';
    pad[1] = b'\n';
    pad
};

impl PrettyJson<'_> {
    /// `,` (unless `first`), a line break and the current indentation, in one copy.
    fn separator(&mut self, first: bool) {
        let end = 2 + 2 * self.level;
        if end <= PAD.len() {
            self.out.extend_from_slice(&PAD[usize::from(first)..end]);
        } else {
            self.out.extend_from_slice(&PAD[usize::from(first)..2]);
            let n = self.out.len() + 2 * self.level;
            self.out.resize(n, b' ');
        }
    }

    /// Opens an object or a non-empty array.
    fn open(&mut self, bracket: u8) {
        self.out.push(bracket);
        self.level += 1;
    }

    /// Closes an object or array that holds values, on its own line.
    fn close(&mut self, bracket: u8) {
        self.level -= 1;
        self.separator(true);
        self.out.push(bracket);
    }

    /// Starts an array element.
    fn element(&mut self, first: bool) {
        self.separator(first);
    }

    /// Starts an object entry; `quoted` is the key as written with its colon, e.g.
    /// `"id": ` (field names need no escaping).
    fn key(&mut self, first: bool, quoted: &str) {
        self.separator(first);
        self.out.extend_from_slice(quoted.as_bytes());
    }

    fn uint(&mut self, n: u64) {
        push_u64(self.out, n);
    }

    /// A number as serde_json writes an `f64`: shortest round-trip text, `null` when not
    /// finite.
    fn float(&mut self, v: f64) {
        use serde_json::ser::Formatter as _;
        if v.is_finite() {
            // Writing into a Vec cannot fail.
            let _ = serde_json::ser::CompactFormatter.write_f64(self.out, v);
        } else {
            self.out.extend_from_slice(b"null");
        }
    }

    /// A non-empty array of numbers, one per line.
    fn floats(&mut self, values: &[f64]) {
        self.open(b'[');
        for (i, &v) in values.iter().enumerate() {
            self.element(i == 0);
            self.float(v);
        }
        self.close(b']');
    }

    /// One [`ClusterInfo`] object, fields in declaration order (as the derive writes them).
    fn cluster(&mut self, c: &ClusterInfo) {
        let ClusterInfo {
            id,
            n_points,
            centroid,
            aabb_min,
            aabb_max,
            extent,
            oriented_box,
            min_range,
            mean_range,
            mean_intensity,
            lasers,
            object,
        } = c;
        let crate::cluster::OrientedBox {
            center,
            length,
            width,
            yaw_deg,
            z_min,
            z_max,
        } = oriented_box;
        self.open(b'{');
        self.key(true, "\"id\": ");
        push_i64(self.out, i64::from(*id));
        self.key(false, "\"n_points\": ");
        self.uint(*n_points as u64);
        for (name, v) in [
            ("\"centroid\": ", centroid),
            ("\"aabb_min\": ", aabb_min),
            ("\"aabb_max\": ", aabb_max),
            ("\"extent\": ", extent),
        ] {
            self.key(false, name);
            self.floats(v);
        }
        self.key(false, "\"oriented_box\": ");
        self.open(b'{');
        self.key(true, "\"center\": ");
        self.floats(center);
        for (name, v) in [
            ("\"length\": ", length),
            ("\"width\": ", width),
            ("\"yaw_deg\": ", yaw_deg),
            ("\"z_min\": ", z_min),
            ("\"z_max\": ", z_max),
        ] {
            self.key(false, name);
            self.float(*v);
        }
        self.close(b'}');
        for (name, v) in [
            ("\"min_range\": ", min_range),
            ("\"mean_range\": ", mean_range),
            ("\"mean_intensity\": ", mean_intensity),
        ] {
            self.key(false, name);
            self.float(*v);
        }
        self.key(false, "\"lasers\": ");
        if lasers.is_empty() {
            self.out.extend_from_slice(b"[]");
        } else {
            self.open(b'[');
            for (i, &l) in lasers.iter().enumerate() {
                self.element(i == 0);
                self.uint(u64::from(l));
            }
            self.close(b']');
        }
        self.key(false, "\"object\": ");
        self.out
            .extend_from_slice(if *object { b"true" } else { b"false" });
        self.close(b'}');
    }
}

/// Writes `value` as serde_json's pretty printer lays it out `level` levels deep inside a
/// pretty document: the bytes of `to_string_pretty(value)` with `2 * level` spaces after
/// each line break (JSON text has no other line breaks: strings escape them), serialised
/// straight into `out` instead of re-indented line by line.
pub fn write_pretty_nested<W: std::io::Write, T: Serialize + ?Sized>(
    out: W,
    level: usize,
    value: &T,
) -> serde_json::Result<()> {
    let mut ser = serde_json::Serializer::with_formatter(
        out,
        NestedPretty {
            level,
            has_value: false,
        },
    );
    value.serialize(&mut ser)
}

/// serde_json's `PrettyFormatter` with a two-space indent, starting `level` levels deep.
struct NestedPretty {
    level: usize,
    has_value: bool,
}

impl NestedPretty {
    /// Opens an array or object one level deeper.
    fn open<W: ?Sized + std::io::Write>(
        &mut self,
        w: &mut W,
        bracket: &[u8],
    ) -> std::io::Result<()> {
        self.level += 1;
        self.has_value = false;
        w.write_all(bracket)
    }

    /// Closes an array or object, on its own line when it holds values.
    fn close<W: ?Sized + std::io::Write>(
        &mut self,
        w: &mut W,
        bracket: &[u8],
    ) -> std::io::Result<()> {
        self.level -= 1;
        if self.has_value {
            self.newline(w, b"\n", self.level)?;
        }
        w.write_all(bracket)
    }

    fn newline<W: ?Sized + std::io::Write>(
        &self,
        w: &mut W,
        text: &[u8],
        level: usize,
    ) -> std::io::Result<()> {
        const SPACES: [u8; 64] = [b' '; 64];
        w.write_all(text)?;
        let mut n = 2 * level;
        while n > 0 {
            let k = n.min(SPACES.len());
            w.write_all(&SPACES[..k])?;
            n -= k;
        }
        Ok(())
    }
}

impl serde_json::ser::Formatter for NestedPretty {
    fn begin_array<W: ?Sized + std::io::Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        self.open(w, b"[")
    }

    fn end_array<W: ?Sized + std::io::Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        self.close(w, b"]")
    }

    fn begin_array_value<W: ?Sized + std::io::Write>(
        &mut self,
        w: &mut W,
        first: bool,
    ) -> std::io::Result<()> {
        self.newline(w, if first { b"\n" } else { b",\n" }, self.level)
    }

    fn end_array_value<W: ?Sized + std::io::Write>(&mut self, _w: &mut W) -> std::io::Result<()> {
        self.has_value = true;
        Ok(())
    }

    fn begin_object<W: ?Sized + std::io::Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        self.open(w, b"{")
    }

    fn end_object<W: ?Sized + std::io::Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        self.close(w, b"}")
    }

    fn begin_object_key<W: ?Sized + std::io::Write>(
        &mut self,
        w: &mut W,
        first: bool,
    ) -> std::io::Result<()> {
        self.newline(w, if first { b"\n" } else { b",\n" }, self.level)
    }

    fn begin_object_value<W: ?Sized + std::io::Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        w.write_all(b": ")
    }

    fn end_object_value<W: ?Sized + std::io::Write>(&mut self, _w: &mut W) -> std::io::Result<()> {
        self.has_value = true;
        Ok(())
    }
}

/// The cluster report as one CSV table, one row per cluster.
pub fn cluster_table(frames: &[FrameClusters]) -> CsvTable {
    let mut t = CsvTable::new(&CLUSTER_COLUMNS);
    let f = fixed4;
    for frame in frames {
        for c in &frame.clusters {
            let b = &c.oriented_box;
            let lasers: Vec<String> = c.lasers.iter().map(|l| l.to_string()).collect();
            t.rows.push(vec![
                frame.index.to_string(),
                c.id.to_string(),
                u8::from(c.object).to_string(),
                c.n_points.to_string(),
                f(c.centroid[0]),
                f(c.centroid[1]),
                f(c.centroid[2]),
                f(c.aabb_min[0]),
                f(c.aabb_min[1]),
                f(c.aabb_min[2]),
                f(c.aabb_max[0]),
                f(c.aabb_max[1]),
                f(c.aabb_max[2]),
                f(c.extent[0]),
                f(c.extent[1]),
                f(c.extent[2]),
                f(b.center[0]),
                f(b.center[1]),
                f(b.length),
                f(b.width),
                f(b.yaw_deg),
                f(b.z_min),
                f(b.z_max),
                f(c.min_range),
                f(c.mean_range),
                f(c.mean_intensity),
                lasers.join(" "),
            ]);
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cluster::OrientedBox;
    use crate::writers::Output;
    use rand::{Rng, SeedableRng};

    fn check(v: f64) {
        assert_eq!(fixed4(v), format!("{v:.4}"), "{v:e} ({:#x})", v.to_bits());
        let mut pushed = b"x".to_vec();
        push_fixed4(&mut pushed, v);
        assert_eq!(pushed[1..], *format!("{v:.4}").as_bytes(), "{v:e}");
    }

    #[test]
    fn fixed4_matches_format_on_ties_and_edges() {
        for v in [
            0.0,
            -0.0,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1e6,
            -1e6,
            999_999.999_95,
            1e300,
            -0.00004,
            -0.00005,
            -0.00006,
            0.00005,
            0.00015,
            1.00005,
            2.5e-5,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
        ] {
            check(v);
        }
        // Exact ties of the scaled value (dyadic fractions) and their neighbours.
        for k in -4096i64..4096 {
            for e in [5, 6, 7, 8, 10] {
                let v = k as f64 / f64::from(1u32 << e);
                check(v);
                check(f64::from_bits(v.to_bits() + 1));
                check(f64::from_bits(v.to_bits().wrapping_sub(1)));
            }
        }
    }

    #[test]
    fn fixed4_matches_format_on_random_values() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(14);
        for _ in 0..200_000 {
            let mag = 10f64.powi(rng.random_range(-6..8));
            let v = rng.random_range(-1.0..1.0) * mag;
            check(v);
            check(v as f32 as f64);
            // Values one 1e-4 step apart land on every fraction of the scaled value.
            check((v * 1e4).round() / 1e4 + 5e-5);
        }
    }

    fn cluster(rng: &mut impl Rng, id: i32) -> ClusterInfo {
        let mut v = || -> f64 {
            match rng.random_range(0..12) {
                0 => f64::NAN,
                1 => -0.0,
                2 => -0.00004,
                3 => 1e7 * rng.random_range(-1.0..1.0),
                4 => f64::INFINITY,
                5 => 0.00005,
                _ => rng.random_range(-50.0..50.0),
            }
        };
        let mut a3 = || [v(), v(), v()];
        let (centroid, aabb_min, aabb_max, extent) = (a3(), a3(), a3(), a3());
        let mut v = || rng.random_range(-100.0..100.0);
        ClusterInfo {
            id,
            n_points: (id as usize) * 37,
            centroid,
            aabb_min,
            aabb_max,
            extent,
            oriented_box: OrientedBox {
                center: [v(), v()],
                length: v(),
                width: v(),
                yaw_deg: v(),
                z_min: v(),
                z_max: v(),
            },
            min_range: v(),
            mean_range: v(),
            mean_intensity: v(),
            lasers: (0..(id as u8 % 5) * 7).collect(),
            object: id % 3 == 0,
        }
    }

    fn frames(seed: u64) -> Vec<FrameClusters> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        (0..4)
            .map(|f| FrameClusters {
                index: f * 1000 + 7,
                clusters: (0..f as i32 * 5).map(|i| cluster(&mut rng, i)).collect(),
            })
            .collect()
    }

    #[test]
    fn cluster_csv_matches_the_table_writer() {
        let frames = frames(3);
        assert!(frames
            .iter()
            .any(|f| f.clusters.iter().any(|c| c.lasers.is_empty())));
        for set in [&frames[..], &frames[..1], &frames[2..3]] {
            let mut table = Vec::new();
            cluster_table(set).write_to(&mut table).unwrap();
            let mut direct = Vec::new();
            write_cluster_csv(&mut direct, set);
            assert_eq!(
                String::from_utf8(direct).unwrap(),
                String::from_utf8(table).unwrap()
            );
        }
    }

    #[test]
    fn direct_cluster_json_matches_the_serde_writer() {
        let mut all = frames(9);
        all.extend(frames(10));
        assert!(all.iter().any(|f| f.clusters.is_empty()));
        assert!(all
            .iter()
            .any(|f| f.clusters.iter().any(|c| c.lasers.is_empty())));
        assert!(all.iter().any(|f| f
            .clusters
            .iter()
            .any(|c| c.centroid.iter().any(|v| v.is_nan()))));
        for frame in &all {
            // 70 levels: deeper than the copied indentation reaches.
            for level in [0, 1, 2, 5, 70] {
                let mut serde = b"x".to_vec();
                write_pretty_nested(&mut serde, level, frame).unwrap();
                let mut direct = b"x".to_vec();
                write_frame_clusters_json(&mut direct, level, frame);
                assert_eq!(
                    String::from_utf8(direct).unwrap(),
                    String::from_utf8(serde).unwrap(),
                    "level {level}"
                );
            }
        }
    }

    #[test]
    fn nested_pretty_json_matches_reindented_pretty_text() {
        #[derive(Serialize)]
        struct Doc {
            name: String,
            empty: Vec<u8>,
            empty_map: std::collections::BTreeMap<String, u8>,
            nested: Vec<Vec<f64>>,
            frames: Vec<FrameClusters>,
            text: &'static str,
        }
        let doc = Doc {
            name: "a \"quoted\"\nline".into(),
            empty: vec![],
            empty_map: Default::default(),
            nested: vec![vec![], vec![1.5, -0.0, 1e300]],
            frames: frames(5)
                .into_iter()
                .map(|mut f| {
                    // JSON has no NaN: serde_json writes null for it, as before.
                    f.clusters.truncate(3);
                    f
                })
                .collect(),
            text: "end",
        };
        for level in [0, 1, 2, 5] {
            let text = serde_json::to_string_pretty(&doc).unwrap();
            let pad = " ".repeat(2 * level);
            let expected = text.replace('\n', &format!("\n{pad}"));
            let mut out = Vec::new();
            write_pretty_nested(&mut out, level, &doc).unwrap();
            assert_eq!(String::from_utf8(out).unwrap(), expected, "level {level}");
        }
    }
}
