//! Result tables and how they reach disk: every table is written as CSV and Parquet through
//! polars, atomically (temporary file in the same folder, then rename), so an interrupted run
//! never leaves a half-written file.

use super::Error;
use polars::prelude::*;
use std::io::Write;
use std::path::{Path, PathBuf};

/// One cell of a row.
#[derive(Debug, Clone, PartialEq)]
pub enum Cell {
    /// A float.
    F(f64),
    /// An integer.
    I(i64),
    /// A string.
    S(String),
}

impl From<f64> for Cell {
    fn from(v: f64) -> Self {
        Cell::F(v)
    }
}
impl From<i64> for Cell {
    fn from(v: i64) -> Self {
        Cell::I(v)
    }
}
impl From<usize> for Cell {
    fn from(v: usize) -> Self {
        Cell::I(v as i64)
    }
}
impl From<u32> for Cell {
    fn from(v: u32) -> Self {
        Cell::I(v as i64)
    }
}
impl From<&str> for Cell {
    fn from(v: &str) -> Self {
        Cell::S(v.to_string())
    }
}
impl From<String> for Cell {
    fn from(v: String) -> Self {
        Cell::S(v)
    }
}
impl From<&String> for Cell {
    fn from(v: &String) -> Self {
        Cell::S(v.clone())
    }
}

impl From<&toml::Value> for Cell {
    fn from(v: &toml::Value) -> Self {
        match v {
            toml::Value::Integer(i) => Cell::I(*i),
            toml::Value::Float(f) => Cell::F(*f),
            toml::Value::String(s) => Cell::S(s.clone()),
            other => Cell::S(other.to_string()),
        }
    }
}

/// Builds a row of cells: `row![a, b, c]`.
#[macro_export]
macro_rules! row {
    ($($x:expr),* $(,)?) => { vec![$($crate::experiment::output::Cell::from($x)),*] };
}

/// A typed column.
#[derive(Debug, Clone, PartialEq)]
pub enum ColumnData {
    /// Floats.
    F(Vec<f64>),
    /// Integers.
    I(Vec<i64>),
    /// Strings.
    S(Vec<String>),
}

impl ColumnData {
    /// Number of values.
    pub fn len(&self) -> usize {
        match self {
            ColumnData::F(v) => v.len(),
            ColumnData::I(v) => v.len(),
            ColumnData::S(v) => v.len(),
        }
    }
    /// Whether it holds no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    fn push(&mut self, c: Cell) -> Result<(), String> {
        match (self, c) {
            (ColumnData::F(v), Cell::F(x)) => v.push(x),
            (ColumnData::F(v), Cell::I(x)) => v.push(x as f64),
            (ColumnData::I(v), Cell::I(x)) => v.push(x),
            (ColumnData::S(v), Cell::S(x)) => v.push(x),
            (col, c) => return Err(format!("cell {c:?} does not fit a {} column", col.kind())),
        }
        Ok(())
    }
    fn kind(&self) -> &'static str {
        match self {
            ColumnData::F(_) => "float",
            ColumnData::I(_) => "integer",
            ColumnData::S(_) => "string",
        }
    }
    /// Whether row `i` holds the value `c` (integers and floats compare as numbers).
    fn cell_matches(&self, i: usize, c: &Cell) -> bool {
        match (self, c) {
            (ColumnData::S(v), Cell::S(x)) => v[i] == *x,
            (ColumnData::F(v), Cell::F(x)) => v[i] == *x,
            (ColumnData::I(v), Cell::I(x)) => v[i] == *x,
            (ColumnData::F(v), Cell::I(x)) => v[i] == *x as f64,
            (ColumnData::I(v), Cell::F(x)) => v[i] as f64 == *x,
            _ => false,
        }
    }
    fn repeat(c: &Cell, n: usize) -> Self {
        match c {
            Cell::F(x) => ColumnData::F(vec![*x; n]),
            Cell::I(x) => ColumnData::I(vec![*x; n]),
            Cell::S(x) => ColumnData::S(vec![x.clone(); n]),
        }
    }
    fn extend(&mut self, other: &ColumnData) -> Result<(), String> {
        match (self, other) {
            (ColumnData::F(a), ColumnData::F(b)) => a.extend_from_slice(b),
            (ColumnData::I(a), ColumnData::I(b)) => a.extend_from_slice(b),
            (ColumnData::S(a), ColumnData::S(b)) => a.extend_from_slice(b),
            (a, b) => return Err(format!("cannot append {} to {}", b.kind(), a.kind())),
        }
        Ok(())
    }
}

/// A named-column table built row by row. The column types are fixed by the first row.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Table {
    names: Vec<String>,
    columns: Vec<ColumnData>,
}

impl Table {
    /// An empty table with these column names.
    pub fn new(names: &[&str]) -> Self {
        Self {
            names: names.iter().map(|s| s.to_string()).collect(),
            columns: Vec::new(),
        }
    }

