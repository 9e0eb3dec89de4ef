//! Which sensor recorded a point cloud, where the data says it (issue 31: "`--sensor NAME`
//! says which sensor recorded them, guessed with a clear message where the data says it (a
//! ring field, 32 or 64 elevation bands)"), and the sensor names `--sensor` accepts.
//!
//! The evidence, strongest first:
//! - a ring field: its largest ring says 16, 32 or 64 lasers; among the 16- and 32-laser
//!   models the elevation span of the points tells them apart (VLP-16 +-15 deg, Puck
//!   Hi-Res +-10, HDL-32E -30.7 to +10.7, VLP-32C -25 to +15).
//! - without one (KITTI), the span of the elevations (the 0.2 % and 99.8 % quantiles of
//!   the elevation of points beyond 3 m, where a laser's vertical offset no longer blurs
//!   its beam). A scan may lose its lowest beams (KITTI object scans are cut to the
//!   camera's view, and the vehicle hides the ground near it) but never gains points above
//!   the top beam: a model fits when the points lie within its beams (1.5 deg of slack for
//!   pitch and noise), and of those that fit the one whose top beam is nearest the top of
//!   the points is guessed, when within 1.5 deg. HDL-64E top beam +2.8 deg, HDL-32E +10.7,
//!   Puck Hi-Res +10, VLP-16 and VLP-32C +15 (told apart by their lowest beams, -15 and
//!   -25). Counting elevation bands was tried and dropped: on real KITTI scans the rows
//!   of neighbouring lasers overlap (0.3 to 0.5 deg apart, each spread over +-0.15 deg),
//!   and 0.05 deg bins found 5 to 32 bands on scans of 47 rows.
//!   Nothing is guessed from a cloud of fewer than 1000 such points.

use super::CloudPoint;
use crate::sensor::{
    SensorModel, HDL32E, HDL64E_KITTI, HDL64E_S2, HDL64E_S3, PUCK_HI_RES, VLP16, VLP32C,
};

/// The sensor model a `--sensor` name means (case and `-`/`_` ignored): `hdl32e`,
/// `vlp16` (also `puck`, `puck-lite`), `puck-hi-res` (also `vlp16-hi-res`), `vlp32c`,
/// `hdl64e` (the S2, KITTI's, with the default beams), `hdl64e-s2`, `hdl64e-s3`,
/// `hdl64e-kitti` (also `kitti`: the S2 with the beams of KITTI's unit, for KITTI scans).
pub fn sensor_by_name(name: &str) -> Option<&'static SensorModel> {
    let key: String = name
        .chars()
        .filter(|c| !matches!(c, '-' | '_' | ' '))
        .collect::<String>()
        .to_ascii_lowercase();
    Some(match key.as_str() {
        "hdl32e" | "hdl32" => &HDL32E,
        "vlp16" | "puck" | "pucklite" => &VLP16,
        "puckhires" | "vlp16hires" => &PUCK_HI_RES,
        "vlp32c" | "vlp32" => &VLP32C,
        "hdl64e" | "hdl64" | "hdl64es2" => &HDL64E_S2,
        "hdl64es3" => &HDL64E_S3,
        "hdl64ekitti" | "kitti" | "hdl64es2(kitti)" => &HDL64E_KITTI,
        // Any described model by its name (the VLS-128 and its fw5.1 timing too), so the
        // name a capture's summary gives is one this takes.
        _ => return crate::sensor::by_name(name).ok(),
    })
}

/// The names [`sensor_by_name`] accepts, for messages.
pub const SENSOR_NAMES: &str = "hdl32e, vlp16, puck-hi-res, vlp32c, hdl64e (S2), hdl64e-s3, \
     hdl64e-kitti (KITTI's unit), vls128, vls128-fw5.1";

/// A guessed sensor and the evidence, as one sentence.
#[derive(Clone, Debug, PartialEq)]
pub struct Guess {
    /// The model guessed.
    pub model: &'static SensorModel,
    /// Why, in words (the ring range or the elevation span and bands).
    pub reason: String,
}

/// What the elevations of a cloud look like.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ElevationProfile {
    /// Points beyond 3 m used.
    pub points: usize,
    /// 0.2 % quantile of their elevation, degrees.
    pub low_deg: f64,
    /// 99.8 % quantile, degrees.
    pub high_deg: f64,
}

