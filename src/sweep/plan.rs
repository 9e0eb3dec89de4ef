//! The cells of a sweep: every combination of the `--vary` values and `--seeds`, and the
//! configuration of each cell built from the base configuration.

use crate::config::overrides::apply_set;
use crate::config::reader::Locator;
use crate::config::STAGE_TYPES;
use crate::config::{Config, DEFAULT_LABEL, DEFAULT_TOML};
use crate::error::{Error, Result};
use std::path::{Path, PathBuf};
use toml::{Table, Value};

/// What a `--vary` key changes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum VaryKind {
    /// `<stage type>=on,off`: off removes every stage of that type.
    Toggle {
        /// The stage type.
        stage: String,
    },
    /// `<stage type>.<option>`: the option of the first stage of that type (one is
    /// appended when the base configuration has none).
    StageOption {
        /// The stage type.
        stage: String,
        /// The option name.
        option: String,
    },
    /// Any other dotted path accepted by `--set`, e.g. `noise[1].rate_mm_h`.
    Path,
    /// `sweep --interactions`: each value keeps a subset of the base configuration's
    /// noise stages, by index in the `[[noise]]` list (`subsets[i]` for `values[i]`).
    Stages {
        /// Stage indexes kept by each value, ascending.
        subsets: Vec<Vec<usize>>,
    },
}

/// One `--vary KEY=v1,v2,...`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Vary {
    /// The key as given.
    pub key: String,
    /// The values as given, in order.
    pub values: Vec<String>,
    /// What the key changes.
    pub kind: VaryKind,
}

impl Vary {
    /// Parses `KEY=v1,v2,...`, where a value may be a range `A..B` or `A..B:STEP`
    /// (numbers from A to B inclusive, step 1 by default).
    pub fn parse(arg: &str) -> Result<Vary> {
        let bad = |m: &str| Error::Invalid(format!("--vary {arg}: {m}"));
        let (key, values) = arg
            .split_once('=')
            .ok_or_else(|| bad("expected KEY=v1,v2,... or KEY=A..B[:STEP]"))?;
        let key = key.trim().to_string();
        let mut expanded: Vec<String> = Vec::new();
        for v in values.split(',').map(str::trim) {
            match v.split_once("..") {
                // Only a number starts a range (a path such as ../a.xml is a value).
                Some((a, rest)) if a.trim().parse::<f64>().is_ok() => {
                    expand_range(a, rest, &mut expanded).map_err(|m| bad(&m))?
                }
                _ => expanded.push(v.to_string()),
            }
        }
        let values = expanded;
        if key.is_empty() || values.iter().any(String::is_empty) {
            return Err(bad("empty key or value"));
        }
        let mut seen = std::collections::HashSet::new();
        if let Some(dup) = values.iter().find(|v| !seen.insert(v.as_str())) {
            return Err(bad(&format!("value {dup} is given twice")));
        }
        let is_stage = |s: &str| STAGE_TYPES.contains(&s);
        let kind = if is_stage(&key) {
            if let Some(v) = values.iter().find(|v| *v != "on" && *v != "off") {
                return Err(bad(&format!("a stage type takes on or off, not {v}")));
            }
            VaryKind::Toggle { stage: key.clone() }
        } else {
            match key.split_once('.') {
                Some((stage, option)) if is_stage(stage) && !option.contains(['.', '[']) => {
                    VaryKind::StageOption {
                        stage: stage.to_string(),
                        option: option.to_string(),
                    }
                }
                _ => VaryKind::Path,
            }
        };
        Ok(Vary { key, values, kind })
    }

