//! Laser diode piece to piece (p-diagram 01): each emitter/receiver pair has its own
//! power, range offset and pointing error, fixed for the unit.
//!
//! Model (pdiagram-models.md, 01): per laser l, P' = g_l P with g_l = exp(N(0, s_g^2)),
//! R' = R + b_l with b_l ~ N(0, s_b^2) (the byte follows g_l by the chain's intensity
//! rule, `noise`, "Intensity"); plus (this
//! issue) elevation and azimuth offsets ~ N(0, s^2) in degrees: the point is reported
//! along the turned direction at its range (the scene is not re-ray-cast: the range the
//! turned beam would have measured is unknown). All draws are made once per seed from
//! the stage's unit stream, four per laser in a fixed order, so a value given per laser
//! replaces its draw without moving the others. Source: Levinson and Thrun, ISER 2010
//! (per-beam intensity response and range offsets); defaults are engineering
//! assumptions under the HDL-32E's 2 cm accuracy. The defaults are the spread between
//! units (to add to a recording, see `sensor`, "What the defaults stand for"): the
//! per-laser range bias SD is 5 mm (10 mm before issue 29, which with the clock and
//! receiver defaults added 2.2 cm at 25 m, beyond the datasheet's 2 cm for the whole
//! sensor).

use super::{check_per_laser, float, normal, per_laser, sigma};
use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::registry::OptionSpec;
use crate::noise::spurious::MAX_LASERS;
use crate::noise::{NoiseStage, NoisyFrame, StageKind, LASER_MASK};
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "laser_diode";

/// The laser-diode stage.
#[derive(Clone, Debug)]
pub struct LaserDiode {
    /// SD of the log power factor.
    pub sigma_power: f64,
    /// SD of the range bias, metres.
    pub sigma_range_m: f64,
    /// SD of the elevation offset, degrees.
    pub sigma_elevation_deg: f64,
    /// SD of the azimuth offset, degrees.
    pub sigma_azimuth_deg: f64,
    /// Given per-laser values (power factor, range bias, elevation, azimuth offset).
    pub given: [Option<Vec<f64>>; 4],
    /// Values in use per laser id: power factor, range bias m, elevation deg, azimuth
    /// deg (every id a sensor model may have).
    pub values: [[f64; MAX_LASERS]; 4],
}

