//! # Units, shards, resume and merge
//!
//! An experiment runs as *units*: each sweep point once, or each point with each seed when seeds
//! are swept ([`super::resolve::Resolved::units`], seed-major). A unit's tables (already
//! prefixed with its sweep values and seed) can be stored as one JSON file,
//! `<store>/<hash>.json`, where the hash (64-bit FNV-1a, hex) is taken over a canonical JSON
//! *key* of everything that determines them: the store format, experiment id and family, quick
//! flag, the unit's seed, its sweep values, its typed parameters, the crate version and the git
//! revision. The file repeats the key and a load checks it, as the emulator cache does
//! (`src/emulator/cache.rs`); floats are stored as their bit patterns, so a loaded unit is
//! bit-identical to the computed one. Files are written atomically (temporary file, then
//! rename), so a killed run leaves complete unit files or none.
//!
//! - A sweep (more than one unit) or a `--resume` run keeps its units in `<out>/<id>/units/`;
//!   `--resume` loads the ones whose key matches instead of running them again.
//! - `--shard I/N` runs the units whose index is `I - 1` modulo `N` into
//!   `<out>/<id>/shards/I-of-N/units/` and, when all are done, writes `shard.json` there (the
//!   shard's number, the spec hash, the git revision, the resolve options and its units).
//! - [`merge`](super::runner::merge) checks that the shards are one complete set (all of `1..=N`, none twice, same
//!   spec hash, revision and options, each with all its unit files) before writing anything,
//!   then writes what the unsharded run writes, byte for byte (CSV and Parquet; `run.json`
//!   records times).

use super::output::{atomic_write, ColumnData, Table, Tables};
use super::resolve::{resolve, ResolveOptions, Resolved, Unit};
use super::spec::SpecFile;
use super::{Error, Registry};
use crate::emulator::cache::fnv1a;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Bumped whenever the meaning of a stored unit changes.
pub const UNIT_FORMAT: u32 = 1;

/// `--shard I/N`: the `I`-th of `N` shards (1-based).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// Which shard, 1..=count.
    pub index: usize,
    /// How many shards.
    pub count: usize,
}

impl Shard {
    /// Parses `I/N` with `1 <= I <= N`.
    pub fn parse(text: &str) -> Result<Self, String> {
        let bad = || format!("--shard `{text}`: expected I/N with 1 <= I <= N, e.g. 2/8");
        let (i, n) = text.split_once('/').ok_or_else(bad)?;
        let index: usize = i.trim().parse().map_err(|_| bad())?;
        let count: usize = n.trim().parse().map_err(|_| bad())?;
        if index == 0 || count == 0 || index > count {
            return Err(bad());
        }
        Ok(Self { index, count })
    }

    /// The shard's folder name, `I-of-N`.
    pub fn dir_name(&self) -> String {
        format!("{}-of-{}", self.index, self.count)
    }

    /// Whether this shard runs unit `unit_index`.
    pub fn owns(&self, unit_index: usize) -> bool {
        unit_index % self.count == self.index - 1
    }
}

/// The canonical key of a unit: everything that determines its tables.
pub fn unit_key(res: &Resolved, unit: &Unit, revision: Option<&str>) -> String {
    let point = &res.points[unit.point];
    let sweep: serde_json::Map<String, serde_json::Value> = point
        .values
        .iter()
        .map(|(k, v)| (k.clone(), super::resolve::toml_to_json(v)))
        .collect();
    serde_json::json!({
        "format": UNIT_FORMAT,
        "id": res.id,
        "experiment": res.family.kind(),
        "quick": res.quick,
        "seed": unit.seed,
        "seeded": res.seeds.is_some(),
        "sweep": sweep,
        "params": point.job.params_json(),
        "crate_version": env!("CARGO_PKG_VERSION"),
        "git_revision": revision,
    })
    .to_string()
}

/// The file of the unit with `key` in `store`.
pub fn unit_path(store: &Path, key: &str) -> PathBuf {
    store.join(format!("{:016x}.json", fnv1a(key.as_bytes())))
}

#[derive(Serialize, Deserialize)]
enum StoredColumn {
    /// Float bit patterns.
    F(Vec<u64>),
    I(Vec<i64>),
    S(Vec<String>),
}

