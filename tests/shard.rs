//! Sweeps that shard, resume and merge, and seeds: the shards of a sweep, run one after the
//! other, merge into the unsharded run's files byte for byte; merge refuses incomplete or
//! inconsistent sets; a killed sweep resumes with only its missing points.

use crate::util::*;
use std::path::Path;
use std::process::Output;

/// `lbc_projection` with a three-point sweep, written to `s.toml` in `dir`.
fn sweep_spec(dir: &Path, extra: &str) {
    let text = format!(
        "{}\n[sweep]\nscale = [1.0, 4.0, 2.0]\n{extra}",
        spec("lbc_projection")
    );
    std::fs::write(dir.join("s.toml"), text).unwrap();
}

fn run(dir: &Path, target: &str, out: &str, args: &[&str]) -> Output {
    let mut a = vec!["run", target, "--quick", "--out", out, "--figures"];
    let figs = format!("{out}-figs");
    a.push(&figs);
    a.extend_from_slice(args);
    motionlab(dir, &a)
}

fn merge(dir: &Path, target: &str, out: &str) -> Output {
    let figs = format!("{out}-figs");
    motionlab(
        dir,
        &["merge", target, "--quick", "--out", out, "--figures", &figs],
    )
}

/// CSV, Parquet and PNG files of `a` and `b` (below the experiment folders) are identical, but
/// for tables named in `timing` (whose timing columns change from run to run).
fn assert_same_outputs(a: &Path, b: &Path, timing: &[&str]) {
    for (sub, ext) in [("", "csv"), ("", "parquet"), ("-figs", "png")] {
        let dir = |p: &Path| {
            p.with_file_name(format!("{}{sub}", p.file_name().unwrap().to_str().unwrap()))
        };
        let timed = |f: &(String, Vec<u8>)| {
            let stem = Path::new(&f.0)
                .file_stem()
                .unwrap()
                .to_str()
                .unwrap()
                .to_string();
            !timing.contains(&stem.as_str())
        };
        let fa: Vec<_> = files_with_ext(&dir(a), ext)
            .into_iter()
            .filter(timed)
            .collect();
        let fb: Vec<_> = files_with_ext(&dir(b), ext)
            .into_iter()
            .filter(timed)
            .collect();
        assert!(!fa.is_empty(), "no {ext} files in {}", dir(a).display());
        let names = |f: &[(String, Vec<u8>)]| f.iter().map(|x| x.0.clone()).collect::<Vec<_>>();
        assert_eq!(names(&fa), names(&fb), "{ext} files");
        for ((n, x), (_, y)) in fa.iter().zip(&fb) {
            assert!(
                x == y,
                "{n} differs between the unsharded run and the merged shards"
            );
        }
    }
}

#[test]
fn merged_shards_are_byte_identical_to_the_unsharded_sweep() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    sweep_spec(dir, "");
    // 3 points x 2 seeds = 6 units over 4 shards (uneven: 2, 2, 1, 1 units).
    ok(&run(dir, "s.toml", "a", &["--seeds", "2"]));
    for i in 1..=4 {
        let e = stderr(&run(
            dir,
            "s.toml",
            "b",
            &["--seeds", "2", "--shard", &format!("{i}/4")],
        ));
        let n = if i <= 2 { 2 } else { 1 };
        assert!(e.contains(&format!("({n} units run, 0 resumed)")), "{e}");
    }
    // A shard writes no tables of its own.
    assert!(!dir.join("b/lbc_projection/weights.csv").exists());
    assert!(dir
        .join("b/lbc_projection/shards/3-of-4/shard.json")
        .is_file());
    let e = stderr(&merge(dir, "s.toml", "b"));
    assert!(e.contains("merged 6 units"), "{e}");
    assert_same_outputs(&dir.join("a"), &dir.join("b"), &[]);
    let w = std::fs::read_to_string(dir.join("b/lbc_projection/weights.csv")).unwrap();
    assert!(w.starts_with("seed,scale,spacing"), "{w}");
    // merge writes the report section of the merged experiment.
    let report = std::fs::read_to_string(dir.join("b/REPORT.md")).unwrap();
    assert!(report.contains("**Over 2 seeds** (1, 2)"), "{report}");
}

