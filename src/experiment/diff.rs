//! # Comparing two result folders: what `motionlab diff A B` reports
//!
//! Two results folders that should hold the same numbers (two revisions' `results/`, a merge of
//! shards against the unsharded run, a rerun on another machine) are compared table by table,
//! so that "nothing changed but timing" is checked rather than eyeballed. A folder is a results
//! root as `reproduce` writes it: one subfolder per experiment id holding CSV tables (and their
//! `seeds/<seed>/` copies), and a `REPORT.md` whose claims tables give each experiment's verdict.
//!
//! - **Folders and tables.** The experiment folders (the root's subfolders) and the CSV tables
//!   (every `*.csv` below the root, by relative path) present on one side only. A table under a
//!   folder that is missing altogether is not listed again on its own.
//! - **Cells.** For each table present on both sides: the columns on one side only, the number
//!   of rows, and the cells of the shared columns (matched by name, rows by position) that
//!   differ. Two cells that both read as numbers are equal within `atol + rtol·max(|a|, |b|)`,
//!   a NaN equals a NaN and an infinity only itself; any other pair is compared as text,
//!   exactly. A bounded sample of the differing cells is kept, and their count.
//! - **Timing columns.** Wall-clock columns (see [`is_timing_column`]) differ on every run, so
//!   their cells are not counted as changes unless `all_columns` is set; where they differ they
//!   are listed apart ([`IgnoredColumn`]), so nothing is dropped silently. A timing column that
//!   appears or disappears is still a change of the table's columns.
//! - **Verdicts.** The verdict of each experiment in the claims tables of both `REPORT.md`
//!   files, without its parenthesized marks ("(stale)", "(changed after results: 2)"). When
//!   either side has no `REPORT.md` the verdicts are skipped, saying so.
//! - **Not compared.** `run.json` (it names revisions, hosts and times), the Parquet twins of
//!   the CSV tables (the same tables), resume units (JSON) and figures (kept elsewhere).
//!
//! [`diff`] reads the two folders and returns a [`Diff`]; it prints nothing. Its `Display` is
//! the text `motionlab diff` prints and its serde form the `--json` object.

use super::output::csv_records;
use super::Error;
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};
use std::ffi::OsString;
use std::fmt;
use std::path::{Path, PathBuf};

/// The report whose claims tables give the verdicts, at the root of each folder.
pub const REPORT: &str = "REPORT.md";

/// How two folders are compared.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Options {
    /// Relative tolerance of numeric cells.
    pub rtol: f64,
    /// Absolute tolerance of numeric cells.
    pub atol: f64,
    /// Compare timing columns too (see [`is_timing_column`]).
    pub all_columns: bool,
    /// Most differing cells kept per table as a sample (all are counted).
    pub max_cells: usize,
}

impl Default for Options {
    /// Tolerances tight enough that only rounding in the last digits passes: the tables of two
    /// runs of the same code are bit for bit equal, so anything more is a change.
    fn default() -> Self {
        Self {
            rtol: 1e-9,
            atol: 1e-12,
            all_columns: false,
            max_cells: 10,
        }
    }
}

impl Options {
    /// Refuses a tolerance that is negative or not finite: it would make every cell equal, or
    /// none.
    pub fn check(&self) -> Result<(), Error> {
        for (flag, v) in [("--rtol", self.rtol), ("--atol", self.atol)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::Other(format!(
                    "{flag} must be >= 0 and finite, got {v:?}"
                )));
            }
        }
        Ok(())
    }
}

/// Everything that differs between folders A and B (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Diff {
    /// Folder A, as given.
    pub a: String,
    /// Folder B, as given.
    pub b: String,
    /// How they were compared.
    pub options: Options,
    /// Whether anything below differs (ignored timing columns do not count).
    pub changed: bool,
    /// Experiment folders in A and not in B.
    pub folders_missing_in_b: Vec<String>,
    /// Experiment folders in B and not in A.
    pub folders_extra_in_b: Vec<String>,
    /// CSV tables in A and not in B (relative paths), other than those of a missing folder.
    pub tables_missing_in_b: Vec<String>,
    /// CSV tables in B and not in A, other than those of an extra folder.
    pub tables_extra_in_b: Vec<String>,
    /// Number of tables present on both sides, all compared.
    pub tables_compared: usize,
    /// The tables that differ, in path order.
    pub tables: Vec<TableDiff>,
    /// The timing columns whose cells differ, not counted as changes.
    pub ignored: Vec<IgnoredColumn>,
    /// The verdicts of the two reports.
    pub verdicts: Verdicts,
}