#[derive(Serialize, Deserialize)]
struct StoredTable {
    name: String,
    names: Vec<String>,
    columns: Vec<StoredColumn>,
}

#[derive(Serialize, Deserialize)]
struct StoredUnit {
    key: String,
    tables: Vec<StoredTable>,
    /// Seconds per stage when it was computed.
    stages: Vec<(String, f64)>,
}

/// A unit's tables and the seconds per stage it took.
pub type UnitResult = (Tables, Vec<(String, f64)>);

/// Writes a unit's tables atomically to `path`.
pub fn save_unit(path: &Path, key: &str, result: &UnitResult) -> Result<(), Error> {
    let tables = result
        .0
         .0
        .iter()
        .map(|(name, t)| StoredTable {
            name: name.clone(),
            names: t.names().to_vec(),
            columns: t
                .columns()
                .iter()
                .map(|c| match c {
                    ColumnData::F(v) => StoredColumn::F(v.iter().map(|x| x.to_bits()).collect()),
                    ColumnData::I(v) => StoredColumn::I(v.clone()),
                    ColumnData::S(v) => StoredColumn::S(v.clone()),
                })
                .collect(),
        })
        .collect();
    let stored = StoredUnit {
        key: key.to_string(),
        tables,
        stages: result.1.clone(),
    };
    let text = serde_json::to_string(&stored).map_err(|e| Error::Other(e.to_string()))?;
    atomic_write(path, text.as_bytes())
}

/// The unit stored at `path` under `key`, or why it cannot be used (missing, truncated, or
/// stored under another key).
pub fn load_unit(path: &Path, key: &str) -> Result<UnitResult, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let s: StoredUnit = serde_json::from_str(&text)
        .map_err(|e| format!("{}: incomplete or corrupt: {e}", path.display()))?;
    if s.key != key {
        return Err(format!(
            "{}: stored for another point, seed or revision",
            path.display()
        ));
    }
    let mut tables = Tables::default();
    for t in s.tables {
        let columns = t
            .columns
            .into_iter()
            .map(|c| match c {
                StoredColumn::F(v) => ColumnData::F(v.into_iter().map(f64::from_bits).collect()),
                StoredColumn::I(v) => ColumnData::I(v),
                StoredColumn::S(v) => ColumnData::S(v),
            })
            .collect();
        let table = Table::from_parts(t.names, columns)
            .map_err(|e| format!("{}: table {}: {e}", path.display(), t.name))?;
        tables.insert(&t.name, table);
    }
    Ok((tables, s.stages))
}

/// What a finished shard records in `shard.json`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ShardRecord {
    /// Experiment id.
    pub id: String,
    /// Which shard, 1..=of.
    pub shard: usize,
    /// How many shards.
    pub of: usize,
    /// [`Resolved::spec_hash`] of the spec it ran.
    pub spec_hash: String,
    /// Git revision of the code that ran it.
    pub git_revision: Option<String>,
    /// Whether that code had uncommitted changes.
    pub git_dirty: Option<bool>,
    /// `--quick`.
    pub quick: bool,
    /// `--seed`.
    pub seed: Option<u64>,
    /// `--set` overrides.
    pub sets: Vec<String>,
    /// `--seeds`.
    pub seeds: Option<usize>,
    /// `(unit index, unit file name)` of every unit it ran, in order.
    pub units: Vec<(usize, String)>,
    /// Worker threads.
    pub threads: usize,
    /// Wall time in seconds.
    pub seconds_total: f64,
}

impl ShardRecord {
    /// The resolve options the shard ran with.
    pub fn options(&self) -> ResolveOptions {
        ResolveOptions {
            quick: self.quick,
            seed: self.seed,
            sets: self.sets.clone(),
            seeds: self.seeds,
        }
    }

    fn shard(&self) -> Shard {
        Shard {
            index: self.shard,
            count: self.of,
        }
    }
}

/// The file name of a shard's record.
pub const SHARD_RECORD: &str = "shard.json";

