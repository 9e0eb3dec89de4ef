//! The Python package (python/, issue 32) under the README's one test command: builds the
//! wheel with maturin in a temporary virtual environment and runs its pytest suite, which
//! checks `Chain.apply` against this build's `lidar-noise run` on every configuration.
//!
//! Affordable: the wheel is built once into `target/python` (release, the same build the
//! CI step `maturin build --release` reuses), so later runs only relink what changed.
//! Where python3, the venv module or the network (PyPI for maturin, numpy, pytest) is
//! missing, or `LIDAR_NOISE_SKIP_PYTHON` is set, it prints `SKIPPED: <reason>` and passes.

use std::path::{Path, PathBuf};
use std::process::Command;

fn skip(reason: &str) {
    println!("SKIPPED: {reason}");
    eprintln!("SKIPPED: {reason}");
}

/// Runs `cmd`, returning its combined output on failure.
fn run(cmd: &mut Command) -> Result<(), String> {
    let out = cmd
        .output()
        .map_err(|e| format!("{:?}: {e}", cmd.get_program()))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "{:?} {:?} failed ({}):\n{}\n{}",
            cmd.get_program(),
            cmd.get_args().collect::<Vec<_>>(),
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        ))
    }
}

#[test]
fn python_package_builds_and_its_tests_pass() {
    if std::env::var_os("LIDAR_NOISE_SKIP_PYTHON").is_some() {
        return skip("LIDAR_NOISE_SKIP_PYTHON is set");
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let python = match ["python3", "python"].into_iter().find(|p| {
        Command::new(p)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success())
    }) {
        Some(p) => p,
        None => return skip("no python3 on the PATH"),
    };
    let tmp = tempfile::tempdir().expect("temporary folder");
    let venv = tmp.path().join("venv");
    if let Err(e) = run(Command::new(python).args(["-m", "venv"]).arg(&venv)) {
        return skip(&format!("python3 -m venv failed: {e}"));
    }
    let bin = venv.join("bin");
    let pip = bin.join("pip");
    if let Err(e) = run(Command::new(&pip).args([
        "install",
        "--quiet",
        "--disable-pip-version-check",
        "maturin>=1.5,<2",
        "numpy",
        "pytest",
    ])) {
        return skip(&format!(
            "could not install maturin, numpy and pytest from PyPI (no network?): {}",
            e.lines().last().unwrap_or("")
        ));
    }
    let target: PathBuf = root.join("target").join("python");
    let wheels = tmp.path().join("wheels");
    run(Command::new(bin.join("maturin"))
        .args(["build", "--release", "--quiet", "--manifest-path"])
        .arg(root.join("python").join("Cargo.toml"))
        .arg("--out")
        .arg(&wheels)
        .arg("--interpreter")
        .arg(bin.join("python"))
        .env("CARGO_TARGET_DIR", &target))
    .expect("maturin build of python/");
    let wheel = std::fs::read_dir(&wheels)
        .expect("wheel folder")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|x| x == "whl"))
        .expect("a wheel");
    run(Command::new(&pip)
        .args([
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "--no-deps",
        ])
        .arg(&wheel))
    .expect("installing the wheel");
    // Run from the tests' folder, not python/, so that the installed wheel is imported
    // (python/lidar_noise has no compiled module).
    let status = Command::new(bin.join("python"))
        .args(["-m", "pytest", "-q", "-p", "no:cacheprovider"])
        .arg(root.join("python").join("tests"))
        .current_dir(tmp.path())
        .env("LIDAR_NOISE_BIN", env!("CARGO_BIN_EXE_lidar-noise"))
        .status()
        .expect("pytest");
    assert!(
        status.success(),
        "the Python package's tests failed (above)"
    );
}
