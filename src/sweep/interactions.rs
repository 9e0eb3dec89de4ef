//! Interaction verdicts between noise stages (issue 9, part B; pure logic only so far).
//!
//! Inputs are object counts per seed for one distance band: stage `a` alone, stage `b`
//! alone and both together, each run with common random numbers. Each seed's frames are
//! pooled first (detected share = detected / objects over the seed's frames: frames of one
//! capture are not independent samples), then two per-seed differences are summarised by
//! their mean and 95 % t interval over seeds ([`super::tables::interval`]):
//!
//! - `vs_independence = both - a * b` (the product is the independence prediction);
//! - `vs_worse = both - min(a, b)` (the worse of the two alone).
//!
//! The verdict, with tolerance [`TOLERANCE`] (absolute, in detected share):
//!
//! 1. **masking** when `vs_worse` has mean above the tolerance and (with two or more
//!    seeds) its interval lies above 0: the pair detects more than the worse stage alone;
//! 2. **compounding** when `vs_independence` has mean below minus the tolerance and (with
//!    two or more seeds) its interval lies below 0: worse than independence predicts;
//! 3. **independent** when the mean of `vs_independence` is within the tolerance of 0 or
//!    (with two or more seeds) its interval contains 0;
//! 4. **unclear** otherwise (e.g. better than independence but not better than the worse
//!    stage alone).

use super::tables::{interval, Interval};
use serde::Serialize;

/// Tolerance of the verdicts, in detected share (5 percentage points).
pub const TOLERANCE: f64 = 0.05;

/// Objects and detected objects of one seed (frames pooled) in one band.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    /// Objects present.
    pub objects: u64,
    /// Objects detected.
    pub detected: u64,
}

impl Counts {
    /// Detected share, `None` without objects.
    pub fn share(&self) -> Option<f64> {
        (self.objects > 0).then(|| self.detected as f64 / self.objects as f64)
    }
}

/// Plain-language verdict on one stage pair in one band.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    /// Together clearly worse than the product of each alone.
    Compounding,
    /// Together within the tolerance (or the interval) of the product.
    Independent,
    /// Together better than the worse of the two alone.
    Masking,
    /// None of the above holds clearly.
    Unclear,
}

impl Verdict {
    /// The verdict's word as written in tables.
    pub fn word(self) -> &'static str {
        match self {
            Verdict::Compounding => "compounding",
            Verdict::Independent => "independent",
            Verdict::Masking => "masking",
            Verdict::Unclear => "unclear",
        }
    }
}

/// Summary of one pair in one band over seeds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairResult {
    /// Seeds with objects in all three runs.
    pub seeds: usize,
    /// Mean detected share of stage `a` alone.
    pub a: f64,
    /// Mean detected share of stage `b` alone.
    pub b: f64,
    /// Mean detected share with both.
    pub both: f64,
    /// `both - a * b` over seeds.
    pub vs_independence: Interval,
    /// `both - min(a, b)` over seeds.
    pub vs_worse: Interval,
    /// The verdict.
    pub verdict: Verdict,
}

/// Verdict of one pair in one band from per-seed counts (same seed order in all three);
/// `None` when no seed has objects in all three runs.
pub fn pair_result(a: &[Counts], b: &[Counts], both: &[Counts]) -> Option<PairResult> {
    let mut sa = Vec::new();
    let mut sb = Vec::new();
    let mut sab = Vec::new();
    for ((x, y), z) in a.iter().zip(b).zip(both) {
        if let (Some(x), Some(y), Some(z)) = (x.share(), y.share(), z.share()) {
            sa.push(x);
            sb.push(y);
            sab.push(z);
        }
    }
    let indep: Vec<f64> = (0..sab.len()).map(|i| sab[i] - sa[i] * sb[i]).collect();
    let worse: Vec<f64> = (0..sab.len()).map(|i| sab[i] - sa[i].min(sb[i])).collect();
    let vs_independence = interval(&indep)?;
    let vs_worse = interval(&worse)?;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    Some(PairResult {
        seeds: sab.len(),
        a: mean(&sa),
        b: mean(&sb),
        both: mean(&sab),
        vs_independence,
        vs_worse,
        verdict: verdict(&vs_independence, &vs_worse),
    })
}

/// The rule of the module docs applied to the two summarised differences.
pub fn verdict(vs_independence: &Interval, vs_worse: &Interval) -> Verdict {
    if vs_worse.mean > TOLERANCE && vs_worse.lo.is_none_or(|lo| lo > 0.0) {
        return Verdict::Masking;
    }
    if vs_independence.mean < -TOLERANCE && vs_independence.hi.is_none_or(|hi| hi < 0.0) {
        return Verdict::Compounding;
    }
    let contains_zero = matches!(
        (vs_independence.lo, vs_independence.hi),
        (Some(lo), Some(hi)) if lo <= 0.0 && hi >= 0.0
    );
    if vs_independence.mean.abs() <= TOLERANCE || contains_zero {
        return Verdict::Independent;
    }
    Verdict::Unclear
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c(objects: u64, detected: u64) -> Counts {
        Counts { objects, detected }
    }

    #[test]
    fn each_alone_keeps_both_lose_is_compounding() {
        // Each stage alone keeps 9 of 10 objects, together only 2: product predicts 0.81.
        let a = [c(10, 9), c(10, 9), c(10, 8)];
        let b = [c(10, 9), c(10, 10), c(10, 9)];
        let both = [c(10, 2), c(10, 3), c(10, 2)];
        let r = pair_result(&a, &b, &both).unwrap();
        assert_eq!(r.verdict, Verdict::Compounding, "{r:?}");
    }

    #[test]
    fn pair_better_than_worse_alone_is_masking() {
        // b alone is bad (0.3), but with a it recovers to 0.8.
        let a = [c(10, 9), c(10, 9), c(10, 9)];
        let b = [c(10, 3), c(10, 3), c(10, 4)];
        let both = [c(10, 8), c(10, 8), c(10, 8)];
        let r = pair_result(&a, &b, &both).unwrap();
        assert_eq!(r.verdict, Verdict::Masking, "{r:?}");
    }

    #[test]
    fn product_is_independent() {
        let a = [c(10, 5), c(10, 5)];
        let b = [c(10, 8), c(10, 8)];
        let both = [c(10, 4), c(10, 4)];
        let r = pair_result(&a, &b, &both).unwrap();
        assert!((r.vs_independence.mean).abs() < 1e-12);
        assert_eq!(r.verdict, Verdict::Independent, "{r:?}");
    }

    #[test]
    fn single_seed_uses_the_tolerance_only() {
        let r = pair_result(&[c(4, 4)], &[c(4, 4)], &[c(4, 3)]).unwrap();
        assert_eq!(r.vs_independence.lo, None);
        assert_eq!(r.verdict, Verdict::Compounding);
        let r = pair_result(&[c(100, 100)], &[c(100, 100)], &[c(100, 96)]).unwrap();
        assert_eq!(r.verdict, Verdict::Independent);
    }

    #[test]
    fn seeds_without_objects_are_skipped() {
        assert!(pair_result(&[c(0, 0)], &[c(3, 3)], &[c(3, 3)]).is_none());
        let r = pair_result(
            &[c(0, 0), c(2, 2)],
            &[c(3, 3), c(2, 2)],
            &[c(3, 3), c(2, 2)],
        );
        assert_eq!(r.unwrap().seeds, 1);
    }
}
