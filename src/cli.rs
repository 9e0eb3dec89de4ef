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
    crate::signals::install();
    let global = Global { quiet: cli.quiet };
    let result = match cli.command {
        Command::Run(args) => commands::run::run(args, global),
        Command::Info(args) => commands::info::run(args, global),
        Command::Convert(args) => commands::convert::run(args, global),
        Command::Validate(args) => commands::validate::run(args, global),
        Command::Synth(args) => commands::synth::run(args, global),
        Command::Sweep(args) => commands::sweep::run(args, global),
    };
    match result {
        Ok(()) => EXIT_OK,
        // A reader that closed our stdout (`info X | head -1`) wanted no more: not an error.
        Err(e) if is_broken_pipe(&e) => EXIT_OK,
        Err(e) => {
            eprintln!("lidar-noise: error: {}", message_of(&e));
            EXIT_ERROR
        }
    }
}

/// True when the error comes from writing to a closed pipe.
fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// The error and its causes joined by ": ", leaving out a cause whose text the message
/// already ends with (our errors print their source themselves, so `{:#}` said it twice).
pub fn message_of(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain() {
        let part = cause.to_string();
        if text.ends_with(&part) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&part);
    }
    text
}
