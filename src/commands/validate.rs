//! `lidar-noise validate`: checks an experiment configuration and lists its stages.

use lidar_noise::config::Config;
use std::path::PathBuf;

/// Arguments of `lidar-noise validate`.
#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// Configuration file (TOML); the built-in configs/paper.toml when omitted.
    #[arg(value_name = "CONFIG")]
    pub config: Option<PathBuf>,
    /// The configuration file as `run` and `sweep` take it (same as CONFIG).
    #[arg(
        short = 'c',
        long = "config",
        value_name = "FILE",
        conflicts_with = "config"
    )]
    pub config_file: Option<PathBuf>,
    /// Override a key before validation, e.g. `noise[1].rate_mm_h=3` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Override the seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Print the effective configuration (overrides applied, defaults filled in) as TOML
    /// to stdout instead of the summary; save it to rerun the same experiment.
    #[arg(long)]
    pub print: bool,
}

/// Validates the configuration: prints "CONFIG: ok" and the stage list to stdout and the
/// warnings to stderr, or returns the error naming key and line.
pub fn run(args: Args, global: crate::cli::Global) -> anyhow::Result<()> {
    let path = args.config.as_deref().or(args.config_file.as_deref());
    let (config, warnings) = Config::load(path, &args.set, args.seed)?;
    for w in &warnings {
        global.warn(w);
    }
    use std::fmt::Write as _;
    let mut out = String::new();
    if args.print {
        let _ = writeln!(
            out,
            "# effective configuration of {}\n# written by lidar-noise {} (validate --print)\n",
            config.provenance(),
            env!("CARGO_PKG_VERSION")
        );
        out.push_str(&config.effective_toml());
        return super::write_stdout(out);
    }
    let _ = writeln!(out, "{}: ok", config.source.display());
    let _ = writeln!(out, "seed {}", config.seed);
    if config.noise.is_empty() {
        out.push_str("no noise stages\n");
    }
    for line in config.stage_lines() {
        let _ = writeln!(out, "{line}");
    }
    let _ = writeln!(
        out,
        "detection: min_power {} of emitted power, min_range {} m",
        config.detection.min_power, config.detection.min_range_m
    );
    super::write_stdout(out)
}
