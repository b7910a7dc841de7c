//! An experiment's output folder as a whole (issue 55): the clean-up of leftovers touches only
//! this program's temporary files in its own folders; a run that fails part way marks its folder
//! and `reproduce`/`merge` refuse it until it is rerun; two runs into one folder do not mix (the
//! second refuses); a run without seeds removes an earlier run's seeds.

use crate::util::*;
use std::path::Path;
use std::process::Output;

/// No process has an id above Linux's largest (2²²): a file named for it has no live owner.
const DEAD: u32 = u32::MAX;

/// `motionlab [--experiments <exp>] <args> --quick --out out --figures <figs>` in `dir`.
fn cli(dir: &Path, exp: Option<&Path>, args: &[&str], figs: &str) -> Output {
    let mut a: Vec<&str> = Vec::new();
    if let Some(e) = exp {
        a.extend(["--experiments", e.to_str().unwrap()]);
    }
    a.extend_from_slice(args);
    a.extend(["--quick", "--out", "out", "--figures", figs]);
    motionlab(dir, &a)
}

fn set_old(f: &Path) {
    let old = std::time::SystemTime::now() - std::time::Duration::from_secs(3600);
    let file = std::fs::File::options().write(true).open(f).unwrap();
    file.set_modified(old).unwrap();
}

/// Item 2: a user's files that look like temporary files (`.IMG_0001.tmp-424242.jpg`, old,
/// of a process that is gone) stay, wherever they are under `--out` and `--figures`; this
/// program's own stale temporary files in its folders go, and only those; ours in a folder
/// that is not an experiment's stay too.
#[test]
fn the_clean_up_removes_only_this_programs_temporary_files_in_its_folders() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let exp = root().join("experiments");
    let mine = [
        dir.join(format!(
            "out/lbc_projection/.motionlab-tmp-{DEAD}-weights.csv"
        )),
        dir.join(format!(
            "figs/.motionlab-tmp-{DEAD}-lbc_projection_cost.png"
        )),
    ];
    let users = [
        dir.join("out/.IMG_0001.tmp-424242.jpg"),
        dir.join(format!("out/.IMG_0001.tmp-{DEAD}.jpg")),
        dir.join(format!("out/photos/.IMG_0001.tmp-{DEAD}.jpg")),
        dir.join("out/photos/.IMG_0001.tmp-424242.jpg"),
        dir.join(format!("out/photos/.motionlab-tmp-{DEAD}-x.csv")),
        dir.join(format!("out/lbc_projection/.IMG_0001.tmp-{DEAD}.jpg")),
        dir.join(format!(
            "out/lbc_projection/photos/.motionlab-tmp-{DEAD}-x.csv"
        )),
        dir.join(format!("figs/.IMG_0001.tmp-{DEAD}.jpg")),
    ];
    for f in mine.iter().chain(&users) {
        std::fs::create_dir_all(f.parent().unwrap()).unwrap();
        std::fs::write(f, b"x").unwrap();
        set_old(f);
    }
    let e = stderr(&cli(dir, Some(&exp), &["run", "lbc_projection"], "figs"));
    for f in &users {
        assert!(
            f.exists(),
            "a user's file was removed: {}\n{e}",
            f.display()
        );
    }
    for f in &mine {
        assert!(!f.exists(), "{} left", f.display());
        let name = f.file_name().unwrap().to_string_lossy();
        assert!(e.contains(&*name), "not reported: {name}\n{e}");
    }
    assert_eq!(e.matches("removed").count(), mine.len(), "{e}");
}

/// Two experiment files (ids `proj_a`, `proj_b`) of the quick, fast `lbc_projection` in
/// `<dir>/exp`.
fn two_experiments(dir: &Path) -> std::path::PathBuf {
    let exp = dir.join("exp");
    std::fs::create_dir_all(&exp).unwrap();
    let text = spec("lbc_projection");
    for id in ["proj_a", "proj_b"] {
        let t = text.replace("id = \"lbc_projection\"", &format!("id = \"{id}\""));
        assert!(t.contains(&format!("id = \"{id}\"")));
        std::fs::write(exp.join(format!("{id}.toml")), t).unwrap();
    }
    exp
}

