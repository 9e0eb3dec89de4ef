//! Command-line parsing: turns arguments into a command and its settings.

use crate::commands;
use clap::{Parser, Subcommand};

/// Exit code for success.
pub const EXIT_OK: i32 = 0;
/// Exit code for an error in the input, the configuration or the file system.
pub const EXIT_ERROR: i32 = 1;
/// Exit code for a command-line usage error (clap's own).
pub const EXIT_USAGE: i32 = 2;

/// Shows what rain and a dirty lens do to an HDL-32E LiDAR.
#[derive(Debug, Parser)]
#[command(name = "lidar-noise", version, about, long_about = None)]
pub struct Cli {
    /// Print no warnings and no progress (errors are still printed).
    #[arg(long, short, global = true)]
    pub quiet: bool,
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run the whole pipeline: noise, detection filters, ground, clusters, reports.
    Run(commands::run::Args),
    /// Describe a capture: format, packets, sensor, frames, returns.
    Info(commands::info::Args),
    /// Decode a capture to one PLY point cloud per frame.
    Convert(commands::convert::Args),
    /// Check an experiment configuration without running it.
    Validate(commands::validate::Args),
    /// Ray-cast a scene into a synthetic HDL-32E capture with ground-truth labels.
    Synth(commands::synth::SynthArgs),
    /// Run every combination of varied settings and seeds; tables, plots and a web page.
    Sweep(commands::sweep::Args),
    /// Compare two result folders field by field (exit 0 same, 1 different).
    Compare(commands::compare::Args),
}

/// Settings every command receives.
#[derive(Clone, Copy, Debug)]
pub struct Global {
    /// Suppress warnings and progress bars.
    pub quiet: bool,
}

impl Global {
    /// Prints a warning to stderr unless quiet.
    pub fn warn(&self, message: &str) {
        if !self.quiet {
            eprintln!("lidar-noise: warning: {message}");
        }
    }
}

/// Runs the command line and returns the process exit code.
pub fn main() -> i32 {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            let code = if e.use_stderr() { EXIT_USAGE } else { EXIT_OK };
            let _ = e.print();
            return code;
        }
    };
    let global = Global { quiet: cli.quiet };
    let result = match cli.command {
        Command::Run(args) => commands::run::run(args, global),
        Command::Info(args) => commands::info::run(args, global),
        Command::Convert(args) => commands::convert::run(args, global),
        Command::Validate(args) => commands::validate::run(args, global),
        Command::Synth(args) => commands::synth::run(args, global),
        Command::Sweep(args) => commands::sweep::run(args, global),
        // compare has three outcomes (same, different, unusable), not two.
        Command::Compare(args) => return commands::compare::run(args, global),
    };
    match result {
        Ok(()) => EXIT_OK,
        Err(e) => {
            eprintln!("lidar-noise: error: {e:#}");
            EXIT_ERROR
        }
    }
}