    /// Column names.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.columns.first().map_or(0, |c| c.len())
    }

    /// Whether it has no rows.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Appends a row; panics when the row's length or types do not fit (a programming error).
    pub fn push(&mut self, row: Vec<Cell>) {
        assert_eq!(
            row.len(),
            self.names.len(),
            "row length for columns {:?}",
            self.names
        );
        if self.columns.is_empty() {
            self.columns = row
                .iter()
                .map(|c| match c {
                    Cell::F(_) => ColumnData::F(Vec::new()),
                    Cell::I(_) => ColumnData::I(Vec::new()),
                    Cell::S(_) => ColumnData::S(Vec::new()),
                })
                .collect();
        }
        for (i, c) in row.into_iter().enumerate() {
            if let Err(e) = self.columns[i].push(c) {
                panic!("column `{}`: {e}", self.names[i]);
            }
        }
    }

    /// A column's data by name.
    pub fn column(&self, name: &str) -> Option<&ColumnData> {
        let i = self.names.iter().position(|n| n == name)?;
        self.columns.get(i)
    }

    /// Float values of a column (integers converted); empty for a table without rows.
    ///
    /// Panics when the table has no such column or it holds strings: these tables are built by
    /// the job in the same program, so either is a programming error, never an empty column.
    pub fn f64s(&self, name: &str) -> Vec<f64> {
        match self.named_column(name) {
            None => Vec::new(),
            Some(ColumnData::F(v)) => v.clone(),
            Some(ColumnData::I(v)) => v.iter().map(|&x| x as f64).collect(),
            Some(ColumnData::S(_)) => panic!("column `{name}` holds strings, not numbers"),
        }
    }

    /// Integer values of a column; empty for a table without rows. Panics when the table has
    /// no such column or it holds floats or strings (a programming error, as in
    /// [`Table::f64s`]).
    pub fn i64s(&self, name: &str) -> Vec<i64> {
        match self.named_column(name) {
            None => Vec::new(),
            Some(ColumnData::I(v)) => v.clone(),
            Some(_) => panic!("column `{name}` does not hold integers"),
        }
    }

    /// String values of a column; empty for a table without rows. Panics when the table has no
    /// such column or it holds numbers (a programming error, as in [`Table::f64s`]).
    pub fn strs(&self, name: &str) -> Vec<String> {
        match self.named_column(name) {
            None => Vec::new(),
            Some(ColumnData::S(v)) => v.clone(),
            Some(_) => panic!("column `{name}` holds numbers, not strings"),
        }
    }

    /// The data of column `name` (`None` before the first row); panics when no column has
    /// that name.
    fn named_column(&self, name: &str) -> Option<&ColumnData> {
        let Some(i) = self.names.iter().position(|n| n == name) else {
            panic!("no column `{name}` among {:?}", self.names);
        };
        self.columns.get(i)
    }

    /// This table with constant columns prepended (the sweep values of its point). A table that
    /// already has a column of that name holding that value in every row (a swept parameter the
    /// job also writes, e.g. `regimes` in a summary) keeps its own column alone; one whose column
    /// of that name holds other values gets the prefix as `sweep_<name>`.
    pub fn with_prefix(&self, prefix: &[(String, Cell)]) -> Table {
        let n = self.len();
        let (mut names, mut columns) = (Vec::new(), Vec::new());
        for (k, c) in prefix {
            let name = match self.column(k) {
                None => k.clone(),
                Some(own) if (0..n).all(|i| own.cell_matches(i, c)) => continue,
                Some(_) => format!("sweep_{k}"),
            };
            names.push(name);
            columns.push(ColumnData::repeat(c, n));
        }
        names.extend(self.names.iter().cloned());
        columns.extend(self.columns.iter().cloned());
        Table { names, columns }
    }

    /// The column data, in the order of [`Table::names`] (empty before the first row).
    pub fn columns(&self) -> &[ColumnData] {
        &self.columns
    }

    /// A table from its column names and data (all columns of one length, or no data at all).
    pub fn from_parts(names: Vec<String>, columns: Vec<ColumnData>) -> Result<Table, String> {
        if !columns.is_empty() && columns.len() != names.len() {
            return Err(format!(
                "{} columns of data for {} names",
                columns.len(),
                names.len()
            ));
        }
        if let Some(first) = columns.first() {
            if columns.iter().any(|c| c.len() != first.len()) {
                return Err("columns of different lengths".into());
            }
        }
        Ok(Table { names, columns })
    }

    /// The rows `i` for which `keep(i)` holds, in order, without the column `drop` (if given).
    pub fn select(&self, keep: impl Fn(usize) -> bool, drop: Option<&str>) -> Table {
        let rows: Vec<usize> = (0..self.len()).filter(|&i| keep(i)).collect();
        let pick = |c: &ColumnData| match c {
            ColumnData::F(v) => ColumnData::F(rows.iter().map(|&i| v[i]).collect()),
            ColumnData::I(v) => ColumnData::I(rows.iter().map(|&i| v[i]).collect()),
            ColumnData::S(v) => ColumnData::S(rows.iter().map(|&i| v[i].clone()).collect()),
        };
        let kept = |n: &String| Some(n.as_str()) != drop;
        Table {
            names: self.names.iter().filter(|n| kept(n)).cloned().collect(),
            columns: self
                .names
                .iter()
                .zip(&self.columns)
                .filter(|(n, _)| kept(n))
                .map(|(_, c)| pick(c))
                .collect(),
        }
    }

    /// Appends the rows of a table with the same columns.
    pub fn append(&mut self, other: &Table) -> Result<(), String> {
        if self.columns.is_empty() {
            *self = other.clone();
            return Ok(());
        }
        if other.columns.is_empty() {
            return Ok(());
        }
        if self.names != other.names {
            return Err(format!("columns {:?} vs {:?}", self.names, other.names));
        }
        for (a, b) in self.columns.iter_mut().zip(&other.columns) {
            a.extend(b)?;
        }
        Ok(())
    }

    /// As a polars data frame.
    pub fn to_polars(&self) -> PolarsResult<DataFrame> {
        let cols: Vec<Column> = self
            .names
            .iter()
            .enumerate()
            .map(|(i, name)| {
                let name = PlSmallStr::from(name.as_str());
                match self.columns.get(i) {
                    Some(ColumnData::F(v)) => Column::new(name, v),
                    Some(ColumnData::I(v)) => Column::new(name, v),
                    Some(ColumnData::S(v)) => Column::new(name, v),
                    None => Column::new(name, Vec::<f64>::new()),
                }
            })
            .collect();
        DataFrame::new(self.len(), cols)
    }
}