impl NoiseStage for LaserDiode {
    fn kind(&self) -> &'static str {
        NAME
    }
    fn uses_layout(&self) -> bool {
        true
    }
    fn describe(&self) -> String {
        format!(
            "per-laser power lognormal SD {}, range bias SD {} m, elevation SD {} deg, azimuth SD {} deg (once per seed)",
            self.sigma_power, self.sigma_range_m, self.sigma_elevation_deg, self.sigma_azimuth_deg
        )
    }
    fn settings(&self) -> Vec<(&'static str, Value)> {
        let mut v = vec![
            ("sigma_power", float(self.sigma_power)),
            ("sigma_range_m", float(self.sigma_range_m)),
            ("sigma_elevation_deg", float(self.sigma_elevation_deg)),
            ("sigma_azimuth_deg", float(self.sigma_azimuth_deg)),
        ];
        for (name, g) in GIVEN_KEYS.iter().zip(&self.given) {
            if let Some(g) = g {
                v.push((name, Value::Array(g.iter().map(|&x| float(x)).collect())));
            }
        }
        v
    }
    fn with_unit_draws(&self, rng: &mut ChaCha8Rng) -> Option<Arc<dyn NoiseStage>> {
        let mut s = self.clone();
        // Laser by laser, so the first 32 lasers' values do not depend on how many more
        // the sensor has.
        for l in 0..MAX_LASERS {
            let d = [normal(rng), normal(rng), normal(rng), normal(rng)];
            s.values[0][l] = (self.sigma_power * d[0]).exp();
            s.values[1][l] = self.sigma_range_m * d[1];
            s.values[2][l] = self.sigma_elevation_deg * d[2];
            s.values[3][l] = self.sigma_azimuth_deg * d[3];
            for (k, g) in self.given.iter().enumerate() {
                if let Some(&v) = g.as_ref().and_then(|g| g.get(l)) {
                    s.values[k][l] = v;
                }
            }
        }
        Some(Arc::new(s))
    }
    fn check_lasers(&self, lasers: usize) -> std::result::Result<(), String> {
        for (key, g) in GIVEN_KEYS.iter().zip(&self.given) {
            check_per_laser(key, g.as_deref(), lasers)?;
        }
        Ok(())
    }
    fn apply(&self, frame: &mut NoisyFrame, _rng: &mut ChaCha8Rng) {
        let [gain, bias, elev, azim] = &self.values;
        let n = frame.len();
        let gains = gain.iter().any(|&g| g != 1.0);
        let biases = bias.iter().any(|&b| b != 0.0);
        let elevs = elev.iter().any(|&v| v != 0.0);
        let azims = azim.iter().any(|&v| v != 0.0);
        if !(gains || biases || elevs || azims) {
            return;
        }
        // The laser ids come from the frame's compact columns (not the 48-byte returns).
        // The pointing offsets apply whatever the fate, the power and range only to
        // alive returns.
        let lay = frame.layout();
        let NoisyFrame {
            fate,
            power,
            range,
            moved,
            ..
        } = frame;
        let lasers = &lay.laser[..n];
        // `0.0 + x`, not `x`: the same value as adding to a zero vector (-0.0 becomes
        // +0.0); the sums are tabled per laser.
        let offsets = [elev, azim].map(|v| v.map(|x| 0.0 + x as f32));
        let firings = &lay.firings[..];
        // Columns no stage made yet are built together, in one walk over the firings
        // (two walks, one per column, cost a third more on a real frame, whose firings
        // are often incomplete); existing ones get the offsets added.
        let mut fresh: Vec<(&mut Option<Vec<f32>>, &[f32; MAX_LASERS])> = Vec::new();
        for (on, v, off) in [
            (elevs, &mut moved.elevation_deg, &offsets[0]),
            (azims, &mut moved.azimuth_deg, &offsets[1]),
        ] {
            if !on {
                continue;
            }
            match v {
                None => fresh.push((v, off)),
                Some(v) => {
                    for (d, &l) in v.iter_mut().zip(lasers) {
                        *d += off[usize::from(l & LASER_MASK)];
                    }
                }
            }
        }
        let tables: Vec<&[f32; MAX_LASERS]> = fresh.iter().map(|(_, t)| *t).collect();
        for ((v, _), column) in fresh
            .into_iter()
            .zip(per_laser_columns(lasers, firings, &tables))
        {
            *v = Some(column);
        }
        if gains {
            // Power only: the byte follows by the chain's intensity rule.
            if biases {
                // Power and range in one pass over fates and laser ids.
                for (((p, r), &l), f) in power
                    .iter_mut()
                    .zip(range.iter_mut())
                    .zip(lasers)
                    .zip(fate.iter())
                {
                    if f.is_alive() {
                        let l = usize::from(l & LASER_MASK);
                        *p *= gain[l];
                        *r = (f64::from(*r) + bias[l]) as f32;
                    }
                }
                return;
            }
            for ((p, &l), f) in power.iter_mut().zip(lasers).zip(fate.iter()) {
                if f.is_alive() {
                    *p *= gain[usize::from(l & LASER_MASK)];
                }
            }
        }
        if biases {
            for ((r, &l), f) in range.iter_mut().zip(lasers).zip(fate.iter()) {
                if f.is_alive() {
                    *r = (f64::from(*r) + bias[usize::from(l & LASER_MASK)]) as f32;
                }
            }
        }
    }
}

/// The laser ids of a firing in which every laser returned, in firing order (its
/// first 16, 32, 64 or 128 for the sensor's lasers).
const IN_ORDER: [u8; MAX_LASERS] = {
    let mut ids = [0u8; MAX_LASERS];
    let mut l = 0;
    while l < MAX_LASERS {
        ids[l] = l as u8;
        l += 1;
    }
    ids
};

/// `table[l]` for every laser id `l` of `lasers` and every table of `tables`, firing by
/// firing: a firing of lasers 0, 1, 2, ... in order (every laser returned) is a copy of
/// each table's start; the others are looked up return by return. The same values
/// either way.
fn per_laser_columns(
    lasers: &[u8],
    firings: &[[u32; 2]],
    tables: &[&[f32; MAX_LASERS]],
) -> Vec<Vec<f32>> {
    let mut out: Vec<Vec<f32>> = tables
        .iter()
        .map(|_| Vec::with_capacity(lasers.len()))
        .collect();
    if tables.is_empty() {
        return out;
    }
    for &[start, end] in firings {
        let ids = &lasers[start as usize..end as usize];
        if IN_ORDER.get(..ids.len()) == Some(ids) {
            for (column, table) in out.iter_mut().zip(tables) {
                column.extend_from_slice(&table[..ids.len()]);
            }
        } else {
            for (column, table) in out.iter_mut().zip(tables) {
                column.extend(ids.iter().map(|&l| table[usize::from(l & LASER_MASK)]));
            }
        }
    }
    out
}

