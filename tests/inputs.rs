//! Inputs the harness must refuse or read strictly (issue 55, items 5, 7, 10, 11 and 14):
//! malformed result tables, the code revision of the build, `[quick]` keys and repeated sweep
//! values, sizes beyond the stated limits, and error messages that name the right place once.

use crate::util::*;
use motionlab::experiment::output::{read_csv, write_table, Table};
use motionlab::experiment::resolve::{
    resolve, ResolveOptions, MAX_SEEDS, MAX_SWEEP_POINTS, MAX_UNITS,
};
use motionlab::experiment::runner::MAX_JOBS;
use motionlab::experiment::spec::SpecFile;
use std::path::Path;
use std::process::Output;

fn fails(out: &Output) -> String {
    assert!(
        !out.status.success(),
        "motionlab should have failed:\nstdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn stderr(out: &Output) -> String {
    ok(out);
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn line_of(text: &str, needle: &str) -> usize {
    text.lines()
        .position(|l| l.contains(needle))
        .unwrap_or_else(|| panic!("{needle:?} in text"))
        + 1
}

/// Writes `text` as `s.toml` in a fresh temp dir and runs `run s.toml` there with `args`
/// (outputs in `out/` and `figs/`).
fn run_spec(text: &str, args: &[&str]) -> (Output, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("s.toml"), text).unwrap();
    let mut a = vec!["run", "s.toml", "--out", "out", "--figures", "figs"];
    a.extend_from_slice(args);
    (motionlab(dir.path(), &a), dir)
}

/// Runs a spec that must be refused before any work; returns the error.
fn refused(text: &str, args: &[&str]) -> String {
    let (out, dir) = run_spec(text, args);
    let err = fails(&out);
    assert!(
        !dir.path().join("out").exists() && !dir.path().join("figs").exists(),
        "nothing may be written: {err}"
    );
    err
}

// ---- Item 5: result tables are read strictly --------------------------------------------

/// A table as `write_table` writes it: a string column, an integer and a float column.
fn written_table(dir: &Path) -> String {
    let mut t = Table::new(&["model", "n", "x"]);
    t.push(motionlab::row!["a", 1usize, 0.5]);
    t.push(motionlab::row!["7", 2usize, 1.25]);
    t.push(motionlab::row!["c", 3usize, 5.054592468979538]);
    write_table(dir, "t", &t).unwrap();
    std::fs::read_to_string(dir.join("t.csv")).unwrap()
}

/// A truncated row, a cut-off last line, a row cut off or added at a row boundary (against the
/// Parquet table written beside it), a non-numeric or empty cell in a numeric column: each
/// is an error naming the file and the line; the table as written reads back, numeric-looking
/// strings in a string column included.
#[test]
fn a_malformed_table_is_an_error_naming_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let good = written_table(dir.path());
    let path = dir.path().join("t.csv");
    assert_eq!(read_csv(&path).unwrap().height(), 3, "{good}");
    let cases: Vec<(String, usize, &str)> = vec![
        // The last row lost its last field (and its line end).
        (
            good.trim_end().rsplit_once(',').unwrap().0.to_string(),
            4,
            "fields",
        ),
        // The last number was cut short: no line end.
        (
            good.trim_end()[..good.trim_end().len() - 4].to_string(),
            4,
            "line end",
        ),
        // A row with a field too many.
        (good.replacen("a,1,0.5", "a,1,0.5,9", 1), 2, "fields"),
        (good.replacen("a,1,0.5", "a,1,0.5x", 1), 2, "not a number"),
        (
            good.replacen("7,2,1.25", "7,two,1.25", 1),
            3,
            "not a number",
        ),
        (good.replacen("7,2,1.25", "7,2,", 1), 3, "empty"),
        (String::new(), 1, "empty"),
        // Cut at a row boundary: a whole table to look at, one row fewer than was written
        // (a seed's rows gone would change a median, not fail a parse).
        (
            good.lines().take(3).map(|l| format!("{l}\n")).collect(),
            3,
            "2 rows where the Parquet table written beside it has 3",
        ),
        // A row added.
        (format!("{good}d,4,1.5\n"), 5, "4 rows where"),
    ];
    for (text, line, what) in cases {
        std::fs::write(&path, &text).unwrap();
        let e = read_csv(&path)
            .map(|df| format!("{df}"))
            .expect_err(&format!("{text:?} must be refused"))
            .to_string();
        assert!(e.contains(&format!("t.csv:{line}")), "{text:?}: {e}");
        assert!(e.contains(what), "{text:?}: {e}");
    }
    // Without the Parquet twin a column is numeric when most of its cells are numbers: the
    // string column with a "7" reads, the bad number is found.
    std::fs::write(&path, &good).unwrap();
    std::fs::remove_file(dir.path().join("t.parquet")).unwrap();
    assert_eq!(read_csv(&path).unwrap().height(), 3);
    std::fs::write(&path, good.replacen("7,2,1.25", "7,2,1.2.5", 1)).unwrap();
    let e = read_csv(&path).unwrap_err().to_string();
    assert!(e.contains("t.csv:3") && e.contains("not a number"), "{e}");
}

