//! Synthetic scenes: a TOML description of the sensor, the ground and simple objects.
//!
//! World frame: x forward, y left, z up (ROS), origin at the sensor's xy at the
//! datum `z = 0`. The ground's height under the sensor is `ground.height_m` (default
//! 0) and the sensor sits `sensor.height_m` above it. Example:
//!
//! ```toml
//! name = "demo"            # optional, defaults to the file stem
//! frames = 3               # rotations to synthesize
//! seed = 1                 # seeds the range noise
//! range_noise_m = 0.01     # optional Gaussian range sigma, metres (default 0)
//!
//! [sensor]
//! height_m = 1.9           # above the ground
//! pitch_deg = 0.0          # about y (left); positive tips the forward axis down
//! roll_deg = 0.0           # about x (forward); positive tips the left side up
//! rotation_hz = 10.0       # 5..20
//!
//! [ground]
//! height_m = 0.0           # ground z under the sensor
//! slope_deg = 0.0          # 0..45
//! slope_azimuth_deg = 0.0  # direction the ground rises, clockwise from x (as lidar azimuths)
//! reflectance = 0.2        # 0..1
//!
//! [[objects]]
//! kind = "car"             # car, van, truck, wall, pole, cone, barrel, curb
//! shape = "box"            # optional: cylinder for pole, cone, barrel, else box
//! x = 10.0                 # centre of the footprint; the base sits on the ground
//! y = -3.0
//! yaw_deg = 0.0            # counter-clockwise from x about z (ROS yaw); boxes only
//! length_m = 4.5           # along the box's own x
//! width_m = 1.8
//! height_m = 1.5
//! reflectance = 0.4        # or retro = true for a retro-reflector
//!
//! [[objects]]
//! kind = "pole"
//! x = 5.0
//! y = 4.0
//! radius_m = 0.1
//! height_m = 3.0
//! reflectance = 0.3
//! ```
//!
//! Objects get ids 1..k in file order; label 0 is the ground.
//!
//! A `curb` is a raised sidewalk: a box (length, width, yaw) whose top lies `height_m`
//! above the ground everywhere, following the ground's slope, so its long side is a curb
//! face `height_m` high. Its returns (top and faces) are labelled 0, ground, like the
//! road: SemanticKITTI counts sidewalks among the ground classes, and a 0.1-0.2 m face is
//! not an obstacle a clustering should report. Its id is kept (ids stay in file order)
//! but no return carries it.
//!
//! [`random_scene`] builds a randomized street scene from a seed (`lidar-noise synth
//! --random SEED`).

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Embedded preset scenes: (name, TOML source).
pub const PRESETS: [(&str, &str); 3] = [
    (
        "crossroad",
        include_str!("../../configs/scenes/crossroad.toml"),
    ),
    ("parking", include_str!("../../configs/scenes/parking.toml")),
    ("empty", include_str!("../../configs/scenes/empty.toml")),
];

/// Object kinds a scene may contain.
pub const KINDS: [&str; 8] = [
    "car", "van", "truck", "wall", "pole", "cone", "barrel", "curb",
];

/// The kind of a raised sidewalk, whose returns are labelled ground.
pub const CURB: &str = "curb";

/// Sensor mounting and spin rate.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Sensor {
    /// Height of the sensor origin above the ground under it, metres.
    pub height_m: f64,
    /// Pitch about the sensor's y axis, degrees; positive tips the forward axis down.
    pub pitch_deg: f64,
    /// Roll about the sensor's x axis, degrees; positive tips the left side up.
    pub roll_deg: f64,
    /// Head rotation rate, Hz (5..20).
    pub rotation_hz: f64,
}

/// The ground plane.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Ground {
    /// Ground z under the sensor (world datum), metres.
    pub height_m: f64,
    /// Slope angle, degrees (0..45).
    pub slope_deg: f64,
    /// Direction the ground rises, degrees clockwise from x seen from above.
    pub slope_azimuth_deg: f64,
    /// Diffuse reflectance 0..1.
    pub reflectance: f64,
}

