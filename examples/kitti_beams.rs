//! The beam table of KITTI's HDL-64E, measured on real scans, and how well it gives each
//! point its laser (`sensor::HDL64E_KITTI`, `--sensor hdl64e-kitti`).
//!
//! `cargo run --release --example kitti_beams -- tune SCAN...`: per laser, the line its
//! points lie on and the table to paste into `src/sensor/mod.rs`.
//! `cargo run --release --example kitti_beams -- measure SCAN...`: per scan, the share of
//! points whose laser from the elevation is ambiguous, with the built-in HDL-64E table and
//! with KITTI's, and how often that laser is the ring recovered from the point order.
//!
//! Scan lines from the point order: KITTI stores each laser's sweep in turn, top beam
//! first. A line ends where the azimuth (counter-clockwise, from the cut angle) falls back
//! by more than 180 deg after passing 180 deg, so jitter at the cut does not start a line.
//! The lines of the object-benchmark scans (cut to the camera's view) and of the
//! SemanticKITTI scan tried all start at azimuth 0; a cut at the back (180 deg, where the
//! azimuth of atan2 jumps) is tried too, and of the two the one whose lines are the
//! straightest in (horizontal distance, z) is taken: at the wrong cut a line holds half
//! of two lasers. Line `k` is ring `63 - k`; lines past the 64th are counted, not
//! compared.
//!
//! Why lines and not just elevations: KITTI's points carry each laser's vertical offset
//! (they lie on z = h tan(el) + dz, dz about 0.2 m for the upper bank and 0.12 m for the
//! lower one), so a laser's elevation seen from the origin falls with range, by 1.5 deg
//! between 6 and 30 m: `tune` prints it.

use lidar_noise::cloud::returns::{to_returns, ReturnsOptions};
use lidar_noise::cloud::{read_file, CloudPoint, ReadOptions};
use lidar_noise::sensor::{SensorModel, HDL64E_KITTI, HDL64E_S2};
use std::path::Path;

/// A line's points must lie this close (median, metres) to a straight line in (h, z) for
/// its least-squares fit to give the laser's elevation and offset.
const STRAIGHT_M: f64 = 0.005;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (mode, scans) = args.split_first().expect("tune|measure SCAN...");
    let scans: Vec<Scan> = scans
        .iter()
        .map(|s| Scan::read(Path::new(s)))
        .collect::<Result<_, _>>()
        .unwrap_or_else(|e| panic!("{e}"));
    match mode.as_str() {
        "tune" => tune(&scans),
        "measure" => measure(&scans),
        _ => panic!("tune|measure SCAN..."),
    }
}

/// A scan and its scan lines from the point order.
struct Scan {
    name: String,
    points: Vec<CloudPoint>,
    /// Line of each point, 0 = the first (top) line.
    line: Vec<usize>,
    lines: usize,
    cut_deg: f64,
}

impl Scan {
    /// Reads a scan and finds its lines.
    fn read(path: &Path) -> Result<Scan, String> {
        let cloud = read_file(path, &ReadOptions::default()).map_err(|e| e.to_string())?;
        let points = cloud.points;
        let (line, cut_deg) = [0.0, 180.0]
            .iter()
            .map(|&c| (split(&points, c), c))
            .min_by(|a, b| straightness(&points, &a.0).total_cmp(&straightness(&points, &b.0)))
            .expect("two cuts");
        let lines = line.last().map_or(0, |l| l + 1);
        Ok(Scan {
            name: path.display().to_string(),
            points,
            line,
            lines,
            cut_deg,
        })
    }

    /// Points of ring `ring` (line 63 - ring) as (horizontal distance, z).
    fn ring(&self, ring: usize) -> Vec<(f64, f64)> {
        self.points
            .iter()
            .zip(&self.line)
            .filter(|(_, &l)| l < 64 && 63 - l == ring)
            .map(|(p, _)| hz(p))
            .collect()
    }
}

/// A point's horizontal distance and height.
fn hz(p: &CloudPoint) -> (f64, f64) {
    let (x, y) = (f64::from(p.x), f64::from(p.y));
    ((x * x + y * y).sqrt(), f64::from(p.z))
}