    /// The `stages` key of `sweep --interactions` over the base configuration's noise
    /// stages: no stage, each stage alone, each pair and (with three or more) all of them.
    ///
    /// Values name the stages by type (`occlusion`, `rain`, `occlusion+rain`); a type
    /// that occurs twice is named with its index in the `[[noise]]` list (`occlusion[0]`).
    pub fn interactions(base: &BaseConfig) -> Result<Vary> {
        let kinds: Vec<&str> = base.config.noise.iter().map(|s| s.kind()).collect();
        let n = kinds.len();
        if n < 2 {
            return Err(Error::Invalid(format!(
                "--interactions: {} has {n} noise stage{}; it needs at least two \
                 [[noise]] stages to pair",
                base.source.display(),
                if n == 1 { "" } else { "s" }
            )));
        }
        let name = |i: usize| {
            if kinds.iter().filter(|k| **k == kinds[i]).count() > 1 {
                format!("{}[{i}]", kinds[i])
            } else {
                kinds[i].to_string()
            }
        };
        let mut values = vec![NO_STAGES.to_string()];
        let mut subsets = vec![Vec::new()];
        for i in 0..n {
            values.push(name(i));
            subsets.push(vec![i]);
        }
        for i in 0..n {
            for j in i + 1..n {
                values.push(format!("{}+{}", name(i), name(j)));
                subsets.push(vec![i, j]);
            }
        }
        if n > 2 {
            values.push(ALL_STAGES.to_string());
            subsets.push((0..n).collect());
        }
        Ok(Vary {
            key: STAGES_KEY.to_string(),
            values,
            kind: VaryKind::Stages { subsets },
        })
    }

    /// True when every value reads as a number (the key can be a plot axis).
    pub fn is_numeric(&self) -> bool {
        self.values.iter().all(|v| v.parse::<f64>().is_ok())
    }
}

/// The key of the `--interactions` sweep.
pub const STAGES_KEY: &str = "stages";
/// The `--interactions` value without any noise stage.
pub const NO_STAGES: &str = "none";
/// The `--interactions` value with every noise stage (three or more stages).
pub const ALL_STAGES: &str = "all";

/// Parses `--seeds`: `N`, `A..B` (both included) or `a,b,c`.
pub fn parse_seeds(text: &str) -> Result<Vec<u64>> {
    let bad = || {
        Error::Invalid(format!(
            "--seeds {text}: expected N, A..B (both included) or a,b,c with whole numbers"
        ))
    };
    let num = |s: &str| s.trim().parse::<u64>().map_err(|_| bad());
    let seeds: Vec<u64> = match text.split_once("..") {
        Some((a, b)) => {
            let (a, b) = (num(a)?, num(b.trim_start_matches('='))?);
            if b < a || b - a >= 100_000 {
                return Err(bad());
            }
            (a..=b).collect()
        }
        None => text.split(',').map(num).collect::<Result<_>>()?,
    };
    let mut seen = std::collections::HashSet::new();
    if seeds
        .iter()
        .any(|s| !seen.insert(*s) || i64::try_from(*s).is_err())
    {
        return Err(bad());
    }
    Ok(seeds)
}

/// One combination of varied values and a seed.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Cell {
    /// One value per `--vary`, in the order of the `--vary` options.
    pub values: Vec<String>,
    /// Seed of every random stream.
    pub seed: u64,
}

impl Cell {
    /// Human-readable key, e.g. `rain.rate_mm_h=0.5 occlusion=on seed=1`.
    pub fn key(&self, varies: &[Vary]) -> String {
        let mut parts: Vec<String> = varies
            .iter()
            .zip(&self.values)
            .map(|(v, x)| format!("{}={x}", v.key))
            .collect();
        parts.push(format!("seed={}", self.seed));
        parts.join(" ")
    }

    /// File name of the cell's result: the key made file-safe, plus a hash of the exact
    /// key so that two keys never share a file.
    pub fn file_name(&self, varies: &[Vary]) -> String {
        let key = self.key(varies);
        let safe: String = key
            .chars()
            .map(|c| match c {
                'a'..='z' | 'A'..='Z' | '0'..='9' | '.' | '=' | '-' | '_' => c,
                _ => '_',
            })
            .collect();
        format!("{safe}-{:08x}.json", fnv1a64(&key) as u32)
    }
}

/// 64-bit FNV-1a hash (stable across runs and platforms).
pub fn fnv1a64(text: &str) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in text.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// Most values one `--vary` range may give.
pub const MAX_RANGE_VALUES: usize = 10_000;

