//! # Results over seeds
//!
//! When seeds are swept (`--seeds K` or a `seeds = [...]` axis of `[sweep]`), every table gets a
//! leading `seed` column, each seed's rows are also written without it to
//! `<out>/<id>/seeds/<seed>/` (so the family's figures and report read one seed's results as they
//! read an unseeded run), and `seed_summary.csv` aggregates the seeds row by row:
//!
//! - rows align by position: row r of a table in every seed is the same quantity, which holds
//!   when its string columns (and sweep values) agree across seeds, as they do when seeds change
//!   values, not the shape of the results; a table where they disagree is left out;
//! - tables longer than [`MAX_ROWS_PER_SEED`] rows per seed (traces over time or iterations,
//!   ours) are left out;
//! - each numeric column (integers too, except `seed` and the sweep axes) of each row gives one
//!   line: `table, row, label, column, seeds, mean, std, min, max` over the seeds whose value is
//!   finite (`std`: sample standard deviation, NaN below two seeds).

use super::output::{df_f64, df_str, read_csv, Cell, ColumnData, Table, Tables};
use super::plot::{Figure, Mark, Panel, Series};
use super::report::sig;
use super::Error;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Tables longer than this (rows per seed) are left out of `seed_summary.csv` (ours).
pub const MAX_ROWS_PER_SEED: usize = 100;

/// The name of the summary table.
pub const SUMMARY: &str = "seed_summary";

/// The seeds of `seeds` beyond a run's own (`own`), in their order, without repeats: the further
/// net seeds a family repeats its measure through (its own seed's results are the run's).
pub fn further_seeds(seeds: &[u64], own: u64) -> Vec<u64> {
    let mut out: Vec<u64> = Vec::new();
    for &s in seeds {
        if s != own && !out.contains(&s) {
            out.push(s);
        }
    }
    out
}

/// Removes what an earlier run over seeds wrote into the experiment folder `dir` (and
/// `figures`) that the run now writing it does not: the folders `seeds/<seed>/` of seeds not in
/// `keep` (their tables, `.csv` and `.parquet`, and the folder when nothing else is in it) and,
/// when `keep` is empty (a run without seeds), `seed_summary.csv`, `seed_summary.parquet`,
/// the figure `<id>_seeds` (`.png`, `.svg`) and the `seeds/` folder when it is left empty. Other
/// files stay. Returns what was removed, folders last.
pub fn remove_stale_outputs(
    dir: &Path,
    figures: &Path,
    id: &str,
    keep: &[u64],
) -> Result<Vec<PathBuf>, Error> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| Error::Io { path, source }
    };
    let mut removed = Vec::new();
    let mut remove = |f: PathBuf| -> Result<(), Error> {
        match std::fs::remove_file(&f) {
            Ok(()) => {
                removed.push(f);
                Ok(())
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
            Err(e) => Err(io(&f)(e)),
        }
    };
    let root = dir.join("seeds");
    let mut emptied = Vec::new();
    for folder in super::output::experiment_folders(dir)? {
        let Some(seed) = folder
            .strip_prefix(&root)
            .ok()
            .and_then(|s| s.to_str())
            .and_then(|s| s.parse::<u64>().ok())
        else {
            continue;
        };
        if keep.contains(&seed) {
            continue;
        }
        let mut paths = std::fs::read_dir(&folder)
            .and_then(|es| {
                es.map(|e| e.map(|e| e.path()))
                    .collect::<Result<Vec<_>, _>>()
            })
            .map_err(io(&folder))?;
        paths.sort();
        for path in paths {
            let table = path
                .extension()
                .is_some_and(|e| e == "csv" || e == "parquet");
            if table && path.is_file() {
                remove(path)?;
            }
        }
        emptied.push(folder);
    }
    if keep.is_empty() {
        for ext in ["csv", "parquet"] {
            remove(dir.join(format!("{SUMMARY}.{ext}")))?;
        }
        for ext in ["png", "svg"] {
            remove(figures.join(format!("{id}_seeds.{ext}")))?;
        }
        emptied.push(root);
    }
    for folder in emptied {
        // Only when nothing else is in it.
        if std::fs::remove_dir(&folder).is_ok() {
            removed.push(folder);
        }
    }
    Ok(removed)
}