/// Each point's line, lines cut at `cut_deg` (the module's documentation says how).
fn split(points: &[CloudPoint], cut_deg: f64) -> Vec<usize> {
    let (mut line, mut armed, mut prev) = (0, false, f64::NAN);
    points
        .iter()
        .map(|p| {
            let a = (f64::from(p.y).atan2(f64::from(p.x)).to_degrees() - cut_deg).rem_euclid(360.0);
            if armed && a < prev - 180.0 {
                line += 1;
                armed = false;
            }
            armed |= a > 180.0;
            prev = a;
            line
        })
        .collect()
}

/// Median over lines (of 20 points or more) of the median distance to the line's fit.
fn straightness(points: &[CloudPoint], line: &[usize]) -> f64 {
    let n = line.last().map_or(0, |l| l + 1);
    let mut by = vec![Vec::new(); n];
    for (p, &l) in points.iter().zip(line) {
        by[l].push(hz(p));
    }
    median(
        by.iter()
            .filter(|v| v.len() >= 20)
            .map(|v| fit(v).2)
            .collect(),
    )
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn quantile(v: &[f64], q: f64) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v.get(((v.len().max(1) - 1) as f64 * q).round() as usize)
        .copied()
        .unwrap_or(f64::NAN)
}

/// Least squares z = a h + b.
fn lsq(v: &[(f64, f64)]) -> (f64, f64) {
    let n = v.len() as f64;
    let (sx, sy) = v.iter().fold((0.0, 0.0), |s, p| (s.0 + p.0, s.1 + p.1));
    let (mx, my) = (sx / n, sy / n);
    let (sxx, sxy) = v.iter().fold((0.0, 0.0), |s, p| {
        (s.0 + (p.0 - mx).powi(2), s.1 + (p.0 - mx) * (p.1 - my))
    });
    let a = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    (a, my - a * mx)
}

/// A line's fit beyond 2 m, trimmed of points over three median residuals (+1 mm) off it
/// (a point of a neighbouring line, a mixed pixel): slope, offset, median residual.
fn fit(v: &[(f64, f64)]) -> (f64, f64, f64) {
    let mut kept: Vec<(f64, f64)> = v.iter().copied().filter(|p| p.0 > 2.0).collect();
    if kept.len() < 10 {
        return (0.0, 0.0, f64::INFINITY);
    }
    let (mut a, mut b) = lsq(&kept);
    for _ in 0..4 {
        let res = median(kept.iter().map(|p| (p.1 - a * p.0 - b).abs()).collect());
        let all: Vec<(f64, f64)> = v.iter().copied().filter(|p| p.0 > 2.0).collect();
        kept = all
            .into_iter()
            .filter(|p| (p.1 - a * p.0 - b).abs() <= 3.0 * res + 0.001)
            .collect();
        (a, b) = lsq(&kept);
    }
    let res = median(kept.iter().map(|p| (p.1 - a * p.0 - b).abs()).collect());
    (a, b, res)
}

