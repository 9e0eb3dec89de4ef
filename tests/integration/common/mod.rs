//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod ground_eval;
pub mod ground_scene;

use std::path::PathBuf;

/// Path of a file under ../shared/data, or None (with a skip message) when absent.
pub fn shared(rel: &str) -> Option<PathBuf> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel);
    if path.exists() {
        Some(path)
    } else {
        eprintln!(
            "SKIPPED: {} is absent (the shared data sits beside the project in CI)",
            path.display()
        );
        None
    }
}

/// The project's own fixture directory.
pub fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("fixtures")
}

/// Every file under `dir` by relative path, with its bytes.
pub fn files(dir: &std::path::Path) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(
                    p.strip_prefix(dir).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                );
            }
        }
    }
    out
}

/// A configuration from TOML text (panics with the text when it does not load).
pub fn config(text: &str) -> lidar_noise::config::Config {
    lidar_noise::config::Config::from_toml_str(text, std::path::Path::new("test.toml"), &[], None)
        .unwrap_or_else(|e| panic!("config should load: {e}\n{text}"))
        .0
}

/// The noise chain of `text` run on a frame.
pub fn run(text: &str, f: &lidar_noise::frame::Frame) -> lidar_noise::noise::NoisyFrame {
    lidar_noise::noise::NoiseChain::new(&config(text)).process(f)
}

/// A configuration of one `[[noise]]` stage of type `kind` with option lines `body`.
pub fn stage(kind: &str, body: &str) -> String {
    format!("seed = 5\n[[noise]]\ntype = \"{kind}\"\n{body}\n")
}

/// The error message of a configuration that must not load.
pub fn err(text: &str) -> String {
    match lidar_noise::config::Config::from_toml_str(
        text,
        std::path::Path::new("bad.toml"),
        &[],
        None,
    ) {
        Ok(_) => panic!("should fail: {text}"),
        Err(e) => e.to_string(),
    }
}

/// A return of `laser` (built-in calibration) at `range` m and `azimuth` deg, at `time` s,
/// in firing `firing` of a capture in `kind`'s return mode: 12 firings per packet, or 6
/// in dual mode, where a firing's last and strongest entries take blocks 2k and 2k + 1.
pub fn beam_return(
    laser: u8,
    range: f32,
    azimuth: f32,
    intensity: u8,
    firing: u32,
    time: f64,
    kind: lidar_noise::frame::ReturnKind,
) -> lidar_noise::frame::Return {
    use lidar_noise::frame::ReturnKind;
    let cal = lidar_noise::sensor::calibration::Calibration::builtin();
    let el = cal.lasers[laser as usize].elevation_deg as f32;
    let (se, ce) = el.to_radians().sin_cos();
    let (sa, ca) = azimuth.to_radians().sin_cos();
    let dual = matches!(kind, ReturnKind::DualLast | ReturnKind::DualStrongest);
    let block = if dual {
        (firing % 6) as u8 * 2 + u8::from(kind == ReturnKind::DualStrongest)
    } else {
        (firing % 12) as u8
    };
    lidar_noise::frame::Return {
        x: range * ce * ca,
        y: -range * ce * sa,
        z: range * se,
        range,
        azimuth,
        elevation: el,
        time,
        packet: if dual { firing / 6 } else { firing / 12 },
        raw_distance: (range / 0.002) as u16,
        intensity,
        laser,
        ring: cal.rings()[laser as usize],
        block,
        kind,
    }
}

/// The body of a PLY file: its bytes after the header.
pub fn ply_payload(path: &std::path::Path) -> Vec<u8> {
    let bytes = std::fs::read(path).unwrap();
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    bytes[end..].to_vec()
}

/// Runs `lidar-noise --quiet run` on frame 0 of the crossroad fixture once per
/// configuration text in `configs` (plus `args`), each in its own folder under `dir`;
/// returns the frame's PLY file of each run, in order.
pub fn run_frame0(dir: &std::path::Path, configs: &[&str], args: &[&str]) -> Vec<PathBuf> {
    configs
        .iter()
        .enumerate()
        .map(|(i, text)| {
            let cfg = dir.join(format!("config-{i}.toml"));
            std::fs::write(&cfg, text).unwrap();
            let out = dir.join(format!("out-{i}"));
            assert_cmd::Command::cargo_bin("lidar-noise")
                .unwrap()
                .args(["--quiet", "run"])
                .arg(fixtures().join("crossroad.pcap"))
                .arg("-c")
                .arg(&cfg)
                .args(["--frames", "0"])
                .args(args)
                .arg("-o")
                .arg(&out)
                .assert()
                .success();
            out.join("crossroad/frame_00000.ply")
        })
        .collect()
}

