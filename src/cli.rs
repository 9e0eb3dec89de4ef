//! Command-line parsing: turns arguments into a command and its settings.

use crate::commands;
use clap::{CommandFactory, Parser, Subcommand};
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use lidar_noise::error::message_of;
use lidar_noise::observe::{Counter, Observer};
use std::sync::Mutex;

/// Exit code for success.
pub const EXIT_OK: i32 = 0;
/// Exit code for an error in the input, the configuration or the file system.
pub const EXIT_ERROR: i32 = 1;
/// Exit code for a command-line usage error (clap's own).
pub const EXIT_USAGE: i32 = 2;
/// Exit code for an output folder that holds another run's results (rerun with `--force`)
/// or files this tool did not write.
pub const EXIT_REFUSED: i32 = 3;

/// Shows what rain and a dirty lens do to an HDL-32E LiDAR.
#[derive(Debug, Parser)]
#[command(name = "lidar-noise", version, about, long_about = None)]
pub struct Cli {
    /// Print no warnings and no progress (errors are still printed).
    #[arg(long, short, global = true)]
    pub quiet: bool,
    /// Worker threads (default: one per core, or RAYON_NUM_THREADS); outputs do not
    /// depend on it.
    #[arg(long, global = true, value_name = "N", value_parser = clap::value_parser!(u16).range(1..))]
    pub threads: Option<u16>,
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run the whole pipeline: noise, detection filters, ground, clusters, reports.
    #[command(after_help = "Examples:
  lidar-noise run                                   # the built-in crossroad scan -> lidar-noise-out/
  lidar-noise run scan.pcap -c configs/rain.toml --set rain.rate_mm_h=3 --seed 7 -o out
  lidar-noise run scan.pcap --keep-dropped --format laz --frames 0..9")]
    Run(commands::run::Args),
    /// Describe a capture: format, packets, sensor, frames, returns.
    #[command(after_help = "Examples:
  lidar-noise info scan.pcap
  lidar-noise info *.pcap --json | jq .full_frames
  tcpdump -r big.pcap -w - 'udp port 2368' | lidar-noise info -")]
    Info(commands::info::Args),
    /// Decode captures to one point cloud (PLY, LAS or LAZ) per frame, without noise.
    #[command(after_help = "Examples:
  lidar-noise convert scan.pcap -o frames --frames 0..9
  lidar-noise convert a.pcap b.pcap -o frames --format laz      # frames/a/, frames/b/
  lidar-noise convert scan.pcap -o frames --ply-style cloudcompare")]
    Convert(commands::convert::Args),
    /// Check an experiment configuration without running it.
    #[command(after_help = "Examples:
  lidar-noise validate configs/rain.toml
  lidar-noise validate -c configs/paper.toml --set rain.rate_mm_h=1 --seed 3
  lidar-noise validate -c configs/paper.toml --set rain.rate_mm_h=1 --print > my.toml")]
    Validate(commands::validate::Args),
    /// List every noise stage type with its options, units, defaults and sources.
    #[command(after_help = "Examples:
  lidar-noise stages
  lidar-noise stages --markdown > docs/stages.md")]
    Stages(commands::stages::Args),
    /// Ray-cast a scene into a synthetic HDL-32E capture with ground-truth labels.
    #[command(after_help = "Examples:
  lidar-noise synth --preset crossroad -o scenes
  lidar-noise synth my-scene.toml --rotations 20 --seed 4 -o scenes")]
    Synth(commands::synth::SynthArgs),
    /// Run every combination of varied settings and seeds; tables, plots and a web page.
    #[command(after_help = "Examples:
  lidar-noise sweep scan.pcap --vary rain.rate_mm_h=0,1,3,7 --vary occlusion=on,off -o sweep-out
  lidar-noise sweep a.pcap b.pcap --config configs/paper.toml --vary rain.rate_mm_h=0,7 --seeds 1..5 -o out")]
    Sweep(commands::sweep::Args),
    /// Compare two result folders field by field (exit 0 same, 1 different, 2 usage).
    #[command(after_help = "Examples:
  lidar-noise compare tests/expected out
  lidar-noise compare expected out --tolerance ground_fraction=1e-9 --tolerance power=0.1%
  lidar-noise compare expected out --junit compare-junit.xml")]
    Compare(commands::compare::Args),
    /// Print a shell completion script to stdout.
    #[command(after_help = "Examples:
  lidar-noise completions bash > ~/.local/share/bash-completion/completions/lidar-noise
  lidar-noise completions zsh > ~/.zfunc/_lidar-noise
  lidar-noise completions fish > ~/.config/fish/completions/lidar-noise.fish")]
    Completions {
        /// The shell.
        #[arg(value_enum)]
        shell: clap_complete::Shell,
    },
    /// Print the manual page (roff) to stdout.
    #[command(after_help = "Examples:
  lidar-noise man > lidar-noise.1 && man ./lidar-noise.1
  lidar-noise man | gzip > /usr/local/share/man/man1/lidar-noise.1.gz")]
    Man,
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

/// Warnings and status lines on stderr, no progress (for commands that draw none).
impl Observer for Global {
    fn warn(&self, message: &str) {
        Global::warn(self, message);
    }
    fn note(&self, message: &str) {
        if !self.quiet {
            eprintln!("{message}");
        }
    }
}

/// The command line's [`Observer`]: warnings and status lines on stderr, progress bars
/// on stderr when it is a terminal; nothing but errors when quiet.
pub struct Console {
    global: Global,
    /// Progress is drawn (not quiet, stderr a terminal).
    visible: bool,
    multi: MultiProgress,
    /// The bar of each counter started, in the order started.
    bars: Mutex<Vec<(Counter, ProgressBar)>>,
}

impl Console {
    /// A console for the settings of `global`.
    pub fn new(global: Global) -> Console {
        use std::io::IsTerminal;
        let visible = !global.quiet && std::io::stderr().is_terminal();
        Console {
            global,
            visible,
            multi: MultiProgress::with_draw_target(if visible {
                ProgressDrawTarget::stderr()
            } else {
                ProgressDrawTarget::hidden()
            }),
            bars: Mutex::new(Vec::new()),
        }
    }