/// The named tables an experiment produced; names are file stems (`energy_drift` →
/// `energy_drift.csv`).
#[derive(Debug, Clone, Default)]
pub struct Tables(pub Vec<(String, Table)>);

impl Tables {
    /// Adds a table.
    pub fn insert(&mut self, name: &str, t: Table) {
        self.0.push((name.to_string(), t));
    }
    /// A table by name.
    pub fn get(&self, name: &str) -> Option<&Table> {
        self.0.iter().find(|(n, _)| n == name).map(|(_, t)| t)
    }

    /// A table by name, or an error naming it.
    pub fn require(&self, name: &str) -> Result<&Table, Error> {
        self.get(name)
            .ok_or_else(|| Error::Other(format!("no `{name}` table")))
    }
}

impl<const N: usize> From<[(&str, Table); N]> for Tables {
    /// Named tables, in the order given.
    fn from(tables: [(&str, Table); N]) -> Self {
        Tables(
            tables
                .into_iter()
                .map(|(n, t)| (n.to_string(), t))
                .collect(),
        )
    }
}

/// Writes `bytes` to `path` atomically: a temporary file beside it, then a rename.
pub fn atomic_write(path: &Path, bytes: &[u8]) -> Result<(), Error> {
    let io = |e: std::io::Error| Error::Io {
        path: path.to_path_buf(),
        source: e,
    };
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(io)?;
    }
    let tmp = temp_path(path);
    let written = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()
    })();
    rename_into_place(&tmp, path, written.map_err(io))
}

/// The prefix of the name of every temporary file this program writes ([`temp_path`]); the
/// clean-up of [`remove_stale_temps`] touches no other name.
pub const TEMP_PREFIX: &str = ".motionlab-tmp-";

/// A temporary sibling of `path` that keeps its name, and so its extension, behind this
/// program's prefix and process id (`a.png` → `.motionlab-tmp-PID-a.png`).
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path.file_name().and_then(|s| s.to_str()).unwrap_or("out");
    path.with_file_name(format!("{TEMP_PREFIX}{}-{name}", std::process::id()))
}

/// Puts the temporary file `tmp` that `made` wrote in its place, `path`, by a rename; when
/// `made` failed (a disk that filled up, a figure that could not be drawn), or the rename does,
/// the temporary file is removed and the error returned.
pub fn rename_into_place(tmp: &Path, path: &Path, made: Result<(), Error>) -> Result<(), Error> {
    let placed = made.and_then(|()| {
        std::fs::rename(tmp, path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })
    });
    if placed.is_err() {
        let _ = std::fs::remove_file(tmp);
    }
    placed
}

/// The process id and the final file name in the name of a temporary file of [`temp_path`]
/// (`.motionlab-tmp-PID-a.png` → `(PID, "a.png")`), if the name is one.
fn temp_owner(name: &str) -> Option<(u32, &str)> {
    let rest = name.strip_prefix(TEMP_PREFIX)?;
    let (digits, target) = rest.split_once('-')?;
    if digits.is_empty() || target.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    Some((digits.parse().ok()?, target))
}

/// Whether process `pid` is running on this machine: `Some` where the system says (Linux's
/// `/proc`), `None` where it cannot tell.
pub fn process_alive(pid: u32) -> Option<bool> {
    if pid == std::process::id() {
        return Some(true);
    }
    let proc = Path::new("/proc");
    (cfg!(target_os = "linux") && proc.join("self").exists())
        .then(|| proc.join(pid.to_string()).exists())
}

/// How long a temporary file must have gone unmodified before [`remove_stale_temps`] takes it
/// for a leftover. One write takes well under a second; the margin covers shards of one sweep
/// on other machines writing into a shared folder, whose processes this machine cannot see.
pub const STALE_AFTER: std::time::Duration = std::time::Duration::from_secs(600);

