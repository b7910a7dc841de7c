//! Validated, typed experiments: `[quick]` and `--set` overrides applied, sweep axes expanded,
//! every point's parameters checked by its family before any work is done.

use super::spec::{backticked, SpecError, SpecFile};
use super::Registry;
use super::{Experiment, Job};
use serde::de::DeserializeOwned;
use std::path::PathBuf;

pub use crate::params::{all_positive, at_most, distinct, each_bar, ensure, positive, ParamError};

/// The most seeds a run may sweep (`--seeds K`, or a `seeds = [...]` sweep axis).
pub const MAX_SEEDS: usize = 1_000;

/// The most points a sweep may have (the product of its axes' lengths).
pub const MAX_SWEEP_POINTS: usize = 10_000;

/// The most runs (sweep points times seeds) one experiment may have: each keeps its results in
/// memory until the tables are written.
pub const MAX_UNITS: usize = 100_000;

/// Deserializes a family's parameters, naming the key of any unknown field, missing field or
/// wrong type.
pub fn parse_params<P: DeserializeOwned>(value: &toml::Value) -> Result<P, ParamError> {
    serde_path_to_error::deserialize(value.clone()).map_err(|e| {
        let path = e.path().to_string();
        let path = if path == "." { String::new() } else { path };
        let msg = e.inner().to_string();
        let key = match backticked(&msg) {
            // The path of an unknown field already ends in it (the key that failed to
            // deserialize); that of a missing field is the table that lacks it.
            Some(field)
                if msg.starts_with("unknown field")
                    && (path == field || path.ends_with(&format!(".{field}"))) =>
            {
                path
            }
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
    /// `--seeds K`: run every sweep point with the K seeds `seed, seed + 1, …, seed + K - 1`
    /// (K at most [`MAX_SEEDS`]).
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
    /// The claim in a few words (the claims table).
    pub claim: String,
    /// The paper's number or statement in a few words (the claims table).
    pub paper_number: String,
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
    /// Changes of its rule or setup made after a result (the spec's `[[history]]`).
    pub history: Vec<super::spec::HistoryEntry>,
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
/// parameters are valid, with `[quick]` applied and without (so that a mistake in either table
/// is found whichever mode runs), sweep values are distinct and the run is within
/// [`MAX_SEEDS`], [`MAX_SWEEP_POINTS`] and [`MAX_UNITS`]. Nothing is run or written. The family
/// is looked up in `registry`.
pub fn resolve(
    file: &SpecFile,
    opts: &ResolveOptions,
    registry: &Registry,
) -> Result<Resolved, SpecError> {
    let raw = &file.raw;
    let family = find_family(file, registry)?;
    check_claim_and_history(file)?;
    let over = overrides(file, opts)?;
    let seeds = seed_axis(file, opts, &over)?;
    let axes = sweep_axes(file, &over.sweep)?;
    let total = sweep_size(file, opts, &axes, seeds.as_ref().map_or(1, |s| s.len()))?;
    let points = sweep_points(file, opts, family, &over.sets, &axes, total)?;
    Ok(Resolved {
        id: raw.id.clone(),
        title: raw.title.clone(),
        paper_item: raw.paper_item.clone(),
        paper_claim: raw.paper_claim.clone(),
        claim: raw.claim.clone(),
        paper_number: raw.paper_number.clone(),
        family,
        seed: over.seed,
        quick: opts.quick,
        points,
        path: file.path.clone(),
        seeds,
        options: opts.clone(),
        history: raw.history.clone(),
    })
}

/// The experiment file's family, from `registry`.
fn find_family(file: &SpecFile, registry: &Registry) -> Result<&'static dyn Experiment, SpecError> {
    let raw = &file.raw;
    registry.find(&raw.experiment).ok_or_else(|| {
        let known: Vec<&str> = registry.families().iter().map(|f| f.kind()).collect();
        file.error_at(
            "experiment",
            format!(
                "unknown experiment family `{}` (known: {})",
                raw.experiment,
                known.join(", ")
            ),
        )
    })
}

/// The claim within its word limit and every history entry well formed.
fn check_claim_and_history(file: &SpecFile) -> Result<(), SpecError> {
    let raw = &file.raw;
    let words = raw.claim.split_whitespace().count();
    if words > super::spec::CLAIM_WORDS {
        return Err(file.error_at(
            "claim",
            format!(
                "{words} words: the claims table's claim has at most {}",
                super::spec::CLAIM_WORDS
            ),
        ));
    }
    if let Some(i) = raw.history.iter().position(|h| !h.is_well_formed()) {
        return Err(file.error_at(
            &format!("history[{i}]"),
            "a history entry needs a date (YYYY-MM-DD), the old rule or setup (`old`) and the reason (`reason`)",
        ));
    }
    Ok(())
}

/// `(as given, key inside [params], value)` of a `--set`.
type Set = (String, String, toml::Value);

/// The file's seed and sweep after `--seed` and the `--set` overrides.
struct Overrides {
    /// The run's seed.
    seed: u64,
    /// Whether `--seed` or `--set seed=` gave it.
    seed_overridden: bool,
    /// The sweep's axes less `seeds` and less every key a `--set` overrides.
    sweep: toml::Table,
    /// The file's `seeds` sweep axis, if any.
    seeds_axis: Option<toml::Value>,
    /// Each `--set` other than the seed, in the order given.
    sets: Vec<Set>,
}

/// An error in the `--set` override of `key`.
fn set_err(key: &str, message: String) -> SpecError {
    SpecError {
        path: PathBuf::from("--set"),
        line: None,
        key: key.to_string(),
        message,
    }
}

/// An error in the command-line flag `flag`.
fn flag_err(flag: &str, message: String) -> SpecError {
    SpecError {
        path: PathBuf::from(flag),
        line: None,
        key: flag.trim_start_matches('-').to_string(),
        message,
    }
}

/// Applies `--seed` and reads the `--set` overrides: a swept key that is set leaves the sweep.
fn overrides(file: &SpecFile, opts: &ResolveOptions) -> Result<Overrides, SpecError> {
    let raw = &file.raw;
    let mut seed = raw.seed;
    if let Some(s) = opts.seed {
        seed = s;
    }
    let mut sweep = raw.sweep.clone();
    let seeds_axis = sweep.remove("seeds");
    let mut seed_overridden = opts.seed.is_some();
    // `(as given, key inside [params], value)` of each `--set`.
    let mut sets: Vec<(String, String, toml::Value)> = Vec::new();
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
        sweep.remove(key);
        sets.push((k.to_string(), key.to_string(), parse_value(v.trim())));
    }
    Ok(Overrides {
        seed,
        seed_overridden,
        sweep,
        seeds_axis,
        sets,
    })
}

/// `[params]`, with `[quick]` over it in quick mode, then the `--set` overrides.
fn params_for(file: &SpecFile, sets: &[Set], quick: bool) -> Result<toml::Table, SpecError> {
    let raw = &file.raw;
    let mut params = raw.params.clone();
    if quick {
        merge(&mut params, &raw.quick);
    }
    for (given, key, value) in sets {
        set_path(&mut params, key, value.clone()).map_err(|m| set_err(given, m))?;
    }
    Ok(params)
}

/// The seeds swept: a `seeds` axis or `--seeds K`; an explicit seed override drops a `seeds`
/// axis, as overriding a swept key does.
fn seed_axis(
    file: &SpecFile,
    opts: &ResolveOptions,
    over: &Overrides,
) -> Result<Option<Vec<u64>>, SpecError> {
    let seed = over.seed;
    let seeds_axis = over.seeds_axis.clone();
    let seed_overridden = over.seed_overridden;
    Ok(
        match (seeds_axis.filter(|_| !seed_overridden), opts.seeds) {
            (Some(_), Some(_)) => {
                return Err(file.error_at(
                    "sweep.seeds",
                    "give either --seeds or a `seeds` sweep axis, not both",
                ))
            }
            (Some(axis), None) => Some(seed_list(file, &axis)?),
            (None, Some(0)) => return Err(flag_err("--seeds", "must be at least 1".into())),
            (None, Some(k)) if k > MAX_SEEDS => {
                return Err(flag_err(
                    "--seeds",
                    format!("must be at most {MAX_SEEDS}, got {k}"),
                ))
            }
            (None, Some(k)) => Some(
                (0..k as u64)
                    .map(|i| seed.checked_add(i).filter(|&s| i64::try_from(s).is_ok()))
                    .collect::<Option<Vec<u64>>>()
                    .ok_or_else(|| {
                        flag_err(
                            "--seeds",
                            format!(
                            "seeds {seed} to {seed} + {k} - 1 pass 2^63 (the `seed` column is i64)"
                        ),
                        )
                    })?,
            ),
            (None, None) => None,
        },
    )
}

/// Sweep axes: non-empty arrays of distinct values.
fn sweep_axes(
    file: &SpecFile,
    sweep: &toml::Table,
) -> Result<Vec<(String, Vec<toml::Value>)>, SpecError> {
    let mut axes: Vec<(String, Vec<toml::Value>)> = Vec::new();
    for (k, v) in sweep {
        match v {
            toml::Value::Array(a) if !a.is_empty() => {
                for (i, x) in a.iter().enumerate() {
                    if let Some(j) = a[..i].iter().position(|y| same_value(x, y)) {
                        return Err(file.error_at(
                            &format!("sweep.{k}[{i}]"),
                            format!(
                                "{x} is listed twice (also at sweep.{k}[{j}]); it would only repeat rows"
                            ),
                        ));
                    }
                }
                axes.push((k.clone(), a.clone()))
            }
            _ => {
                return Err(file.error_at(
                    &format!("sweep.{k}"),
                    "a sweep axis must be a non-empty array of values",
                ))
            }
        }
    }
    Ok(axes)
}

/// The number of sweep points, checked (with `n_seeds`) against the limits before anything
/// is allocated for them.
fn sweep_size(
    file: &SpecFile,
    opts: &ResolveOptions,
    axes: &[(String, Vec<toml::Value>)],
    n_seeds: usize,
) -> Result<usize, SpecError> {
    let total = axes
        .iter()
        .try_fold(1usize, |n, (_, v)| n.checked_mul(v.len()))
        .filter(|&n| n <= MAX_SWEEP_POINTS)
        .ok_or_else(|| {
            let lens: Vec<String> = axes.iter().map(|(_, v)| v.len().to_string()).collect();
            file.error_at(
                "sweep",
                format!(
                    "{} sweep points are more than {MAX_SWEEP_POINTS}, the most a run may have",
                    lens.join(" x ")
                ),
            )
        })?;
    if total * n_seeds > MAX_UNITS {
        let message = format!(
            "{total} sweep points x {n_seeds} seeds = {} runs are more than {MAX_UNITS}, the most a run may have",
            total * n_seeds
        );
        return Err(match opts.seeds {
            Some(_) => flag_err("--seeds", message),
            None => file.error_at("sweep", message),
        });
    }
    Ok(total)
}

/// Where a family's error belongs: a sweep value, a `--set`, `[quick]` (in quick mode) or
/// `[params]`.
fn locate(
    file: &SpecFile,
    axes: &[(String, Vec<toml::Value>)],
    sets: &[Set],
    pe: ParamError,
    axis_index: &[usize],
    quick: bool,
) -> SpecError {
    let raw = &file.raw;
    let root = pe.key.split(['.', '[']).next().unwrap_or("").to_string();
    if let Some(pos) = axes.iter().position(|(k, _)| *k == pe.key || *k == root) {
        return file.error_at(
            &format!("sweep.{}[{}]", axes[pos].0, axis_index[pos]),
            pe.message,
        );
    }
    // The last `--set` that wrote the key, a table around it or a key inside it.
    if let Some((given, key, _)) = sets
        .iter()
        .rev()
        .find(|(_, key, _)| nested(&pe.key, key) || nested(key, &pe.key))
    {
        let shown = if nested(&pe.key, key) { &pe.key } else { given };
        return set_err(shown, pe.message);
    }
    if quick && raw.quick.contains_key(&root) {
        return file.error_at(&format!("quick.{}", pe.key), pe.message);
    }
    file.error_at(&format!("params.{}", pe.key), pe.message)
}

/// Every point in the mode asked for, each resolved by its family; then, so that neither
/// table hides a mistake until the other mode runs, every point in the other mode, whose
/// errors say which mode.
fn sweep_points(
    file: &SpecFile,
    opts: &ResolveOptions,
    family: &'static dyn Experiment,
    sets: &[Set],
    axes: &[(String, Vec<toml::Value>)],
    total: usize,
) -> Result<Vec<SweepPoint>, SpecError> {
    let mut points = Vec::with_capacity(total);
    for quick in [opts.quick, !opts.quick] {
        let params = params_for(file, sets, quick)?;
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
                set_path(&mut p, k, v.clone())
                    .map_err(|m| file.error_at(&format!("sweep.{k}"), m))?;
                values.push((k.clone(), v));
            }
            match family.resolve(&toml::Value::Table(p)) {
                Ok(job) if quick == opts.quick => points.push(SweepPoint { values, job }),
                Ok(_) => {}
                Err(e) => {
                    let mut err = locate(file, axes, sets, e, &idx, quick);
                    if quick != opts.quick && !err.key.starts_with("quick.") {
                        err.message = format!(
                            "{} ({})",
                            err.message,
                            if quick {
                                "with [quick] applied, as --quick runs it"
                            } else {
                                "without [quick], as a full run runs it"
                            }
                        );
                    }
                    return Err(err);
                }
            }
        }
    }
    Ok(points)
}

/// Whether dotted key `inner` is `outer` or lies inside it (`a.b` and `a.b[2]` lie in `a`).
fn nested(inner: &str, outer: &str) -> bool {
    inner
        .strip_prefix(outer)
        .is_some_and(|rest| rest.is_empty() || rest.starts_with(['.', '[']))
}

/// Whether two sweep values are the same value (an integer and a float of equal value are).
fn same_value(a: &toml::Value, b: &toml::Value) -> bool {
    match (a, b) {
        (toml::Value::Integer(i), toml::Value::Float(f))
        | (toml::Value::Float(f), toml::Value::Integer(i)) => *i as f64 == *f,
        _ => a == b,
    }
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
    if values.len() > MAX_SEEDS {
        return Err(file.error_at(
            "sweep.seeds",
            format!(
                "{} seeds are more than {MAX_SEEDS}, the most a run may have",
                values.len()
            ),
        ));
    }
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
