//! Loading a configuration: `config` parses the file into plain data, the noise
//! registry validates the `[[noise]]` entries. Both steps meet here so that `config`
//! never imports `noise`.

use crate::config::Config;
use crate::error::Result;
use std::path::Path;

impl Config {
    /// Loads `path` (or the built-in `configs/paper.toml`), applies `--set key=value`
    /// overrides in order and `--seed`, validates (stage options included), and returns
    /// the configuration with its warnings (for the caller to print).
    pub fn load(
        path: Option<&Path>,
        sets: &[String],
        seed: Option<u64>,
    ) -> Result<(Config, Vec<String>)> {
        let (mut config, mut warnings) = Config::parse_file(path, sets, seed)?;
        warnings.splice(0..0, crate::noise::registry::resolve(&mut config.noise)?);
        Ok((config, warnings))
    }

    /// Same as [`Config::load`] on text already read; `file` names it in errors.
    pub fn from_toml_str(
        text: &str,
        file: &Path,
        sets: &[String],
        seed: Option<u64>,
    ) -> Result<(Config, Vec<String>)> {
        let (mut config, mut warnings) = Config::parse_str(text, file, sets, seed)?;
        warnings.splice(0..0, crate::noise::registry::resolve(&mut config.noise)?);
        Ok((config, warnings))
    }
}
