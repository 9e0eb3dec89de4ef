//! Dataset folders as inputs of `run` (the walk over their scans comes next).

use super::{Plan, RunRequest};
use crate::cli::Global;
use anyhow::Result;
use std::path::Path;

/// Runs a dataset folder: not yet supported.
pub fn run(_plan: &Plan, _request: &RunRequest, dir: &Path, _global: Global) -> Result<()> {
    anyhow::bail!("{}: dataset folders are not supported yet", dir.display())
}