impl Ground {
    /// Ground height (world z) at world (x, y).
    pub fn z_at(&self, x: f64, y: f64) -> f64 {
        let a = self.slope_azimuth_deg.to_radians();
        let along = x * a.cos() - y * a.sin();
        self.height_m + self.slope_deg.to_radians().tan() * along
    }
}

/// Shape and size of an object.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(tag = "shape", rename_all = "lowercase")]
pub enum Shape {
    /// An oriented box standing on its base.
    Box {
        /// Size along the box's own x, metres.
        length_m: f64,
        /// Size along the box's own y, metres.
        width_m: f64,
        /// Height, metres.
        height_m: f64,
        /// Yaw, degrees counter-clockwise from world x about z.
        yaw_deg: f64,
    },
    /// A vertical cylinder with flat caps.
    Cylinder {
        /// Radius, metres.
        radius_m: f64,
        /// Height, metres.
        height_m: f64,
    },
}

/// One object of a scene.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Object {
    /// Label of the object's returns, 1..k in file order.
    pub id: u16,
    /// Kind (car, van, truck, wall, pole, cone, barrel, curb).
    pub kind: String,
    /// Centre of the footprint, world x, metres.
    pub x: f64,
    /// Centre of the footprint, world y, metres.
    pub y: f64,
    /// World z of the base (the ground height at the centre), metres.
    pub z: f64,
    /// Shape and size.
    #[serde(flatten)]
    pub shape: Shape,
    /// Diffuse reflectance 0..1 (ignored for retro-reflectors).
    pub reflectance: f64,
    /// True for a retro-reflector (intensity 101..255).
    pub retro: bool,
}

/// A validated scene.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Scene {
    /// Scene name, used for output file names.
    pub name: String,
    /// Number of full rotations to synthesize.
    pub frames: u32,
    /// Seed of the range-noise streams.
    pub seed: u64,
    /// Gaussian range noise sigma, metres (0 = none).
    pub range_noise_m: f64,
    /// Sensor mounting.
    pub sensor: Sensor,
    /// Ground plane.
    pub ground: Ground,
    /// Objects, ids 1..k in order.
    pub objects: Vec<Object>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    name: Option<String>,
    frames: Option<i64>,
    seed: Option<u64>,
    range_noise_m: Option<f64>,
    sensor: SensorFile,
    #[serde(default)]
    ground: GroundFile,
    #[serde(default)]
    objects: Vec<ObjectFile>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SensorFile {
    height_m: f64,
    #[serde(default)]
    pitch_deg: f64,
    #[serde(default)]
    roll_deg: f64,
    #[serde(default = "default_rotation_hz")]
    rotation_hz: f64,
}

