//! The reported view of a [`NoisyFrame`] and the intensity rule's bytes.

use super::noisy::along_beam;
use super::*;
use crate::frame::Return;
use crate::numeric::{round_clamped, small_sin_cos, wrap_360};

/// The returns of a [`NoisyFrame`] as reported: noisy where the sensor still reports
/// the return, as recorded where it was dropped (as `run --keep-dropped` writes them).
/// The frame's optional parts are resolved once for all the returns visited, where
/// [`NoisyFrame::noisy_return`] resolves them at every call.
pub struct Reported<'a> {
    pub(super) view: View<'a>,
    pub(super) fate: &'a [Fate],
}

impl Reported<'_> {
    /// Number of returns: the recorded ones, then those the stages added.
    pub fn len(&self) -> usize {
        self.fate.len()
    }

    /// True for a frame without returns.
    pub fn is_empty(&self) -> bool {
        self.fate.is_empty()
    }

    /// True where the sensor still reports return `i` (it was not dropped).
    #[inline(always)]
    pub fn is_alive(&self, i: usize) -> bool {
        self.fate[i].is_alive()
    }

    /// Return `i` as reported.
    #[inline(always)]
    pub fn of(&self, i: usize) -> Return {
        if self.fate[i].is_alive() {
            self.view.noisy_return(i)
        } else {
            self.view.clean[i]
        }
    }
}

/// The per-return state of a [`NoisyFrame`] with its optional parts resolved once, so
/// the per-return loop of [`NoisyFrame::survivors`] tests no `Option` per return.
pub(super) struct View<'a> {
    clean: &'a [Return],
    range: &'a [f32],
    azimuth: Option<&'a [f32]>,
    elevation: Option<&'a [f32]>,
    pose: Option<&'a sensor::Poses>,
    time: Option<&'a [f64]>,
    time_stretch: &'a [TimeStretch],
    intensity: Option<&'a [u8]>,
}

impl<'a> View<'a> {
    pub(super) fn of(frame: &'a NoisyFrame) -> Self {
        let m = &frame.moved;
        View {
            clean: &frame.clean,
            range: &frame.range,
            azimuth: m.azimuth_deg.as_deref(),
            elevation: m.elevation_deg.as_deref(),
            pose: m.pose.as_ref(),
            time: m.time.as_deref(),
            time_stretch: &m.time_stretch,
            intensity: m.intensity.as_deref(),
        }
    }

    /// True when no sensor state is set (only the range changed).
    pub(super) fn plain(&self) -> bool {
        self.azimuth.is_none()
            && self.elevation.is_none()
            && self.pose.is_none()
            && self.time.is_none()
            && self.time_stretch.is_empty()
            && self.intensity.is_none()
    }

    // Inlined into the loop of `survivors` so the return is built in registers and stored
    // once into the output (a call wrote it to the stack first and the loop copied it,
    // stalling on the store forwarding of every return).
    #[inline(always)]
    pub(super) fn noisy_return(&self, i: usize) -> Return {
        let r = &self.clean[i];
        let mut out = along_beam(r, self.range[i]);
        let da = self.azimuth.map_or(0.0, |v| v[i]);
        let de = self.elevation.map_or(0.0, |v| v[i]);
        if (da != 0.0 || de != 0.0) && r.range > 0.0 {
            // Turn the actual direction of the point (whatever the calibration's azimuth
            // offsets): elevation in the vertical plane of the beam, then azimuth about
            // z, clockwise seen from above like the sensor's azimuth.
            let (x, y, z) = (f64::from(out.x), f64::from(out.y), f64::from(out.z));
            let (se, ce) = small_sin_cos(f64::from(de).to_radians());
            let (x1, y1, z2) = if de != 0.0 || (x == 0.0 && y == 0.0) {
                let h = (x * x + y * y).sqrt();
                let (h2, z2) = (h * ce - z * se, h * se + z * ce);
                if h > 0.0 {
                    let k = h2 / h;
                    (x * k, y * k, z2)
                } else {
                    (h2, 0.0, z2)
                }
            } else {
                // No elevation change (se = +-0, ce = 1) and h > 0: the turn above gives
                // h2 = h, k = 1 and z2 = (+-0) + z exactly, so skip its square root and
                // division (h * se is a zero with the sign of se).
                (x, y, se + z * ce)
            };
            let (sa, ca) = small_sin_cos(f64::from(da).to_radians());
            out.x = (x1 * ca + y1 * sa) as f32;
            out.y = (y1 * ca - x1 * sa) as f32;
            out.z = z2 as f32;
            out.azimuth = wrap_360(f64::from(r.azimuth) + f64::from(da)) as f32;
            out.elevation = r.elevation + de;
        }
        if let Some(p) = self.pose {
            let [x, y, z] = p.of(i).apply([out.x, out.y, out.z], r.time - p.t_ref);
            out.x = x;
            out.y = y;
            out.z = z;
        }
        if let Some(t) = self.time {
            out.time = t[i];
        }
        // As `Moved::reported_time` (here with `time` resolved once).
        out.time = TimeStretch::apply_all(self.time_stretch, i, out.time);
        if let Some(v) = self.intensity {
            out.intensity = v[i];
        }
        out
    }
}