/// Appends the values of the range `A..B[:STEP]` (given as `a` and `B[:STEP]`): A, A +
/// STEP, ... up to B inclusive, written with no more decimals than A, B and STEP have
/// (`0..1:0.25` gives 0, 0.25, 0.5, 0.75, 1).
fn expand_range(a: &str, rest: &str, out: &mut Vec<String>) -> std::result::Result<(), String> {
    let (b, step) = match rest.split_once(':') {
        Some((b, step)) => (b, step),
        None => (rest, "1"),
    };
    let num = |t: &str| -> std::result::Result<f64, String> {
        t.trim()
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("`{t}` in the range {a}..{rest} is not a finite number"))
    };
    let (lo, hi, d) = (num(a)?, num(b)?, num(step)?);
    if d <= 0.0 {
        return Err(format!("the step of {a}..{rest} must be above 0"));
    }
    if hi < lo {
        return Err(format!("the range {a}..{rest} ends below its start"));
    }
    let count = ((hi - lo) / d + 1e-9).floor() + 1.0;
    if count > MAX_RANGE_VALUES as f64 {
        return Err(format!(
            "the range {a}..{rest} gives {count} values, more than the {MAX_RANGE_VALUES} a sweep takes"
        ));
    }
    let decimals = [a, b, step]
        .iter()
        .map(|t| t.trim().split_once('.').map_or(0, |(_, f)| f.len()))
        .max()
        .unwrap_or(0);
    for k in 0..count as usize {
        let x = lo + d * k as f64;
        let text = format!("{x:.decimals$}");
        // 1.50 -> 1.5, 2.0 -> 2, -0 -> 0: as a person writes the list.
        let text = if text.contains('.') {
            text.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            text
        };
        out.push(if text == "-0" { "0".to_string() } else { text });
    }
    Ok(())
}

/// Every combination: seeds outermost, then the `--vary` values, first key slowest.
pub fn cells(varies: &[Vary], seeds: &[u64]) -> Vec<Cell> {
    let mut combos: Vec<Vec<String>> = vec![Vec::new()];
    for v in varies {
        combos = combos
            .into_iter()
            .flat_map(|c| {
                v.values.iter().map(move |x| {
                    let mut c = c.clone();
                    c.push(x.clone());
                    c
                })
            })
            .collect();
    }
    seeds
        .iter()
        .flat_map(|&seed| {
            combos.iter().map(move |values| Cell {
                values: values.clone(),
                seed,
            })
        })
        .collect()
}

/// The base configuration as a TOML document, from which each cell's is derived.
#[derive(Clone, Debug)]
pub struct BaseConfig {
    /// The document after the user's `--set` overrides.
    pub table: Table,
    /// Where it came from (for errors).
    pub source: PathBuf,
    /// The validated base configuration.
    pub config: Config,
}

impl BaseConfig {
    /// Loads `path` (or the built-in configuration) and applies `sets`; returns the base
    /// and the configuration's warnings.
    pub fn load(path: Option<&Path>, sets: &[String]) -> Result<(BaseConfig, Vec<String>)> {
        let (text, source) = match path {
            Some(p) => (crate::error::read_text_bounded(p)?, p.to_path_buf()),
            None => (DEFAULT_TOML.to_string(), PathBuf::from(DEFAULT_LABEL)),
        };
        // Validating the text as given first gives errors with file lines.
        let (config, warnings) = Config::from_toml_str(&text, &source, sets, None)?;
        let mut table: Table = toml::from_str(&text).map_err(|e| Error::Config {
            path: source.clone(),
            message: e.to_string(),
        })?;
        let mut locator = Locator::default();
        for s in sets {
            apply_set(&mut table, s, &mut locator).map_err(|m| Error::Config {
                path: source.clone(),
                message: format!("--set {s}: {m}"),
            })?;
        }
        Ok((
            BaseConfig {
                table,
                source,
                config,
            },
            warnings,
        ))
    }

    /// Seed of the base configuration.
    pub fn seed(&self) -> u64 {
        self.config.seed
    }