/// How one table present on both sides differs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TableDiff {
    /// Its path relative to the folder, `/`-separated (`ms_lattices/lattices.csv`).
    pub table: String,
    /// Columns in A and not in B.
    pub columns_missing_in_b: Vec<String>,
    /// Columns in B and not in A.
    pub columns_extra_in_b: Vec<String>,
    /// Data rows in A (the header not counted).
    pub rows_a: usize,
    /// Data rows in B.
    pub rows_b: usize,
    /// Cells that differ beyond the tolerances, in the shared columns and rows.
    pub cells_differing: usize,
    /// The first of them (at most [`Options::max_cells`]), row by row.
    pub cells: Vec<CellDiff>,
}

/// One cell that differs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CellDiff {
    /// Data row, from 0 (the header not counted).
    pub row: usize,
    /// Column name.
    pub column: String,
    /// The cell in A, as written.
    pub a: String,
    /// The cell in B, as written.
    pub b: String,
}

/// A timing column whose cells differ, left out of the comparison.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IgnoredColumn {
    /// The table's relative path.
    pub table: String,
    /// The column.
    pub column: String,
    /// How many of its cells differ.
    pub cells_differing: usize,
}

/// The verdicts of the two reports' claims tables.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum Verdicts {
    /// Both reports were read.
    Compared {
        /// Experiments listed in both.
        compared: usize,
        /// Those whose verdict differs.
        changed: Vec<VerdictChange>,
        /// Experiments in A's claims tables and not in B's.
        missing_in_b: Vec<String>,
        /// Experiments in B's claims tables and not in A's.
        extra_in_b: Vec<String>,
    },
    /// Not compared, and why (a `REPORT.md` is absent).
    Skipped {
        /// Which report is absent.
        reason: String,
    },
}

impl Verdicts {
    fn changed(&self) -> bool {
        match self {
            Verdicts::Compared {
                changed,
                missing_in_b,
                extra_in_b,
                ..
            } => !(changed.is_empty() && missing_in_b.is_empty() && extra_in_b.is_empty()),
            Verdicts::Skipped { .. } => false,
        }
    }
}

/// An experiment whose verdict differs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VerdictChange {
    /// Experiment id.
    pub id: String,
    /// Its verdict in A.
    pub a: String,
    /// Its verdict in B.
    pub b: String,
}

/// Whether column `name` holds a wall-clock measurement, which differs from run to run (and
/// machine to machine) while every other number is reproducible: a name with `seconds` in it,
/// or one of the measured rates and times the result tables name otherwise ([`TIMING`]).
/// Columns of simulated time or physical units (`horizon_s`, `fell_at_s`, `speed_m_s`,
/// `wall_force`) are results and are compared; `--all-columns` compares every column.
pub fn is_timing_column(name: &str) -> bool {
    name.contains("seconds") || TIMING.contains(&name)
}

/// Wall-clock columns whose names do not say `seconds`: the step costs and rates of the
/// speed tables and what is computed from them.
const TIMING: [&str; 9] = [
    "train_s",
    "emulator_s",
    "emulator_step_s",
    "physical_s",
    "physical_step_s",
    "evals_per_s",
    "us_per_step",
    "speedup",
    "step_cost_ratio",
];

/// Whether two cells are the same: equal text; or two numbers within `atol + rtol·max(|a|,
/// |b|)` when both are finite, and otherwise equal (an infinity only equals itself, a NaN a
/// NaN).
pub fn cells_equal(a: &str, b: &str, rtol: f64, atol: f64) -> bool {
    if a == b {
        return true;
    }
    let number = |s: &str| s.trim().parse::<f64>().ok();
    match (number(a), number(b)) {
        (Some(x), Some(y)) if x.is_finite() && y.is_finite() => {
            (x - y).abs() <= atol + rtol * x.abs().max(y.abs())
        }
        (Some(x), Some(y)) => x == y || (x.is_nan() && y.is_nan()),
        _ => false,
    }
}