    /// The bar of `counter`, if started.
    fn bar(&self, counter: Counter) -> Option<ProgressBar> {
        let bars = self.bars.lock().unwrap_or_else(|e| e.into_inner());
        bars.iter()
            .find(|(c, _)| *c == counter)
            .map(|(_, b)| b.clone())
    }
}

impl Observer for Console {
    fn warn(&self, message: &str) {
        self.multi.suspend(|| self.global.warn(message));
    }
    fn note(&self, message: &str) {
        if !self.global.quiet {
            self.multi.suspend(|| eprintln!("{message}"));
        }
    }
    fn shows_progress(&self) -> bool {
        self.visible
    }
    fn start(&self, counter: Counter, total: Option<u64>) {
        if !self.visible {
            return;
        }
        let unit = counter.unit();
        let (bar, template) = match total {
            Some(n) => (
                ProgressBar::new(n),
                format!(
                    "{{bar:30}} {{pos}}/{{len}} {unit} {{elapsed}} elapsed, {{eta}} left {{msg}}"
                ),
            ),
            None => (
                ProgressBar::new_spinner(),
                format!("{{spinner}} {{pos}} {unit} {{elapsed}} {{msg}}"),
            ),
        };
        if let Ok(style) = ProgressStyle::with_template(&template) {
            bar.set_style(style);
        }
        let mut bars = self.bars.lock().unwrap_or_else(|e| e.into_inner());
        match bars.iter_mut().find(|(c, _)| *c == counter) {
            // Started again (a sweep's frames, capture by capture): in its place.
            Some((_, old)) => {
                let bar = self.multi.insert_after(old, bar);
                old.finish_and_clear();
                self.multi.remove(old);
                *old = bar;
                old.enable_steady_tick(std::time::Duration::from_millis(200));
            }
            None => {
                let bar = self.multi.add(bar);
                bar.enable_steady_tick(std::time::Duration::from_millis(200));
                bars.push((counter, bar));
            }
        }
    }
    fn set_total(&self, counter: Counter, total: u64) {
        if let Some(bar) = self.bar(counter) {
            bar.set_length(total);
        }
    }
    fn label(&self, counter: Counter, label: &str) {
        if let Some(bar) = self.bar(counter) {
            bar.set_message(label.to_string());
        }
    }
    fn advance(&self, counter: Counter, n: u64) {
        if let Some(bar) = self.bar(counter) {
            bar.inc(n);
        }
    }
    fn finish(&self, counter: Counter) {
        let mut bars = self.bars.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(i) = bars.iter().position(|(c, _)| *c == counter) {
            let (_, bar) = bars.remove(i);
            bar.finish_and_clear();
            self.multi.remove(&bar);
        }
    }
}

impl Drop for Console {
    /// Bars of a call that failed go before its error is printed.
    fn drop(&mut self) {
        let bars = self.bars.get_mut().unwrap_or_else(|e| e.into_inner());
        for (_, bar) in bars.drain(..) {
            bar.finish_and_clear();
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
    lidar_noise::signals::install();
    let global = Global { quiet: cli.quiet };
    if let Some(n) = cli.threads {
        lidar_noise::par::set_worker_threads(usize::from(n));
        if let Err(e) = rayon::ThreadPoolBuilder::new()
            .num_threads(usize::from(n))
            .build_global()
        {
            eprintln!("lidar-noise: error: --threads {n}: {e}");
            return EXIT_ERROR;
        }
    }
    let result = match cli.command {
        Command::Run(args) => commands::run::run(args, global),
        Command::Info(args) => commands::info::run(args, global),
        Command::Convert(args) => commands::convert::run(args, global),
        Command::Validate(args) => commands::validate::run(args, global),
        Command::Stages(args) => commands::stages::run(args),
        Command::Synth(args) => commands::synth::run(args, global),
        Command::Sweep(args) => commands::sweep::run(args, global),
        // compare has three outcomes (same, different, unusable), not two.
        Command::Compare(args) => return commands::compare::run(args, global),
        Command::Completions { shell } => {
            // Into memory first: clap_complete panics when its writer fails.
            let mut script = Vec::new();
            clap_complete::generate(shell, &mut Cli::command(), "lidar-noise", &mut script);
            commands::write_stdout(script)
        }
        Command::Man => clap_mangen::Man::new(Cli::command())
            .render(&mut std::io::stdout())
            .map_err(anyhow::Error::from),
    };
    match result {
        Ok(()) => EXIT_OK,
        // A reader that closed our stdout (`info X | head -1`) wanted no more: not an error.
        Err(e) if is_broken_pipe(&e) => EXIT_OK,
        Err(e)
            if e.chain().any(|c| {
                c.downcast_ref::<lidar_noise::writers::staging::Refused>()
                    .is_some()
            }) =>
        {
            eprintln!("lidar-noise: error: {}", message_of(&e));
            EXIT_REFUSED
        }
        Err(e) => {
            eprintln!("lidar-noise: error: {}", message_of(&e));
            EXIT_ERROR
        }
    }
}

/// True when the error comes from writing to a closed pipe.
pub(crate) fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}