/// A checked, complete set of shards: the spec resolved as they ran it and every unit's result
/// in unit order.
pub struct MergedShards {
    /// The experiment as the shards resolved it.
    pub resolved: Resolved,
    /// Every unit's tables and stages, in unit order.
    pub results: Vec<UnitResult>,
    /// The shards' git revision and dirty flag.
    pub git_revision: Option<String>,
    /// Whether the shards' code had uncommitted changes.
    pub git_dirty: Option<bool>,
    /// How many shards.
    pub count: usize,
}

fn refuse(dir: &Path, msg: impl std::fmt::Display) -> Error {
    Error::Other(format!("merge {}: {msg}; nothing written", dir.display()))
}

/// Reads and checks the shards below `<out>/<id>/shards/` for the experiment `file`: refuses
/// (nothing is written) when one is missing, unfinished or duplicated, when they disagree on
/// the number of shards, spec hash, revision or options, when the spec now resolves to another
/// hash, or when a unit file is missing or corrupt.
pub fn read_shards(
    file: &SpecFile,
    out: &Path,
    registry: &Registry,
) -> Result<MergedShards, Error> {
    let dir = out.join(&file.raw.id).join("shards");
    let records = shard_records(file, &dir)?;
    let Some((_, first)) = records.first().cloned() else {
        return Err(refuse(&dir, "no shards"));
    };
    let n = first.of;
    check_records(file, &dir, &records)?;
    let missing: Vec<String> = (1..=n)
        .filter(|i| !records.iter().any(|(_, r)| r.shard == *i))
        .map(|i| i.to_string())
        .collect();
    if !missing.is_empty() {
        return Err(refuse(
            &dir,
            format!("missing shard(s) {} of {n}", missing.join(", ")),
        ));
    }
    let res = resolve(file, &first.options(), registry)?;
    if res.spec_hash() != first.spec_hash {
        return Err(refuse(
            &dir,
            format!(
                "the shards ran a different spec (hash {}) than {} now resolves to (hash {})",
                first.spec_hash,
                file.path.display(),
                res.spec_hash()
            ),
        ));
    }
    let units = res.units();
    let mut results: Vec<Option<UnitResult>> = (0..units.len()).map(|_| None).collect();
    for (f, r) in &records {
        let expected: Vec<usize> = units
            .iter()
            .filter(|u| r.shard().owns(u.index))
            .map(|u| u.index)
            .collect();
        let got: Vec<usize> = r.units.iter().map(|(i, _)| *i).collect();
        if got != expected {
            return Err(refuse(
                &dir,
                format!("{} lists units {got:?}, expected {expected:?}", f.display()),
            ));
        }
        for &i in &expected {
            let key = unit_key(&res, &units[i], r.git_revision.as_deref());
            let path = unit_path(&f.join("units"), &key);
            results[i] = Some(load_unit(&path, &key).map_err(|e| refuse(&dir, e))?);
        }
    }
    Ok(MergedShards {
        resolved: res,
        results: results.into_iter().map(|r| r.unwrap_or_default()).collect(),
        git_revision: first.git_revision,
        git_dirty: first.git_dirty,
        count: n,
    })
}

/// Every shard's record under `dir`, in folder order; a shard without one did not finish.
fn shard_records(file: &SpecFile, dir: &Path) -> Result<Vec<(PathBuf, ShardRecord)>, Error> {
    let entries = std::fs::read_dir(dir).map_err(|e| {
        refuse(
            dir,
            format!(
                "no shards ({e}); run `motionlab run {} --shard I/N` for every I first",
                file.raw.id
            ),
        )
    })?;
    let mut folders: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    folders.sort();
    let mut records: Vec<(PathBuf, ShardRecord)> = Vec::new();
    for f in folders {
        let path = f.join(SHARD_RECORD);
        let text = std::fs::read_to_string(&path).map_err(|_| {
            refuse(
                dir,
                format!(
                    "{} has no {SHARD_RECORD}: that shard did not finish (rerun it, with --resume \
                     to keep its finished points)",
                    f.display()
                ),
            )
        })?;
        let r: ShardRecord = serde_json::from_str(&text)
            .map_err(|e| refuse(dir, format!("{}: {e}", path.display())))?;
        records.push((f, r));
    }
    Ok(records)
}