    /// The configuration of one cell.
    pub fn cell_config(&self, varies: &[Vary], cell: &Cell) -> Result<Config> {
        let mut table = self.table.clone();
        let label = self.source.with_file_name(format!(
            "{} [sweep cell {}]",
            self.source
                .file_name()
                .map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
            cell.key(varies)
        ));
        let fail = |m: String| Error::Config {
            path: label.clone(),
            message: m,
        };
        let mut locator = Locator::default();
        // Values first, on the stage list as written, so that `noise[i]` paths keep
        // meaning what they mean in the file; removals come last.
        for (v, value) in varies.iter().zip(&cell.values) {
            // `--set` resolves the `<stage type>.<option>` shorthand itself.
            let set = match &v.kind {
                VaryKind::Toggle { .. } | VaryKind::Stages { .. } => continue,
                VaryKind::StageOption { .. } | VaryKind::Path => format!("{}={value}", v.key),
            };
            apply_set(&mut table, &set, &mut locator)
                .map_err(|m| fail(format!("--vary {}: {m}", v.key)))?;
        }
        for (v, value) in varies.iter().zip(&cell.values) {
            if let VaryKind::Toggle { stage } = &v.kind {
                if stage_index(&table, stage).is_none() {
                    return Err(fail(format!(
                        "--vary {}: the configuration has no {stage} stage to switch",
                        v.key
                    )));
                }
                if value == "off" {
                    retain_stages(&mut table, |t| t != stage);
                }
            }
        }
        for (v, value) in varies.iter().zip(&cell.values) {
            if let VaryKind::Stages { subsets } = &v.kind {
                let keep = v
                    .values
                    .iter()
                    .position(|x| x == value)
                    .and_then(|i| subsets.get(i))
                    .ok_or_else(|| fail(format!("{}: no stage subset {value}", v.key)))?;
                retain_stage_indexes(&mut table, keep);
            }
        }
        config_of(&table, &label, cell.seed)
    }

    /// The clean baseline of a cell configuration: the same without any noise stage.
    pub fn baseline_config(&self, varies: &[Vary], cell: &Cell) -> Result<Config> {
        let mut config = self.cell_config(varies, cell)?;
        config.noise.clear();
        Ok(config)
    }

    /// The base configuration keeping only the stages whose type is in `types`.
    pub fn only_stages(&self, types: &[&str], seed: u64) -> Result<Config> {
        let mut config = self.config.clone();
        config.noise.retain(|s| types.contains(&s.kind()));
        config.seed = seed;
        Ok(config)
    }
}

fn config_of(table: &Table, label: &Path, seed: u64) -> Result<Config> {
    let text = toml::to_string(table).map_err(|e| Error::Config {
        path: label.to_path_buf(),
        message: e.to_string(),
    })?;
    Ok(Config::from_toml_str(&text, label, &[], Some(seed))?.0)
}

fn stage_type(v: &Value) -> Option<&str> {
    v.as_table()?.get("type")?.as_str()
}

fn stage_index(table: &Table, stage: &str) -> Option<usize> {
    table
        .get("noise")?
        .as_array()?
        .iter()
        .position(|v| stage_type(v) == Some(stage))
}

fn retain_stages(table: &mut Table, keep: impl Fn(&str) -> bool) {
    if let Some(Value::Array(list)) = table.get_mut("noise") {
        list.retain(|v| stage_type(v).is_none_or(&keep));
        if list.is_empty() {
            table.remove("noise");
        }
    }
}

fn retain_stage_indexes(table: &mut Table, keep: &[usize]) {
    if let Some(Value::Array(list)) = table.get_mut("noise") {
        let mut i = 0;
        list.retain(|_| {
            i += 1;
            keep.contains(&(i - 1))
        });
        if list.is_empty() {
            table.remove("noise");
        }
    }
}

/// Largest distance band edge (`--bands`), in metres: far beyond any sensor's range.
pub const MAX_BAND_EDGE_M: f64 = 100_000.0;