#[test]
fn sharded_seeds_of_a_random_search_merge_to_the_unsharded_run() {
    // Hill climbing depends on the seed: each unit must draw from its own seed wherever it runs.
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let exp = root().join("experiments/ms_spider_leap.toml");
    let exp = exp.to_str().unwrap();
    // The spec sweeps seeds 1-5 itself.
    ok(&run(dir, exp, "a", &["--jobs", "2"]));
    for i in 1..=2 {
        ok(&run(
            dir,
            exp,
            "b",
            &["--jobs", "1", "--shard", &format!("{i}/2")],
        ));
    }
    ok(&merge(dir, exp, "b"));
    // summary.csv has the search's seconds and evaluations per second.
    assert_same_outputs(&dir.join("a"), &dir.join("b"), &["summary", "seed_summary"]);
    let best = |s: u64| {
        std::fs::read_to_string(dir.join(format!("a/ms_spider_leap/seeds/{s}/best.csv"))).unwrap()
    };
    assert!(
        best(1) != best(2) || best(2) != best(3),
        "seeds 1, 2, 3 give the same search"
    );
    let summary = std::fs::read_to_string(dir.join("a/ms_spider_leap/seed_summary.csv")).unwrap();
    assert!(
        summary.starts_with("table,row,label,column,seeds,mean,std,min,max"),
        "{summary}"
    );
}

#[test]
fn merge_refuses_missing_duplicated_and_foreign_shards() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    sweep_spec(dir, "");
    let shard = |i: &str| ok(&run(dir, "s.toml", "o", &["--shard", i]));
    let nothing_written = || {
        assert!(!dir.join("o/lbc_projection/weights.csv").exists());
        assert!(!dir.join("o/lbc_projection/run.json").exists());
        assert!(!dir.join("o/REPORT.md").exists());
    };
    // Bad --shard values.
    for bad in ["0/3", "4/3", "2", "a/b"] {
        let e = fails(&run(dir, "s.toml", "o", &["--shard", bad]));
        assert!(e.contains("1 <= I <= N"), "{bad}: {e}");
    }
    let e = fails(&merge(dir, "s.toml", "o"));
    assert!(e.contains("no shards"), "{e}");
    shard("1/3");
    shard("3/3");
    let e = fails(&merge(dir, "s.toml", "o"));
    assert!(e.contains("missing shard(s) 2 of 3"), "{e}");
    nothing_written();
    shard("2/3");
    let shards = dir.join("o/lbc_projection/shards");
    // Duplicated: a copy of shard 2 beside it.
    let copy = shards.join("2-of-3-copy");
    std::fs::create_dir_all(copy.join("units")).unwrap();
    for sub in ["", "units"] {
        for e in std::fs::read_dir(shards.join("2-of-3").join(sub)).unwrap() {
            let p = e.unwrap().path();
            if p.is_file() {
                std::fs::copy(&p, copy.join(sub).join(p.file_name().unwrap())).unwrap();
            }
        }
    }
    let e = fails(&merge(dir, "s.toml", "o"));
    assert!(e.contains("shard 2 of 3 is duplicated"), "{e}");
    nothing_written();
    std::fs::remove_dir_all(&copy).unwrap();
    // Shards of another count.
    shard("2/2");
    let e = fails(&merge(dir, "s.toml", "o"));
    assert!(e.contains("different counts"), "{e}");
    std::fs::remove_dir_all(shards.join("2-of-2")).unwrap();
    // Another revision.
    let rec = shards.join("1-of-3/shard.json");
    let text = std::fs::read_to_string(&rec).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["git_revision"] = serde_json::json!("0123456789abcdef");
    std::fs::write(&rec, v.to_string()).unwrap();
    let e = fails(&merge(dir, "s.toml", "o"));
    assert!(e.contains("different code revisions"), "{e}");
    std::fs::write(&rec, text).unwrap();
    // The spec changed after the shards ran.
    let spec_text = std::fs::read_to_string(dir.join("s.toml")).unwrap();
    let changed = spec_text.replace("scale = [1.0, 4.0, 2.0]", "scale = [1.0, 4.0, 3.0]");
    std::fs::write(dir.join("s.toml"), &changed).unwrap();
    let e = fails(&merge(dir, "s.toml", "o"));
    assert!(e.contains("different spec"), "{e}");
    nothing_written();
    // One shard rerun with the changed spec: the shards disagree.
    shard("3/3");
    let e = fails(&merge(dir, "s.toml", "o"));
    assert!(e.contains("different specs"), "{e}");
    nothing_written();
    // A missing unit file.
    std::fs::write(dir.join("s.toml"), &spec_text).unwrap();
    shard("3/3");
    let units = shards.join("1-of-3/units");
    let unit = std::fs::read_dir(&units)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let kept = std::fs::read(&unit).unwrap();
    std::fs::remove_file(&unit).unwrap();
    let e = fails(&merge(dir, "s.toml", "o"));
    assert!(
        e.contains(unit.file_name().unwrap().to_str().unwrap()),
        "{e}"
    );
    nothing_written();
    std::fs::write(&unit, kept).unwrap();
    ok(&merge(dir, "s.toml", "o"));
    assert!(dir.join("o/lbc_projection/weights.csv").is_file());
}

