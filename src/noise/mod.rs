//! The noise chain: ideal power, noise stages in configured order, detection filters.
//!
//! A frame enters as clean returns; [`NoiseChain::process`] gives each return an ideal
//! power (see [`power`]), runs the `[[noise]]` stages in file order on a [`NoisyFrame`]
//! and then the detection filters (see [`detection`]). Nothing is removed from the
//! arrays: each return gets a [`Fate`], and [`NoisyFrame::survivors`] builds the
//! surviving returns with their noisy range and coordinates.
//!
//! # Adding a stage
//! Write one file with a type implementing [`NoiseStage`] and a `build` function reading
//! its options from a `Section`, then add one [`StageKind`] line to [`REGISTRY`]. A
//! stage sees only its own options, the frame being processed and its own random stream.
//!
//! # Random streams
//! Every stage of every frame draws from its own ChaCha8 stream:
//! key = `ChaCha8Rng::seed_from_u64(seed)`, stream number =
//! `frame_index << 32 | stage_tag`, where `stage_tag = fnv1a16(type) << 16 | occurrence`
//! (occurrence = how many stages of the same `type` come earlier in the chain). Keying by
//! type and occurrence rather than by chain position means adding or removing another
//! stage (say, the occlusion) leaves the rain draws unchanged, so "rain alone" and
//! "rain + occlusion" use common random numbers. Because every frame has its own stream,
//! frames can be processed in any order on any number of threads with identical results.
//!
//! # Intensity
//! One rule sets the intensity byte the sensor reports, applied once after the chain
//! (stages, spurious echoes resolved, detection filters) by
//! [`NoisyFrame::apply_intensity_rule`]:
//! - a return's own echo (fate [`Fate::Kept`]) reports
//!   I' = clamp(round(I g P / P_i), 0, 255), with I the recorded byte, P_i its ideal
//!   power (see [`power`]), P its power after every stage and g the product of the
//!   receivers' `gain_error` (a factor on the byte alone, not on the power). Every
//!   attenuating stage (fog, rain, snow, lens damage, occlusion with a transmission,
//!   emitter, laser-diode and receiver gains, a mixed pixel's own share) only multiplies
//!   `power`, so the byte sees the product of all losses, rounded once.
//! - In reflectivity mode the firmware turns the raw level into reflectivity with a
//!   range compensation calibrated in clear air (the recorded byte already carries it):
//!   the compensation stays, and what the atmosphere and the optics take from the echo
//!   shows as a lower reflectivity (Filgueira et al., Measurement 95, 2017: HDL-32E
//!   intensity falls with the rain rate). In raw mode the level is proportional to the
//!   received power of an unsaturated linear receiver, so a loss factor f on the power
//!   is a factor f on the level: the same factor in both modes. The compensation is
//!   that of the recorded range (a range noise of centimetres changes it by well under
//!   one byte).
//! - Spurious echoes (fates [`Fate::Replaced`], [`Fate::Added`]: fog, drops, flakes,
//!   crosstalk, spoofing, multipath mixtures, EMI, scattered beams) keep the intensity
//!   their stage or [`IdealPower::intensity_of`] gave them from their own power.
//! - Saturation: the ideal power is clamped at 1 (a bound of the power model, reached
//!   within about 10 m of a white target), and stages multiply the clamped value, so
//!   P / P_i is still exactly the product of the loss factors and the byte is scaled by
//!   it. This treats the byte as the linear reflectivity the firmware reports
//!   (including retro-reflectors above 100) rather than modelling a receiver that hides
//!   a loss until the echo falls below saturation, which the capture cannot tell us.
//! - At zero strength every stage leaves P = P_i bit for bit and g = 1, so every byte
//!   is the recorded one and no intensity column is made (same output bytes).

mod chain;
pub mod detection;
mod layout;
mod noisy;
pub mod power;
pub mod registry;
mod reported;
pub mod sensor;
pub mod spurious;
mod stage;
pub mod summary;
pub mod transmission;
mod wire;
pub mod world;

pub use crate::frame::{Fate, NO_CAUSE};
pub use chain::NoiseChain;
pub use layout::{check_ids, LaserSet, Layout, LASER_MASK};
pub(crate) use noisy::room_for_added;
pub use noisy::{Moved, NoisyFrame, TimeStretch};
pub use reported::Reported;
pub use stage::{stage_rng, stage_tags, NoiseStage, UNIT_FRAME};
pub use wire::GeometryChange;