/// Runs `lidar-noise --quiet run` on the crossroad fixture with the configuration text
/// `config`, checks that it fails and leaves no output, and returns its error output.
pub fn refused_run(dir: &std::path::Path, config: &str) -> String {
    let cfg = dir.join("refused.toml");
    std::fs::write(&cfg, config).unwrap();
    let out = dir.join("refused");
    let o = assert_cmd::Command::cargo_bin("lidar-noise")
        .unwrap()
        .args(["--quiet", "run"])
        .arg(fixtures().join("crossroad.pcap"))
        .arg("-c")
        .arg(&cfg)
        .arg("-o")
        .arg(&out)
        .assert()
        .failure();
    assert!(
        !out.exists() || std::fs::read_dir(&out).unwrap().next().is_none(),
        "a refused run wrote into {}",
        out.display()
    );
    String::from_utf8_lossy(&o.get_output().stderr).to_string()
}

/// True when both lists hold the same returns bit for bit (position, range, angles, time,
/// intensity).
pub fn same_returns(a: &[lidar_noise::frame::Return], b: &[lidar_noise::frame::Return]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(x, y)| {
            x.x.to_bits() == y.x.to_bits()
                && x.y.to_bits() == y.y.to_bits()
                && x.z.to_bits() == y.z.to_bits()
                && x.range.to_bits() == y.range.to_bits()
                && x.azimuth.to_bits() == y.azimuth.to_bits()
                && x.elevation.to_bits() == y.elevation.to_bits()
                && x.time.to_bits() == y.time.to_bits()
                && x.intensity == y.intensity
        })
}

/// Exit code of a refused output folder (README and manual, exit codes).
pub const EXIT_REFUSED: i32 = 3;

/// The `lidar-noise` binary on two worker threads.
pub fn bin2() -> assert_cmd::Command {
    let mut c = assert_cmd::Command::cargo_bin("lidar-noise").unwrap();
    c.env("RAYON_NUM_THREADS", "2");
    c
}

/// Synthesizes `rotations` turns of `scene_args` for `sensor` (a `synth --sensor` name)
/// into `dir/<sensor>`; the capture written.
pub fn synth_capture(
    dir: &std::path::Path,
    sensor: &str,
    scene_args: &[&str],
    rotations: u32,
) -> PathBuf {
    let out = dir.join(sensor);
    bin2()
        .args(["--quiet", "synth", "--sensor", sensor, "--rotations"])
        .arg(rotations.to_string())
        .args(scene_args)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "pcap"))
        .expect("synth wrote a capture")
}

/// `run INPUT ARGS -c CONFIG -o OUT` (quiet, two threads), which must succeed.
pub fn run_ok(
    input: &std::path::Path,
    args: &[&str],
    config: &std::path::Path,
    out: &std::path::Path,
) {
    bin2()
        .args(["--quiet", "run"])
        .arg(input)
        .args(args)
        .arg("-c")
        .arg(config)
        .arg("-o")
        .arg(out)
        .assert()
        .success();
}

/// The crossroad fixture capture.
pub fn crossroad() -> PathBuf {
    fixtures().join("crossroad.pcap")
}

/// A return of `laser` in firing `firing` of a 10 Hz rotation: azimuth `firing` x
/// `az_step_deg` (wrapped to a turn), firing time 100 s + 46.08 us per firing + 1.152 us
/// per laser (the HDL-32E's firing timing), as [`beam_return`] builds it.
pub fn firing_return(
    laser: u8,
    range: f32,
    intensity: u8,
    firing: u32,
    az_step_deg: f32,
    kind: lidar_noise::frame::ReturnKind,
) -> lidar_noise::frame::Return {
    let time = 100.0 + f64::from(firing) * 46.08e-6 + f64::from(laser) * 1.152e-6;
    let azimuth = (firing as f32 * az_step_deg) % 360.0;
    beam_return(laser, range, azimuth, intensity, firing, time, kind)
}

/// The intensity byte the default power model reports for an echo of `power` at `range`
/// m: reflectivity rho = P / p_th x rho_ref x (R / z_ref)^2 (p_th 1e-3, rho_ref 0.1,
/// z_ref 100 m), clamped to [0, 1], on the 0-100 scale.
pub fn echo_byte(power: f64, range: f32) -> u8 {
    let q = f64::from(range) / 100.0;
    let rho = (power / 1e-3 * 0.1 * q * q).clamp(0.0, 1.0);
    // A reported echo crossed the threshold: its byte is at least 1 (issue 50).
    ((rho * 100.0).round() as u8).max(1)
}