#[test]
fn a_killed_sweep_resumes_with_only_its_unfinished_points() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    sweep_spec(dir, "");
    ok(&run(dir, "s.toml", "o", &[]));
    let before = files_with_ext(&dir.join("o/lbc_projection"), "csv");
    let units = dir.join("o/lbc_projection/units");
    let mut files: Vec<_> = std::fs::read_dir(&units)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    assert_eq!(files.len(), 3, "one stored result per sweep point");
    // Everything complete: nothing runs again.
    let e = stderr(&run(dir, "s.toml", "o", &["--resume"]));
    assert!(e.contains("(0 units run, 3 resumed)"), "{e}");
    // A kill: one point never written (a temporary file left behind), one cut off mid-write.
    let tmp = files[0].with_file_name(".x.tmp-999.json");
    std::fs::rename(&files[0], &tmp).unwrap();
    let text = std::fs::read(&files[1]).unwrap();
    std::fs::write(&files[1], &text[..text.len() / 2]).unwrap();
    let untouched = std::fs::metadata(&files[2]).unwrap().modified().unwrap();
    let e = stderr(&run(dir, "s.toml", "o", &["--resume"]));
    assert!(e.contains("(2 units run, 1 resumed)"), "{e}");
    assert_eq!(
        std::fs::metadata(&files[2]).unwrap().modified().unwrap(),
        untouched
    );
    // The cut-off point is recomputed: the same key and tables (its stage times differ).
    let stored = |b: &[u8]| -> serde_json::Value {
        let v: serde_json::Value = serde_json::from_slice(b).unwrap();
        serde_json::json!([v["key"], v["tables"]])
    };
    assert!(stored(&std::fs::read(&files[1]).unwrap()) == stored(&text));
    assert!(files[0].is_file());
    let after = files_with_ext(&dir.join("o/lbc_projection"), "csv");
    assert_eq!(before, after, "the resumed run writes the same tables");
    // A changed parameter changes every key: nothing is reused.
    let e = stderr(&run(
        dir,
        "s.toml",
        "o",
        &["--resume", "--set", "spacings=[0.5, 3.0]"],
    ));
    assert!(e.contains("(3 units run, 0 resumed)"), "{e}");
}