/// `reproduce` reads another experiment's tables for REPORT.md: a cut-off `orders.csv` of
/// physics_validation (its last measured order `5.05…` cut to `5.0`) no longer reads as
/// "held" with a wrong number; the command fails naming the file and line.
#[test]
fn reproduce_refuses_a_truncated_table_of_another_experiment() {
    let dir = tempfile::tempdir().unwrap();
    let exp = dir.path().join("experiments");
    std::fs::create_dir_all(&exp).unwrap();
    for id in ["physics_validation", "lbc_projection"] {
        std::fs::write(exp.join(format!("{id}.toml")), spec(id)).unwrap();
    }
    let args = |only: &'static str| {
        vec![
            "reproduce",
            "--quick",
            "--only",
            only,
            "--out",
            "out",
            "--figures",
            "figs",
        ]
    };
    ok(&motionlab(dir.path(), &args("physics_validation")));
    let orders = dir.path().join("out/physics_validation/orders.csv");
    let text = std::fs::read_to_string(&orders).unwrap();
    let last = text.trim_end().lines().count();
    let cut = text.trim_end().rsplit_once(',').unwrap().0;
    let cut = &cut[..cut.rfind('.').unwrap() + 2];
    std::fs::write(&orders, cut).unwrap();
    let e = fails(&motionlab(dir.path(), &args("lbc_projection")));
    assert!(e.contains(&format!("orders.csv:{last}")), "{e}");
    let report = std::fs::read_to_string(dir.path().join("out/REPORT.md")).unwrap();
    let row = report
        .lines()
        .find(|l| l.starts_with("| [`physics_validation`]"))
        .unwrap();
    assert!(!row.contains("| held"), "{row}");
}

// ---- Item 7: the code revision is the build's ---------------------------------------------

/// A sweep resumed, or sharded, from another working directory (here: the crate's git
/// checkout, then a folder outside it) is the same code: nothing is recomputed and the shards
/// merge.
#[test]
fn the_revision_comes_from_the_build_not_the_working_directory() {
    let dir = tempfile::tempdir().unwrap();
    let s = dir.path().join("s.toml");
    std::fs::write(
        &s,
        format!("{}\n[sweep]\nscale = [1.0, 4.0]\n", spec("lbc_projection")),
    )
    .unwrap();
    let (s, out, figs) = (
        s.to_str().unwrap().to_string(),
        dir.path().join("o").to_str().unwrap().to_string(),
        dir.path().join("f").to_str().unwrap().to_string(),
    );
    let run = |cwd: &Path, extra: &[&str]| {
        let mut a = vec!["run", &s, "--quick", "--out", &out, "--figures", &figs];
        a.extend_from_slice(extra);
        motionlab(cwd, &a)
    };
    let revision = || -> serde_json::Value {
        let t = std::fs::read_to_string(dir.path().join("o/lbc_projection/run.json")).unwrap();
        let v: serde_json::Value = serde_json::from_str(&t).unwrap();
        serde_json::json!([v["git_revision"], v["git_dirty"]])
    };
    let e = stderr(&run(&root(), &["--resume"]));
    assert!(e.contains("(2 units run, 0 resumed)"), "{e}");
    let first = revision();
    let e = stderr(&run(dir.path(), &["--resume"]));
    assert!(e.contains("(0 units run, 2 resumed)"), "{e}");
    assert_eq!(revision(), first);
    // Shards run from two folders merge.
    stderr(&run(&root(), &["--shard", "1/2"]));
    stderr(&run(dir.path(), &["--shard", "2/2"]));
    stderr(&motionlab(
        dir.path(),
        &["merge", &s, "--quick", "--out", &out, "--figures", &figs],
    ));
    assert_eq!(revision(), first);
}

