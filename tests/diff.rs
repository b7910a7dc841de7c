//! `motionlab diff A B`: the committed results against themselves, a copied experiment folder
//! with one cell changed, and a folder that does not exist, by exit code and report.

use crate::util::*;
use std::path::Path;
use std::process::Output;

fn stdout(out: &Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Copies folder `from` (its files and subfolders) to `to`.
fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let target = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &target);
        } else {
            std::fs::copy(e.path(), target).unwrap();
        }
    }
}

#[test]
fn diff_of_the_committed_results_with_themselves_is_no_change() {
    let out = motionlab(&root(), &["diff", "results", "results"]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}{}",
        stdout(&out),
        stderr(&out)
    );
    let text = stdout(&out);
    assert!(text.trim_end().ends_with("no change"), "{text}");
    assert!(
        text.contains("verdicts: ") && text.contains(" 0 changed"),
        "{text}"
    );
}

#[test]
fn diff_names_the_table_row_and_column_of_a_changed_cell() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    for side in [&a, &b] {
        copy_dir(
            &root().join("results/ms_lattices"),
            &side.join("ms_lattices"),
        );
    }
    let table = b.join("ms_lattices/lattices.csv");
    let text = std::fs::read_to_string(&table).unwrap();
    assert!(text.starts_with("lattice,masses,springs,rigid_reflexes\ncube,8,28,0\n"));
    std::fs::write(&table, text.replacen("cube,8,", "cube,9,", 1)).unwrap();
    let (a, b) = (a.to_str().unwrap(), b.to_str().unwrap());

    let out = motionlab(dir.path(), &["diff", a, b]);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}{}",
        stdout(&out),
        stderr(&out)
    );
    let text = stdout(&out);
    assert!(
        text.contains("ms_lattices/lattices.csv row 0 column masses: A 8 B 9"),
        "{text}"
    );
    assert!(text.contains("verdicts not compared"), "{text}");

    let out = motionlab(dir.path(), &["diff", a, b, "--json"]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let json: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert_eq!(json["changed"], true);
    let t = &json["tables"][0];
    assert_eq!(t["table"], "ms_lattices/lattices.csv");
    assert_eq!(t["cells"][0]["row"], 0);
    assert_eq!(t["cells"][0]["column"], "masses");
    assert_eq!(json["tables"].as_array().map(Vec::len), Some(1));
}

#[test]
fn diff_of_a_folder_that_does_not_exist_exits_2_naming_it() {
    let out = motionlab(&root(), &["diff", "results", "no-such-results"]);
    assert_eq!(
        out.status.code(),
        Some(2),
        "{}{}",
        stdout(&out),
        stderr(&out)
    );
    let err = stderr(&out);
    assert!(
        err.contains("no-such-results") && err.contains("does not exist"),
        "{err}"
    );
    assert!(out.stdout.is_empty());
}

/// Two runs of one experiment, the second with one parameter changed (the projection's
/// spacings), into two folders: `diff` exits 1 and names the changed tables, their rows, and
/// compares the two reports' verdicts.
#[test]
fn diff_of_two_runs_with_one_changed_parameter_names_tables_rows_and_verdicts() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let spec = std::fs::read_to_string(root().join("experiments/lbc_projection.toml")).unwrap();
    let changed = spec.replacen(
        "spacings = [0.5, 2.0, 6.0]",
        "spacings = [0.5, 2.0, 5.0]",
        1,
    );
    assert_ne!(spec, changed, "the quick spacings moved: update this test");
    for (side, text) in [("a", &spec), ("b", &changed)] {
        let exp = d.join(format!("exp_{side}"));
        std::fs::create_dir_all(&exp).unwrap();
        std::fs::write(exp.join("lbc_projection.toml"), text).unwrap();
        let out = motionlab(
            d,
            &[
                "--experiments",
                exp.to_str().unwrap(),
                "reproduce",
                "--quick",
                "--only",
                "lbc_projection",
                "--out",
                side,
                "--figures",
                &format!("figs_{side}"),
            ],
        );
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let out = motionlab(d, &["diff", "a", "b"]);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}{}",
        stdout(&out),
        stderr(&out)
    );
    let text = stdout(&out);
    assert!(text.contains("table lbc_projection/"), "{text}");
    assert!(text.contains(" row "), "{text}");
    assert!(text.contains("verdicts: 1 compared"), "{text}");
}