pub use registry::{build_stage, StageKind, REGISTRY};
pub use world::{occlusion, rain};

pub use detection::{apply_detection, decide_recorded, DetectionRule};
pub use power::{IdealPower, PowerConstants};
pub use spurious::{DenseEchoes, Echo, SlotId, Slots};
pub use summary::NoiseSummary;

#[cfg(test)]
mod tests {
    use super::layout::LAYOUT_CHUNK;
    use super::reported::*;
    use super::*;
    use crate::config::Config;
    use crate::frame::{Frame, Return};
    use crate::numeric::{round_clamped, wrap_360};

    /// Bytes, powers, ideal powers, fates, ranges and draws.
    type Columns = (Vec<u8>, Vec<f64>, Vec<f64>, Vec<Fate>, Vec<f32>, Vec<f64>);

    /// Columns of mixed fates, powers (zero, tiny, large, NaN) and bytes, from a fixed seed.
    fn mixed_columns(n: usize) -> Columns {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let fates = [
            Fate::Kept,
            Fate::Occluded,
            Fate::BelowPower,
            Fate::Replaced,
            Fate::Added,
        ];
        let mut cols = (vec![], vec![], vec![], vec![], vec![], vec![]);
        for i in 0..n {
            cols.0.push(rng.random::<u8>());
            let p = match i % 7 {
                0 => 0.0,
                1 => f64::NAN,
                2 => 1e-300,
                _ => rng.random::<f64>() * 3.0,
            };
            cols.1.push(p);
            cols.2.push(if i % 11 == 0 {
                0.0
            } else {
                rng.random::<f64>() * 2.0
            });
            cols.3.push(fates[rng.random_range(0..fates.len())]);
            cols.4.push(rng.random::<f32>() * 120.0);
            cols.5.push(rng.random::<f64>() * 2.0 - 1.0);
        }
        cols
    }