/// Compares folders `a` and `b` (see the [module docs](self)). Errors: a side that is not a
/// folder (named, and which side), a file that cannot be read, a CSV with a quote left open.
pub fn diff(a: &Path, b: &Path, opts: &Options) -> Result<Diff, Error> {
    opts.check()?;
    for (side, dir) in [("A", a), ("B", b)] {
        if !dir.is_dir() {
            let what = if dir.exists() {
                "is not a folder"
            } else {
                "does not exist"
            };
            return Err(Error::Other(format!(
                "folder {side} {what}: {}",
                dir.display()
            )));
        }
    }
    let (folders_a, folders_b) = (subfolders(a)?, subfolders(b)?);
    let folders_missing_in_b = minus(&folders_a, &folders_b);
    let folders_extra_in_b = minus(&folders_b, &folders_a);
    let (tables_a, tables_b) = (csv_tables(a)?, csv_tables(b)?);
    // A table of a folder missing altogether is said once, by its folder.
    let under = |folders: &[String], table: &str| {
        table
            .split_once('/')
            .is_some_and(|(top, _)| folders.iter().any(|f| f == top))
    };
    let tables_missing_in_b = minus(&tables_a, &tables_b)
        .into_iter()
        .filter(|t| !under(&folders_missing_in_b, t))
        .collect();
    let tables_extra_in_b = minus(&tables_b, &tables_a)
        .into_iter()
        .filter(|t| !under(&folders_extra_in_b, t))
        .collect();
    let (mut tables, mut ignored, mut tables_compared) = (Vec::new(), Vec::new(), 0);
    for (name, rel) in &tables_a {
        if tables_b.contains_key(name) {
            tables_compared += 1;
            let (t, i) = compare_table(name, &a.join(rel), &b.join(rel), opts)?;
            tables.extend(t);
            ignored.extend(i);
        }
    }
    let verdicts = compare_verdicts(a, b)?;
    let mut d = Diff {
        a: a.display().to_string(),
        b: b.display().to_string(),
        options: *opts,
        changed: false,
        folders_missing_in_b,
        folders_extra_in_b,
        tables_missing_in_b,
        tables_extra_in_b,
        tables_compared,
        tables,
        ignored,
        verdicts,
    };
    d.changed = !(d.folders_missing_in_b.is_empty()
        && d.folders_extra_in_b.is_empty()
        && d.tables_missing_in_b.is_empty()
        && d.tables_extra_in_b.is_empty()
        && d.tables.is_empty())
        || d.verdicts.changed();
    Ok(d)
}

/// The keys of `x` that are not in `y`, in order.
fn minus<T>(x: &BTreeMap<String, T>, y: &BTreeMap<String, T>) -> Vec<String> {
    x.keys().filter(|k| !y.contains_key(*k)).cloned().collect()
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |source| Error::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// The entries of `dir` with their kinds, sorted by name (links are neither files nor folders
/// here, so none is followed).
fn entries(dir: &Path) -> Result<Vec<(OsString, std::fs::FileType)>, Error> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).map_err(io(dir))? {
        let e = e.map_err(io(dir))?;
        let kind = e.file_type().map_err(io(&e.path()))?;
        out.push((e.file_name(), kind));
    }
    out.sort_by(|x, y| x.0.cmp(&y.0));
    Ok(out)
}

/// The folders directly in `dir` (the experiment folders of a results root), by name.
fn subfolders(dir: &Path) -> Result<BTreeMap<String, ()>, Error> {
    Ok(entries(dir)?
        .into_iter()
        .filter(|(_, kind)| kind.is_dir())
        .map(|(name, _)| (name.to_string_lossy().into_owned(), ()))
        .collect())
}

/// Every `*.csv` file below `root`: its `/`-separated relative path, and the path to join to
/// the root.
fn csv_tables(root: &Path) -> Result<BTreeMap<String, PathBuf>, Error> {
    let mut out = BTreeMap::new();
    let mut stack = vec![PathBuf::new()];
    while let Some(rel) = stack.pop() {
        for (name, kind) in entries(&root.join(&rel))? {
            let path = rel.join(&name);
            if kind.is_dir() {
                stack.push(path);
            } else if kind.is_file() && path.extension().is_some_and(|e| e == "csv") {
                let key = path
                    .components()
                    .map(|c| c.as_os_str().to_string_lossy())
                    .collect::<Vec<_>>()
                    .join("/");
                out.insert(key, path);
            }
        }
    }
    Ok(out)
}

