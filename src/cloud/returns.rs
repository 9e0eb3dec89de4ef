//! Point-cloud points as returns of a spinning sensor model (issue 31, "Point clouds in
//! and out"; the Python package's `Chain.apply` on plain arrays, issue 32).
//!
//! Each point becomes the [`Return`] the sensor would have reported:
//! - range, azimuth and elevation from x y z (azimuth clockwise seen from above, as the
//!   decoder gives it: x = r cos(el) cos(az), y = -r cos(el) sin(az)); x y z are kept as
//!   stored. The model's mounting offsets are not applied (the HDL-32E has none in its
//!   built-in table).
//! - the laser from the ring (0 = lowest beam, the sensor's rings) where the point has
//!   one, else from the elevation: the laser whose table elevation is nearest.
//! - the firing slot from the azimuth on the sensor's firing grid: at `rotation_hz` a turn
//!   holds n = round(1 / (rotation_hz * block_us)) firings (2170 for the HDL-32E at
//!   10 Hz), firing k starting at azimuth 360 k / n, and laser l of a firing fires
//!   `l * laser_us` after its start. A point goes to the firing whose laser-l direction is
//!   nearest its azimuth; when two points claim one slot (a dataset's motion compensation
//!   or a merged sweep), the later in file order moves to the nearest free firing within
//!   two on either side, and shares the slot only when those are taken too (counted in
//!   [`CloudReturns::shared`]). Slots no point claims are the sensor's empty slots (sky,
//!   no echo), which the spurious-return rules of `noise::spurious` need.
//! - packet and block from the firing (firings numbered from 0 at the turn's start,
//!   `sequences_per_packet` firings a packet), time = `start_time` + the firing's and
//!   laser's offsets, so time follows the azimuth as in a capture.
//! - the intensity byte from the stored value by the format's scale (KITTI 0-1 times 255,
//!   nuScenes and unstated as stored), rounded and clamped to 0-255.
//!
//! The returns come out in firing order (capture order), which the noise stages and the
//! slots expect; [`CloudReturns::order`] gives each return's point index, so results can
//! be put back in file order.

use crate::cloud::{CloudPoint, IntensityScale};
use crate::error::{Error, Result};
use crate::frame::{Return, ReturnKind};
use crate::sensor::{ReturnMode, SensorModel};

/// How points are placed on the sensor's firing grid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReturnsOptions {
    /// Rotation rate in Hz (HDL-32E default 10; nuScenes records at 20).
    pub rotation_hz: f64,
    /// How the stored intensity is scaled.
    pub intensity_scale: IntensityScale,
    /// Time of the turn's first firing in seconds (the returns' time base).
    pub start_time: f64,
}

impl Default for ReturnsOptions {
    fn default() -> Self {
        ReturnsOptions {
            rotation_hz: 10.0,
            intensity_scale: IntensityScale::Byte,
            start_time: 0.0,
        }
    }
}

/// Points turned into returns.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CloudReturns {
    /// The returns, in firing order.
    pub returns: Vec<Return>,
    /// Index in the input of each return's point.
    pub order: Vec<u32>,
    /// Firings in the turn (the grid's size).
    pub firings: u32,
    /// Points moved to a neighbouring firing because their own slot was taken.
    pub moved: usize,
    /// Points left sharing a slot with an earlier point (no free slot within reach).
    pub shared: usize,
}

/// Firings on either side searched for a free slot when a point's own is taken.
const REACH: i64 = 2;

