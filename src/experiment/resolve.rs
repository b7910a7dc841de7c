//! Validated, typed experiments: `[quick]` and `--set` overrides applied, sweep axes expanded,
//! every point's parameters checked by its family before any work is done.

use super::spec::{backticked, SpecError, SpecFile};
use super::Registry;
use super::{Experiment, Job};
use serde::de::DeserializeOwned;
use std::path::PathBuf;

pub use crate::params::{all_positive, ensure, positive, ParamError};

/// Deserializes a family's parameters, naming the key of any unknown field, missing field or
/// wrong type.
pub fn parse_params<P: DeserializeOwned>(value: &toml::Value) -> Result<P, ParamError> {
    serde_path_to_error::deserialize(value.clone()).map_err(|e| {
        let path = e.path().to_string();
        let path = if path == "." { String::new() } else { path };
        let msg = e.inner().to_string();
        let key = match backticked(&msg) {
            Some(field) if msg.starts_with("unknown field") || msg.starts_with("missing field") => {
                if path.is_empty() {
                    field
                } else {
                    format!("{path}.{field}")
                }
            }
            _ => path,
        };
        // An error inside a flattened struct names its own key in front of the message
        // (`` `horizon`: invalid type… ``, see `families::na::control_task::keyed`): join it to
        // the enclosing path so the error points at the key.
        if let Some((inner, rest)) = msg
            .strip_prefix('`')
            .and_then(|m| m.split_once("`: "))
            .filter(|(inner, _)| !inner.is_empty() && !inner.contains(' '))
        {
            let key = if key.is_empty() {
                inner.to_string()
            } else {
                format!("{key}.{inner}")
            };
            return ParamError::new(key, rest);
        }
        ParamError::new(key, msg)
    })
}

/// Range checks of a family's typed parameters, naming the bad key.
pub trait Validate {
    /// Checks every value; the error names the key inside `[params]`.
    fn validate(&self) -> Result<(), ParamError>;
}

/// The usual `Experiment::resolve`: deserialize `P`, validate it, box it as the job.
pub fn typed_job<P>(value: &toml::Value) -> Result<Box<dyn Job>, ParamError>
where
    P: DeserializeOwned + Validate + Job + 'static,
{
    let p: P = parse_params(value)?;
    p.validate()?;
    Ok(Box::new(p))
}

/// How to resolve a spec: quick mode, seed override, `--set KEY=VALUE` overrides.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ResolveOptions {
    /// Apply the `[quick]` table.
    pub quick: bool,
    /// Replace the file's seed.
    pub seed: Option<u64>,
    /// `KEY=VALUE` overrides of `[params]` keys (or `seed`); VALUE is a TOML value, or a bare
    /// string.
    pub sets: Vec<String>,
    /// `--seeds K`: run every sweep point with the K seeds `seed, seed + 1, …, seed + K - 1`.
    pub seeds: Option<usize>,
}

/// One point of the sweep: the axis values that define it and its validated job.
pub struct SweepPoint {
    /// `(params key, value)` of each sweep axis, in axis order.
    pub values: Vec<(String, toml::Value)>,
    /// The job with typed parameters.
    pub job: Box<dyn Job>,
}

/// A fully validated experiment, ready to run.
pub struct Resolved {
    /// Experiment id.
    pub id: String,
    /// Title.
    pub title: String,
    /// Paper item.
    pub paper_item: String,
    /// The paper's claim.
    pub paper_claim: String,
    /// The family that runs it.
    pub family: &'static dyn Experiment,
    /// Root seed.
    pub seed: u64,
    /// Whether `[quick]` was applied.
    pub quick: bool,
    /// Every sweep point (one when there is no sweep).
    pub points: Vec<SweepPoint>,
    /// The file it came from.
    pub path: PathBuf,
    /// The seeds every point runs with, when seeds are swept (`--seeds K` or a `seeds = [...]`
    /// axis of `[sweep]`); `None` runs each point once with `seed` and adds no `seed` column.
    pub seeds: Option<Vec<u64>>,
    /// The options it was resolved with (recorded by shards, so `merge` resolves alike).
    pub options: ResolveOptions,
}

/// One run of one sweep point with one seed: the unit that shards, resumes and merges.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Unit {
    /// Position in [`Resolved::units`] (seed-major: every point of the first seed, then the
    /// next seed).
    pub index: usize,
    /// Index into [`Resolved::points`].
    pub point: usize,
    /// The seed it runs with.
    pub seed: u64,
}