/// Removes the temporary files ([`temp_path`]) that runs stopped mid-write left (an atomic
/// write's temporary file, never a final one) in the folders this program writes, and only
/// there: `<out>/<id>/` of each experiment id in `ids` with the folders a run makes in it
/// (`units/`, `seeds/<seed>/`, `shards/<I-of-N>/` and its `units/`), the report's in `out`
/// itself, and the figures' (`<id>_…`) in `figures`; returns the files removed. Only names with
/// this program's prefix ([`TEMP_PREFIX`]) count, and one counts as left over when nothing has
/// written to it for [`STALE_AFTER`] and the process named in it is not running on this machine
/// (or the system cannot say). Folders that do not exist have none; other folders and files
/// (a user's `photos/.IMG_0001.tmp-424242.jpg`) are never touched.
pub fn remove_stale_temps(
    out: &Path,
    figures: &Path,
    ids: &[String],
) -> Result<Vec<PathBuf>, Error> {
    let mut removed = vec![];
    sweep_temps(out, &|t| t == "REPORT.md", &mut removed)?;
    let of_an_id = |t: &str| {
        ids.iter().any(|id| {
            t.strip_prefix(id.as_str())
                .is_some_and(|r| r.starts_with('_'))
        })
    };
    sweep_temps(figures, &of_an_id, &mut removed)?;
    for id in ids {
        for dir in experiment_folders(&out.join(id))? {
            sweep_temps(&dir, &|_| true, &mut removed)?;
        }
    }
    Ok(removed)
}

/// The folder of an experiment and the folders a run makes in it: `units/`, `seeds/<seed>/`,
/// `shards/<I-of-N>/` and `shards/<I-of-N>/units/` (those that exist; links not followed).
pub fn experiment_folders(dir: &Path) -> Result<Vec<PathBuf>, Error> {
    let seed = |n: &str| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit());
    let shard = |n: &str| {
        n.split_once("-of-")
            .is_some_and(|(i, k)| seed(i) && seed(k))
    };
    if !dir.is_dir() {
        return Ok(vec![]);
    }
    let mut all = vec![dir.to_path_buf()];
    all.extend(subfolders(dir, &|n| n == "units")?);
    for seeds in subfolders(dir, &|n| n == "seeds")? {
        all.extend(subfolders(&seeds, &seed)?);
    }
    for shards in subfolders(dir, &|n| n == "shards")? {
        for one in subfolders(&shards, &shard)? {
            all.extend(subfolders(&one, &|n| n == "units")?);
            all.push(one);
        }
    }
    Ok(all)
}

/// The folders (not links) in `dir` whose names `keep`, sorted; none when `dir` does not exist.
fn subfolders(dir: &Path, keep: &dyn Fn(&str) -> bool) -> Result<Vec<PathBuf>, Error> {
    let mut out = vec![];
    for entry in entries(dir)? {
        let kind = entry.file_type().map_err(|source| Error::Io {
            path: entry.path(),
            source,
        })?;
        if kind.is_dir() && entry.file_name().to_str().is_some_and(keep) {
            out.push(entry.path());
        }
    }
    Ok(out)
}

/// The entries of `dir`, sorted by name; none when it does not exist or is not a folder.
fn entries(dir: &Path) -> Result<Vec<std::fs::DirEntry>, Error> {
    let io = |source| Error::Io {
        path: dir.to_path_buf(),
        source,
    };
    let entries = match std::fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(e)
            if matches!(
                e.kind(),
                std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory
            ) =>
        {
            return Ok(vec![])
        }
        Err(e) => return Err(io(e)),
    };
    let mut entries = entries.collect::<Result<Vec<_>, _>>().map_err(io)?;
    entries.sort_by_key(|e| e.file_name());
    Ok(entries)
}

/// Removes the stale temporary files directly in `dir` (not below) whose final name `want`s.
fn sweep_temps(
    dir: &Path,
    want: &dyn Fn(&str) -> bool,
    removed: &mut Vec<PathBuf>,
) -> Result<(), Error> {
    for entry in entries(dir)? {
        let path = entry.path();
        let io = |source| Error::Io {
            path: path.clone(),
            source,
        };
        if !entry.file_type().map_err(io)?.is_file() {
            continue;
        }
        let name = entry.file_name();
        let Some((pid, target)) = name.to_str().and_then(temp_owner) else {
            continue;
        };
        let idle = || {
            let modified = entry.metadata().and_then(|m| m.modified());
            modified.is_ok_and(|t| t.elapsed().is_ok_and(|age| age >= STALE_AFTER))
        };
        if want(target) && process_alive(pid) != Some(true) && idle() {
            std::fs::remove_file(&path).map_err(io)?;
            removed.push(path);
        }
    }
    Ok(())
}

/// Writes `<dir>/<name>.csv` and `<dir>/<name>.parquet`; returns both paths.
pub fn write_table(dir: &Path, name: &str, table: &Table) -> Result<Vec<PathBuf>, Error> {
    let pl = |e: PolarsError| Error::Polars(format!("{name}: {e}"));
    let mut df = table.to_polars().map_err(pl)?;
    let mut csv = Vec::new();
    CsvWriter::new(&mut csv).finish(&mut df).map_err(pl)?;
    let mut pq = Vec::new();
    ParquetWriter::new(&mut pq).finish(&mut df).map_err(pl)?;
    let csv_path = dir.join(format!("{name}.csv"));
    let pq_path = dir.join(format!("{name}.parquet"));
    atomic_write(&csv_path, &csv)?;
    atomic_write(&pq_path, &pq)?;
    Ok(vec![csv_path, pq_path])
}