#[test]
fn seeds_come_from_the_flag_or_a_sweep_axis() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    sweep_spec(dir, "seeds = [3, 5]\n");
    ok(&run(dir, "s.toml", "o", &[]));
    let out = dir.join("o/lbc_projection");
    let w = std::fs::read_to_string(out.join("weights.csv")).unwrap();
    assert!(w.starts_with("seed,scale,"), "{w}");
    let seeds: Vec<&str> = w
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap())
        .collect();
    // Seed-major: every point of seed 3, then seed 5.
    assert_eq!(seeds.first(), Some(&"3"));
    assert_eq!(seeds.last(), Some(&"5"));
    let one = std::fs::read_to_string(out.join("seeds/5/weights.csv")).unwrap();
    assert!(one.starts_with("scale,spacing"), "{one}");
    assert_eq!(
        one.lines().count() - 1,
        seeds.iter().filter(|s| **s == "5").count()
    );
    assert!(out.join("seed_summary.csv").is_file());
    // Both ways at once is an error; an explicit seed drops the axis.
    let e = fails(&run(dir, "s.toml", "o2", &["--seeds", "2"]));
    assert!(e.contains("sweep.seeds") && e.contains("not both"), "{e}");
    ok(&run(dir, "s.toml", "o3", &["--seed", "9"]));
    let w = std::fs::read_to_string(dir.join("o3/lbc_projection/weights.csv")).unwrap();
    assert!(w.starts_with("scale,"), "{w}");
    let e = fails(&run(dir, "s.toml", "o4", &["--seed", "9", "--seeds", "0"]));
    assert!(e.contains("--seeds") && e.contains("at least 1"), "{e}");
    sweep_spec(dir, "seeds = [3, 3]\n");
    let e = fails(&run(dir, "s.toml", "o5", &[]));
    assert!(
        e.contains("s.toml:") && e.contains("sweep.seeds[1]") && e.contains("twice"),
        "{e}"
    );
}

#[test]
fn reproduce_with_seeds_reports_each_seed_and_the_spread() {
    let d = tempfile::tempdir().unwrap();
    let exp = root().join("experiments");
    ok(&motionlab(
        d.path(),
        &[
            "--experiments",
            exp.to_str().unwrap(),
            "reproduce",
            "--quick",
            "--seeds",
            "2",
            "--only",
            "lbc_projection",
            "--out",
            "out",
            "--figures",
            "figs",
        ],
    ));
    // The report gives each seed's verdict; the experiment's DETAILS.md the first seed's
    // tables and the spread.
    let report = std::fs::read_to_string(d.path().join("out/REPORT.md")).unwrap();
    assert!(
        report.contains("**Over 2 seeds** (1, 2): the verdict held for 2."),
        "{report}"
    );
    let details = std::fs::read_to_string(d.path().join("out/lbc_projection/DETAILS.md")).unwrap();
    assert!(details.contains("*Seed 1, the first of 2"), "{details}");
    assert!(details.contains("values vary with the seed"), "{details}");
}

#[test]
fn the_shipped_sweep_example_runs_and_plots_its_seeds() {
    let d = tempfile::tempdir().unwrap();
    let file = root().join("experiments/sweeps/ms_spider_leap_regimes.toml");
    ok(&motionlab(
        d.path(),
        &[
            "run",
            file.to_str().unwrap(),
            "--quick",
            "--jobs",
            "2",
            "--out",
            "o",
            "--figures",
            "f",
        ],
    ));
    let out = d.path().join("o/ms_spider_leap_regimes");
    // The swept parameter the summary already carries is not duplicated.
    let summary = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    let head = summary.lines().next().unwrap();
    assert!(head.starts_with("seed,motion,lattice,regimes,"), "{head}");
    assert_eq!(summary.lines().count() - 1, 9, "3 regime counts x 3 seeds");
    let spread = std::fs::read_to_string(out.join("seed_summary.csv")).unwrap();
    assert!(spread.contains("regimes=6\",best_objective,3,"), "{spread}");
    assert!(d
        .path()
        .join("f/ms_spider_leap_regimes_seeds.png")
        .is_file());
}
