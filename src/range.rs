//! Frame ranges: which frames a run, a conversion or a sweep processes, by sweep index,
//! as given (`N`, `A..B`, `A..`, `..B`, both ends included) and as messages name them.

use crate::error::{Error, Result};
use std::ops::RangeInclusive;

/// Every frame of a capture.
pub const ALL_FRAMES: RangeInclusive<u32> = 0..=u32::MAX;

/// Parses an inclusive index range: `N`, `A..B`, `A..` or `..B`; `flag` names the
/// option in errors.
pub fn parse_range(flag: &str, text: &str) -> Result<RangeInclusive<u32>> {
    let bad = || {
        Error::Invalid(format!(
            "{flag} {text}: expected N, A..B, A.. or ..B with whole numbers (both ends included)"
        ))
    };
    let num = |s: &str| s.trim().parse::<u32>().map_err(|_| bad());
    let range = match text.split_once("..") {
        None => {
            let n = num(text)?;
            n..=n
        }
        Some((a, b)) => {
            let lo = if a.trim().is_empty() { 0 } else { num(a)? };
            let hi = if b.trim().is_empty() {
                u32::MAX
            } else {
                num(b.trim_start_matches('='))?
            };
            lo..=hi
        }
    };
    if range.start() > range.end() {
        return Err(Error::Invalid(format!(
            "{flag} {text}: the range is reversed ({} is after {}); write {}..{}",
            range.start(),
            range.end(),
            range.end(),
            range.start()
        )));
    }
    Ok(range)
}

/// How a frame range reads in messages: `--frames A..B`, `--frames A..` when open-ended,
/// or "the whole capture" when no `--frames` narrowed it.
pub fn frames_phrase(frames: &RangeInclusive<u32>) -> String {
    match (*frames.start(), *frames.end()) {
        (0, u32::MAX) => "the whole capture".to_string(),
        (a, u32::MAX) => format!("--frames {a}.."),
        (a, b) => format!("--frames {a}..{b}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_are_inclusive_and_checked() {
        assert_eq!(parse_range("--frames", "3").unwrap(), 3..=3);
        assert_eq!(parse_range("--frames", "1..10").unwrap(), 1..=10);
        assert_eq!(parse_range("--frames", "1..=10").unwrap(), 1..=10);
        assert_eq!(parse_range("--frames", "5..").unwrap(), 5..=u32::MAX);
        assert_eq!(parse_range("--frames", "..4").unwrap(), 0..=4);
        assert!(parse_range("--frames", "4..2").is_err());
        assert!(parse_range("--frames", "x").is_err());
        assert!(parse_range("--frames", "-1..2").is_err());
        assert_eq!(frames_phrase(&ALL_FRAMES), "the whole capture");
    }
}