impl Resolved {
    /// The resolved spec as JSON (written into `run.json`).
    pub fn to_json(&self) -> serde_json::Value {
        let points: Vec<serde_json::Value> = self
            .points
            .iter()
            .map(|p| {
                serde_json::json!({
                    "sweep": p.values.iter().map(|(k, v)| (k.clone(), toml_to_json(v))).collect::<serde_json::Map<_, _>>(),
                    "params": p.job.params_json(),
                })
            })
            .collect();
        let mut v = serde_json::json!({
            "id": self.id,
            "experiment": self.family.kind(),
            "title": self.title,
            "paper_item": self.paper_item,
            "seed": self.seed,
            "quick": self.quick,
            "spec_file": self.path.display().to_string(),
            "points": points,
        });
        if let Some(seeds) = &self.seeds {
            v["seeds"] = serde_json::json!(seeds);
        }
        v
    }

    /// Every run of the experiment: each sweep point once with `seed`, or, when seeds are swept,
    /// each point with each seed, seed-major.
    pub fn units(&self) -> Vec<Unit> {
        let seeds = self.seeds.clone().unwrap_or_else(|| vec![self.seed]);
        let n = self.points.len();
        seeds
            .iter()
            .enumerate()
            .flat_map(|(k, &seed)| {
                (0..n).map(move |point| Unit {
                    index: k * n + point,
                    point,
                    seed,
                })
            })
            .collect()
    }

    /// A content hash (64-bit FNV-1a, hex) of everything that determines the results: the
    /// resolved spec without the path of its file, and the seeds.
    pub fn spec_hash(&self) -> String {
        let mut v = self.to_json();
        if let Some(m) = v.as_object_mut() {
            m.remove("spec_file");
        }
        format!(
            "{:016x}",
            crate::emulator::cache::fnv1a(v.to_string().as_bytes())
        )
    }
}

/// Converts a TOML value to JSON.
pub fn toml_to_json(v: &toml::Value) -> serde_json::Value {
    serde_json::to_value(v).unwrap_or(serde_json::Value::Null)
}

fn set_path(table: &mut toml::Table, key: &str, value: toml::Value) -> Result<(), String> {
    let mut parts: Vec<&str> = key.split('.').collect();
    let last = parts.pop().ok_or("empty key")?;
    let mut t = table;
    for p in parts {
        let entry = t
            .entry(p.to_string())
            .or_insert_with(|| toml::Value::Table(Default::default()));
        t = entry
            .as_table_mut()
            .ok_or_else(|| format!("`{p}` is not a table"))?;
    }
    t.insert(last.to_string(), value);
    Ok(())
}

/// Deep-merges `from` into `into`: tables merge key by key, any other value replaces.
pub fn merge(into: &mut toml::Table, from: &toml::Table) {
    for (k, v) in from {
        match (into.get_mut(k), v) {
            (Some(toml::Value::Table(a)), toml::Value::Table(b)) => merge(a, b),
            _ => {
                into.insert(k.clone(), v.clone());
            }
        }
    }
}