/// A CSV table as text: its header and rows.
struct Csv {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

fn parse_csv(path: &Path, text: &str) -> Result<Csv, Error> {
    let mut records = csv_records(path, text)?
        .into_iter()
        .map(|(_, fields)| fields.into_iter().map(|(f, _)| f).collect::<Vec<_>>());
    let header = records.next().unwrap_or_default();
    Ok(Csv {
        header,
        rows: records.collect(),
    })
}

/// How table `name` differs between files `a` and `b` (`None` when it does not, timing
/// columns aside), and the timing columns whose cells differ.
fn compare_table(
    name: &str,
    a: &Path,
    b: &Path,
    opts: &Options,
) -> Result<(Option<TableDiff>, Vec<IgnoredColumn>), Error> {
    let text_a = std::fs::read_to_string(a).map_err(io(a))?;
    let text_b = std::fs::read_to_string(b).map_err(io(b))?;
    if text_a == text_b {
        return Ok((None, Vec::new()));
    }
    let (ta, tb) = (parse_csv(a, &text_a)?, parse_csv(b, &text_b)?);
    let position = |header: &[String], c: &str| header.iter().position(|h| h == c);
    let columns_missing_in_b: Vec<String> = ta
        .header
        .iter()
        .filter(|c| position(&tb.header, c).is_none())
        .cloned()
        .collect();
    let columns_extra_in_b: Vec<String> = tb
        .header
        .iter()
        .filter(|c| position(&ta.header, c).is_none())
        .cloned()
        .collect();
    // The shared columns, in A's order, each with its index on both sides and whether its
    // cells count.
    let shared: Vec<(&String, usize, usize, bool)> = ta
        .header
        .iter()
        .enumerate()
        .filter(|(i, c)| position(&ta.header, c) == Some(*i))
        .filter_map(|(i, c)| {
            let j = position(&tb.header, c)?;
            Some((c, i, j, opts.all_columns || !is_timing_column(c)))
        })
        .collect();
    /// Cell `i` of row `r`; a row cut short reads as empty cells.
    fn cell(r: &[String], i: usize) -> &str {
        r.get(i).map_or("", |s| s.as_str())
    }
    let (mut cells, mut cells_differing) = (Vec::new(), 0);
    let mut ignored: Vec<usize> = vec![0; shared.len()];
    // A summary table (seed_summary.csv) has one row per summarized column, named in its
    // `column` cell: a row summarizing a timing column is timing throughout.
    let summarized = position(&ta.header, "column");
    for (row, (ra, rb)) in ta.rows.iter().zip(&tb.rows).enumerate() {
        let timing_row =
            !opts.all_columns && summarized.is_some_and(|c| is_timing_column(cell(ra, c)));
        for (k, &(column, i, j, counts)) in shared.iter().enumerate() {
            let counts = counts && !timing_row;
            let (x, y) = (cell(ra, i), cell(rb, j));
            if cells_equal(x, y, opts.rtol, opts.atol) {
                continue;
            }
            if !counts {
                ignored[k] += 1;
                continue;
            }
            cells_differing += 1;
            if cells.len() < opts.max_cells {
                cells.push(CellDiff {
                    row,
                    column: column.clone(),
                    a: x.to_string(),
                    b: y.to_string(),
                });
            }
        }
    }
    let ignored = shared
        .iter()
        .zip(ignored)
        .filter(|(_, n)| *n > 0)
        .map(|((column, ..), n)| IgnoredColumn {
            table: name.to_string(),
            column: (*column).clone(),
            cells_differing: n,
        })
        .collect();
    let (rows_a, rows_b) = (ta.rows.len(), tb.rows.len());
    let same = columns_missing_in_b.is_empty()
        && columns_extra_in_b.is_empty()
        && rows_a == rows_b
        && cells_differing == 0;
    let table = (!same).then(|| TableDiff {
        table: name.to_string(),
        columns_missing_in_b,
        columns_extra_in_b,
        rows_a,
        rows_b,
        cells_differing,
        cells,
    });
    Ok((table, ignored))
}

/// The cells of a Markdown table row, trimmed (a `\|` inside a cell does not split it).
fn table_cells(line: &str) -> Vec<String> {
    let inner = line.trim().trim_start_matches('|');
    let inner = inner.strip_suffix('|').unwrap_or(inner);
    let (mut cells, mut cell, mut escaped) = (Vec::new(), String::new(), false);
    for c in inner.chars() {
        match c {
            '|' if !escaped => cells.push(std::mem::take(&mut cell).trim().to_string()),
            c => cell.push(c),
        }
        escaped = c == '\\';
    }
    cells.push(cell.trim().to_string());
    cells
}

/// A verdict without its parenthesized marks: `partly held (stale) (changed after results: 2)`
/// is `partly held`.
pub fn verdict_label(cell: &str) -> String {
    let mut s = cell.trim();
    while s.ends_with(')') {
        let mut depth = 0;
        let open = s.char_indices().rev().find_map(|(i, c)| {
            match c {
                ')' => depth += 1,
                '(' => depth -= 1,
                _ => {}
            }
            (depth == 0).then_some(i)
        });
        match open {
            Some(i) if i > 0 => s = s[..i].trim_end(),
            _ => break,
        }
    }
    s.to_string()
}

/// The verdicts of a `REPORT.md`'s claims tables (each under a header row
/// `| experiment | … | verdict | … |`), by experiment id: the id is the first cell's
/// `` `code` `` (the cell itself when it has none), the verdict as [`verdict_label`] gives it.
pub fn claims_verdicts(report: &str) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    let mut verdict_column = None;
    for line in report.lines() {
        if !line.trim_start().starts_with('|') {
            verdict_column = None;
            continue;
        }
        let cells = table_cells(line);
        if cells.first().is_some_and(|c| c == "experiment") {
            verdict_column = cells.iter().position(|c| c == "verdict");
            continue;
        }
        let Some(col) = verdict_column else {
            continue;
        };
        let rule = |c: &String| !c.is_empty() && c.chars().all(|ch| matches!(ch, '-' | ':'));
        if cells.iter().all(rule) {
            continue;
        }
        let first = cells[0].as_str();
        let id = first
            .split('`')
            .nth(1)
            .filter(|_| first.matches('`').count() >= 2)
            .unwrap_or(first)
            .trim();
        if let (false, Some(v)) = (id.is_empty(), cells.get(col)) {
            out.insert(id.to_string(), verdict_label(v));
        }
    }
    out
}

