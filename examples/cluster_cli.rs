//! Clusters a CSV point cloud with lidar-noise, for cross-checks against SciPy.
//!
//! `cluster_cli points.csv --cut distance|inconsistent|maxclust --t T [--max-edge M]
//!  --labels labels.csv --linkage linkage.csv`
//! The input has a header and columns x,y,z. For `distance` T is the cutoff in metres, for
//! `inconsistent` the coefficient threshold (depth 2), for `maxclust` the cluster count.

use anyhow::{bail, Context, Result};
use clap::{Parser, ValueEnum};
use lidar_noise::cluster::{cluster, linkage, write_linkage_csv, ClusterOptions, CutRule};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

#[derive(Clone, Copy, ValueEnum)]
enum Cut {
    Distance,
    Inconsistent,
    Maxclust,
}

#[derive(Parser)]
struct Args {
    /// CSV with header and columns x,y,z.
    input: PathBuf,
    /// Cut rule.
    #[arg(long, value_enum)]
    cut: Cut,
    /// Threshold: cutoff (m), inconsistency coefficient or number of clusters.
    #[arg(long)]
    t: f64,
    /// Longest merge-tree edge in metres (infinite: the complete tree).
    #[arg(long, default_value_t = f64::INFINITY)]
    max_edge: f64,
    /// Output CSV of labels, one per input point.
    #[arg(long)]
    labels: PathBuf,
    /// Output CSV of the linkage matrix.
    #[arg(long)]
    linkage: PathBuf,
}

fn read_points(path: &Path) -> Result<Vec<[f32; 3]>> {
    let mut rdr = csv::Reader::from_path(path).with_context(|| format!("{}", path.display()))?;
    let mut pts = Vec::new();
    for (i, rec) in rdr.records().enumerate() {
        let rec = rec.with_context(|| format!("{}: record {}", path.display(), i + 1))?;
        if rec.len() < 3 {
            bail!("{}: line {}: expected x,y,z", path.display(), i + 2);
        }
        let mut p = [0f32; 3];
        for (k, v) in p.iter_mut().enumerate() {
            *v = rec[k].trim().parse().with_context(|| {
                format!(
                    "{}: line {}, column {}: not a number",
                    path.display(),
                    i + 2,
                    k + 1
                )
            })?;
        }
        pts.push(p);
    }
    Ok(pts)
}

/// Writes through a temporary file in the target folder, renamed into place when complete.
fn write_atomic(
    path: &Path,
    body: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<()> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut tmp =
        tempfile::NamedTempFile::new_in(dir).with_context(|| format!("{}", dir.display()))?;
    {
        let mut w = BufWriter::new(tmp.as_file_mut());
        body(&mut w).with_context(|| format!("{}", path.display()))?;
        w.flush()?;
    }
    tmp.persist(path)
        .with_context(|| format!("{}", path.display()))?;
    Ok(())
}

fn main() -> Result<()> {
    let args = Args::parse();
    let pts = read_points(&args.input)?;
    let cut = match args.cut {
        Cut::Distance => CutRule::Distance,
        Cut::Inconsistent => CutRule::Inconsistent { threshold: args.t },
        Cut::Maxclust => {
            if args.t < 1.0 || args.t.fract() != 0.0 {
                bail!(
                    "--t: maxclust needs a whole number of clusters >= 1, got {}",
                    args.t
                );
            }
            CutRule::MaxClust { k: args.t as usize }
        }
    };
    let opts = ClusterOptions {
        cut,
        cutoff_m: args.t,
        cutoff_per_m: 0.0,
        min_points: 1,
        max_edge_m: args.max_edge,
    };
    let c = cluster(&pts, &opts)?;
    let z = linkage(&pts, args.max_edge)?;
    write_atomic(&args.labels, |w| {
        writeln!(w, "label")?;
        for l in &c.labels {
            writeln!(w, "{l}")?;
        }
        Ok(())
    })?;
    write_atomic(&args.linkage, |w| write_linkage_csv(w, &z))?;
    eprintln!(
        "{} points, {} clusters, {} merges",
        pts.len(),
        c.n_clusters,
        z.len()
    );
    Ok(())
}