/// Item 3: a rerun into an existing folder that fails part way (its figures cannot be written,
/// after its tables were) leaves the new tables beside the old `run.json`: the folder is marked,
/// and `reproduce` and `merge` (whose reports would read it) refuse it before any work, naming
/// it and saying to rerun it, until a rerun (here with `--resume`) completes it.
#[test]
fn a_run_that_fails_part_way_leaves_a_folder_that_reproduce_and_merge_refuse() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let exp = two_experiments(dir);
    let a = dir.join("out/proj_a");
    ok(&cli(dir, Some(&exp), &["run", "proj_a"], "figs"));
    assert!(a.join("run.json").is_file() && !a.join("INCOMPLETE").exists());
    // A figures "folder" that is a file: the tables are written, the figures fail.
    std::fs::write(dir.join("not_a_folder"), b"x").unwrap();
    let args = ["run", "proj_a", "--resume", "--set", "samples=301"];
    fails(&cli(dir, Some(&exp), &args, "not_a_folder"));
    assert!(a.join("run.json").is_file(), "the old run.json stays");
    assert!(
        a.join("INCOMPLETE").is_file(),
        "a folder mixing two runs carries no mark"
    );
    let refused = |e: &str| {
        assert!(
            e.contains(&format!("out{}proj_a", std::path::MAIN_SEPARATOR))
                && e.contains("did not finish")
                && e.contains("rerun"),
            "{e}"
        );
    };
    let e = fails(&cli(
        dir,
        Some(&exp),
        &["reproduce", "--only", "proj_b"],
        "figs",
    ));
    refused(&e);
    assert!(
        !dir.join("out/proj_b").exists(),
        "work done before refusing"
    );
    assert!(!dir.join("out/REPORT.md").exists());
    ok(&cli(
        dir,
        Some(&exp),
        &["run", "proj_b", "--shard", "1/1"],
        "figs",
    ));
    let e = fails(&cli(dir, Some(&exp), &["merge", "proj_b"], "figs"));
    refused(&e);
    assert!(!dir.join("out/proj_b/run.json").exists());
    assert!(!dir.join("out/REPORT.md").exists());
    // The rerun completes the folder (reusing its units); then both go ahead.
    let e = stderr(&cli(dir, Some(&exp), &args, "figs"));
    assert!(e.contains("(0 units run, 1 resumed)"), "{e}");
    assert!(!a.join("INCOMPLETE").exists());
    let run: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(a.join("run.json")).unwrap()).unwrap();
    assert_eq!(run["spec"]["points"][0]["params"]["samples"], 301, "{run}");
    ok(&cli(dir, Some(&exp), &["merge", "proj_b"], "figs"));
    ok(&cli(
        dir,
        Some(&exp),
        &["reproduce", "--only", "proj_b"],
        "figs",
    ));
    assert!(dir.join("out/REPORT.md").is_file());
}

/// Item 4: while another run (here this test's process) holds an experiment folder, a second
/// run into it refuses before any work, naming the folder and the holder; a lock left by a run
/// that no longer runs is taken over, saying so; a run releases its lock when it ends, also
/// when it fails; a shard's run locks only its shard's folder.
#[test]
fn a_second_run_into_a_folder_in_use_is_refused() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let exp = root().join("experiments");
    let folder = dir.join("out/lbc_projection");
    let lock = folder.join(".motionlab.lock");
    std::fs::create_dir_all(&folder).unwrap();
    let held = format!(
        "pid {} host {}\n",
        std::process::id(),
        motionlab::experiment::folder::host_name()
    );
    std::fs::write(&lock, &held).unwrap();
    let run = |figs: &str| cli(dir, Some(&exp), &["run", "lbc_projection"], figs);
    let e = fails(&run("figs"));
    assert!(
        e.contains(&folder.strip_prefix(dir).unwrap().display().to_string())
            && e.contains(&format!("process {}", std::process::id()))
            && e.contains("another motionlab run"),
        "{e}"
    );
    assert!(
        !folder.join("weights.csv").exists(),
        "it wrote while refused"
    );
    assert_eq!(std::fs::read_to_string(&lock).unwrap(), held);
    // Shards lock their own folders: they run beside a run of the whole experiment.
    ok(&cli(
        dir,
        Some(&exp),
        &["run", "lbc_projection", "--shard", "1/1"],
        "figs",
    ));
    assert_eq!(std::fs::read_to_string(&lock).unwrap(), held);
    let e = fails(&cli(dir, Some(&exp), &["merge", "lbc_projection"], "figs"));
    assert!(e.contains("another motionlab run"), "{e}");
    // The holder is gone (a killed run): its lock is taken over.
    std::fs::write(
        &lock,
        format!(
            "pid {DEAD} host {}\n",
            motionlab::experiment::folder::host_name()
        ),
    )
    .unwrap();
    let e = stderr(&run("figs"));
    assert!(
        e.contains("took over") && e.contains(&DEAD.to_string()),
        "{e}"
    );
    assert!(!lock.exists(), "the lock outlived its run");
    assert!(folder.join("run.json").is_file());
    // A run that fails releases its lock too.
    std::fs::write(dir.join("not_a_folder"), b"x").unwrap();
    fails(&run("not_a_folder"));
    assert!(!lock.exists(), "a failed run kept its lock");
    ok(&run("figs"));
}

