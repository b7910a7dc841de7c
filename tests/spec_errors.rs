//! Bad experiment files are rejected before any work, naming file, line and key.

use crate::util::*;
use std::path::Path;

/// Writes `text` as `bad.toml` in a temp dir, runs it, and returns (stderr, temp dir).
fn run_bad(text: &str, extra: &[&str]) -> (String, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.toml");
    std::fs::write(&path, text).unwrap();
    let mut args = vec![
        "run",
        "bad.toml",
        "--quick",
        "--out",
        "out",
        "--figures",
        "figs",
    ];
    args.extend_from_slice(extra);
    let out = motionlab(dir.path(), &args);
    assert!(!out.status.success(), "a bad spec must fail");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(
        !dir.path().join("out").exists(),
        "nothing may be written: {err}"
    );
    assert!(
        !dir.path().join("figs").exists(),
        "nothing may be written: {err}"
    );
    (err, dir)
}

fn line_of(text: &str, needle: &str) -> usize {
    text.lines()
        .position(|l| l.contains(needle))
        .expect("needle in text")
        + 1
}

#[test]
fn unknown_param_key_names_file_line_and_key() {
    let text =
        spec("physics_validation").replacen("duration = 2.0", "duration = 2.0\ndurration = 3.0", 1);
    let (err, _d) = run_bad(&text, &[]);
    let line = line_of(&text, "durration");
    assert!(err.contains(&format!("bad.toml:{line}")), "{err}");
    assert!(err.contains("durration"), "{err}");
}

#[test]
fn unknown_top_level_key_is_rejected() {
    let text = spec("lbc_projection").replace("seed = 1", "seed = 1\nsed = 2");
    let (err, _d) = run_bad(&text, &[]);
    assert!(
        err.contains(&format!("bad.toml:{}", line_of(&text, "sed = 2"))),
        "{err}"
    );
    assert!(err.contains("`sed`"), "{err}");
}

#[test]
fn wrong_type_names_line_and_key() {
    let text = spec("lbc_projection").replace("dimension = 1", "dimension = \"one\"");
    let (err, _d) = run_bad(&text, &[]);
    assert!(
        err.contains(&format!(
            "bad.toml:{}",
            line_of(&text, "dimension = \"one\"")
        )),
        "{err}"
    );
    assert!(err.contains("`dimension`"), "{err}");
}

#[test]
fn non_positive_dt_names_the_element() {
    let text = spec("physics_validation").replace(
        "dts = [0.02, 0.01, 0.005, 0.0025, 0.00125]",
        "dts = [0.02,\n  -0.01]",
    );
    // Not quick: the [quick] table would replace dts.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("bad.toml"), &text).unwrap();
    let out = motionlab(
        dir.path(),
        &["run", "bad.toml", "--out", "out", "--figures", "figs"],
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(&format!("bad.toml:{}", line_of(&text, "-0.01"))),
        "{err}"
    );
    assert!(
        err.contains("params.dts[1]") && err.contains("must be > 0"),
        "{err}"
    );
    assert!(!dir.path().join("out").exists());
}

#[test]
fn quick_override_errors_point_into_quick_table() {
    let text = spec("physics_validation").replace("duration = 0.5", "duration = 0.0");
    let (err, _d) = run_bad(&text, &[]);
    assert!(
        err.contains(&format!("bad.toml:{}", line_of(&text, "duration = 0.0"))),
        "{err}"
    );
    assert!(err.contains("quick.duration"), "{err}");
}

#[test]
fn unknown_model_and_family_are_rejected() {
    let text = spec("physics_validation").replace(
        "models = [\"pendulum3\", \"acrobot\"]",
        "models = [\"pendulum3\", \"pendulum9\"]",
    );
    let (err, _d) = run_bad(&text, &[]);
    assert!(
        err.contains("params.models[1]") && err.contains("pendulum9"),
        "{err}"
    );
    let text =
        spec("lbc_projection").replace("experiment = \"lbc_projection\"", "experiment = \"nope\"");
    let (err, _d) = run_bad(&text, &[]);
    assert!(
        err.contains(&format!(
            "bad.toml:{}",
            line_of(&text, "experiment = \"nope\"")
        )),
        "{err}"
    );
}

#[test]
fn bad_set_override_names_set() {
    let text = spec("lbc_projection");
    let (err, _d) = run_bad(&text, &["--set", "scale=-1"]);
    assert!(err.contains("--set") && err.contains("scale"), "{err}");
}

#[test]
fn syntax_error_names_line() {
    let text = spec("lbc_projection").replace("dimension = 1", "dimension = = 1");
    let (err, _d) = run_bad(&text, &[]);
    assert!(
        err.contains(&format!("bad.toml:{}", line_of(&text, "dimension = = 1"))),
        "{err}"
    );
}

#[test]
fn bad_sweep_value_points_at_the_sweep() {
    let text = format!("{}\n[sweep]\nscale = [1.0, -2.0]\n", spec("lbc_projection"));
    let (err, _d) = run_bad(&text, &[]);
    assert!(err.contains("sweep.scale[1]"), "{err}");
    assert!(
        err.contains(&format!(
            "bad.toml:{}",
            line_of(&text, "scale = [1.0, -2.0]")
        )),
        "{err}"
    );
}

#[test]
fn reproduce_validates_every_file_first() {
    let dir = tempfile::tempdir().unwrap();
    let exp = dir.path().join("experiments");
    std::fs::create_dir_all(&exp).unwrap();
    std::fs::write(exp.join("a_good.toml"), spec("lbc_projection")).unwrap();
    std::fs::write(
        exp.join("b_bad.toml"),
        spec("lbc_projection").replace("scale = 1.0", "scale = 0.0"),
    )
    .unwrap();
    let out = motionlab(
        dir.path(),
        &["reproduce", "--quick", "--out", "out", "--figures", "figs"],
    );
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("b_bad.toml"));
    assert!(
        !Path::new(&dir.path().join("out")).exists(),
        "the good one must not have run either"
    );
}