/// The verdicts of `a/REPORT.md` and `b/REPORT.md` compared; skipped when either is absent.
fn compare_verdicts(a: &Path, b: &Path) -> Result<Verdicts, Error> {
    let (pa, pb) = (a.join(REPORT), b.join(REPORT));
    let absent: Vec<String> = [("A", &pa), ("B", &pb)]
        .iter()
        .filter(|(_, p)| !p.is_file())
        .map(|(side, p)| format!("{side} has no {}", p.display()))
        .collect();
    if !absent.is_empty() {
        return Ok(Verdicts::Skipped {
            reason: absent.join(" and "),
        });
    }
    let read = |p: &Path| std::fs::read_to_string(p).map_err(io(p));
    let (va, vb) = (claims_verdicts(&read(&pa)?), claims_verdicts(&read(&pb)?));
    let changed = va
        .iter()
        .filter_map(|(id, x)| {
            let y = vb.get(id)?;
            (x != y).then(|| VerdictChange {
                id: id.clone(),
                a: x.clone(),
                b: y.clone(),
            })
        })
        .collect();
    Ok(Verdicts::Compared {
        compared: va.keys().filter(|id| vb.contains_key(*id)).count(),
        changed,
        missing_in_b: minus(&va, &vb),
        extra_in_b: minus(&vb, &va),
    })
}

/// Up to `n` of `items` joined by ", ", then how many more.
fn some_of(items: &[String], n: usize) -> String {
    let mut s = items[..items.len().min(n)].join(", ");
    if items.len() > n {
        s.push_str(&format!(", … ({} more)", items.len() - n));
    }
    s
}

fn plural(n: usize, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}