/// Float values of a polars column (integers cast), nulls as NaN.
pub fn df_f64(df: &DataFrame, name: &str) -> Result<Vec<f64>, Error> {
    let pe = |e: PolarsError| Error::Polars(format!("column {name}: {e}"));
    let c = df
        .column(name)
        .map_err(pe)?
        .cast(&DataType::Float64)
        .map_err(pe)?;
    Ok(c.f64()
        .map_err(pe)?
        .iter()
        .map(|v| v.unwrap_or(f64::NAN))
        .collect())
}

/// String values of a polars column, nulls as empty strings.
pub fn df_str(df: &DataFrame, name: &str) -> Result<Vec<String>, Error> {
    let pe = |e: PolarsError| Error::Polars(format!("column {name}: {e}"));
    let c = df
        .column(name)
        .map_err(pe)?
        .cast(&DataType::String)
        .map_err(pe)?;
    Ok(c.str()
        .map_err(pe)?
        .iter()
        .map(|v| v.unwrap_or("").to_string())
        .collect())
}

/// Unique values in first-seen order (e.g. the series names of a long table).
pub fn unique(v: &[String]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for s in v {
        if !out.contains(s) {
            out.push(s.clone());
        }
    }
    out
}

/// The run record (`run.json`) that covers the result folder `dir`: the experiment's own, or
/// for a seed's folder (`<id>/seeds/<s>/`) the experiment's two levels up.
fn run_record(dir: &Path) -> Option<PathBuf> {
    [Some(dir), dir.parent().and_then(Path::parent)]
        .into_iter()
        .flatten()
        .map(|d| d.join("run.json"))
        .find(|p| p.is_file())
}

/// [`read_csv`] of `dir/name`, a table that a run writes only when its spec asks for the study
/// behind it (net seeds, DAgger rounds, a sweep): whether the run wrote it is read from the run
/// record's file list (`run.json`'s `files`), not from the folder.
///
/// - Listed there: the table is read, and a missing or cut file is an error naming it.
/// - Not listed: `None`, the study was not asked for.
/// - No run record (a folder that no run finished, as in tests): `None` when the file is
///   absent, else it is read.
///
/// So deleting or truncating a table the run wrote is an error, never a quieter verdict.
pub fn written_csv(dir: &Path, name: &str) -> Result<Option<DataFrame>, Error> {
    let path = dir.join(name);
    let Some(record) = run_record(dir) else {
        return if path.exists() {
            read_csv(&path).map(Some)
        } else {
            Ok(None)
        };
    };
    let text = std::fs::read_to_string(&record).map_err(|source| Error::Io {
        path: record.clone(),
        source,
    })?;
    let bad = |why: &str| Error::Other(format!("{}: {why}", record.display()));
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| bad(&format!("not JSON: {e}")))?;
    let files = v
        .get("files")
        .and_then(|f| f.as_array())
        .ok_or_else(|| bad("has no `files` list"))?;
    // `files` names paths relative to the results root, the folder above the experiment's.
    let root = record
        .parent()
        .and_then(Path::parent)
        .unwrap_or(Path::new(""));
    let rel = path.strip_prefix(root).unwrap_or(&path);
    let rel = rel.to_string_lossy().replace('\\', "/");
    if files.iter().any(|f| f.as_str() == Some(rel.as_str())) {
        read_csv(&path).map(Some)
    } else {
        Ok(None)
    }
}

/// An integer column of a data frame; a missing value, or a column that does not hold integers
/// (e.g. `0.5`), is an error naming the column.
pub fn df_i64(df: &DataFrame, name: &str) -> Result<Vec<i64>, Error> {
    let pe = |e: PolarsError| Error::Polars(format!("column {name}: {e}"));
    let c = df.column(name).map_err(pe)?;
    // A table with a header and no rows gives polars nothing to infer a type from.
    if c.is_empty() {
        return Ok(Vec::new());
    }
    if !c.dtype().is_integer() {
        return Err(Error::Polars(format!(
            "column {name}: {} values, not integers",
            c.dtype()
        )));
    }
    let c = c.cast(&DataType::Int64).map_err(pe)?;
    c.i64()
        .map_err(pe)?
        .iter()
        .map(|v| v.ok_or_else(|| Error::Polars(format!("column {name}: a missing value"))))
        .collect()
}

/// Reads a CSV written by [`write_table`] into a polars data frame, strictly: a table that is
/// not whole (see [`check_csv`]) is an error naming the file and line, never a frame with
/// missing or made-up values.
pub fn read_csv(path: &Path) -> Result<DataFrame, Error> {
    let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let twin = parquet_twin(path);
    let have = check_csv(path, &text, &twin.numeric)?;
    if let Some(rows) = twin.rows {
        if have != rows {
            return Err(malformed(
                path,
                text.lines().count(),
                format!(
                    "{have} rows where the Parquet table written beside it has {rows} \
                     (rows cut off or added)"
                ),
            ));
        }
    }
    CsvReadOptions::default()
        .with_has_header(true)
        .try_into_reader_with_file_path(Some(path.to_path_buf()))
        .and_then(|r| r.finish())
        .map_err(|e| Error::Polars(format!("{}: {e}", path.display())))
}