/// The shards are of this spec, one run of N shards from one spec and code revision, each
/// once and in its own folder (`records` is not empty).
fn check_records(
    file: &SpecFile,
    dir: &Path,
    records: &[(PathBuf, ShardRecord)],
) -> Result<(), Error> {
    let (first_dir, first) = &records[0];
    let n = first.of;
    for (f, r) in records {
        let name = f.file_name().and_then(|s| s.to_str()).unwrap_or("");
        let differs = |what: &str| {
            refuse(
                dir,
                format!(
                    "{} and {} come from different {what}",
                    first_dir.display(),
                    f.display()
                ),
            )
        };
        if r.id != file.raw.id {
            return Err(refuse(
                dir,
                format!("{} is a shard of `{}`", f.display(), r.id),
            ));
        }
        if r.of != n {
            return Err(refuse(
                dir,
                format!(
                    "{} is a shard of {} but {} one of {n}: shards of different counts N",
                    f.display(),
                    r.of,
                    first_dir.display()
                ),
            ));
        }
        if r.spec_hash != first.spec_hash || r.options() != first.options() {
            return Err(differs("specs (spec hash or options)"));
        }
        if r.git_revision != first.git_revision || r.git_dirty != first.git_dirty {
            return Err(differs("code revisions"));
        }
        if r.shard == 0 || r.shard > n {
            return Err(refuse(
                dir,
                format!("{}: shard {} of {n} is out of range", f.display(), r.shard),
            ));
        }
        if let Some((g, _)) = records
            .iter()
            .find(|(g, q)| g != f && q.shard == r.shard && g < f)
        {
            return Err(refuse(
                dir,
                format!(
                    "shard {} of {n} is duplicated ({} and {})",
                    r.shard,
                    g.display(),
                    f.display()
                ),
            ));
        }
        if name != r.shard().dir_name() {
            return Err(refuse(
                dir,
                format!(
                    "{} holds shard {} of {n}, whose folder is {}",
                    f.display(),
                    r.shard,
                    r.shard().dir_name()
                ),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_parses_i_of_n_and_partitions_the_units() {
        assert_eq!(Shard::parse("2/5"), Ok(Shard { index: 2, count: 5 }));
        assert_eq!(Shard::parse("3/3").unwrap().dir_name(), "3-of-3");
        for bad in ["0/3", "4/3", "1/0", "3", "a/2", "1/2/3", ""] {
            assert!(Shard::parse(bad).is_err(), "{bad}");
        }
        // Every unit belongs to exactly one of N shards.
        for n in 1..6 {
            for u in 0..20 {
                let owners = (1..=n)
                    .filter(|&i| Shard { index: i, count: n }.owns(u))
                    .count();
                assert_eq!(owners, 1, "unit {u} of {n} shards");
            }
        }
    }

    #[test]
    fn units_round_trip_bit_for_bit() {
        let dir = tempfile::tempdir().unwrap();
        let mut t = Table::new(&["name", "n", "x"]);
        t.push(crate::row!["a", 1i64, 0.1 + 0.2]);
        t.push(crate::row!["b", -3i64, f64::NAN]);
        t.push(crate::row!["c", 0i64, -0.0]);
        let tables = Tables::from([("t", t.clone()), ("empty", Table::new(&["y"]))]);
        let path = unit_path(dir.path(), "key");
        save_unit(&path, "key", &(tables, vec![("run".into(), 0.5)])).unwrap();
        let (back, stages) = load_unit(&path, "key").unwrap();
        let bt = back.get("t").unwrap();
        assert_eq!(bt.strs("name"), t.strs("name"));
        let bits = |v: Vec<f64>| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(bt.f64s("x")), bits(t.f64s("x")));
        assert_eq!(bt.column("n"), t.column("n"));
        assert_eq!(back.get("empty").unwrap().names(), ["y"]);
        assert_eq!(stages, vec![("run".to_string(), 0.5)]);
        // Another key, or a truncated file, is not a stored result.
        assert!(load_unit(&path, "other").is_err());
        let text = std::fs::read(&path).unwrap();
        std::fs::write(&path, &text[..text.len() - 3]).unwrap();
        assert!(load_unit(&path, "key").is_err());
    }
}