fn parse_value(text: &str) -> toml::Value {
    toml::from_str::<toml::Table>(&format!("v = {text}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(text.to_string()))
}

/// Resolves a parsed experiment file: the family exists, overrides apply, every sweep point's
/// parameters are valid. Nothing is run or written. The family is looked up in `registry`.
pub fn resolve(
    file: &SpecFile,
    opts: &ResolveOptions,
    registry: &Registry,
) -> Result<Resolved, SpecError> {
    let raw = &file.raw;
    let family = registry.find(&raw.experiment).ok_or_else(|| {
        let known: Vec<&str> = registry.families().iter().map(|f| f.kind()).collect();
        file.error_at(
            "experiment",
            format!(
                "unknown experiment family `{}` (known: {})",
                raw.experiment,
                known.join(", ")
            ),
        )
    })?;
    let mut params = raw.params.clone();
    if opts.quick {
        merge(&mut params, &raw.quick);
    }
    let mut seed = raw.seed;
    if let Some(s) = opts.seed {
        seed = s;
    }
    let mut sweep = raw.sweep.clone();
    let seeds_axis = sweep.remove("seeds");
    let mut seed_overridden = opts.seed.is_some();
    let mut set_keys = Vec::new();
    let set_err = |key: &str, message: String| SpecError {
        path: PathBuf::from("--set"),
        line: None,
        key: key.to_string(),
        message,
    };
    for s in &opts.sets {
        let (k, v) = s
            .split_once('=')
            .ok_or_else(|| set_err(s, "expected KEY=VALUE".into()))?;
        let k = k.trim();
        if k == "seed" {
            seed = v
                .trim()
                .parse()
                .map_err(|e| set_err(k, format!("seed must be a non-negative integer: {e}")))?;
            seed_overridden = true;
            continue;
        }
        let key = k.strip_prefix("params.").unwrap_or(k);
        set_path(&mut params, key, parse_value(v.trim())).map_err(|m| set_err(k, m))?;
        sweep.remove(key);
        set_keys.push(key.to_string());
    }
    // Seeds: an explicit seed override drops a `seeds` axis, as overriding a swept key does.
    let seeds = match (seeds_axis.filter(|_| !seed_overridden), opts.seeds) {
        (Some(_), Some(_)) => {
            return Err(file.error_at(
                "sweep.seeds",
                "give either --seeds or a `seeds` sweep axis, not both",
            ))
        }
        (Some(axis), None) => Some(seed_list(file, &axis)?),
        (None, Some(0)) => {
            return Err(SpecError {
                path: PathBuf::from("--seeds"),
                line: None,
                key: "seeds".into(),
                message: "must be at least 1".into(),
            })
        }
        (None, Some(k)) => Some(
            (0..k as u64)
                .map(|i| seed.checked_add(i).filter(|&s| i64::try_from(s).is_ok()))
                .collect::<Option<Vec<u64>>>()
                .ok_or_else(|| SpecError {
                    path: PathBuf::from("--seeds"),
                    line: None,
                    key: "seeds".into(),
                    message: format!(
                        "seeds {seed} to {seed} + {k} - 1 pass 2^63 (the `seed` column is i64)"
                    ),
                })?,
        ),
        (None, None) => None,
    };
    // Sweep axes.
    let mut axes: Vec<(String, Vec<toml::Value>)> = Vec::new();
    for (k, v) in &sweep {
        match v {
            toml::Value::Array(a) if !a.is_empty() => axes.push((k.clone(), a.clone())),
            _ => {
                return Err(file.error_at(
                    &format!("sweep.{k}"),
                    "a sweep axis must be a non-empty array of values",
                ))
            }
        }
    }
    let locate = |pe: ParamError, axis_index: &[usize]| -> SpecError {
        let root = pe.key.split(['.', '[']).next().unwrap_or("").to_string();
        if let Some(pos) = axes.iter().position(|(k, _)| *k == pe.key || *k == root) {
            return file.error_at(
                &format!("sweep.{}[{}]", axes[pos].0, axis_index[pos]),
                pe.message,
            );
        }
        if set_keys.iter().any(|k| *k == pe.key || *k == root) {
            return set_err(&pe.key, pe.message);
        }
        if opts.quick && raw.quick.contains_key(&root) {
            return file.error_at(&format!("quick.{}", pe.key), pe.message);
        }
        file.error_at(&format!("params.{}", pe.key), pe.message)
    };
    let total: usize = axes.iter().map(|(_, v)| v.len()).product();
    let mut points = Vec::with_capacity(total);
    for flat in 0..total {
        // Row-major: the last axis varies fastest.
        let mut idx = vec![0; axes.len()];
        let mut rem = flat;
        for (a, (_, vals)) in axes.iter().enumerate().rev() {
            idx[a] = rem % vals.len();
            rem /= vals.len();
        }
        let mut p = params.clone();
        let mut values = Vec::new();
        for (a, (k, vals)) in axes.iter().enumerate() {
            let v = vals[idx[a]].clone();
            set_path(&mut p, k, v.clone()).map_err(|m| file.error_at(&format!("sweep.{k}"), m))?;
            values.push((k.clone(), v));
        }
        let job = family
            .resolve(&toml::Value::Table(p))
            .map_err(|e| locate(e, &idx))?;
        points.push(SweepPoint { values, job });
    }
    Ok(Resolved {
        id: raw.id.clone(),
        title: raw.title.clone(),
        paper_item: raw.paper_item.clone(),
        paper_claim: raw.paper_claim.clone(),
        family,
        seed,
        quick: opts.quick,
        points,
        path: file.path.clone(),
        seeds,
        options: opts.clone(),
    })
}

/// The seeds of a `seeds = [...]` sweep axis: distinct non-negative integers.
fn seed_list(file: &SpecFile, axis: &toml::Value) -> Result<Vec<u64>, SpecError> {
    let values = match axis {
        toml::Value::Array(a) if !a.is_empty() => a,
        _ => {
            return Err(file.error_at(
                "sweep.seeds",
                "a sweep axis must be a non-empty array of values",
            ))
        }
    };
    let mut seeds = Vec::with_capacity(values.len());
    for (i, v) in values.iter().enumerate() {
        let s = v
            .as_integer()
            .and_then(|s| u64::try_from(s).ok())
            .ok_or_else(|| {
                file.error_at(
                    &format!("sweep.seeds[{i}]"),
                    format!("a seed must be a non-negative integer, got {v}"),
                )
            })?;
        if seeds.contains(&s) {
            return Err(file.error_at(
                &format!("sweep.seeds[{i}]"),
                format!("seed {s} is listed twice"),
            ));
        }
        seeds.push(s);
    }
    Ok(seeds)
}