/// Parses `--bands`: comma-separated, strictly ascending edges from 0 to
/// [`MAX_BAND_EDGE_M`].
pub fn parse_bands(text: &str) -> Result<Vec<f64>> {
    let bad = |m: String| Error::Invalid(format!("--bands {text}: {m}"));
    let edges: Vec<f64> = text
        .split(',')
        .map(|e| {
            e.trim()
                .parse::<f64>()
                .ok()
                // Bounded: each band names plot files (a 1e308 m edge wrote 309 digits).
                .filter(|v| v.is_finite() && (0.0..=MAX_BAND_EDGE_M).contains(v))
                .ok_or_else(|| {
                    bad(format!(
                        "`{e}` is not a distance from 0 to {MAX_BAND_EDGE_M} m"
                    ))
                })
        })
        .collect::<Result<_>>()?;
    if let Some(w) = edges.windows(2).find(|w| w[0] >= w[1]) {
        return Err(bad(format!(
            "edges must increase ({} is followed by {})",
            w[0], w[1]
        )));
    }
    Ok(edges)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vary_ranges_expand_as_written_by_hand() {
        let v = |a: &str| Vary::parse(a).map(|v| v.values);
        let s = |xs: &[&str]| xs.iter().map(|x| x.to_string()).collect::<Vec<_>>();
        assert_eq!(
            v("rain.rate_mm_h=0..7").unwrap(),
            s(&["0", "1", "2", "3", "4", "5", "6", "7"])
        );
        assert_eq!(
            v("rain.rate_mm_h=0..1:0.25").unwrap(),
            s(&["0", "0.25", "0.5", "0.75", "1"])
        );
        // The end is included when the steps reach it despite rounding (0.1 * 3).
        assert_eq!(v("x=0..0.3:0.1").unwrap(), s(&["0", "0.1", "0.2", "0.3"]));
        assert_eq!(v("x=-1..1").unwrap(), s(&["-1", "0", "1"]));
        assert_eq!(v("x=1,3..5,9").unwrap(), s(&["1", "3", "4", "5", "9"]));
        assert_eq!(v("x=0..10:4").unwrap(), s(&["0", "4", "8"]));
        // A path with .. is a value, not a range.
        assert_eq!(v("calibration=../a.xml").unwrap(), s(&["../a.xml"]));
        for bad in [
            "x=0..1:0",
            "x=2..1",
            "x=0..1e9:1e-9",
            "x=0..b",
            "x=0..1:-1",
            "x=1,0..2",
        ] {
            assert!(v(bad).is_err(), "{bad} should be refused");
        }
    }

    #[test]
    fn seeds_and_cells() {
        assert_eq!(parse_seeds("1..10").unwrap(), (1..=10).collect::<Vec<_>>());
        assert_eq!(parse_seeds("3,1").unwrap(), vec![3, 1]);
        assert!(parse_seeds("5..1").is_err());
        let v = [
            Vary::parse("rain.rate_mm_h=0,1").unwrap(),
            Vary::parse("occlusion=on,off").unwrap(),
        ];
        assert_eq!(
            v[0].kind,
            VaryKind::StageOption {
                stage: "rain".into(),
                option: "rate_mm_h".into()
            }
        );
        let c = cells(&v, &[1, 2]);
        assert_eq!(c.len(), 8);
        assert_eq!(c[1].values, vec!["0", "off"]);
        assert_eq!(c[4].seed, 2);
        assert!(Vary::parse("occlusion=maybe").is_err());
    }

    #[test]
    fn cell_configs_switch_and_set_stages() {
        let (base, _) = BaseConfig::load(None, &[]).unwrap();
        let v = [
            Vary::parse("rain.rate_mm_h=0,3").unwrap(),
            Vary::parse("occlusion=on,off").unwrap(),
        ];
        let c = base
            .cell_config(
                &v,
                &Cell {
                    values: vec!["3".into(), "off".into()],
                    seed: 5,
                },
            )
            .unwrap();
        assert_eq!(c.seed, 5);
        assert_eq!(c.noise.len(), 1);
        assert_eq!(c.noise[0].kind(), "rain");
        assert!(c.noise[0].describe().contains('3'));
        let b = base
            .baseline_config(
                &v,
                &Cell {
                    values: vec!["3".into(), "on".into()],
                    seed: 5,
                },
            )
            .unwrap();
        assert!(b.noise.is_empty());
    }
}