/// Turns `points` into returns of `model` (see the module's documentation). Errors name
/// `source` and the point index: a non-finite coordinate or intensity, a ring at or above
/// the model's number of lasers, a rotation rate outside the model's range.
pub fn to_returns(
    points: &[CloudPoint],
    model: &SensorModel,
    options: &ReturnsOptions,
    source: &str,
) -> Result<CloudReturns> {
    let (lo, hi) = model.rotation_hz;
    if !(options.rotation_hz >= lo && options.rotation_hz <= hi) {
        return Err(Error::Invalid(format!(
            "{source}: rotation_hz {}: the {} turns at {lo} to {hi} Hz",
            options.rotation_hz, model.name
        )));
    }
    if !options.start_time.is_finite() {
        return Err(Error::Invalid(format!(
            "{source}: start_time {} is not a finite number",
            options.start_time
        )));
    }
    if points.len() >= u32::MAX as usize {
        return Err(Error::Invalid(format!(
            "{source}: {} points, more than one turn can hold",
            points.len()
        )));
    }
    let lasers = model.lasers;
    let block_us = model.block_us();
    let n = (1e6 / (options.rotation_hz * block_us)).round().max(1.0) as i64;
    let us_per_deg = 1e6 / (360.0 * options.rotation_hz);
    let per_packet = model.sequences_per_packet(ReturnMode::Strongest) as i64;
    let rings = model.rings();
    let mut laser_of_ring = vec![0u8; lasers];
    for (laser, &ring) in rings.iter().enumerate() {
        laser_of_ring[ring as usize] = laser as u8;
    }
    // Lasers sorted by elevation with the midpoints between neighbours: the nearest laser
    // of an elevation is one binary search.
    let by_elevation: Vec<usize> = laser_of_ring.iter().map(|&l| l as usize).collect();
    let bounds: Vec<f64> = by_elevation
        .windows(2)
        .map(|w| 0.5 * (model.elevation_deg[w[0]] + model.elevation_deg[w[1]]))
        .collect();
    let scale = match options.intensity_scale {
        IntensityScale::Unit => 255.0,
        IntensityScale::Byte | IntensityScale::Unstated => 1.0,
    };
    let mut taken = vec![false; n as usize * lasers];
    let (mut moved, mut shared) = (0, 0);
    // Per point: its slot (firing * lasers + laser) and its return, in input order.
    let mut slot_of = Vec::with_capacity(points.len());
    let mut placed = Vec::with_capacity(points.len());
    for (i, p) in points.iter().enumerate() {
        if let Some((field, v)) = p.non_finite() {
            return Err(Error::Invalid(format!(
                "{source}: point {i} (0-based): {field} is {v}, not a finite number"
            )));
        }
        let (x, y, z) = (f64::from(p.x), f64::from(p.y), f64::from(p.z));
        // sqrt of the sums, not hypot: libm's hypot (overflow-safe, not needed for
        // coordinates in metres) was an eighth of the conversion's time.
        let h2 = x * x + y * y;
        let horizontal = h2.sqrt();
        let range = (h2 + z * z).sqrt();
        let azimuth = (-y).atan2(x).to_degrees().rem_euclid(360.0);
        let elevation = z.atan2(horizontal).to_degrees();
        let laser = match p.ring {
            Some(ring) if usize::from(ring) < lasers => laser_of_ring[usize::from(ring)],
            Some(ring) => {
                return Err(Error::Invalid(format!(
                    "{source}: point {i} (0-based): ring {ring} is out of range for the {} \
                     ({lasers} lasers, rings 0 to {})",
                    model.name,
                    lasers - 1
                )))
            }
            None => by_elevation[bounds.partition_point(|&b| b < elevation)] as u8,
        };
        let l = usize::from(laser);
        let laser_us = l as f64 * model.laser_us;
        let k = ((azimuth * us_per_deg - laser_us) / block_us)
            .round()
            .clamp(0.0, (n - 1) as f64) as i64;
        let free = |f: i64| (0..n).contains(&f) && !taken[f as usize * lasers + l];
        let firing = if free(k) {
            k
        } else if let Some(f) = (1..=REACH).flat_map(|d| [k - d, k + d]).find(|&f| free(f)) {
            moved += 1;
            f
        } else {
            shared += 1;
            k
        };
        taken[firing as usize * lasers + l] = true;
        let time_us = firing as f64 * block_us + laser_us;
        let byte = (f64::from(p.intensity) * scale).round().clamp(0.0, 255.0) as u8;
        slot_of.push(firing as u32 * lasers as u32 + u32::from(laser));
        placed.push(Return {
            x: p.x,
            y: p.y,
            z: p.z,
            range: range as f32,
            azimuth: azimuth as f32,
            elevation: elevation as f32,
            time: options.start_time + time_us * 1e-6,
            packet: (firing / per_packet) as u32,
            raw_distance: (range / model.distance_resolution_m)
                .round()
                .clamp(0.0, f64::from(u16::MAX)) as u16,
            intensity: byte,
            laser,
            ring: rings[l],
            block: (firing % per_packet) as u8,
            kind: ReturnKind::Strongest,
        });
    }
    // Counting sort by slot: firing order, then laser, then file order (stable, so the
    // same points always give the same returns).
    let mut start = vec![0u32; taken.len() + 1];
    for &s in &slot_of {
        start[s as usize + 1] += 1;
    }
    for j in 1..start.len() {
        start[j] += start[j - 1];
    }
    let mut order = vec![0u32; points.len()];
    for (i, &s) in slot_of.iter().enumerate() {
        order[start[s as usize] as usize] = i as u32;
        start[s as usize] += 1;
    }
    let returns = order.iter().map(|&i| placed[i as usize]).collect();
    Ok(CloudReturns {
        returns,
        order,
        firings: n as u32,
        moved,
        shared,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::HDL32E;

    fn point(x: f32, y: f32, z: f32, intensity: f32, ring: Option<u16>) -> CloudPoint {
        CloudPoint {
            x,
            y,
            z,
            intensity,
            ring,
            time: None,
        }
    }

    /// The point laser `laser` would measure at `range` in firing `k` of a 10 Hz turn,
    /// written from the sensor's description (not from the code under test).
    fn on_grid(k: u32, laser: usize, range: f64) -> CloudPoint {
        // 46.08 us a firing, 1.152 us a laser; 10 Hz is 3.6e-3 degrees a microsecond.
        let az = (f64::from(k) * 46.08 + laser as f64 * 1.152) * 3.6e-3;
        let el = crate::calibration::BUILTIN_ELEVATION_DEG[laser];
        let (sa, ca) = az.to_radians().sin_cos();
        let (se, ce) = el.to_radians().sin_cos();
        point(
            (range * ce * ca) as f32,
            (-range * ce * sa) as f32,
            (range * se) as f32,
            100.0,
            None,
        )
    }

    #[test]
    fn a_point_on_the_grid_gets_its_firing_laser_and_time() {
        let opts = ReturnsOptions::default();
        for (k, laser) in [(0u32, 0usize), (1, 31), (100, 15), (1085, 7), (2169, 30)] {
            let out = to_returns(&[on_grid(k, laser, 20.0)], &HDL32E, &opts, "t").unwrap();
            let r = out.returns[0];
            assert_eq!(out.firings, 2170);
            assert_eq!(usize::from(r.laser), laser, "firing {k}");
            assert_eq!(r.packet, k / 12, "firing {k}");
            assert_eq!(u32::from(r.block), k % 12, "firing {k}");
            let t = (f64::from(k) * 46.08 + laser as f64 * 1.152) * 1e-6;
            assert!((r.time - t).abs() < 1e-12, "firing {k}: {} vs {t}", r.time);
            assert!((r.range - 20.0).abs() < 1e-4);
            assert!(
                (f64::from(r.elevation) - crate::calibration::BUILTIN_ELEVATION_DEG[laser]).abs()
                    < 1e-3
            );
            assert_eq!(r.raw_distance, 10_000);
            assert_eq!(r.ring, HDL32E.rings()[laser]);
        }
    }

    #[test]
    fn the_ring_decides_the_laser_when_given() {
        // Ring 31 is the top beam (+10.67 deg, laser 31) even for a point at -30 deg.
        let p = point(10.0, 0.0, -5.0, 1.0, Some(31));
        let out = to_returns(&[p], &HDL32E, &ReturnsOptions::default(), "t").unwrap();
        assert_eq!(out.returns[0].laser, 31);
        assert_eq!(out.returns[0].ring, 31);
        // Without a ring, the nearest elevation: atan(-5/10) = -26.57 deg, laser 6 (-26.67).
        let p = point(10.0, 0.0, -5.0, 1.0, None);
        let out = to_returns(&[p], &HDL32E, &ReturnsOptions::default(), "t").unwrap();
        assert_eq!(out.returns[0].laser, 6);
    }

    #[test]
    fn returns_come_in_firing_order_with_the_input_index() {
        // Input in reverse firing order; a taken slot moves the later point to the firing
        // before (the nearer side searched first is the earlier one).
        let pts = vec![
            on_grid(500, 3, 10.0),
            on_grid(20, 9, 10.0),
            on_grid(20, 4, 10.0),
            on_grid(20, 4, 11.0),
        ];
        let out = to_returns(&pts, &HDL32E, &ReturnsOptions::default(), "t").unwrap();
        assert_eq!(out.order, vec![3, 2, 1, 0]);
        let firing = |r: &Return| r.packet * 12 + u32::from(r.block);
        let f: Vec<u32> = out.returns.iter().map(firing).collect();
        assert_eq!(f, vec![19, 20, 20, 500]);
        assert_eq!(out.returns[0].range, 11.0);
        assert_eq!((out.moved, out.shared), (1, 0));
    }

    #[test]
    fn a_full_slot_neighbourhood_is_shared_and_counted() {
        let pts: Vec<CloudPoint> = (0..7).map(|_| on_grid(40, 0, 10.0)).collect();
        let out = to_returns(&pts, &HDL32E, &ReturnsOptions::default(), "t").unwrap();
        assert_eq!((out.moved, out.shared), (4, 2));
    }

    #[test]
    fn intensity_scales_by_format() {
        let p = point(5.0, 1.0, 0.0, 0.5, None);
        let unit = ReturnsOptions {
            intensity_scale: IntensityScale::Unit,
            ..ReturnsOptions::default()
        };
        let out = to_returns(&[p], &HDL32E, &unit, "t").unwrap();
        assert_eq!(out.returns[0].intensity, 128);
        let p = point(5.0, 1.0, 0.0, 300.0, None);
        let out = to_returns(&[p], &HDL32E, &ReturnsOptions::default(), "t").unwrap();
        assert_eq!(out.returns[0].intensity, 255);
    }

    #[test]
    fn bad_points_are_refused_with_their_index() {
        let opts = ReturnsOptions::default();
        let mut pts = vec![point(1.0, 2.0, 3.0, 4.0, None); 5];
        pts[3].y = f32::NAN;
        let e = to_returns(&pts, &HDL32E, &opts, "scan.bin")
            .unwrap_err()
            .to_string();
        assert!(e.contains("scan.bin: point 3 (0-based): y is NaN"), "{e}");
        pts[3].y = 0.0;
        pts[4].ring = Some(32);
        let e = to_returns(&pts, &HDL32E, &opts, "scan.bin")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("point 4 (0-based): ring 32 is out of range"),
            "{e}"
        );
        let slow = ReturnsOptions {
            rotation_hz: 1.0,
            ..opts
        };
        let e = to_returns(&pts[..1], &HDL32E, &slow, "t")
            .unwrap_err()
            .to_string();
        assert!(e.contains("rotation_hz 1"), "{e}");
    }

    #[test]
    fn the_origin_is_a_return_at_zero_range_not_a_nan() {
        let out = to_returns(
            &[point(0.0, 0.0, 0.0, 0.0, None)],
            &HDL32E,
            &ReturnsOptions::default(),
            "t",
        )
        .unwrap();
        let r = out.returns[0];
        assert_eq!((r.range, r.azimuth, r.elevation), (0.0, 0.0, 0.0));
    }
}