/// `x` rounded half up and clamped to a byte, the value of
/// [`sensor::scale_byte`]`(1, x)` (`round(x).clamp(0, 255)`): [`round_clamped`] to 255.
#[inline(always)]
pub(super) fn round_byte(x: f64) -> u8 {
    round_clamped(x, 255) as u8
}

/// The intensity rule on recorded bytes `bytes` in place (module documentation,
/// "Intensity"): each kept return's byte times g P / P_i, rounded once and clamped;
/// other returns get their current byte (`current`, else their recorded one). True when
/// some byte differs from the current one. Free of branches so it vectorises, with
/// AVX-512 or AVX2 where the processor has it (see [`crate::numeric::wide`]).
pub(super) fn intensity_bytes(
    bytes: &mut [u8],
    current: Option<&[u8]>,
    columns: (&[f64], &[f64], &[Fate]),
    g: f64,
) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        if crate::numeric::avx512() {
            // SAFETY: the processor has AVX-512 F and DQ (checked on the line above).
            return unsafe { intensity_bytes_avx512(bytes, current, columns, g) };
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2 (checked on the line above).
            return unsafe { intensity_bytes_avx2(bytes, current, columns, g) };
        }
    }
    intensity_bytes_body(bytes, current, columns, g)
}

/// [`intensity_bytes`] compiled with AVX-512.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq")]
pub(super) unsafe fn intensity_bytes_avx512(
    bytes: &mut [u8],
    current: Option<&[u8]>,
    columns: (&[f64], &[f64], &[Fate]),
    g: f64,
) -> bool {
    intensity_bytes_body(bytes, current, columns, g)
}

/// [`intensity_bytes`] compiled with AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(super) unsafe fn intensity_bytes_avx2(
    bytes: &mut [u8],
    current: Option<&[u8]>,
    columns: (&[f64], &[f64], &[Fate]),
    g: f64,
) -> bool {
    intensity_bytes_body(bytes, current, columns, g)
}

/// The loops of [`intensity_bytes`].
#[inline(always)]
pub(super) fn intensity_bytes_body(
    bytes: &mut [u8],
    current: Option<&[u8]>,
    (power, ideal, fate): (&[f64], &[f64], &[Fate]),
    g: f64,
) -> bool {
    // The rule's byte of a return whose recorded byte is `v`, or `cur` unless kept.
    let byte = |v: u8, p: f64, p0: f64, fate: Fate, cur: u8| {
        // A zero ideal power (reflectance floor 0 and byte 0) has byte 0 anyway.
        let f = if p0 > 0.0 { g * (p / p0) } else { g };
        let new = round_byte(f64::from(v) * f);
        if fate == Fate::Kept {
            new
        } else {
            cur
        }
    };
    let parts = power.iter().zip(ideal).zip(fate);
    let mut any = false;
    match current {
        // One loop per case, so neither tests an `Option` per return.
        None => {
            for (v, ((&p, &p0), &fate)) in bytes.iter_mut().zip(parts) {
                let out = byte(*v, p, p0, fate, *v);
                any |= out != *v;
                *v = out;
            }
        }
        Some(c) => {
            for ((v, &cur), ((&p, &p0), &fate)) in bytes.iter_mut().zip(c).zip(parts) {
                let out = byte(*v, p, p0, fate, cur);
                any |= out != cur;
                *v = out;
            }
        }
    }
    any
}