/// The rows of one seed, without the `seed` column.
pub fn one_seed(tables: &Tables, seed: u64) -> Tables {
    Tables(
        tables
            .0
            .iter()
            .map(|(name, t)| {
                let col = match t.column("seed") {
                    Some(ColumnData::I(v)) => v.clone(),
                    _ => Vec::new(),
                };
                let t = t.select(|i| col.get(i) == Some(&(seed as i64)), Some("seed"));
                (name.clone(), t)
            })
            .collect(),
    )
}

fn cell_text(c: &ColumnData, i: usize) -> String {
    match c {
        ColumnData::F(v) => format!("{}", v[i]),
        ColumnData::I(v) => v[i].to_string(),
        ColumnData::S(v) => v[i].clone(),
    }
}

/// Mean, sample standard deviation, min and max of the finite values, and their count.
fn stats(values: &[f64]) -> (usize, f64, f64, f64, f64) {
    let v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    let n = v.len();
    if n == 0 {
        return (0, f64::NAN, f64::NAN, f64::NAN, f64::NAN);
    }
    let mean = v.iter().sum::<f64>() / n as f64;
    let std = if n < 2 {
        f64::NAN
    } else {
        (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
    };
    let min = v.iter().copied().fold(f64::INFINITY, f64::min);
    let max = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    (n, mean, std, min, max)
}

/// `seed_summary`: every numeric cell of the (short, row-aligned) tables aggregated over seeds.
/// `axes` are the sweep axis names (labels, not aggregated).
pub fn seed_summary(tables: &Tables, seeds: &[u64], axes: &[String]) -> Table {
    let mut out = Table::new(&[
        "table", "row", "label", "column", "seeds", "mean", "std", "min", "max",
    ]);
    for (name, t) in &tables.0 {
        let Some(ColumnData::I(seed_col)) = t.column("seed") else {
            continue;
        };
        let rows: Vec<Vec<usize>> = seeds
            .iter()
            .map(|&s| (0..t.len()).filter(|&i| seed_col[i] == s as i64).collect())
            .collect();
        let longest = rows.iter().map(Vec::len).max().unwrap_or(0);
        if longest > MAX_ROWS_PER_SEED {
            continue;
        }
        let cols: Vec<(&String, &ColumnData)> = t.names().iter().zip(t.columns()).collect();
        let is_label = |n: &String, c: &ColumnData| {
            axes.contains(n) || matches!(c, ColumnData::S(_)) && n != "seed"
        };
        let label = |i: usize| -> String {
            cols.iter()
                .filter(|(n, c)| is_label(n, c))
                .map(|(n, c)| format!("{n}={}", cell_text(c, i)))
                .collect::<Vec<_>>()
                .join(", ")
        };
        // Labels of each row position; the table is left out unless every seed agrees.
        let mut labels = Vec::with_capacity(longest);
        let mut aligned = true;
        for r in 0..longest {
            let ls: Vec<String> = rows
                .iter()
                .filter_map(|v| v.get(r))
                .map(|&i| label(i))
                .collect();
            aligned &= ls.iter().all(|l| *l == ls[0]);
            labels.push(ls[0].clone());
        }
        if !aligned {
            continue;
        }
        for (r, l) in labels.iter().enumerate() {
            for (n, c) in cols.iter().filter(|(n, c)| !is_label(n, c) && *n != "seed") {
                let values: Vec<f64> = rows
                    .iter()
                    .filter_map(|v| v.get(r))
                    .map(|&i| match c {
                        ColumnData::F(v) => v[i],
                        ColumnData::I(v) => v[i] as f64,
                        ColumnData::S(_) => f64::NAN,
                    })
                    .collect();
                let (k, mean, std, min, max) = stats(&values);
                out.push(vec![
                    Cell::from(name.as_str()),
                    Cell::from(r),
                    Cell::from(l.as_str()),
                    Cell::from(n.as_str()),
                    Cell::from(k),
                    Cell::F(mean),
                    Cell::F(std),
                    Cell::F(min),
                    Cell::F(max),
                ]);
            }
        }
    }
    out
}

/// A result a family plots over seeds in its `<id>_seeds` figure: `column` of `table`, in the rows
/// whose string column `row.0` equals `row.1` when `row` is set (one row per seed and sweep point).
#[derive(Debug, Clone, Copy)]
pub struct SeedMetric {
    /// Result table.
    pub table: &'static str,
    /// Numeric column.
    pub column: &'static str,
    /// Row selector (key column, value) for tables with one row per quantity.
    pub row: Option<(&'static str, &'static str)>,
    /// Axis description with unit.
    pub label: &'static str,
}

/// The seeds figure: one panel per metric, the sweep points along x (one category when there is
/// no sweep), every seed's value as a dot, and the mean with a ±1 sample standard deviation bar
/// and the min–max range beside it. `tables` hold every seed (a leading `seed` column); `axes`
/// are the sweep axes. `None` when no metric has values.
pub fn seed_figure(tables: &Tables, axes: &[String], metrics: &[SeedMetric]) -> Option<Figure> {
    let mut panels = Vec::new();
    let (mut longest, mut count) = (0usize, 0usize);
    for m in metrics {
        let Some(t) = tables.get(m.table) else {
            continue;
        };
        let Some(ColumnData::I(seed_col)) = t.column("seed") else {
            continue;
        };
        let values = t.f64s(m.column);
        if values.is_empty() {
            continue;
        }
        let key = m.row.map(|(k, _)| t.strs(k));
        let cols: Vec<(&String, &ColumnData)> = t
            .names()
            .iter()
            .zip(t.columns())
            .filter(|(n, _)| axes.contains(n))
            .collect();
        // Sweep points in order of first appearance (units run seed-major).
        let mut points: Vec<(String, Vec<(i64, f64)>)> = Vec::new();
        for i in 0..t.len() {
            if let (Some(k), Some((_, want))) = (&key, m.row) {
                if k.get(i).map(String::as_str) != Some(want) {
                    continue;
                }
            }
            // Values only, in the table's column order (the axis title names the keys).
            let label = cols
                .iter()
                .map(|(_, c)| cell_text(c, i))
                .collect::<Vec<_>>()
                .join(", ");
            let label = if label.is_empty() {
                "all".to_string()
            } else {
                label
            };
            match points.iter_mut().find(|(l, _)| *l == label) {
                Some((_, v)) => v.push((seed_col[i], values[i])),
                None => points.push((label, vec![(seed_col[i], values[i])])),
            }
        }
        if points.is_empty() {
            continue;
        }
        let mut dots = Vec::new();
        let (mut means, mut bars, mut ranges) = (Vec::new(), Vec::new(), Vec::new());
        for (x, (_, v)) in points.iter().enumerate() {
            let n = v.len().max(2) as f64;
            for (j, &(_, y)) in v.iter().enumerate() {
                // Seeds spread a little to the left of the point so equal values stay visible.
                dots.push((x as f64 - 0.25 + 0.15 * j as f64 / (n - 1.0), y));
            }
            let ys: Vec<f64> = v.iter().map(|p| p.1).collect();
            let (k, mean, std, min, max) = stats(&ys);
            if k == 0 {
                continue;
            }
            means.push((x as f64 + 0.1, mean));
            if std.is_finite() {
                bars.push(vec![
                    (x as f64 + 0.1, mean - std),
                    (x as f64 + 0.1, mean + std),
                ]);
            }
            ranges.push(vec![(x as f64 + 0.2, min), (x as f64 + 0.2, max)]);
        }
        let mut series = vec![
            Series::line("each seed", dots, 0).mark(Mark::Points),
            Series::line("mean", means, 1).mark(Mark::Points),
        ];
        for (i, b) in bars.into_iter().enumerate() {
            let label = if i == 0 { "mean ± 1 std" } else { "" };
            series.push(Series::line(label, b, 1));
        }
        for (i, r) in ranges.into_iter().enumerate() {
            let label = if i == 0 { "min to max" } else { "" };
            series.push(Series::line(label, r, 2).mark(Mark::Dashed));
        }
        let seeds = points.iter().map(|(_, v)| v.len()).max().unwrap_or(0);
        longest = longest.max(
            points
                .iter()
                .map(|(l, _)| l.chars().count())
                .max()
                .unwrap_or(0),
        );
        count = count.max(points.len());
        let keys: Vec<&str> = cols.iter().map(|(n, _)| n.as_str()).collect();
        panels.push(Panel {
            title: format!("{} over {seeds} seeds", m.label),
            x_label: if keys.is_empty() {
                "sweep point".into()
            } else {
                format!("sweep point ({})", keys.join(", "))
            },
            y_label: m.label.to_string(),
            x_range: Some((-0.5, points.len() as f64 - 0.5)),
            x_categories: points.into_iter().map(|(l, _)| l).collect(),
            series,
            ..Default::default()
        });
    }
    if panels.is_empty() {
        return None;
    }
    // Panels side by side while every point's label fits its slot (about 7 px a character at
    // the tick font); else one panel per row, wide enough for the labels.
    let slot = |width: usize| width.saturating_sub(100) / count.max(1);
    let need = 7 * longest + 12;
    if slot(640) >= need {
        let columns = panels.len().min(2);
        return Some(Figure::grid(panels, columns));
    }
    let mut fig = Figure::grid(panels, 1);
    fig.panel_size.0 = (100 + need * count.max(1)).clamp(640, 2400) as u32;
    Some(fig)
}

/// Lines of `seed_summary.csv` shown in the report (the rest stay in the file).
pub const REPORT_ROWS: usize = 30;

/// The report's table of `seed_summary.csv` in `dir`: the first [`REPORT_ROWS`] lines whose
/// value varies over the seeds (min < max), with mean, std, min and max, and how many lines are
/// equal for every seed.
pub fn summary_markdown(dir: &Path) -> Result<String, Error> {
    let df = read_csv(&dir.join(format!("{SUMMARY}.csv")))?;
    let rows = df_f64(&df, "row")?;
    let (table, label, column) = (
        df_str(&df, "table")?,
        df_str(&df, "label")?,
        df_str(&df, "column")?,
    );
    let (n, mean, std, min, max) = (
        df_f64(&df, "seeds")?,
        df_f64(&df, "mean")?,
        df_f64(&df, "std")?,
        df_f64(&df, "min")?,
        df_f64(&df, "max")?,
    );
    let varying: Vec<usize> = (0..df.height()).filter(|&i| min[i] < max[i]).collect();
    let mut md = format!(
        "Mean and spread over seeds (`{SUMMARY}.csv`, row by row of the result tables): {} of {} \
         values vary with the seed",
        varying.len(),
        df.height()
    );
    if varying.is_empty() {
        md.push_str(".\n");
        return Ok(md);
    }
    md.push_str(if varying.len() > REPORT_ROWS {
        "; the first of them:\n\n"
    } else {
        ":\n\n"
    });
    md.push_str(
        "| table | row | column | seeds | mean | std | min | max |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n",
    );
    for &i in varying.iter().take(REPORT_ROWS) {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} | {} |",
            table[i],
            if label[i].is_empty() {
                format!("{}", rows[i])
            } else {
                label[i].replace('|', "\\|")
            },
            column[i],
            n[i],
            sig(mean[i]),
            sig(std[i]),
            sig(min[i]),
            sig(max[i])
        );
    }
    Ok(md)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::row;

    #[test]
    fn further_seeds_drop_the_runs_own_and_repeats_in_order() {
        assert_eq!(further_seeds(&[2, 1, 3, 2, 5], 1), vec![2, 3, 5]);
        assert_eq!(further_seeds(&[], 1), Vec::<u64>::new());
    }

    /// A rerun with other seeds removes the tables of the seeds it has not; one without seeds
    /// removes every seed's tables, the summary and the seeds figure; other files stay.
    #[test]
    fn outputs_of_seeds_a_run_does_not_have_are_removed() {
        let d = tempfile::tempdir().unwrap();
        let (dir, figs) = (d.path().join("out/exp"), d.path().join("figs"));
        for s in ["3", "5", "7"] {
            std::fs::create_dir_all(dir.join("seeds").join(s)).unwrap();
            for f in ["t.csv", "t.parquet"] {
                std::fs::write(dir.join("seeds").join(s).join(f), "x").unwrap();
            }
        }
        std::fs::create_dir_all(&figs).unwrap();
        let made = [
            dir.join("seed_summary.csv"),
            dir.join("seed_summary.parquet"),
            figs.join("exp_seeds.png"),
            figs.join("exp_seeds.svg"),
        ];
        let kept = [
            dir.join("t.csv"),
            dir.join("seeds/7/notes.txt"),
            dir.join("seeds/notes.txt"),
            figs.join("exp_other.png"),
            figs.join("other_seeds.png"),
        ];
        for f in made.iter().chain(&kept) {
            std::fs::write(f, "x").unwrap();
        }
        let removed = remove_stale_outputs(&dir, &figs, "exp", &[3, 5]).unwrap();
        assert_eq!(
            removed,
            [dir.join("seeds/7/t.csv"), dir.join("seeds/7/t.parquet")]
        );
        assert!(made.iter().all(|f| f.exists()));
        let removed = remove_stale_outputs(&dir, &figs, "exp", &[]).unwrap();
        for f in made {
            assert!(!f.exists() && removed.contains(&f), "{}", f.display());
        }
        for s in ["3", "5"] {
            assert!(!dir.join("seeds").join(s).exists());
        }
        for f in &kept {
            assert!(f.exists(), "{} was removed", f.display());
        }
    }

    #[test]
    fn summary_aggregates_aligned_rows_over_seeds() {
        let mut t = Table::new(&["seed", "scale", "method", "error", "steps"]);
        for (s, e) in [(5u64, [1.0, 10.0]), (6, [3.0, 20.0]), (7, [2.0, f64::NAN])] {
            t.push(row![s as i64, 0.5, "a", e[0], 4i64]);
            t.push(row![s as i64, 0.5, "b", e[1], 4i64]);
        }
        let tables = Tables::from([("final", t)]);
        let s = seed_summary(&tables, &[5, 6, 7], &["scale".to_string()]);
        assert_eq!(s.len(), 4, "rows a, b times columns error, steps");
        let mean = s.f64s("mean");
        let std = s.f64s("std");
        assert_eq!(s.strs("label")[0], "scale=0.5, method=a");
        assert_eq!(s.strs("column")[0], "error");
        assert!((mean[0] - 2.0).abs() < 1e-12 && (std[0] - 1.0).abs() < 1e-12);
        assert_eq!(s.f64s("seeds")[2], 2.0, "the NaN of seed 7 is left out");
        assert!((mean[2] - 15.0).abs() < 1e-12);
        assert_eq!((s.f64s("min")[0], s.f64s("max")[0]), (1.0, 3.0));
        // One seed's rows, without the seed column.
        let one = one_seed(&tables, 6);
        let t6 = one.get("final").unwrap();
        assert_eq!(t6.names()[0], "scale");
        assert_eq!(t6.f64s("error"), vec![3.0, 20.0]);
    }

    #[test]
    fn seed_figure_has_a_category_per_sweep_point_and_a_dot_per_seed() {
        let mut t = Table::new(&["seed", "regimes", "measure", "value"]);
        for s in [3i64, 4] {
            for r in [2i64, 4, 6] {
                t.push(row![s, r, "distance", (s * r) as f64]);
                t.push(row![s, r, "other", -1.0]);
            }
        }
        let tables = Tables::from([("measures", t)]);
        let metric = SeedMetric {
            table: "measures",
            column: "value",
            row: Some(("measure", "distance")),
            label: "distance (m)",
        };
        let missing = SeedMetric {
            table: "absent",
            ..metric
        };
        let fig = seed_figure(&tables, &["regimes".to_string()], &[metric, missing]).unwrap();
        assert_eq!(
            fig.panels.len(),
            1,
            "a metric without a table draws nothing"
        );
        let p = &fig.panels[0];
        assert_eq!(p.x_categories, ["2", "4", "6"]);
        assert_eq!(p.x_label, "sweep point (regimes)");
        let dots = &p.series[0].points;
        assert_eq!(
            dots.len(),
            6,
            "one dot per seed and point, the other rows left out"
        );
        assert!(dots.iter().all(|&(x, _)| x > -0.5 && x < 2.5));
        // Means at each point: (3r + 4r) / 2.
        let means: Vec<f64> = p.series[1].points.iter().map(|q| q.1).collect();
        assert_eq!(means, vec![7.0, 14.0, 21.0]);
        assert!(seed_figure(&tables, &[], &[missing]).is_none());
    }

    #[test]
    fn misaligned_or_long_tables_are_left_out() {
        let mut t = Table::new(&["seed", "method", "x"]);
        t.push(row![1i64, "a", 1.0]);
        t.push(row![2i64, "b", 1.0]);
        let mut long = Table::new(&["seed", "x"]);
        for i in 0..=MAX_ROWS_PER_SEED {
            long.push(row![1i64, i as f64]);
        }
        let tables = Tables::from([("mis", t), ("long", long)]);
        assert!(seed_summary(&tables, &[1, 2], &[]).is_empty());
    }
}
