//! `lidar-noise synth`: writes a synthetic capture (HDL-32E by default, any described
//! sensor with `--sensor NAME`) with ground-truth labels.

use anyhow::{bail, Context};
use lidar_noise::synth::scene::random_scene;
use lidar_noise::synth::{labels, objects_json, write_capture, Scene, SynthOptions};
use lidar_noise::writers::atomic::temp_file_for;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// Arguments of `lidar-noise synth`.
#[derive(Debug, clap::Args)]
pub struct SynthArgs {
    /// Scene description (TOML); omit when using --preset or --random.
    #[arg(
        value_name = "SCENE.toml",
        conflicts_with_all = ["preset", "random"],
        required_unless_present_any = ["preset", "random"]
    )]
    pub scene: Option<PathBuf>,
    /// Built-in scene: crossroad, parking or empty.
    #[arg(long, value_name = "NAME", conflicts_with = "random")]
    pub preset: Option<String>,
    /// A randomized street scene (slope, curbs, objects) drawn from SEED; named
    /// random-SEED, one rotation unless --rotations says otherwise.
    #[arg(long, value_name = "SEED")]
    pub random: Option<u64>,
    /// Output folder (created if missing).
    #[arg(short = 'o', long = "output", value_name = "DIR")]
    pub output: PathBuf,
    /// Number of full rotations (overrides the scene). `--frames` is a deprecated
    /// spelling: elsewhere `--frames` picks a frame range.
    #[arg(long = "rotations", value_name = "N", alias = "frames")]
    pub frames: Option<u32>,
    /// Range-noise seed (overrides the scene).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Cast every laser of a block at the block azimuth instead of interpolating
    /// towards the next block (`--no-interpolation` is the old spelling).
    #[arg(long = "no-interpolate", alias = "no-interpolation")]
    pub no_interpolation: bool,
    /// Sensor to synthesize: HDL-32E (default), VLP-16, "Puck Hi-Res", VLP-32C,
    /// "HDL-64E S2", "HDL-64E S3", VLS-128 or "VLS-128 fw5.1" (case, spaces and dashes
    /// ignored: vlp16, hdl64e-s3, vls128).
    #[arg(long, value_name = "NAME")]
    pub sensor: Option<String>,
}

/// Runs `lidar-noise synth`: writes DIR/<name>.pcap, DIR/<name>.labels.csv.gz and
/// DIR/<name>.objects.json, each through a temporary file renamed into place.
pub fn run(args: SynthArgs, global: crate::cli::Global) -> anyhow::Result<()> {
    let mut scene = match (&args.scene, &args.preset, args.random) {
        (Some(path), None, None) => Scene::from_file(path)?,
        (None, Some(name), None) => Scene::preset(name)?,
        (None, None, Some(seed)) => random_scene(seed),
        _ => bail!("give one of a scene file, --preset NAME or --random SEED"),
    };
    if let Some(frames) = args.frames {
        if !(1..=100_000).contains(&frames) {
            bail!("--rotations {frames}: must be 1..100000");
        }
        scene.frames = frames;
    }
    if let Some(seed) = args.seed {
        scene.seed = seed;
    }
    let sensor = match &args.sensor {
        Some(name) => {
            lidar_noise::sensor::by_name(name).map_err(|e| anyhow::anyhow!("--sensor: {e}"))?
        }
        None => &lidar_noise::sensor::HDL32E,
    };
    let (lo, hi) = sensor.rotation_hz;
    let hz = scene.sensor.rotation_hz;
    if sensor.name != lidar_noise::sensor::HDL32E.name && !(lo..=hi).contains(&hz) {
        bail!(
            "--sensor {}: the scene turns the sensor at {hz} Hz, the {} turns at {lo} to {hi} Hz \
             (set [sensor] rotation_hz in a scene file)",
            sensor.name,
            sensor.name
        );
    }
    let options = SynthOptions {
        interpolate: !args.no_interpolation,
        sensor,
        ..SynthOptions::default()
    };
    let dir = &args.output;
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let pcap_path = dir.join(format!("{}.pcap", scene.name));
    let labels_path = dir.join(format!("{}.labels.{}", scene.name, labels::EXTENSION));
    let objects_path = dir.join(format!("{}.objects.json", scene.name));
    if let Some(input) = &args.scene {
        for out in [&pcap_path, &labels_path, &objects_path] {
            if same_file(input, out) {
                bail!(
                    "{}: refusing to overwrite the input scene file",
                    out.display()
                );
            }
        }
    }

    let pcap_tmp = temp_file_for(&pcap_path)?;
    let labels_tmp = temp_file_for(&labels_path)?;
    let (summary, pcap_w, labels_w) = write_capture(
        &scene,
        &options,
        BufWriter::new(pcap_tmp),
        BufWriter::new(labels_tmp),
    )
    .with_context(|| format!("{}: cannot write", dir.display()))?;
    let pcap_tmp = pcap_w
        .into_inner()
        .map_err(|e| e.into_error())
        .with_context(|| format!("{}: cannot write", pcap_path.display()))?;
    let labels_tmp = labels_w
        .into_inner()
        .map_err(|e| e.into_error())
        .with_context(|| format!("{}: cannot write", labels_path.display()))?;
    let mut objects_tmp = temp_file_for(&objects_path)?;
    objects_tmp
        .write_all(objects_json(&scene).as_bytes())
        .and_then(|_| objects_tmp.write_all(b"\n"))
        .with_context(|| format!("{}: cannot write", objects_path.display()))?;
    for (tmp, path) in [
        (pcap_tmp, &pcap_path),
        (labels_tmp, &labels_path),
        (objects_tmp, &objects_path),
    ] {
        tmp.as_file()
            .sync_all()
            .with_context(|| format!("{}: cannot write", path.display()))?;
        tmp.persist(path)
            .with_context(|| format!("{}: cannot rename into place", path.display()))?;
    }
    if global.quiet {
        return Ok(());
    }
    eprintln!(
        "{}: {} {} rotations at {} Hz, {} records ({} data, {} position), {} returns",
        scene.name,
        sensor.name,
        summary.frames,
        scene.sensor.rotation_hz,
        summary.records,
        summary.data_packets,
        summary.position_packets,
        summary.returns
    );
    eprintln!(
        "wrote {}, {}, {}",
        pcap_path.display(),
        labels_path.display(),
        objects_path.display()
    );
    Ok(())
}

/// True when both paths name the same existing file.
fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}
