//! `lidar-noise stages`: every noise stage type with its options, generated from the
//! registry (each stage declares its option specs), so the list cannot drift from code.

use lidar_noise::noise::REGISTRY;

/// Arguments of `lidar-noise stages`.
#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// Write Markdown tables instead of plain text.
    #[arg(long)]
    pub markdown: bool,
}

/// The listing as text (plain or Markdown).
pub fn listing(markdown: bool) -> String {
    let mut out = String::new();
    for k in REGISTRY {
        if markdown {
            out.push_str(&format!(
                "### `{}` (p-diagram {})\n\nModel: {}.\n\nSource: {}.\n\n| option | unit | default | meaning |\n|---|---|---|---|\n",
                k.name, k.factor, k.model, k.source
            ));
            for o in k.options {
                out.push_str(&format!(
                    "| `{}` | {} | {} | {} |\n",
                    o.name, o.unit, o.default, o.doc
                ));
            }
            out.push('\n');
        } else {
            out.push_str(&format!(
                "{} (p-diagram {})\n  model:  {}\n  source: {}\n",
                k.name, k.factor, k.model, k.source
            ));
            for o in k.options {
                out.push_str(&format!(
                    "  {:<22} {:<9} default {:<10} {}\n",
                    o.name, o.unit, o.default, o.doc
                ));
            }
            out.push('\n');
        }
    }
    out
}

/// Prints the listing to stdout.
pub fn run(args: Args) -> anyhow::Result<()> {
    super::write_stdout(listing(args.markdown))
}