/// Writes the classic pcap `src` repeated `n` times, record times shifted so that each
/// copy follows the last (payloads unchanged: frames repeat).
pub fn repeated(src: &std::path::Path, n: u32, dst: &std::path::Path) {
    let data = std::fs::read(src).unwrap();
    let (header, body) = data.split_at(24);
    let mut records = Vec::new();
    let mut at = 0;
    while at + 16 <= body.len() {
        let len = u32::from_le_bytes(body[at + 8..at + 12].try_into().unwrap()) as usize;
        records.push(&body[at..at + 16 + len]);
        at += 16 + len;
    }
    let secs = |r: &[u8]| u32::from_le_bytes(r[..4].try_into().unwrap());
    let span = secs(records[records.len() - 1]) - secs(records[0]) + 1;
    let mut out = header.to_vec();
    for k in 0..n {
        for r in &records {
            out.extend_from_slice(&(secs(r) + k * span).to_le_bytes());
            out.extend_from_slice(&r[4..]);
        }
    }
    std::fs::write(dst, out).unwrap();
}

/// The frame as a KITTI `.bin`: x y z reflectance 0-1, float32 little-endian.
pub fn kitti_bytes(frame: &lidar_noise::frame::Frame) -> Vec<u8> {
    frame
        .returns
        .iter()
        .flat_map(|r| {
            [r.x, r.y, r.z, f32::from(r.intensity) / 255.0]
                .into_iter()
                .flat_map(f32::to_le_bytes)
        })
        .collect()
}

/// Runs `args` on `scan` (a point-cloud scan or a capture), expects exit 1 with `what` in
/// the message and no output folder.
pub fn refused_scan(scan: &std::path::Path, args: &[&str], what: &str) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = bin2()
        .arg("run")
        .arg(scan)
        .args(args)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains(what), "{err}");
    assert!(!out.exists(), "{} was written", out.display());
}

/// Whether the golden tests rewrite their goldens instead of comparing with them: the one
/// switch `LIDAR_NOISE_BLESS=1` (any value but empty or `0`), set by hand after a
/// deliberate change, whose `git diff tests/golden` is then reviewed. Tests never rewrite a
/// golden without it.
pub fn bless() -> bool {
    std::env::var_os("LIDAR_NOISE_BLESS").is_some_and(|v| !v.is_empty() && v != "0")
}

/// Writes `text` over the golden `rel` (a path under the project root) when blessing, with
/// a note on standard error; returns whether it did, so that the caller skips comparing.
pub fn bless_golden(rel: &str, text: &[u8]) -> bool {
    if !bless() {
        return false;
    }
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(rel);
    std::fs::write(&path, text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    eprintln!("BLESSED: rewrote {rel}; review `git diff tests/golden`");
    true
}

/// The `lidar-noise` binary under test.
pub fn bin() -> assert_cmd::Command {
    assert_cmd::Command::cargo_bin("lidar-noise").unwrap()
}

/// The `lidar-noise` binary as a plain process (for tests that read its output as it
/// comes, or feed or kill it).
pub fn command() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_lidar-noise"))
}

/// [`command`] run from the project root, where `fixtures/` and `configs/` resolve.
pub fn command_at_root() -> std::process::Command {
    let mut c = command();
    c.current_dir(env!("CARGO_MANIFEST_DIR"));
    c
}

/// A rotation of the built-in 32-laser sensor as frame `index`: for each firing in
/// `0..firings`, lasers 0 to 31 in turn, the return `make(firing, laser)` gives (`None`
/// for an empty slot). The modules' synthetic `turn`s differ only in `make`.
pub fn rotation(
    index: u32,
    firings: u32,
    mut make: impl FnMut(u32, u8) -> Option<lidar_noise::frame::Return>,
) -> lidar_noise::frame::Frame {
    let mut returns = Vec::new();
    for f in 0..firings {
        for l in 0..32u8 {
            returns.extend(make(f, l));
        }
    }
    lidar_noise::frame::Frame {
        index,
        partial: false,
        returns,
    }
}

/// A file of the project's fixture directory.
pub fn fixture(name: &str) -> PathBuf {
    fixtures().join(name)
}

/// The default configuration's ideal received power (power model, sensor, detection).
pub fn ideal() -> lidar_noise::noise::IdealPower {
    let c = config("seed = 1\n");
    lidar_noise::noise::IdealPower::new(&c.power, &c.sensor, &c.detection)
}