    #[test]
    fn the_wide_intensity_loop_gives_the_plain_loops_bits() {
        // The AVX2 and AVX-512 builds (where this machine has them) against the loop
        // compiled for the baseline: the same bytes, with and without current bytes.
        let (bytes, power, ideal, fate, _, _) = mixed_columns(10_007);
        let current: Vec<u8> = bytes.iter().map(|b| b.wrapping_mul(3)).collect();
        type Rule = fn(&mut [u8], Option<&[u8]>, (&[f64], &[f64], &[Fate]), f64) -> bool;
        let mut builds: Vec<(&str, Rule)> = vec![("picked", intensity_bytes)];
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the processor has AVX2 (checked on the line above).
                builds.push(("avx2", |b, c, cols, g| unsafe {
                    intensity_bytes_avx2(b, c, cols, g)
                }));
            }
            if crate::numeric::avx512() {
                // SAFETY: the processor has AVX-512 F and DQ (checked on the line above).
                builds.push(("avx512", |b, c, cols, g| unsafe {
                    intensity_bytes_avx512(b, c, cols, g)
                }));
            }
        }
        for (name, build) in &builds {
            for cur in [None, Some(&current[..])] {
                for g in [1.0, 0.37, 2.5] {
                    let (mut a, mut b) = (bytes.clone(), bytes.clone());
                    let any_a = build(&mut a, cur, (&power, &ideal, &fate), g);
                    let any_b = intensity_bytes_body(&mut b, cur, (&power, &ideal, &fate), g);
                    assert_eq!((a, any_a), (b, any_b), "{name}");
                }
            }
        }
    }

    #[test]
    fn the_wide_attenuation_gives_the_plain_loops_bits() {
        let (_, power, _, fate, range, _) = mixed_columns(10_007);
        let mut wide = power.clone();
        transmission::attenuate(&mut wide, &range, &fate, 0.013);
        for i in 0..power.len() {
            let t = transmission::exp_nonpositive(-0.013 * f64::from(range[i]));
            let want = if fate[i].is_alive() {
                power[i] * t
            } else {
                power[i]
            };
            assert_eq!(wide[i].to_bits(), want.to_bits(), "{i}");
        }
    }

    #[test]
    fn round_byte_is_scale_byte() {
        let mut xs = vec![
            f64::NAN,
            -1.0,
            -0.4,
            -0.0,
            0.0,
            0.5,
            254.5,
            255.49,
            255.5,
            1e12,
        ];
        xs.push(f64::INFINITY);
        xs.push(f64::NEG_INFINITY);
        xs.extend((0..60_000).map(|k| f64::from(k) * 0.004_999_7));
        xs.extend((0..=600).map(|k| f64::from(k) * 0.5));
        xs.push(0.499_999_999_999_999_94);
        for x in xs {
            let want = x.round().clamp(0.0, 255.0) as u8;
            assert_eq!(round_byte(x), want, "{x}");
            assert_eq!(round_byte(x), sensor::scale_byte(1, x), "{x}");
        }
    }

    #[test]
    fn wrap_360_agrees_with_rem_euclid() {
        let mut a = -1000.0f64;
        while a < 1000.0 {
            for x in [
                a,
                a + 1e-9,
                -1e-300,
                -0.0,
                0.0,
                359.99999999999994,
                -360.0,
                720.0,
            ] {
                assert_eq!(wrap_360(x).to_bits(), x.rem_euclid(360.0).to_bits(), "{x}");
            }
            a += 0.37;
        }
    }

    /// `n` returns: firings of up to 32 lasers (some missing), times with NaNs and a
    /// repeat, azimuths varied.
    fn returns(n: usize) -> Vec<Return> {
        (0..n)
            .map(|i| {
                let k = i as u32;
                let time = match i % 97 {
                    5 => f64::NAN,
                    6 => 0.25,
                    _ => 0.25 + f64::from(k) * 1.152e-6 - f64::from(k % 7) * 3e-6,
                };
                Return {
                    range: 1.0 + (k.wrapping_mul(2_654_435_761) % 7900) as f32 / 100.0,
                    azimuth: (k / 29) as f32 * 0.17 + (k % 3) as f32 * 0.01,
                    time,
                    packet: k / 350,
                    intensity: (k % 101) as u8,
                    laser: (k % 29) as u8 + 3 * u8::from(k.is_multiple_of(5)),
                    block: ((k / 29) % 12) as u8,
                    ..Return::BLANK
                }
            })
            .collect()
    }

    #[test]
    fn the_clamped_rounding_is_libms() {
        let mut xs = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            0.499_999_999_999_999_94,
            -0.499_999_999_999_999_94,
            254.5,
            255.49,
            255.5,
            65_534.5,
            65_535.4,
            65_535.5,
            1e12,
            -1e12,
            4.5e15,
            9.3e18,
            -9.3e18,
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
        ];
        xs.extend((-200_000..200_000).map(|k| f64::from(k) * 0.004_999_7));
        xs.extend((-2_000..2_000).map(|k| f64::from(k) * 0.5));
        xs.extend((0..2_000).map(|k| 65_000.0 + f64::from(k) * 0.37));
        for x in xs {
            assert_eq!(
                round_clamped(x, 255),
                x.round().clamp(0.0, 255.0) as u16,
                "{x}"
            );
            let want = x.round().clamp(0.0, f64::from(u16::MAX)) as u16;
            assert_eq!(round_clamped(x, u16::MAX), want, "{x}");
        }
    }

    #[test]
    fn a_copied_frame_gives_what_the_owned_frame_gives() {
        // `process` copies the returns in the pass that reads them and builds the firing
        // slots there; `process_owned` reads the returns it is given. Weather with
        // echoes of every kind, and a sensor chain (the layout's path).
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
        for name in [
            "adverse-weather.toml",
            "pdiagram-world.toml",
            "pdiagram-sensor.toml",
        ] {
            let path = dir.join(name);
            let (cfg, _) = Config::load(Some(&path), &[], None).unwrap();
            let chain = NoiseChain::new(&cfg);
            let frame = Frame {
                index: 3,
                partial: false,
                returns: returns(5000),
            };
            let a = chain.process(&frame);
            let b = chain.process_owned(frame.clone());
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&a.power), bits(&b.power), "{name}");
            assert_eq!(a.range, b.range, "{name}");
            assert_eq!(a.fate, b.fate, "{name}");
            assert_eq!(a.cause, b.cause, "{name}");
            // Debug text: the returns' times hold NaNs.
            let text = |f: &NoisyFrame| format!("{:?}", f.clean);
            assert!(text(&a) == text(&b), "{name}: the returns differ");
            assert_eq!(a.moved.intensity, b.moved.intensity, "{name}");
            assert!(
                a.fate.iter().any(|f| *f != Fate::Kept),
                "{name}: nothing happened"
            );
        }
    }

    #[test]
    fn with_layout_gives_new_s_values_and_the_columns_of_each_return() {
        let ideal = IdealPower::new(
            &crate::config::PowerConfig::default(),
            &crate::config::SensorConfig::default(),
            &crate::config::DetectionConfig::default(),
        );
        // Sizes around the chunk of `Layout::build` and its quads.
        for n in [0, 1, 3, 255, 256, 257, 1000, 3 * LAYOUT_CHUNK + 5] {
            let clean = returns(n);
            let a = NoisyFrame::with_layout(3, clean.clone(), &ideal);
            let b = NoisyFrame::new(3, clean.clone(), &ideal);
            assert_eq!(a.range, b.range);
            assert!(a
                .power
                .iter()
                .zip(&b.power)
                .all(|(x, y)| x.to_bits() == y.to_bits()));
            let l = a.layout.as_ref().expect("built");
            for (i, r) in clean.iter().enumerate() {
                assert_eq!(l.laser[i], r.laser & LASER_MASK);
                assert_eq!(l.intensity[i], r.intensity);
                assert_eq!(l.time[i].to_bits(), r.time.to_bits());
                assert_eq!(l.azimuth[i].to_bits(), r.azimuth.to_bits());
            }
            assert_eq!(l.len(), n);
            // Firings: maximal runs of the same (packet, block), covering every return.
            let mut runs: Vec<[u32; 2]> = Vec::new();
            for (i, r) in clean.iter().enumerate() {
                match runs.last_mut() {
                    Some(last)
                        if {
                            let p = &clean[i - 1];
                            (p.packet, p.block) == (r.packet, r.block)
                        } =>
                    {
                        last[1] = i as u32 + 1
                    }
                    _ => runs.push([i as u32, i as u32 + 1]),
                }
            }
            assert_eq!(l.firings, runs);
            let numbers = clean.iter().map(|r| r.time).filter(|t| !t.is_nan());
            let lo = numbers.clone().fold(f64::INFINITY, f64::min);
            let hi = numbers.fold(f64::NEG_INFINITY, f64::max);
            assert_eq!(l.time_range, [lo, hi], "{n}");
            assert_eq!(l.time_nan, clean.iter().any(|r| r.time.is_nan()), "{n}");
        }
    }

    #[test]
    fn time_stretches_give_the_times_of_stretching_each_time_in_place() {
        let clean = returns(700);
        let maps = [
            TimeStretch {
                t0: clean[0].time,
                scale: 1.0 + 80e-6,
                offset: 12.5e-6,
                len: 600,
            },
            TimeStretch {
                t0: clean[0].time,
                scale: 1.0 - 20e-6,
                offset: -3e-6,
                len: 650,
            },
        ];
        let mut moved = Moved::default();
        // In place, as the clock did: each stretch over the times of the returns it
        // covers (here the returns beyond a stretch's `len` came later).
        let mut times: Vec<f64> = clean.iter().map(|r| r.time).collect();
        for m in &maps {
            moved.time_stretch.push(*m);
            for t in &mut times[..m.len] {
                *t = m.t0 + (*t - m.t0) * m.scale + m.offset;
            }
        }
        let frame = NoisyFrame {
            range: clean.iter().map(|r| r.range).collect(),
            fate: vec![Fate::Kept; clean.len()],
            clean: clean.clone(),
            moved,
            ..NoisyFrame::default()
        };
        let out = frame.survivors();
        for (i, r) in clean.iter().enumerate() {
            let want = times[i].to_bits();
            assert_eq!(frame.moved.reported_time(i, r.time).to_bits(), want, "{i}");
            assert_eq!(out[i].time.to_bits(), want, "{i}");
        }
    }

    #[test]
    fn stage_tags_count_occurrences_per_type() {
        let tags = stage_tags(&["occlusion", "rain", "occlusion"]);
        assert_eq!(tags[0] & 0xffff, 0);
        assert_eq!(tags[2] & 0xffff, 1);
        assert_eq!(tags[0] >> 16, tags[2] >> 16);
        assert_ne!(tags[0] >> 16, tags[1] >> 16);
        // The rain tag does not depend on what precedes it.
        assert_eq!(stage_tags(&["rain"])[0], tags[1]);
    }
}