const GIVEN_KEYS: [&str; 4] = [
    "power_factors",
    "range_bias_m",
    "elevation_offsets_deg",
    "azimuth_offsets_deg",
];

/// Reads the options of a `laser_diode` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    let given = [
        per_laser(opts, GIVEN_KEYS[0], 0.0, 10.0)?,
        per_laser(opts, GIVEN_KEYS[1], -1.0, 1.0)?,
        per_laser(opts, GIVEN_KEYS[2], -5.0, 5.0)?,
        per_laser(opts, GIVEN_KEYS[3], -5.0, 5.0)?,
    ];
    Ok(Arc::new(LaserDiode {
        sigma_power: sigma(opts, "sigma_power", 0.10, 2.0)?,
        sigma_range_m: sigma(opts, "sigma_range_m", 0.005, 1.0)?,
        sigma_elevation_deg: sigma(opts, "sigma_elevation_deg", 0.01, 5.0)?,
        sigma_azimuth_deg: sigma(opts, "sigma_azimuth_deg", 0.01, 5.0)?,
        given,
        values: [
            [1.0; MAX_LASERS],
            [0.0; MAX_LASERS],
            [0.0; MAX_LASERS],
            [0.0; MAX_LASERS],
        ],
    }))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "01 laser diode (piece to piece)",
    model: "per laser, once per seed: P' = g_l P, g_l = exp(N(0, s_g^2)); R' = R + N(0, s_b^2); elevation and azimuth offsets N(0, s^2); the byte follows g_l by the intensity rule",
    source: "Levinson and Thrun, ISER 2010 (per-beam response and range offsets); defaults engineering assumption within the 2 cm spec",
    options: &[
        OptionSpec { name: "sigma_power", unit: "-", default: "0.10", doc: "SD of the per-laser log power factor" },
        OptionSpec { name: "sigma_range_m", unit: "m", default: "0.005", doc: "SD of the per-laser range bias b_l (spread between units)" },
        OptionSpec { name: "sigma_elevation_deg", unit: "deg", default: "0.01", doc: "SD of the per-laser elevation offset" },
        OptionSpec { name: "sigma_azimuth_deg", unit: "deg", default: "0.01", doc: "SD of the per-laser azimuth offset" },
        OptionSpec { name: "power_factors", unit: "-", default: "drawn", doc: "Given power factors (replace the draws), one per laser of the sensor" },
        OptionSpec { name: "range_bias_m", unit: "m", default: "drawn", doc: "Given range biases, one per laser of the sensor" },
        OptionSpec { name: "elevation_offsets_deg", unit: "deg", default: "drawn", doc: "Given elevation offsets, one per laser of the sensor" },
        OptionSpec { name: "azimuth_offsets_deg", unit: "deg", default: "drawn", doc: "Given azimuth offsets, one per laser of the sensor" },
    ],
    build,
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn per_laser_columns_are_the_tables_of_each_return_s_laser() {
        let table: [f32; MAX_LASERS] = std::array::from_fn(|l| 0.0 + (l as f32 - 15.5) * 1e-3);
        // Firings in order (of 32, 16, 64 and 128 lasers), with lasers missing, out of
        // order, ids past 31 and past 127.
        let firings_ids: Vec<Vec<u8>> = vec![
            (0..32).collect(),
            (0..32).filter(|l| l % 5 != 0).collect(),
            (0..32).rev().collect(),
            (0..32).collect(),
            (32..64).collect(),
            (0..16).collect(),
            (0..64).collect(),
            (0..128).collect(),
            (120..=255).collect(),
            vec![],
            vec![7],
            (0..31).collect(),
        ];
        let mut lasers = Vec::new();
        let mut firings = Vec::new();
        for ids in firings_ids.iter().filter(|ids| !ids.is_empty()) {
            let start = lasers.len() as u32;
            lasers.extend_from_slice(ids);
            firings.push([start, lasers.len() as u32]);
        }
        let other: [f32; MAX_LASERS] = std::array::from_fn(|l| -(l as f32) * 2e-3);
        for tables in [
            vec![&table],
            vec![&table, &other],
            vec![&other, &table],
            vec![],
        ] {
            let got = per_laser_columns(&lasers, &firings, &tables);
            assert_eq!(got.len(), tables.len());
            for (got, t) in got.iter().zip(&tables) {
                let want: Vec<f32> = lasers.iter().map(|&l| t[usize::from(l % 128)]).collect();
                assert_eq!(got.len(), want.len());
                assert!(got
                    .iter()
                    .zip(&want)
                    .all(|(a, b)| a.to_bits() == b.to_bits()));
            }
        }
    }
}