/// Prints each ring's line and the table by laser id.
fn tune(scans: &[Scan]) {
    for s in scans {
        println!(
            "{}: {} points, {} lines (cut at {} deg), straightness {:.4} m",
            s.name,
            s.points.len(),
            s.lines,
            s.cut_deg,
            straightness(&s.points, &s.line)
        );
    }
    // Per ring: the points of the scans whose line is straight there (all scans where
    // none is). A straight line over at least 1 m of horizontal distance (10-90 %) gives
    // the elevation and offset by its fit; a shorter one (ground near the car) leaves the
    // offset to the bank, and the elevation is the median of atan2(z - dz, h).
    let mut el = [f64::NAN; 64];
    let mut dz = [f64::NAN; 64];
    let mut how = vec![String::new(); 64];
    let mut pooled = vec![Vec::new(); 64];
    for ring in 0..64 {
        let mut straight = 0;
        for s in scans {
            let v = s.ring(ring);
            if v.len() >= 50 && fit(&v).2 < STRAIGHT_M {
                pooled[ring].extend(v);
                straight += 1;
            }
        }
        if straight == 0 {
            pooled[ring] = scans.iter().flat_map(|s| s.ring(ring)).collect();
            how[ring] = format!("no straight line, {} scans", scans.len());
            continue;
        }
        let h: Vec<f64> = pooled[ring].iter().map(|p| p.0).collect();
        let (h10, h90) = (quantile(&h, 0.1), quantile(&h, 0.9));
        how[ring] = format!(
            "straight in {straight} scans, h {h10:.1}-{h90:.1} m, {} points",
            h.len()
        );
        if h90 - h10 >= 1.0 {
            let (a, b, r) = fit(&pooled[ring]);
            el[ring] = a.atan().to_degrees();
            dz[ring] = b;
            how[ring] += &format!(", line fit (residual {r:.4} m)");
        }
    }
    // Rings 0-31 are the lower bank, 32-63 the upper one.
    let bank = |lo: usize| {
        median(
            (lo..lo + 32)
                .map(|r| dz[r])
                .filter(|d| d.is_finite())
                .collect(),
        )
    };
    let (lower, upper) = (bank(0), bank(32));
    println!("bank offsets (median of the fitted rings): lower {lower:.4} m, upper {upper:.4} m");
    for ring in 0..64 {
        if el[ring].is_finite() {
            continue;
        }
        let d = if ring < 32 { lower } else { upper };
        let e: Vec<f64> = pooled[ring]
            .iter()
            .filter(|p| p.0 > 2.0)
            .map(|p| (p.1 - d).atan2(p.0).to_degrees())
            .collect();
        el[ring] = median(e.clone());
        dz[ring] = d;
        how[ring] += &format!(
            ", bank offset, median atan2(z - dz, h) (10-90 % {:.3} to {:.3} deg)",
            quantile(&e, 0.1),
            quantile(&e, 0.9)
        );
    }
    println!("ring  elevation  offset | origin elevation: median (10-90 %), <10 m, >20 m | source");
    for ring in (0..64).rev() {
        let v: Vec<(f64, f64)> = scans.iter().flat_map(|s| s.ring(ring)).collect();
        let o = |f: &dyn Fn(f64) -> bool| -> Vec<f64> {
            v.iter()
                .filter(|p| f(p.0) && p.0 > 2.0)
                .map(|p| p.1.atan2(p.0).to_degrees())
                .collect()
        };
        let all = o(&|_| true);
        println!(
            "{ring:>4} {:>9.3} {:>7.4} | {:>7.3} ({:.3} to {:.3}), {:>7.3}, {:>7.3} | {}",
            el[ring],
            dz[ring],
            median(all.clone()),
            quantile(&all, 0.1),
            quantile(&all, 0.9),
            median(o(&|h| h < 10.0)),
            median(o(&|h| h > 20.0)),
            how[ring]
        );
    }
    horizontal_offsets(scans);
    // By laser id: ring r is the laser the built-in table puts at ring r.
    let rings = HDL64E_S2.rings();
    let by_id = |t: &[f64; 64], scale: f64, digits: usize| -> String {
        rings
            .iter()
            .map(|&r| format!("{:.*}", digits, t[usize::from(r)] * scale))
            .collect::<Vec<_>>()
            .join(", ")
    };
    println!("elevation by laser id (deg): [{}]", by_id(&el, 1.0, 3));
    println!(
        "vertical offset by laser id (mm): [{}]",
        by_id(&dz, 1000.0, 1)
    );
}

/// Per scan and line, the horizontal offset its points carry, where range edges show it:
/// a laser's point at horizontal distance h lies atan(ho / h) off its firing's azimuth,
/// so between consecutive firings the azimuth step minus the line's median step is about
/// ho times the change of 1 / h. Fitted over the steps where 1 / h changes by more than
/// 0.03 (a near object's edge); lines with fewer than 5 such steps are left out.
fn horizontal_offsets(scans: &[Scan]) {
    println!(
        "horizontal offset by line from the top (m; edges), from azimuth steps at range edges:"
    );
    for s in scans {
        let mut shown = Vec::new();
        for line in 0..s.lines.min(64) {
            let pts: Vec<(f64, f64)> = s
                .points
                .iter()
                .zip(&s.line)
                .filter(|(_, &l)| l == line)
                .map(|(p, _)| {
                    let (x, y) = (f64::from(p.x), f64::from(p.y));
                    (y.atan2(x), (x * x + y * y).sqrt())
                })
                .collect();
            let steps: Vec<(f64, f64)> = pts
                .windows(2)
                .filter(|w| {
                    (w[1].0 - w[0].0).abs() < 1f64.to_radians() && w[0].1 > 2.0 && w[1].1 > 2.0
                })
                .map(|w| (1.0 / w[1].1 - 1.0 / w[0].1, w[1].0 - w[0].0))
                .collect();
            let step = median(steps.iter().map(|p| p.1).collect());
            let edges: Vec<(f64, f64)> = steps.into_iter().filter(|p| p.0.abs() > 0.03).collect();
            if edges.len() >= 5 {
                let (uu, ud) = edges.iter().fold((0.0, 0.0), |a, p| {
                    (a.0 + p.0 * p.0, a.1 + p.0 * (p.1 - step))
                });
                shown.push(format!("{line}:{:+.3}({})", ud / uu, edges.len()));
            }
        }
        println!("  {}: {}", s.name, shown.join(" "));
    }
}