// ---- Item 10: [quick] keys always checked, sweep values distinct ---------------------------

#[test]
fn quick_keys_are_checked_in_a_full_run() {
    // A typo in [quick]: named with its line, without --quick.
    let text = spec("lbc_projection").replace("samples = 201", "sampels = 201");
    let e = refused(&text, &[]);
    assert!(e.contains("quick.sampels"), "{e}");
    assert!(
        e.contains(&format!("s.toml:{}", line_of(&text, "sampels"))),
        "{e}"
    );
    // A bad value in [quick].
    let text = spec("lbc_projection").replace("samples = 201", "samples = 0");
    let e = refused(&text, &[]);
    assert!(e.contains("quick.samples"), "{e}");
    assert!(
        e.contains(&format!("s.toml:{}", line_of(&text, "samples = 0"))),
        "{e}"
    );
    // And the other way round: [params] is checked with --quick too.
    let text = spec("lbc_projection").replace("samples = 1201", "samples = 0");
    let e = refused(&text, &["--quick"]);
    assert!(e.contains("params.samples"), "{e}");
    assert!(
        e.contains(&format!("s.toml:{}", line_of(&text, "samples = 0"))),
        "{e}"
    );
}

#[test]
fn repeated_sweep_values_are_refused() {
    let text = format!(
        "{}\n[sweep]\nscale = [1.0, 2.0,\n  1.0]\n",
        spec("lbc_projection")
    );
    let e = refused(&text, &["--quick"]);
    assert!(e.contains("sweep.scale[2]") && e.contains("twice"), "{e}");
    assert!(
        e.contains(&format!("s.toml:{}", line_of(&text, "  1.0]"))),
        "{e}"
    );
    // An integer and a float of the same value are one value.
    let text = format!(
        "{}\n[sweep]\nscale = [1, 2.0, 1.0]\n",
        spec("lbc_projection")
    );
    let e = refused(&text, &["--quick"]);
    assert!(e.contains("sweep.scale[2]"), "{e}");
    // A family's own lists: repeated spacings would repeat rows.
    let text =
        spec("lbc_projection").replace("spacings = [0.5, 2.0, 6.0]", "spacings = [0.5, 2.0, 0.5]");
    let e = refused(&text, &["--quick"]);
    assert!(
        e.contains("quick.spacings[2]") && e.contains("twice"),
        "{e}"
    );
    let text = spec("physics_validation").replace(
        "integrators = [\"euler\", \"semi_implicit_euler\", \"rk4\", \"dopri5\"]",
        "integrators = [\"euler\", \"rk4\", \"euler\"]",
    );
    let e = refused(&text, &["--quick"]);
    assert!(
        e.contains("params.integrators[2]") && e.contains("twice"),
        "{e}"
    );
}

/// Every shipped experiment file resolves with and without `--quick` (the cross-checks of
/// [quick] and [params] refuse none of them).
#[test]
fn every_shipped_spec_resolves_in_both_modes() {
    let exp = root().join("experiments");
    for e in std::fs::read_dir(&exp).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_none_or(|x| x != "toml") {
            continue;
        }
        let file = SpecFile::load(&p).unwrap();
        for quick in [false, true] {
            let opts = ResolveOptions {
                quick,
                ..Default::default()
            };
            if let Err(e) = resolve(&file, &opts, &motionlab::families::registry()) {
                panic!("{} (quick {quick}): {e}", p.display());
            }
        }
    }
}

// ---- Item 11: sizes beyond the stated limits ----------------------------------------------