impl fmt::Display for Diff {
    /// The report `motionlab diff` prints: what is compared, every difference, and a last line
    /// that says whether anything changed.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let o = &self.options;
        writeln!(f, "A: {}\nB: {}", self.a, self.b)?;
        writeln!(
            f,
            "{} compared (rtol {:e}, atol {:e}{})",
            plural(self.tables_compared, "table", "tables"),
            o.rtol,
            o.atol,
            if o.all_columns {
                ", every column"
            } else {
                ", timing columns ignored"
            }
        )?;
        let list = |f: &mut fmt::Formatter<'_>, what: &str, items: &[String]| {
            if items.is_empty() {
                return Ok(());
            }
            writeln!(f, "{what} ({}):", items.len())?;
            items.iter().try_for_each(|i| writeln!(f, "  {i}"))
        };
        list(
            f,
            "experiment folders missing in B",
            &self.folders_missing_in_b,
        )?;
        list(f, "experiment folders extra in B", &self.folders_extra_in_b)?;
        list(f, "tables missing in B", &self.tables_missing_in_b)?;
        list(f, "tables extra in B", &self.tables_extra_in_b)?;
        for t in &self.tables {
            let mut what = Vec::new();
            if t.rows_a != t.rows_b {
                what.push(format!("rows {} -> {}", t.rows_a, t.rows_b));
            }
            if !t.columns_missing_in_b.is_empty() {
                what.push(format!(
                    "columns missing in B: {}",
                    t.columns_missing_in_b.join(", ")
                ));
            }
            if !t.columns_extra_in_b.is_empty() {
                what.push(format!(
                    "columns extra in B: {}",
                    t.columns_extra_in_b.join(", ")
                ));
            }
            if t.cells_differing > 0 {
                what.push(format!(
                    "{} differ{}",
                    plural(t.cells_differing, "cell", "cells"),
                    if t.cells_differing == 1 { "s" } else { "" }
                ));
            }
            writeln!(f, "table {}: {}", t.table, what.join("; "))?;
            for c in &t.cells {
                // An empty cell is shown as `""`, so that it is seen.
                let shown = |v: &str| if v.is_empty() { "\"\"" } else { v }.to_string();
                writeln!(
                    f,
                    "  {} row {} column {}: A {} B {}",
                    t.table,
                    c.row,
                    c.column,
                    shown(&c.a),
                    shown(&c.b)
                )?;
            }
            if t.cells_differing > t.cells.len() {
                writeln!(f, "  … {} more", t.cells_differing - t.cells.len())?;
            }
        }
        if !self.ignored.is_empty() {
            let columns: BTreeSet<&String> = self.ignored.iter().map(|i| &i.column).collect();
            let tables: BTreeSet<&String> = self.ignored.iter().map(|i| &i.table).collect();
            let columns: Vec<String> = columns.into_iter().cloned().collect();
            writeln!(
                f,
                "timing columns that differ, ignored (--all-columns compares them): {} in {}: {}",
                plural(columns.len(), "column", "columns"),
                plural(tables.len(), "table", "tables"),
                some_of(&columns, 12)
            )?;
        }
        match &self.verdicts {
            Verdicts::Skipped { reason } => writeln!(f, "verdicts not compared: {reason}")?,
            Verdicts::Compared {
                compared,
                changed,
                missing_in_b,
                extra_in_b,
            } => {
                writeln!(
                    f,
                    "verdicts: {} compared, {} changed",
                    compared,
                    changed.len()
                )?;
                for c in changed {
                    writeln!(f, "  {}: {} -> {}", c.id, c.a, c.b)?;
                }
                list(f, "verdicts missing in B", missing_in_b)?;
                list(f, "verdicts extra in B", extra_in_b)?;
            }
        }
        if self.changed {
            write!(f, "changed")
        } else {
            write!(f, "no change")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A folder holding `files` (relative path, text).
    fn folder(files: &[(&str, &str)]) -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        for (rel, text) in files {
            let p = dir.path().join(rel);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, text).unwrap();
        }
        dir
    }

    fn report(rows: &[(&str, &str)]) -> String {
        let mut md = String::from(
            "# report\n\n### Claims\n\n| experiment | paper item | verdict | headline |\n\
             | --- | --- | --- | --- |\n",
        );
        for (id, verdict) in rows {
            md.push_str(&format!(
                "| [`{id}`](#{id}) | Fig. 1 (a) | {verdict} | x \\| y (z) |\n"
            ));
        }
        md.push_str("\n## other\n\n| method | verdict |\n| --- | --- |\n| a | b |\n");
        md
    }

    const T: &str = "name,x,train_s\n\"a, quoted\",1.5,10.0\nb,NaN,11.0\n";

    fn run(a: &[(&str, &str)], b: &[(&str, &str)], opts: &Options) -> Diff {
        let (a, b) = (folder(a), folder(b));
        diff(a.path(), b.path(), opts).unwrap()
    }

    #[test]
    fn identical_folders_show_no_change() {
        let files = [
            ("e1/t.csv", T),
            ("e1/seeds/1/t.csv", T),
            ("e1/run.json", "{}"),
            ("REPORT.md", &report(&[("e1", "held")])),
        ];
        let d = run(&files, &files, &Options::default());
        assert!(!d.changed, "{d}");
        assert_eq!(d.tables_compared, 2);
        assert!(d.tables.is_empty() && d.ignored.is_empty());
        assert!(matches!(d.verdicts, Verdicts::Compared { compared: 1, .. }));
        assert!(d.to_string().ends_with("no change"), "{d}");
    }

    #[test]
    fn numeric_cells_differ_only_beyond_the_tolerance() {
        let a = [("e1/t.csv", T)];
        // Within the tolerance, written differently, NaN against NaN: the same.
        let near = T.replace("1.5,", "1.5000000000001,").replace("NaN", "nan");
        let d = run(&a, &[("e1/t.csv", &near)], &Options::default());
        assert!(!d.changed, "{d}");
        let far = T.replace("1.5,", "1.5001,");
        let d = run(&a, &[("e1/t.csv", &far)], &Options::default());
        assert!(d.changed);
        assert_eq!(d.tables.len(), 1);
        let t = &d.tables[0];
        assert_eq!((t.table.as_str(), t.cells_differing), ("e1/t.csv", 1));
        assert_eq!(
            t.cells,
            vec![CellDiff {
                row: 0,
                column: "x".into(),
                a: "1.5".into(),
                b: "1.5001".into()
            }]
        );
        let text = d.to_string();
        assert!(
            text.contains("e1/t.csv row 0 column x: A 1.5 B 1.5001"),
            "{text}"
        );
        // A looser tolerance accepts it.
        let loose = Options {
            rtol: 1e-3,
            ..Options::default()
        };
        assert!(!run(&a, &[("e1/t.csv", &far)], &loose).changed);
        // Strings compare exactly, the quoted comma inside one cell included.
        let renamed = T.replace("\"a, quoted\"", "\"a, Quoted\"");
        let d = run(&a, &[("e1/t.csv", &renamed)], &Options::default());
        assert_eq!(d.tables[0].cells[0].column, "name");
        assert_eq!(d.tables[0].cells[0].a, "a, quoted");
    }

    #[test]
    fn cells_compare_infinities_and_nans_only_with_themselves() {
        let eq = |a, b| cells_equal(a, b, 1e-9, 1e-12);
        assert!(eq("inf", "inf") && eq("NaN", "NaN") && eq("1", "1.0"));
        assert!(!eq("inf", "-inf") && !eq("NaN", "1") && !eq("inf", "1e308"));
        assert!(!eq("a", "A") && !eq("1", "") && eq("", ""));
        assert!(eq("0", "1e-13") && !eq("0", "1e-11"));
    }

    #[test]
    fn timing_columns_are_ignored_unless_all_columns() {
        let a = [("e1/t.csv", T)];
        let slower = T.replace("10.0", "12.5");
        let b = [("e1/t.csv", slower.as_str())];
        let d = run(&a, &b, &Options::default());
        assert!(!d.changed, "{d}");
        assert_eq!(
            d.ignored,
            vec![IgnoredColumn {
                table: "e1/t.csv".into(),
                column: "train_s".into(),
                cells_differing: 1
            }]
        );
        assert!(d.to_string().contains("train_s"), "{d}");
        let all = Options {
            all_columns: true,
            ..Options::default()
        };
        let d = run(&a, &b, &all);
        assert!(d.changed && d.ignored.is_empty());
        assert_eq!(d.tables[0].cells[0].column, "train_s");
        for timing in [
            "seconds",
            "search_seconds",
            "seconds_to_target",
            "seconds_per_pass",
            "emulator_step_s",
            "wall_seconds_both",
            "train_s",
        ] {
            assert!(is_timing_column(timing), "{timing}");
        }
        for timing in ["speedup", "us_per_step", "step_cost_ratio"] {
            assert!(is_timing_column(timing), "{timing}");
        }
        for kept in [
            "x",
            "seed",
            "sessions",
            "horizon_s",
            "fell_at_s",
            "speed_m_s",
            "wall_force",
            "max_weight_before_second_tug",
        ] {
            assert!(!is_timing_column(kept), "{kept}");
        }
    }

    #[test]
    fn missing_and_extra_tables_folders_rows_and_columns_are_changes() {
        let a = [("e1/t.csv", T), ("e1/u.csv", T), ("e2/t.csv", T)];
        let b = [("e1/t.csv", T), ("e1/v.csv", T), ("e3/t.csv", T)];
        let d = run(&a, &b, &Options::default());
        assert!(d.changed);
        assert_eq!(d.folders_missing_in_b, ["e2"]);
        assert_eq!(d.folders_extra_in_b, ["e3"]);
        // Said once, by its folder.
        assert_eq!(d.tables_missing_in_b, ["e1/u.csv"]);
        assert_eq!(d.tables_extra_in_b, ["e1/v.csv"]);
        assert_eq!(d.tables_compared, 1);

        let longer = format!("{T}c,2,1\n");
        let renamed = T.replacen("x,", "y,", 1);
        let d = run(
            &[("e1/t.csv", T), ("e1/u.csv", T)],
            &[("e1/t.csv", &longer), ("e1/u.csv", &renamed)],
            &Options::default(),
        );
        let (t, u) = (&d.tables[0], &d.tables[1]);
        assert_eq!((t.rows_a, t.rows_b, t.cells_differing), (2, 3, 0));
        assert_eq!(u.columns_missing_in_b, ["x"]);
        assert_eq!(u.columns_extra_in_b, ["y"]);
        let text = d.to_string();
        assert!(text.contains("table e1/t.csv: rows 2 -> 3"), "{text}");
    }

    #[test]
    fn changed_verdicts_are_reported_without_their_marks() {
        let a = report(&[("e1", "held"), ("e2", "partly held"), ("e3", "held")]);
        let b = report(&[
            ("e1", "held (stale) (changed after results: 2)"),
            ("e2", "did not hold (changed after results: 1)"),
            ("e4", "held"),
        ]);
        let d = run(
            &[("REPORT.md", &a)],
            &[("REPORT.md", &b)],
            &Options::default(),
        );
        assert!(d.changed);
        let Verdicts::Compared {
            compared,
            changed,
            missing_in_b,
            extra_in_b,
        } = &d.verdicts
        else {
            panic!("{:?}", d.verdicts)
        };
        assert_eq!(*compared, 2);
        assert_eq!(
            changed,
            &[VerdictChange {
                id: "e2".into(),
                a: "partly held".into(),
                b: "did not hold".into()
            }]
        );
        assert_eq!(
            (missing_in_b.as_slice(), extra_in_b.as_slice()),
            (&["e3".to_string()][..], &["e4".to_string()][..])
        );
        assert!(
            d.to_string().contains("e2: partly held -> did not hold"),
            "{d}"
        );
        // Without a report on one side the verdicts are skipped, saying so, and that is no
        // change.
        let d = run(&[("REPORT.md", &a)], &[], &Options::default());
        assert!(!d.changed);
        assert!(
            matches!(&d.verdicts, Verdicts::Skipped { reason } if reason.starts_with("B has no")),
            "{:?}",
            d.verdicts
        );
    }

    #[test]
    fn the_committed_report_gives_every_verdict() {
        let md = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("results/REPORT.md"),
        )
        .unwrap();
        let v = claims_verdicts(&md);
        assert!(v.len() >= 20, "{v:?}");
        assert!(v.keys().all(|id| !id.contains(['`', '[', ' '])), "{v:?}");
        assert!(v.values().all(|x| !x.contains('(')), "{v:?}");
    }

    #[test]
    fn a_side_that_is_not_a_folder_is_an_error_naming_it() {
        let a = folder(&[]);
        let gone = a.path().join("nope");
        let e = diff(a.path(), &gone, &Options::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("folder B") && e.contains("nope") && e.contains("does not exist"),
            "{e}"
        );
        let bad = Options {
            rtol: -1.0,
            ..Options::default()
        };
        let e = diff(a.path(), a.path(), &bad).unwrap_err().to_string();
        assert!(e.contains("--rtol"), "{e}");
    }
}