/// What the Parquet file [`write_table`] wrote beside a CSV says about the table.
#[derive(Debug, Default)]
struct ParquetTwin {
    /// Each column's name and whether it holds numbers; empty when there is none to read.
    numeric: Vec<(String, bool)>,
    /// Its number of rows, when it can be read: a CSV cut at a row boundary still parses as a
    /// whole table, and only this count tells it from the table the run wrote.
    rows: Option<usize>,
}

/// The [`ParquetTwin`] of the CSV at `path` (empty when there is no Parquet file beside it, as
/// for tables not written by [`write_table`]).
fn parquet_twin(path: &Path) -> ParquetTwin {
    let Ok(file) = std::fs::File::open(path.with_extension("parquet")) else {
        return ParquetTwin::default();
    };
    let mut reader = ParquetReader::new(file);
    let numeric = match reader.schema() {
        Ok(schema) => schema
            .iter()
            .map(|(name, field)| (name.to_string(), field.dtype.is_numeric()))
            .collect(),
        Err(_) => Vec::new(),
    };
    ParquetTwin {
        numeric,
        rows: reader.num_rows().ok(),
    }
}

/// The records of CSV `text` (RFC 4180 quoting, as polars writes it): each with the 1-based
/// line it starts on and its fields (unquoted text, whether it was quoted); an error names
/// the line of a quote left open.
pub(crate) fn csv_records(
    path: &Path,
    text: &str,
) -> Result<Vec<(usize, Vec<(String, bool)>)>, Error> {
    let mut records = Vec::new();
    let (mut line, mut start) = (1, 1);
    let mut fields: Vec<(String, bool)> = Vec::new();
    let (mut field, mut quoted, mut in_quotes) = (String::new(), false, false);
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '"' if in_quotes && chars.peek() == Some(&'"') => {
                chars.next();
                field.push('"');
            }
            '"' if in_quotes => in_quotes = false,
            '"' if field.is_empty() && !quoted => (in_quotes, quoted) = (true, true),
            '\n' if !in_quotes => {
                if field.ends_with('\r') && !quoted {
                    field.pop();
                }
                fields.push((std::mem::take(&mut field), quoted));
                records.push((start, std::mem::take(&mut fields)));
                quoted = false;
                line += 1;
                start = line;
            }
            ',' if !in_quotes => {
                fields.push((std::mem::take(&mut field), quoted));
                quoted = false;
            }
            c => {
                if c == '\n' {
                    line += 1;
                }
                field.push(c);
            }
        }
    }
    if in_quotes {
        return Err(malformed(
            path,
            start,
            "a quoted field is not closed (the file is cut short)",
        ));
    }
    if !field.is_empty() || quoted || !fields.is_empty() {
        fields.push((field, quoted));
        records.push((start, fields));
    }
    Ok(records)
}

fn malformed(path: &Path, line: usize, what: impl std::fmt::Display) -> Error {
    Error::Table {
        path: path.to_path_buf(),
        line,
        message: what.to_string(),
    }
}