#[test]
fn sizes_beyond_the_limits_are_refused_before_any_work() {
    let text = spec("lbc_projection");
    let too_many = (MAX_SEEDS + 1).to_string();
    let e = refused(&text, &["--quick", "--seeds", "4294967296"]);
    assert!(
        e.contains("--seeds") && e.contains(&MAX_SEEDS.to_string()),
        "{e}"
    );
    let e = refused(&text, &["--quick", "--seeds", &too_many]);
    assert!(e.contains("--seeds"), "{e}");
    let e = refused(&text, &["--quick", "--jobs", "100000"]);
    assert!(
        e.contains("--jobs") && e.contains(&MAX_JOBS.to_string()),
        "{e}"
    );
    // A sweep of 1000 x 1000 points.
    let axis = |n: usize| {
        let v: Vec<String> = (1..=n).map(|i| format!("{i}.0")).collect();
        format!("[{}]", v.join(", "))
    };
    let big = format!(
        "{text}\n[sweep]\nscale = {}\nmargin = {}\n",
        axis(1000),
        axis(1000)
    );
    let e = refused(&big, &["--quick"]);
    assert!(
        e.contains("sweep") && e.contains(&MAX_SWEEP_POINTS.to_string()),
        "{e}"
    );
    // Points times seeds.
    let side = MAX_SWEEP_POINTS.min(MAX_UNITS / 2 + 1);
    let sweep = format!("{text}\n[sweep]\nscale = {}\n", axis(side));
    let seeds = (MAX_UNITS / side + 1).min(MAX_SEEDS).to_string();
    if side * (MAX_UNITS / side + 1).min(MAX_SEEDS) > MAX_UNITS {
        let e = refused(&sweep, &["--quick", "--seeds", &seeds]);
        assert!(e.contains(&MAX_UNITS.to_string()), "{e}");
    }
    // A family's sample count that would allocate tens of gigabytes.
    let text = spec("lbc_projection").replace("samples = 201", "samples = 10000000000");
    let e = refused(&text, &["--quick"]);
    assert!(e.contains("quick.samples") && e.contains("at most"), "{e}");
}

/// `--help` states the limits.
#[test]
fn help_states_the_limits() {
    let dir = tempfile::tempdir().unwrap();
    let run = ok(&motionlab(dir.path(), &["run", "--help"]));
    for n in [MAX_SEEDS, MAX_JOBS, MAX_SWEEP_POINTS, MAX_UNITS] {
        assert!(run.contains(&n.to_string()), "{n} not in:\n{run}");
    }
    let reproduce = ok(&motionlab(dir.path(), &["reproduce", "--help"]));
    for n in [MAX_SEEDS, MAX_JOBS] {
        assert!(
            reproduce.contains(&n.to_string()),
            "{n} not in:\n{reproduce}"
        );
    }
}

// ---- Item 14: error messages name the right place, once -------------------------------------

#[test]
fn an_unknown_key_is_named_once() {
    let text = spec("lbc_projection").replace("margin = 3.0", "margn = 3.0");
    let e = refused(&text, &[]);
    assert!(e.contains("`params.margn`"), "{e}");
    assert!(!e.contains("margn.margn"), "{e}");
    assert!(
        e.contains(&format!("s.toml:{}", line_of(&text, "margn"))),
        "{e}"
    );
}

#[test]
fn a_bad_nested_set_is_blamed_on_the_set() {
    let e = refused(&spec("lbc_projection"), &["--quick", "--set", "a.b.c=1"]);
    assert!(e.contains("--set") && e.contains("a.b.c"), "{e}");
    assert!(!e.contains("s.toml"), "{e}");
}

#[test]
fn an_os_error_is_stated_once() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("file"), "x").unwrap();
    let e = fails(&motionlab(
        dir.path(),
        &[
            "simulate",
            "pendulum3",
            "--state",
            "0,0,0,0,0,0",
            "--duration",
            "0.1",
            "--out",
            "file/x.csv",
        ],
    ));
    assert_eq!(e.matches("(os error").count(), 1, "{e}");
    assert!(e.contains("file/x.csv"), "{e}");
}

/// Every committed result table reads back under the strict reader (no table that
/// `write_table` wrote is taken for a malformed one).
#[test]
fn every_committed_table_reads_strictly() {
    let mut stack = vec![root().join("results")];
    let mut n = 0;
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "csv") {
                read_csv(&p).unwrap_or_else(|e| panic!("{e}"));
                n += 1;
            }
        }
    }
    assert!(n > 0 || !root().join("results").exists());
}