/// Item 6: a rerun without seeds after a run with seeds removes that run's `seeds/` folder,
/// `seed_summary.*` and seeds figure, and says so; a user's file in the folder stays.
#[test]
fn a_run_without_seeds_removes_an_earlier_runs_seeds() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let exp = root().join("experiments");
    let folder = dir.join("out/lbc_projection");
    ok(&cli(
        dir,
        Some(&exp),
        &["run", "lbc_projection", "--seeds", "2"],
        "figs",
    ));
    let seeded = [
        folder.join("seeds"),
        folder.join("seed_summary.csv"),
        folder.join("seed_summary.parquet"),
    ];
    for f in &seeded {
        assert!(f.exists(), "{}", f.display());
    }
    let figure = dir.join("figs/lbc_projection_seeds.png");
    let had_figure = figure.exists();
    std::fs::write(folder.join("notes.txt"), b"mine").unwrap();
    let e = stderr(&cli(dir, Some(&exp), &["run", "lbc_projection"], "figs"));
    for f in &seeded {
        assert!(!f.exists(), "{} left\n{e}", f.display());
    }
    assert!(
        !figure.exists(),
        "the seeds figure (made: {had_figure}) left"
    );
    assert!(e.contains("seed_summary.csv") && e.contains("seeds"), "{e}");
    assert!(folder.join("notes.txt").is_file());
    assert!(header(&folder.join("weights.csv")).starts_with("spacing"));
}

/// A spec's `[[history]]` (a rule or setup changed after a result) is shown in its section of
/// REPORT.md with its verdict and the reason, in full with the old rule in the experiment's
/// DETAILS.md, and the summary row marks it; a
/// malformed entry is refused before any work, naming the file and the entry.
#[test]
fn the_report_shows_a_specs_rule_history_and_flags_it_in_the_summary() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let exp = two_experiments(dir);
    let history = "\n[[history]]\ndate = \"2026-11-28\"\nkind = \"rule\"\nold = \"held when one minimum appears\"\nold_verdict = \"held\"\nreason = \"the old rule could not fail\"\n";
    let path = exp.join("proj_a.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let (top, rest) = text.split_at(text.find("[params]").unwrap());
    std::fs::write(&path, format!("{top}{history}\n{rest}")).unwrap();
    ok(&cli(
        dir,
        Some(&exp),
        &["reproduce", "--only", "proj_a"],
        "figs",
    ));
    let report = std::fs::read_to_string(dir.join("out/REPORT.md")).unwrap();
    assert!(report.contains("(changed after results: 1)"), "{report}");
    assert!(
        report.contains(
            "2026-11-28, rule changed (verdict then: held). Why: the old rule could not fail"
        ),
        "{report}"
    );
    let details = std::fs::read_to_string(dir.join("out/proj_a/DETAILS.md")).unwrap();
    assert!(
        details.contains("2026-11-28, rule changed after a result: was held when one minimum appears (verdict then: held). Why: the old rule could not fail"),
        "{details}"
    );
    let bad = history.replace("2026-11-28", "last week");
    std::fs::write(&path, format!("{top}{bad}\n{rest}")).unwrap();
    let e = fails(&cli(dir, Some(&exp), &["run", "proj_a"], "figs2"));
    assert!(e.contains("proj_a.toml") && e.contains("history[0]"), "{e}");
    assert!(!dir.join("figs2").exists(), "work done before refusing");
}

/// `reproduce` says before each experiment where it is (k of n) and, from the last run's
/// `run.json` in the output folder, what that experiment took and about how long is left;
/// each `run.json` records the CPU time beside the wall time, and the details show it.
#[test]
fn reproduce_says_where_it_is_and_what_is_left_from_the_last_run() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let exp = two_experiments(dir);
    let first = cli(dir, Some(&exp), &["reproduce"], "figs");
    ok(&first);
    let e = stderr(&first);
    assert!(
        e.contains("[1/2] proj_a") && e.contains("[2/2] proj_b"),
        "{e}"
    );
    assert!(e.contains("no past run here"), "no past time yet: {e}");
    let run: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/proj_a/run.json")).unwrap())
            .unwrap();
    if std::path::Path::new("/proc/self/stat").exists() {
        let cpu = run["cpu_seconds"].as_f64().expect("cpu_seconds");
        assert!(cpu >= 0.0, "{run}");
        let details = std::fs::read_to_string(dir.join("out/proj_a/DETAILS.md")).unwrap();
        assert!(details.contains("s of CPU time)"), "{details}");
    }
    let second = cli(dir, Some(&exp), &["reproduce"], "figs");
    ok(&second);
    let e = stderr(&second);
    assert!(
        e.contains("[1/2] proj_a (took") && e.contains("left in all"),
        "{e}"
    );
}