/// The elevation profile of `points` (`None` under 1000 points beyond 3 m).
pub fn elevation_profile(points: &[CloudPoint]) -> Option<ElevationProfile> {
    let mut el: Vec<f64> = points
        .iter()
        .filter_map(|p| {
            let (x, y, z) = (f64::from(p.x), f64::from(p.y), f64::from(p.z));
            let h = (x * x + y * y).sqrt();
            (h * h + z * z > 9.0 && (x + y + z).is_finite()).then(|| z.atan2(h).to_degrees())
        })
        .collect();
    if el.len() < 1000 {
        return None;
    }
    el.sort_by(f64::total_cmp);
    let q = |f: f64| el[((el.len() - 1) as f64 * f).round() as usize];
    Some(ElevationProfile {
        points: el.len(),
        low_deg: q(0.002),
        high_deg: q(0.998),
    })
}

/// The lowest and highest beam of a model, degrees.
fn span(model: &SensorModel) -> (f64, f64) {
    let lo = model.elevation_deg.iter().copied().fold(f64::MAX, f64::min);
    let hi = model.elevation_deg.iter().copied().fold(f64::MIN, f64::max);
    (lo, hi)
}

/// Of `models`, the one whose beam span is nearest the observed span (sum of the two
/// ends' distances), with that distance.
fn nearest_span(
    models: &[&'static SensorModel],
    low: f64,
    high: f64,
) -> (&'static SensorModel, f64) {
    models
        .iter()
        .map(|&m| {
            let (lo, hi) = span(m);
            (m, (lo - low).abs() + (hi - high).abs())
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("models is not empty")
}

/// The sensor that recorded `points`, where the data says it; `Err` says why not.
pub fn guess_sensor(points: &[CloudPoint]) -> Result<Guess, String> {
    let max_ring = points.iter().filter_map(|p| p.ring).max();
    let profile = elevation_profile(points);
    let shown = |p: &ElevationProfile| {
        format!(
            "elevations of its {} points beyond 3 m span {:.1} to {:+.1} deg",
            p.points, p.low_deg, p.high_deg
        )
    };
    if let Some(ring) = max_ring {
        let (models, lasers): (&[&'static SensorModel], usize) = match ring {
            0..=15 => (&[&VLP16, &PUCK_HI_RES], 16),
            16..=31 => (&[&HDL32E, &VLP32C], 32),
            32..=63 => (&[&HDL64E_S2], 64),
            _ => {
                return Err(format!(
                    "rings up to {ring}: more than the 64 lasers of any sensor modelled"
                ))
            }
        };
        let model = match (&profile, models) {
            (_, [one]) => *one,
            (Some(p), _) => nearest_span(models, p.low_deg, p.high_deg).0,
            (None, [first, ..]) => *first,
            (None, []) => unreachable!("every ring range names a model"),
        };
        let why = match (&profile, models.len()) {
            (Some(p), 2..) => format!(", and its {}", shown(p)),
            _ => String::new(),
        };
        return Ok(Guess {
            model,
            reason: format!(
                "its ring field runs to {ring}: a {lasers}-laser sensor{why}; guessed {}",
                model.name
            ),
        });
    }
    let Some(p) = profile else {
        return Err(
            "too few points beyond 3 m (under 1000) to tell the sensor by their \
                    elevations"
                .into(),
        );
    };
    let candidates: [&'static SensorModel; 5] =
        [&HDL32E, &VLP16, &PUCK_HI_RES, &VLP32C, &HDL64E_S2];
    const SLACK: f64 = 1.5;
    let fit = candidates
        .iter()
        .map(|&m| (m, span(m)))
        .filter(|(_, (lo, hi))| p.low_deg >= lo - SLACK && p.high_deg <= hi + SLACK)
        .map(|(m, (lo, hi))| (m, (hi - p.high_deg).abs(), (lo - p.low_deg).abs()))
        .min_by(|a, b| a.1.total_cmp(&b.1).then(a.2.total_cmp(&b.2)));
    match fit {
        Some((model, top, _)) if top <= SLACK => {
            let (lo, hi) = span(model);
            Ok(Guess {
                model,
                reason: format!(
                    "its {}: within the {}'s beams ({lo:.1} to {hi:+.1} deg, {} lasers), \
                     whose top beam is the nearest to the points' top; guessed {}",
                    shown(&p),
                    model.name,
                    model.lasers,
                    model.name
                ),
            })
        }
        _ => Err(format!(
            "its {}, which matches no modelled sensor's beams (the points within its beams, \
             its top beam within {SLACK} deg of theirs)",
            shown(&p)
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(el_deg: f64, az_deg: f64, ring: Option<u16>) -> CloudPoint {
        let (se, ce) = el_deg.to_radians().sin_cos();
        let (sa, ca) = az_deg.to_radians().sin_cos();
        let r = 20.0;
        CloudPoint {
            x: (r * ce * ca) as f32,
            y: (r * ce * sa) as f32,
            z: (r * se) as f32,
            intensity: 0.0,
            ring,
            time: None,
        }
    }

    /// A scan of a model's beams (every laser, 100 azimuths), written from its table.
    fn scan(elevations: &[f64], ring: bool) -> Vec<CloudPoint> {
        let mut sorted: Vec<f64> = elevations.to_vec();
        sorted.sort_by(f64::total_cmp);
        (0..100)
            .flat_map(|a| {
                let sorted = &sorted;
                (0..sorted.len())
                    .map(move |i| at(sorted[i], f64::from(a) * 3.6, ring.then_some(i as u16)))
            })
            .collect()
    }

    #[test]
    fn names_are_read_as_users_write_them() {
        assert_eq!(sensor_by_name("HDL-64E").unwrap().name, "HDL-64E S2");
        assert_eq!(sensor_by_name("hdl64e_s3").unwrap().name, "HDL-64E S3");
        assert_eq!(sensor_by_name("Puck Hi-Res").unwrap().name, "Puck Hi-Res");
        assert_eq!(sensor_by_name("vlp-32c").unwrap().name, "VLP-32C");
        assert_eq!(sensor_by_name("vlp16").unwrap().name, "VLP-16");
        assert!(sensor_by_name("vlp64").is_none());
        // Every model by the name a capture's summary gives.
        for m in crate::sensor::MODELS
            .iter()
            .copied()
            .chain([&crate::sensor::HDL64E_KITTI])
        {
            assert_eq!(sensor_by_name(m.name).unwrap().name, m.name);
        }
    }

    #[test]
    fn the_beams_of_each_model_name_it() {
        // The HDL-64E's 64 beams from -24.9 to +2.8 deg (VeloView's HDL-64.xml angles,
        // written here apart from the model's table: the lowest, highest and a few).
        let hdl64: Vec<f64> = (0..64)
            .map(|i| -24.0 + 26.0 * f64::from(i) / 63.0)
            .collect();
        let g = guess_sensor(&scan(&hdl64, false)).unwrap();
        assert_eq!(g.model.name, "HDL-64E S2", "{}", g.reason);
        // Cut to a camera's view (KITTI object scans): the lowest beams are gone.
        let cut: Vec<f64> = hdl64.iter().copied().filter(|&e| e > -15.0).collect();
        let g = guess_sensor(&scan(&cut, false)).unwrap();
        assert_eq!(g.model.name, "HDL-64E S2", "{}", g.reason);
        // HDL-32E manual: -30.67 to +10.67 deg in 32 steps of 4/3 deg.
        let hdl32: Vec<f64> = (0..32).map(|i| -30.67 + f64::from(i) * 4.0 / 3.0).collect();
        let g = guess_sensor(&scan(&hdl32, false)).unwrap();
        assert_eq!(g.model.name, "HDL-32E", "{}", g.reason);
        // VLP-16: -15 to +15 every 2 deg.
        let vlp16: Vec<f64> = (0..16).map(|i| -15.0 + 2.0 * f64::from(i)).collect();
        assert_eq!(
            guess_sensor(&scan(&vlp16, false)).unwrap().model.name,
            "VLP-16"
        );
        let hires: Vec<f64> = (0..16).map(|i| -10.0 + 4.0 / 3.0 * f64::from(i)).collect();
        assert_eq!(
            guess_sensor(&scan(&hires, true)).unwrap().model.name,
            "Puck Hi-Res"
        );
        // A ring field to 31 with the VLP-32C's span (-25 to +15).
        let vlp32: Vec<f64> = (0..32)
            .map(|i| -25.0 + 40.0 * f64::from(i) / 31.0)
            .collect();
        let g = guess_sensor(&scan(&vlp32, true)).unwrap();
        assert_eq!(g.model.name, "VLP-32C", "{}", g.reason);
        assert!(g.reason.contains("ring field runs to 31"), "{}", g.reason);
    }

    #[test]
    fn what_the_data_does_not_say_is_not_guessed() {
        let few = scan(&[0.0, 1.0], false);
        assert!(guess_sensor(&few).unwrap_err().contains("too few points"));
        // A flat disc of points at -60 deg: no sensor looks there.
        let odd: Vec<f64> = (0..20).map(|i| -60.0 + 0.5 * f64::from(i)).collect();
        let e = guess_sensor(&scan(&odd, false)).unwrap_err();
        assert!(e.contains("matches no modelled sensor"), "{e}");
        let mut big = scan(&[0.0; 1], true);
        big[0].ring = Some(100);
        assert!(guess_sensor(&big).unwrap_err().contains("rings up to 100"));
    }
}