fn default_rotation_hz() -> f64 {
    10.0
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct GroundFile {
    #[serde(default)]
    height_m: f64,
    #[serde(default)]
    slope_deg: f64,
    #[serde(default)]
    slope_azimuth_deg: f64,
    #[serde(default = "default_ground_reflectance")]
    reflectance: f64,
}

fn default_ground_reflectance() -> f64 {
    0.2
}

impl Default for GroundFile {
    fn default() -> Self {
        GroundFile {
            height_m: 0.0,
            slope_deg: 0.0,
            slope_azimuth_deg: 0.0,
            reflectance: default_ground_reflectance(),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObjectFile {
    kind: String,
    shape: Option<String>,
    x: f64,
    y: f64,
    yaw_deg: Option<f64>,
    length_m: Option<f64>,
    width_m: Option<f64>,
    height_m: f64,
    radius_m: Option<f64>,
    reflectance: Option<f64>,
    #[serde(default)]
    retro: bool,
}

/// A path into the TOML document, used to find the line of an offending key.
#[derive(Clone, Copy)]
enum Seg<'a> {
    Key(&'a str),
    Index(usize),
}

struct Checker<'a> {
    source: &'a str,
    origin: &'a Path,
}

impl Checker<'_> {
    /// Error naming the key path and the line where it (or its nearest parent) is.
    fn err(&self, path: &[Seg<'_>], message: impl std::fmt::Display) -> Error {
        let key = path_string(path);
        let line = span_of(self.source, path).map(|s| line_of(self.source, s));
        let message = match line {
            Some(line) => format!("line {line}: `{key}`: {message}"),
            None => format!("`{key}`: {message}"),
        };
        Error::Config {
            path: self.origin.to_path_buf(),
            message,
        }
    }

    fn range(&self, path: &[Seg<'_>], v: f64, lo: f64, hi: f64, what: &str) -> Result<()> {
        if !v.is_finite() || v < lo || v > hi {
            return Err(self.err(path, format!("{v} is out of range: {what}")));
        }
        Ok(())
    }

    fn positive(&self, path: &[Seg<'_>], v: f64) -> Result<()> {
        if !v.is_finite() || v <= 0.0 || v > 1000.0 {
            return Err(self.err(
                path,
                format!("{v} must be a size above 0 (metres, at most 1000)"),
            ));
        }
        Ok(())
    }
}

fn path_string(path: &[Seg<'_>]) -> String {
    let mut s = String::new();
    for seg in path {
        match seg {
            Seg::Key(k) => {
                if !s.is_empty() {
                    s.push('.');
                }
                s.push_str(k);
            }
            Seg::Index(i) => s.push_str(&format!("[{i}]")),
        }
    }
    s
}

/// Byte span of the deepest existing element of `path` in the document.
fn span_of(source: &str, path: &[Seg<'_>]) -> Option<std::ops::Range<usize>> {
    let root = toml::de::DeTable::parse(source).ok()?;
    let mut best = None;
    let mut current: Option<&toml::Spanned<toml::de::DeValue<'_>>> = None;
    for (depth, seg) in path.iter().enumerate() {
        let next = match (depth, seg) {
            (0, Seg::Key(k)) => root
                .get_ref()
                .iter()
                .find(|(key, _)| key.get_ref() == k)
                .map(|(key, v)| {
                    best = Some(key.span());
                    v
                }),
            (0, Seg::Index(_)) => None,
            (_, Seg::Key(k)) => current.and_then(|c| {
                c.get_ref().as_table().and_then(|t| {
                    t.iter()
                        .find(|(key, _)| key.get_ref() == k)
                        .map(|(key, v)| {
                            best = Some(key.span());
                            v
                        })
                })
            }),
            (_, Seg::Index(i)) => current.and_then(|c| c.get_ref().get(*i)).inspect(|v| {
                best = Some(v.span());
            }),
        };
        match next {
            Some(v) => current = Some(v),
            None => break,
        }
    }
    best
}

/// Dotted key assigned on one-based line `line` (`table.key`), if the line is
/// a `key = value` line; the table is the nearest `[table]` or `[[table]]` header above.
fn key_on_line(source: &str, line: usize) -> Option<String> {
    let lines: Vec<&str> = source.lines().collect();
    let text = lines.get(line.checked_sub(1)?)?;
    let (key, _) = text.split_once('=')?;
    let key = key.trim();
    if key.is_empty() || key.starts_with('[') || key.starts_with('#') {
        return None;
    }
    let table = lines[..line - 1].iter().rev().find_map(|l| {
        let l = l.trim();
        l.starts_with('[')
            .then(|| l.trim_matches(|c| c == '[' || c == ']').trim().to_string())
    });
    Some(match table {
        Some(t) if !t.is_empty() => format!("{t}.{key}"),
        _ => key.to_string(),
    })
}

/// One-based line number of a byte offset.
fn line_of(source: &str, span: std::ops::Range<usize>) -> usize {
    let end = span.start.min(source.len());
    source.as_bytes()[..end]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

impl Scene {
    /// Reads and validates a scene file; the name defaults to the file stem.
    pub fn from_file(path: &Path) -> Result<Scene> {
        let source = crate::error::read_text_bounded(path)?;
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".to_string());
        Scene::parse(&source, path, &stem)
    }

    /// Loads an embedded preset by name (crossroad, parking, empty).
    pub fn preset(name: &str) -> Result<Scene> {
        let (_, source) = PRESETS.iter().find(|(n, _)| *n == name).ok_or_else(|| {
            let names: Vec<&str> = PRESETS.iter().map(|(n, _)| *n).collect();
            Error::Invalid(format!(
                "unknown preset `{name}`; presets are {}",
                names.join(", ")
            ))
        })?;
        Scene::parse(source, &PathBuf::from(format!("preset:{name}")), name)
    }

    /// Parses and validates TOML `source`; `origin` names it in errors.
    pub fn parse(source: &str, origin: &Path, default_name: &str) -> Result<Scene> {
        let file: SceneFile = toml::from_str(source).map_err(|e| {
            let line = e.span().map(|s| line_of(source, s));
            let mut message = e.message().trim_end().to_string();
            // Type errors do not name the key: take it from the offending line.
            if let Some(key) = line.and_then(|l| key_on_line(source, l)) {
                if !message.contains(&format!("`{key}`")) {
                    message = format!("`{key}`: {message}");
                }
            }
            Error::Config {
                path: origin.to_path_buf(),
                message: match line {
                    Some(line) => format!("line {line}: {message}"),
                    None => message,
                },
            }
        })?;
        let c = Checker { source, origin };
        use Seg::{Index, Key};

        let name = file.name.unwrap_or_else(|| default_name.to_string());
        if name.is_empty()
            || !name
                .chars()
                .all(|ch| ch.is_ascii_alphanumeric() || ch == '-' || ch == '_' || ch == '.')
            || name.starts_with('.')
        {
            return Err(c.err(
                &[Key("name")],
                format!("`{name}` must be a file name made of letters, digits, '-', '_' and '.'"),
            ));
        }
        let frames = file.frames.unwrap_or(1);
        if !(1..=100_000).contains(&frames) {
            return Err(c.err(&[Key("frames")], format!("{frames} must be 1..100000")));
        }
        let range_noise_m = file.range_noise_m.unwrap_or(0.0);
        c.range(
            &[Key("range_noise_m")],
            range_noise_m,
            0.0,
            1.0,
            "sigma in metres, 0..1",
        )?;

        let s = &file.sensor;
        c.range(
            &[Key("sensor"), Key("height_m")],
            s.height_m,
            0.05,
            100.0,
            "the sensor must be 0.05..100 m above the ground",
        )?;
        c.range(
            &[Key("sensor"), Key("pitch_deg")],
            s.pitch_deg,
            -45.0,
            45.0,
            "-45..45 degrees",
        )?;
        c.range(
            &[Key("sensor"), Key("roll_deg")],
            s.roll_deg,
            -45.0,
            45.0,
            "-45..45 degrees",
        )?;
        c.range(
            &[Key("sensor"), Key("rotation_hz")],
            s.rotation_hz,
            5.0,
            20.0,
            "the HDL-32E spins at 5..20 Hz",
        )?;
        let g = &file.ground;
        c.range(
            &[Key("ground"), Key("height_m")],
            g.height_m,
            -1000.0,
            1000.0,
            "-1000..1000 m",
        )?;
        c.range(
            &[Key("ground"), Key("slope_deg")],
            g.slope_deg,
            0.0,
            45.0,
            "0..45 degrees",
        )?;
        c.range(
            &[Key("ground"), Key("slope_azimuth_deg")],
            g.slope_azimuth_deg,
            -360.0,
            360.0,
            "-360..360 degrees",
        )?;
        c.range(
            &[Key("ground"), Key("reflectance")],
            g.reflectance,
            0.0,
            1.0,
            "reflectance is 0..1",
        )?;
        let ground = Ground {
            height_m: g.height_m,
            slope_deg: g.slope_deg,
            slope_azimuth_deg: g.slope_azimuth_deg,
            reflectance: g.reflectance,
        };
        if file.objects.len() > 10_000 {
            return Err(c.err(&[Key("objects")], "at most 10000 objects"));
        }

        let mut objects = Vec::with_capacity(file.objects.len());
        for (i, o) in file.objects.iter().enumerate() {
            let at = |key: &'static str| [Key("objects"), Index(i), Key(key)];
            if !KINDS.contains(&o.kind.as_str()) {
                return Err(c.err(
                    &at("kind"),
                    format!("unknown kind `{}`; kinds are {}", o.kind, KINDS.join(", ")),
                ));
            }
            let default_shape = match o.kind.as_str() {
                "pole" | "cone" | "barrel" => "cylinder",
                _ => "box",
            };
            let shape_name = o.shape.as_deref().unwrap_or(default_shape);
            if o.kind == CURB && shape_name != "box" {
                return Err(c.err(&at("shape"), "a curb is a box"));
            }
            c.range(&at("x"), o.x, -1000.0, 1000.0, "-1000..1000 m")?;
            c.range(&at("y"), o.y, -1000.0, 1000.0, "-1000..1000 m")?;
            c.positive(&at("height_m"), o.height_m)?;
            let shape = match shape_name {
                "box" => {
                    if o.radius_m.is_some() {
                        return Err(c.err(
                            &at("radius_m"),
                            "a box has no radius (use length_m and width_m)",
                        ));
                    }
                    let length_m = o.length_m.ok_or_else(|| {
                        c.err(&[Key("objects"), Index(i)], "a box needs `length_m`")
                    })?;
                    let width_m = o.width_m.ok_or_else(|| {
                        c.err(&[Key("objects"), Index(i)], "a box needs `width_m`")
                    })?;
                    c.positive(&at("length_m"), length_m)?;
                    c.positive(&at("width_m"), width_m)?;
                    let yaw_deg = o.yaw_deg.unwrap_or(0.0);
                    c.range(&at("yaw_deg"), yaw_deg, -360.0, 360.0, "-360..360 degrees")?;
                    Shape::Box {
                        length_m,
                        width_m,
                        height_m: o.height_m,
                        yaw_deg,
                    }
                }
                "cylinder" => {
                    for (key, v) in [
                        ("length_m", o.length_m),
                        ("width_m", o.width_m),
                        ("yaw_deg", o.yaw_deg),
                    ] {
                        if v.is_some() {
                            return Err(
                                c.err(&at(key), "a cylinder takes only radius_m and height_m")
                            );
                        }
                    }
                    let radius_m = o.radius_m.ok_or_else(|| {
                        c.err(&[Key("objects"), Index(i)], "a cylinder needs `radius_m`")
                    })?;
                    c.positive(&at("radius_m"), radius_m)?;
                    Shape::Cylinder {
                        radius_m,
                        height_m: o.height_m,
                    }
                }
                other => {
                    return Err(c.err(
                        &at("shape"),
                        format!("unknown shape `{other}`; shapes are box, cylinder"),
                    ))
                }
            };
            let reflectance = match (o.reflectance, o.retro) {
                (Some(r), _) => {
                    c.range(&at("reflectance"), r, 0.0, 1.0, "reflectance is 0..1")?;
                    r
                }
                (None, true) => 1.0,
                (None, false) => {
                    return Err(c.err(
                        &[Key("objects"), Index(i)],
                        "needs `reflectance` (0..1) or `retro = true`",
                    ))
                }
            };
            let object = Object {
                id: (i + 1) as u16,
                kind: o.kind.clone(),
                x: o.x,
                y: o.y,
                z: ground.z_at(o.x, o.y),
                shape,
                reflectance,
                retro: o.retro,
            };
            if object.contains_xy(0.0, 0.0) {
                return Err(c.err(
                    &at("x"),
                    "the object's footprint contains the sensor position (0, 0)",
                ));
            }
            objects.push(object);
        }
        Ok(Scene {
            name,
            frames: frames as u32,
            seed: file.seed.unwrap_or(0),
            range_noise_m,
            sensor: Sensor {
                height_m: s.height_m,
                pitch_deg: s.pitch_deg,
                roll_deg: s.roll_deg,
                rotation_hz: s.rotation_hz,
            },
            ground,
            objects,
        })
    }

    /// World position of the sensor origin.
    pub fn sensor_position(&self) -> [f64; 3] {
        [0.0, 0.0, self.ground.height_m + self.sensor.height_m]
    }
}

impl Object {
    /// True when world (x, y) lies inside the object's footprint (boundary included).
    pub fn contains_xy(&self, x: f64, y: f64) -> bool {
        let (dx, dy) = (x - self.x, y - self.y);
        match self.shape {
            Shape::Box {
                length_m,
                width_m,
                yaw_deg,
                ..
            } => {
                let (s, c) = yaw_deg.to_radians().sin_cos();
                let u = c * dx + s * dy;
                let v = -s * dx + c * dy;
                u.abs() <= length_m / 2.0 && v.abs() <= width_m / 2.0
            }
            Shape::Cylinder { radius_m, .. } => dx * dx + dy * dy <= radius_m * radius_m,
        }
    }

    /// True when world point p lies inside the object, grown by `tol` metres.
    pub fn contains(&self, p: [f64; 3], tol: f64) -> bool {
        let (dx, dy, dz) = (p[0] - self.x, p[1] - self.y, p[2] - self.z);
        match self.shape {
            Shape::Box {
                length_m,
                width_m,
                height_m,
                yaw_deg,
            } => {
                let (s, c) = yaw_deg.to_radians().sin_cos();
                let u = c * dx + s * dy;
                let v = -s * dx + c * dy;
                u.abs() <= length_m / 2.0 + tol
                    && v.abs() <= width_m / 2.0 + tol
                    && dz >= -tol
                    && dz <= height_m + tol
            }
            Shape::Cylinder { radius_m, height_m } => {
                (dx * dx + dy * dy).sqrt() <= radius_m + tol && dz >= -tol && dz <= height_m + tol
            }
        }
    }

    /// Radius of the footprint's bounding circle around (x, y).
    pub fn bounding_radius(&self) -> f64 {
        match self.shape {
            Shape::Box {
                length_m, width_m, ..
            } => (length_m * length_m + width_m * width_m).sqrt() / 2.0,
            Shape::Cylinder { radius_m, .. } => radius_m,
        }
    }
}

/// A randomized street scene, the same for the same seed.
///
/// The sensor (1.8-2.0 m up, 10 or 20 Hz, one rotation) stands in the middle of a road
/// 7-12 m wide running in a random direction. The ground slopes by 0-5 degrees in a
/// random direction. One or both road edges get a raised sidewalk (`curb`, 0.10-0.20 m
/// high, 2-4 m wide, 90 m long; labelled ground). 8-24 objects: cars, vans and trucks on
/// the road, parallel to it give or take 15 degrees (a quarter of them at any yaw, as
/// parked or turning); poles, cones and barrels anywhere, sidewalks included; walls behind
/// the sidewalks. Objects keep 0.5 m between their bounding circles and stay 3 m from
/// the sensor; a draw that does not fit is dropped, not retried forever.
pub fn random_scene(seed: u64) -> Scene {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let sensor = Sensor {
        height_m: round2(rng.random_range(1.8..=2.0)),
        pitch_deg: 0.0,
        roll_deg: 0.0,
        rotation_hz: if rng.random_bool(0.5) { 10.0 } else { 20.0 },
    };
    let ground = Ground {
        height_m: 0.0,
        slope_deg: round2(rng.random_range(0.0..=5.0)),
        slope_azimuth_deg: round2(rng.random_range(0.0..360.0)),
        reflectance: round2(rng.random_range(0.1..=0.3)),
    };
    let road_yaw: f64 = round2(rng.random_range(0.0..180.0));
    let (sy, cy) = road_yaw.to_radians().sin_cos();
    // World position of (along, across) road coordinates.
    let at = |along: f64, across: f64| (along * cy - across * sy, along * sy + across * cy);
    let half_road = round2(rng.random_range(3.5..=6.0));
    let sides: Vec<f64> = match rng.random_range(0..3) {
        0 => vec![1.0],
        1 => vec![-1.0],
        _ => vec![1.0, -1.0],
    };
    let mut objects: Vec<Object> = Vec::new();
    let push = |objects: &mut Vec<Object>, kind: &str, x: f64, y: f64, shape, refl| {
        let object = Object {
            id: objects.len() as u16 + 1,
            kind: kind.to_string(),
            x,
            y,
            z: ground.z_at(x, y),
            shape,
            reflectance: refl,
            retro: false,
        };
        let r = object.bounding_radius();
        let clear = kind == CURB
            || (x.hypot(y) > r + 3.0
                && objects.iter().all(|o| {
                    o.kind == CURB || (o.x - x).hypot(o.y - y) > o.bounding_radius() + r + 0.5
                }));
        if clear {
            objects.push(object);
        }
    };
    let mut walks = Vec::new();
    for &side in &sides {
        let width = round2(rng.random_range(2.0..=4.0));
        let height = round2(rng.random_range(0.10..=0.20));
        let (x, y) = at(0.0, side * (half_road + width / 2.0));
        push(
            &mut objects,
            CURB,
            x,
            y,
            Shape::Box {
                length_m: 90.0,
                width_m: width,
                height_m: height,
                yaw_deg: road_yaw,
            },
            0.3,
        );
        walks.push((side, width));
    }
    let count = rng.random_range(8..=24);
    for _ in 0..count {
        let pick = rng.random_range(0..10);
        let refl = round2(rng.random_range(0.1..=0.7));
        let along = round2(rng.random_range(-40.0..=40.0));
        match pick {
            0..=4 => {
                let (kind, l, w, h) = match pick {
                    0..=2 => ("car", 4.5, 1.8, 1.5),
                    3 => ("van", 5.2, 2.0, 2.3),
                    _ => ("truck", 8.0, 2.5, 3.2),
                };
                let lane =
                    rng.random_range(-(half_road - w / 2.0 - 0.2)..=(half_road - w / 2.0 - 0.2));
                let yaw = if rng.random_bool(0.25) {
                    rng.random_range(0.0..180.0)
                } else {
                    road_yaw + rng.random_range(-15.0..=15.0)
                };
                let (x, y) = at(along, lane);
                let shape = Shape::Box {
                    length_m: l,
                    width_m: w,
                    height_m: h,
                    yaw_deg: round2(yaw),
                };
                push(&mut objects, kind, round2(x), round2(y), shape, refl);
            }
            5..=7 => {
                let (kind, r, h) = match pick {
                    5 => ("pole", 0.1, 3.0),
                    6 => ("cone", 0.2, 0.7),
                    _ => ("barrel", 0.3, 1.0),
                };
                let across = rng.random_range(-(half_road + 5.0)..=(half_road + 5.0));
                let (x, y) = at(along, across);
                let shape = Shape::Cylinder {
                    radius_m: r,
                    height_m: h,
                };
                push(&mut objects, kind, round2(x), round2(y), shape, refl);
            }
            _ => {
                let &(side, width) = &walks[rng.random_range(0..walks.len())];
                let across = side * (half_road + width + rng.random_range(0.5..=3.0));
                let (x, y) = at(along, across);
                let shape = Shape::Box {
                    length_m: round2(rng.random_range(4.0..=15.0)),
                    width_m: 0.4,
                    height_m: round2(rng.random_range(1.5..=4.0)),
                    yaw_deg: road_yaw,
                };
                push(&mut objects, "wall", round2(x), round2(y), shape, refl);
            }
        }
    }
    Scene {
        name: format!("random-{seed}"),
        frames: 1,
        seed,
        range_noise_m: 0.0,
        sensor,
        ground,
        objects,
    }
}

/// Rounds to hundredths, so a randomized scene prints as the numbers it holds.
fn round2(v: f64) -> f64 {
    (v * 100.0).round() / 100.0
}