/// Checks that CSV `text` from `path` is a whole table as [`write_table`] writes it: a
/// header, every row with as many fields as the header, a line end after the last row (a
/// file cut short mid-row has none), and in every numeric column a number in every row.
/// `numeric` gives the numeric columns by name (from the Parquet file beside it); a column it
/// does not name counts as numeric when most of its cells are numbers. An error names the
/// file and the line; a whole table gives its number of rows.
pub fn check_csv(path: &Path, text: &str, numeric: &[(String, bool)]) -> Result<usize, Error> {
    if text.is_empty() {
        return Err(malformed(path, 1, "the file is empty (no header)"));
    }
    let records = csv_records(path, text)?;
    let Some(((_, header), rows)) = records.split_first() else {
        return Err(malformed(path, 1, "the file is empty (no header)"));
    };
    for (line, fields) in rows {
        if fields.len() != header.len() {
            return Err(malformed(
                path,
                *line,
                format!(
                    "{} fields where the header has {} (a row cut short or run together)",
                    fields.len(),
                    header.len()
                ),
            ));
        }
    }
    let lines = text.lines().count();
    if !text.ends_with('\n') {
        return Err(malformed(
            path,
            lines,
            "the last row has no line end (the file is cut short)",
        ));
    }
    let is_number = |s: &str| s.trim().parse::<f64>().is_ok();
    for (c, (name, _)) in header.iter().enumerate() {
        let declared = numeric.iter().find(|(n, _)| n == name).map(|(_, k)| *k);
        let is_numeric = declared.unwrap_or_else(|| {
            2 * rows
                .iter()
                .filter(|(_, f)| !f[c].1 && is_number(&f[c].0))
                .count()
                > rows.len()
        });
        if !is_numeric {
            continue;
        }
        for (line, fields) in rows {
            let (cell, _) = &fields[c];
            if cell.is_empty() {
                return Err(malformed(
                    path,
                    *line,
                    format!("column `{name}`: empty cell where a number belongs"),
                ));
            }
            if !is_number(cell) {
                return Err(malformed(
                    path,
                    *line,
                    format!("column `{name}`: not a number: {cell:?}"),
                ));
            }
        }
    }
    Ok(rows.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A column read by a name the table does not have, or as the wrong type, stops the
    /// program naming it, rather than reading as an empty column; a table without rows reads
    /// as empty columns.
    #[test]
    fn a_missing_or_mistyped_column_is_an_error_not_an_empty_one() {
        let mut t = Table::new(&["name", "x"]);
        assert!(t.f64s("x").is_empty() && t.strs("name").is_empty());
        t.push(row!["a", 0.5]);
        assert_eq!(t.f64s("x"), vec![0.5]);
        for read in [
            Box::new(|t: &Table| drop(t.f64s("missing"))) as Box<dyn Fn(&Table)>,
            Box::new(|t: &Table| drop(t.strs("missing"))),
            Box::new(|t: &Table| drop(t.f64s("name"))),
            Box::new(|t: &Table| drop(t.strs("x"))),
        ] {
            let err = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| read(&t)))
                .expect_err("a bad column read must not pass");
            let msg = err.downcast_ref::<String>().cloned().unwrap_or_default();
            assert!(msg.contains("column `"), "{msg}");
        }
    }

    /// A table the run record lists is required: deleted or cut, it is an error naming the
    /// file; one the run did not write reads as absent, even when a stray file lies there; a
    /// seed's folder is covered by the experiment's record two levels up.
    #[test]
    fn a_table_the_run_wrote_is_required_and_one_it_did_not_is_absent() {
        let root = tempfile::tempdir().unwrap();
        let dir = root.path().join("e1");
        let seed = dir.join("seeds").join("1");
        std::fs::create_dir_all(&seed).unwrap();
        let files = r#"{"files": ["e1/a.csv", "e1/seeds/1/c.csv"]}"#;
        std::fs::write(dir.join("run.json"), files).unwrap();
        std::fs::write(dir.join("a.csv"), "x\n1\n2\n").unwrap();
        std::fs::write(dir.join("b.csv"), "x\n1\n").unwrap();
        std::fs::write(seed.join("c.csv"), "x\n3\n").unwrap();
        let a = written_csv(&dir, "a.csv").unwrap().expect("listed");
        assert_eq!(df_f64(&a, "x").unwrap(), vec![1.0, 2.0]);
        assert!(
            written_csv(&dir, "b.csv").unwrap().is_none(),
            "not listed: absent"
        );
        let c = written_csv(&seed, "c.csv")
            .unwrap()
            .expect("listed under the seed");
        assert_eq!(df_f64(&c, "x").unwrap(), vec![3.0]);
        // Cut mid-row, then deleted: both errors naming the file.
        std::fs::write(dir.join("a.csv"), "x,y\n1,2\n3").unwrap();
        let cut = written_csv(&dir, "a.csv").expect_err("a cut table is an error");
        assert!(cut.to_string().contains("a.csv"), "{cut}");
        std::fs::remove_file(dir.join("a.csv")).unwrap();
        let gone = written_csv(&dir, "a.csv").expect_err("a deleted table is an error");
        assert!(gone.to_string().contains("a.csv"), "{gone}");
        // Without a record (a folder no run finished) the folder decides.
        let bare = root.path().join("bare");
        std::fs::create_dir_all(&bare).unwrap();
        assert!(written_csv(&bare, "a.csv").unwrap().is_none());
    }

    #[test]
    fn tables_round_trip_through_csv() {
        let dir = tempfile::tempdir().unwrap();
        let mut t = Table::new(&["name", "n", "x"]);
        t.push(row!["a", 1usize, 0.5]);
        t.push(row!["b", 2usize, 1e-12]);
        write_table(dir.path(), "t", &t).unwrap();
        let text = std::fs::read_to_string(dir.path().join("t.csv")).unwrap();
        assert!(text.starts_with("name,n,x\n"), "{text}");
        let df = read_csv(&dir.path().join("t.csv")).unwrap();
        assert_eq!(df.height(), 2);
        assert!(dir.path().join("t.parquet").exists());
        // No temporary files are left behind.
        let leftovers = std::fs::read_dir(dir.path())
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .starts_with(TEMP_PREFIX)
            })
            .count();
        assert_eq!(leftovers, 0);
    }

    /// A write that fails (here the rename: a folder holds the final name) reports the path
    /// and leaves no temporary file.
    #[test]
    fn a_failed_write_leaves_no_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("t.csv");
        std::fs::create_dir(&target).unwrap();
        let err = atomic_write(&target, b"a,b\n").unwrap_err();
        assert!(err.to_string().contains("t.csv"), "{err}");
        let names: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["t.csv"]);
    }

    /// Temporary files of processes that no longer run are removed from an experiment's folder
    /// and the folders a run makes in it, the report's from the results root and the figures'
    /// from the figures folder; those of a running process (this one), final files, names that
    /// merely look alike, a user's files of the old `.<name>.tmp-<pid>.<ext>` shape and anything
    /// in folders that are not an experiment's stay.
    #[test]
    fn stale_temporary_files_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        let (out, figs) = (dir.path().join("out"), dir.path().join("figs"));
        let exp = out.join("exp");
        let units = exp.join("units");
        let seed = exp.join("seeds/3");
        let shard = exp.join("shards/1-of-2");
        let shard_units = shard.join("units");
        let photos = out.join("photos");
        let mine = exp.join("mine");
        for d in [&units, &seed, &shard_units, &photos, &mine, &figs] {
            std::fs::create_dir_all(d).unwrap();
        }
        // No process has an id above Linux's largest (2²²): these owners do not run.
        let dead = u32::MAX;
        let ours = |d: &Path, name: &str| d.join(format!("{TEMP_PREFIX}{dead}-{name}"));
        let stale = [
            ours(&figs, "exp_fig.png"),
            ours(&out, "REPORT.md"),
            ours(&exp, "a.b.csv"),
            ours(&units, "u0.json"),
            ours(&seed, "t.parquet"),
            ours(&shard, "shard.json"),
            ours(&shard_units, "u1.json"),
        ];
        let live = temp_path(&exp.join("t.csv"));
        let kept = [
            live.clone(),
            exp.join("t.csv"),
            exp.join(format!("{TEMP_PREFIX}x1-t.csv")),
            exp.join(format!("{TEMP_PREFIX}-t.csv")),
            exp.join(format!("{TEMP_PREFIX}{dead}-")),
            exp.join(format!("motionlab-tmp-{dead}-t.csv")),
            // A user's files of the old temporary shape, anywhere.
            out.join(".IMG_0001.tmp-424242.jpg"),
            exp.join(format!(".IMG_0001.tmp-{dead}.jpg")),
            photos.join(".IMG_0001.tmp-424242.jpg"),
            figs.join(format!(".exp_fig.tmp-{dead}.png")),
            // Our prefix, but not in a folder of ours or not for a file of ours.
            ours(&photos, "x.csv"),
            ours(&mine, "x.csv"),
            ours(&out, "t.csv"),
            ours(&figs, "other_fig.png"),
            ours(&figs, "expfig.png"),
        ];
        // Written just now: a run on another machine may still be writing it.
        let recent = ours(&exp, "new.csv");
        let old = std::time::SystemTime::now() - STALE_AFTER - STALE_AFTER;
        for f in stale.iter().chain(&kept) {
            std::fs::write(f, b"x").unwrap();
            let file = std::fs::File::options().write(true).open(f).unwrap();
            file.set_modified(old).unwrap();
        }
        std::fs::write(&recent, b"x").unwrap();
        let ids = ["exp".to_string()];
        let mut removed = remove_stale_temps(&out, &figs, &ids).unwrap();
        removed.sort();
        let mut want = stale.to_vec();
        want.sort();
        assert_eq!(removed, want);
        assert!(stale.iter().all(|f| !f.exists()));
        let own = temp_owner(live.file_name().unwrap().to_str().unwrap());
        assert_eq!(own, Some((std::process::id(), "t.csv")));
        assert!(
            recent.exists(),
            "a temporary file written just now was removed"
        );
        for f in &kept {
            assert!(f.exists(), "{} was removed", f.display());
        }
        let none = dir.path().join("none");
        assert!(remove_stale_temps(&none, &none, &ids).unwrap().is_empty());
    }

    /// A temporary file keeps the final name's extension (plotters picks the format by it) and
    /// carries the program's prefix.
    #[test]
    fn temporary_names_carry_the_prefix_and_the_extension() {
        let t = temp_path(Path::new("figs/exp_fig.png"));
        assert_eq!(t.parent(), Some(Path::new("figs")));
        assert_eq!(t.extension().unwrap(), "png");
        let name = t.file_name().unwrap().to_str().unwrap();
        assert!(name.starts_with(TEMP_PREFIX), "{name}");
        assert_eq!(temp_owner(name), Some((std::process::id(), "exp_fig.png")));
    }

    #[test]
    fn prefix_and_append() {
        let mut a = Table::new(&["x"]);
        a.push(row![1.0]);
        let p = a.with_prefix(&[("dt".into(), Cell::F(0.1))]);
        let mut all = Table::default();
        all.append(&p).unwrap();
        all.append(&p).unwrap();
        assert_eq!(all.len(), 2);
        assert_eq!(all.f64s("dt"), vec![0.1, 0.1]);
    }

    #[test]
    fn prefix_of_a_column_the_table_has() {
        let mut a = Table::new(&["regimes", "x"]);
        a.push(row![4i64, 1.0]);
        a.push(row![4i64, 2.0]);
        // The same value: the table's own column stands for the sweep axis.
        let same = a.with_prefix(&[("regimes".into(), Cell::I(4))]);
        assert_eq!(same.names(), &["regimes", "x"]);
        let same_f = a.with_prefix(&[("regimes".into(), Cell::F(4.0))]);
        assert_eq!(same_f.names(), &["regimes", "x"]);
        // Another value: the sweep value gets its own column, no duplicate name.
        let other = a.with_prefix(&[("seed".into(), Cell::I(1)), ("regimes".into(), Cell::I(6))]);
        assert_eq!(other.names(), &["seed", "sweep_regimes", "regimes", "x"]);
        assert_eq!(other.f64s("sweep_regimes"), vec![6.0, 6.0]);
    }
}