/// Rings below this come from the SemanticKITTI scan alone (the object scans, cut to the
/// camera's view, do not reach them): counted apart.
const LOW_RINGS: i32 = 17;

/// Counts of one table on some scans.
#[derive(Default)]
struct Tally {
    /// Points whose laser came from the elevation, and of those ambiguous.
    from_elevation: usize,
    ambiguous: usize,
    /// Points on the first 64 lines, and of those given their line's ring, within one;
    /// the same for rings 0-16.
    compared: usize,
    same: usize,
    near: usize,
    low: usize,
    low_same: usize,
}

impl Tally {
    fn add(&mut self, o: &Tally) {
        self.from_elevation += o.from_elevation;
        self.ambiguous += o.ambiguous;
        self.compared += o.compared;
        self.same += o.same;
        self.near += o.near;
        self.low += o.low;
        self.low_same += o.low_same;
    }

    fn show(&self, name: &str) {
        let pct = |a: usize, b: usize| 100.0 * a as f64 / b.max(1) as f64;
        let low = if self.low > 0 {
            format!(
                "; rings 0-{}: same {:.1} % of {}",
                LOW_RINGS - 1,
                pct(self.low_same, self.low),
                self.low
            )
        } else {
            String::new()
        };
        println!(
            "  {name:<20} ambiguous {:>5.2} % ({} of {}); ring from the order: same {:>6.2} %, \
             within one {:>6.2} % (of {}){low}",
            pct(self.ambiguous, self.from_elevation),
            self.ambiguous,
            self.from_elevation,
            pct(self.same, self.compared),
            pct(self.near, self.compared),
            self.compared
        );
    }
}

/// Per scan and table: ambiguous share, and agreement with the ring from the order.
fn measure(scans: &[Scan]) {
    let models: [&SensorModel; 2] = [&HDL64E_S2, &HDL64E_KITTI];
    let mut total = [Tally::default(), Tally::default()];
    for s in scans {
        let beyond = s.line.iter().filter(|&&l| l >= 64).count();
        println!(
            "{}: {} points, {} lines from the order (cut at {} deg){}",
            s.name,
            s.points.len(),
            s.lines,
            s.cut_deg,
            if beyond > 0 {
                format!(", {beyond} points on lines past the 64th (not compared)")
            } else {
                String::new()
            }
        );
        for (m, t) in models.iter().zip(&mut total) {
            let out = to_returns(&s.points, m, &ReturnsOptions::default(), &s.name)
                .unwrap_or_else(|e| panic!("{e}"));
            let rings = m.rings();
            let mut ring_of = vec![0i32; s.points.len()];
            for (r, &i) in out.returns.iter().zip(&out.order) {
                ring_of[i as usize] = i32::from(rings[usize::from(r.laser)]);
            }
            let mut one = Tally {
                from_elevation: out.from_elevation,
                ambiguous: out.ambiguous,
                ..Tally::default()
            };
            for (&l, &r) in s.line.iter().zip(&ring_of) {
                if l < 64 {
                    let want = 63 - l as i32;
                    one.compared += 1;
                    one.same += usize::from(r == want);
                    one.near += usize::from((r - want).abs() <= 1);
                    if want < LOW_RINGS {
                        one.low += 1;
                        one.low_same += usize::from(r == want);
                    }
                }
            }
            one.show(m.name);
            t.add(&one);
        }
    }
    println!("all {} scans:", scans.len());
    for (m, t) in models.iter().zip(&total) {
        t.show(m.name);
    }
}
