//! The CLI end to end: every experiment in quick mode, determinism across --jobs, sweeps,
//! describe, simulate, reproduce.

use crate::util::*;

#[test]
fn physics_validation_quick_writes_promised_outputs() {
    let d = quick_reproduction();
    let out = d.path().join("out/physics_validation");
    assert_eq!(
        header(&out.join("energy_drift.csv")),
        "model,integrator,dt,drift"
    );
    assert!(out.join("energy_drift.parquet").exists());
    assert!(header(&out.join("orders.csv"))
        .starts_with("model,integrator,theoretical_order,measured_order"));
    assert!(out.join("passive_pendulum3.csv").exists() && out.join("passive_acrobot.csv").exists());
    for f in [
        "energy_drift",
        "adaptive",
        "passive_pendulum3",
        "passive_acrobot",
    ] {
        for ext in ["png", "svg"] {
            let p = d.path().join(format!("figs/physics_validation_{f}.{ext}"));
            assert!(
                p.metadata().map(|m| m.len() > 1000).unwrap_or(false),
                "{}",
                p.display()
            );
        }
    }
    let run: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap();
    for key in [
        "id",
        "seed",
        "spec",
        "crate_version",
        "git_revision",
        "threads",
        "seconds_per_stage",
    ] {
        assert!(run.get(key).is_some(), "run.json lacks {key}");
    }
    assert_eq!(run["threads"], 2);
    // The measured orders of RK4 and Dormand-Prince are close to theory even in quick mode.
    let orders = std::fs::read_to_string(out.join("orders.csv")).unwrap();
    for line in orders.lines().skip(1) {
        let c: Vec<&str> = line.split(',').collect();
        let (theory, measured): (f64, f64) = (c[2].parse().unwrap(), c[3].parse().unwrap());
        if c[1] == "rk4" {
            assert!((measured - theory).abs() < 0.6, "{line}");
        }
    }
}

#[test]
fn every_figure_and_animation_is_in_the_report_with_a_caption() {
    let d = quick_reproduction();
    // The report shows each experiment's main figure; its DETAILS.md shows them all.
    let mut report = std::fs::read_to_string(d.path().join("out/REPORT.md")).unwrap();
    for e in std::fs::read_dir(d.path().join("out")).unwrap() {
        let details = e.unwrap().path().join("DETAILS.md");
        if details.is_file() {
            report.push_str(&std::fs::read_to_string(details).unwrap());
        }
    }
    assert!(
        !report.contains(motionlab::experiment::report::NO_CAPTION),
        "a figure without a caption: {}",
        report
            .lines()
            .filter(|l| l.contains(motionlab::experiment::report::NO_CAPTION))
            .collect::<Vec<_>>()
            .join("\n")
    );
    let mut n = 0;
    for e in std::fs::read_dir(d.path().join("figs")).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().into_owned();
        if name.ends_with(".png") || name.ends_with(".gif") {
            assert!(
                report.contains(&format!("/{name})")),
                "{name} is not in REPORT.md or a DETAILS.md"
            );
            n += 1;
        }
    }
    assert!(n > 40, "only {n} figures");
    for term in [
        "Glossary",
        "NeuroAnimator",
        "Linear Bellman Combination",
        "Mass-Spring",
    ] {
        assert!(report.contains(term), "the report does not name {term}");
    }
}

#[test]
fn lbc_projection_quick_writes_promised_outputs_and_two_minima_when_far() {
    let d = quick_reproduction();
    let out = d.path().join("out/lbc_projection");
    assert!(header(&out.join("weights.csv")).starts_with("spacing,component,weight"));
    let minima = std::fs::read_to_string(out.join("minima.csv")).unwrap();
    // Quick spacings are 0.5, 2 and 6 with the midpoint target: 1 minimum, then 2.
    let counts: Vec<i64> = minima
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(2).unwrap().parse().unwrap())
        .collect();
    assert_eq!(counts.first(), Some(&1), "{minima}");
    assert_eq!(counts.last(), Some(&2), "{minima}");
    for ext in ["png", "svg"] {
        assert!(d
            .path()
            .join(format!("figs/lbc_projection_cost.{ext}"))
            .exists());
        assert!(d
            .path()
            .join(format!("figs/lbc_projection_weights.{ext}"))
            .exists());
    }
}

#[test]
fn lbc_dive_disturbance_quick_pushes_both_controllers_with_the_same_forces() {
    let d = quick_reproduction();
    let out = d.path().join("out/lbc_dive_disturbance");
    assert_eq!(
        header(&out.join("disturbance.csv")),
        "controller,force_scale,effort,deviation,final_error,trial,entry_change,max_torque_fraction"
    );
    let text = std::fs::read_to_string(out.join("disturbance.csv")).unwrap();
    let rows: Vec<Vec<String>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    // Two controllers: the unpushed dive, then 2 quick trials at each of 2 scales.
    assert_eq!(rows.len(), 2 * (1 + 2 * 2), "{text}");
    for r in &rows {
        let v: Vec<f64> = r[1..].iter().map(|x| x.parse().unwrap()).collect();
        assert!(v.iter().all(|x| x.is_finite()), "{r:?}");
        // Unpushed rows deviate by nothing; the torque limits hold.
        if v[0] == 0.0 {
            assert_eq!((v[2], v[5]), (0.0, 0.0), "{r:?}");
        }
        assert!(v[6] <= 1.0 + 1e-12, "{r:?}");
    }
    // Pushed dives differ from the unpushed ones.
    assert!(rows
        .iter()
        .any(|r| r[1] != "0" && r[3].parse::<f64>().unwrap() > 0.0));
    assert!(d
        .path()
        .join("figs/lbc_dive_disturbance_measures.png")
        .exists());
    assert!(d
        .path()
        .join("figs/lbc_dive_disturbance_dives.gif")
        .exists());
}

#[test]
fn lbc_walking_quick_writes_the_promised_tables_and_a_blend_between_the_walkers() {
    let d = quick_reproduction();
    let out = d.path().join("out/lbc_walking");
    assert_eq!(
        header(&out.join("walks.csv")),
        "terrain,controller,distance_m,fell,mean_speed_m_s,steps,fell_at_s,lambda"
    );
    assert!(
        header(&out.join("weights.csv")).starts_with("terrain,t,x,slope_deg,alpha_flat,alpha_hill")
    );
    let walks = std::fs::read_to_string(out.join("walks.csv")).unwrap();
    // Every controller on every terrain.
    assert_eq!(walks.lines().count(), 1 + 3 * 4, "{walks}");
    let weights = std::fs::read_to_string(out.join("weights.csv")).unwrap();
    for l in weights.lines().skip(1) {
        let f: Vec<f64> = l
            .split(',')
            .skip(4)
            .take(2)
            .map(|v| v.parse().unwrap())
            .collect();
        assert!(
            (f[0] + f[1] - 1.0).abs() < 1e-12 && (0.0..=1.0).contains(&f[1]),
            "{l}"
        );
    }
    // The incline's rows carry its slope.
    assert!(weights
        .lines()
        .filter(|l| l.starts_with("incline,"))
        .all(|l| (l.split(',').nth(3).unwrap().parse::<f64>().unwrap() - 10.0).abs() < 1e-9));
    assert!(d.path().join("figs/lbc_walking_weights.png").exists());
    assert!(d.path().join("figs/lbc_walking_filmstrip.png").exists());
    assert!(d.path().join("figs/lbc_walking_track.gif").exists());
}

#[test]
fn lbc_stepping_quick_writes_the_promised_tables_and_two_different_examples() {
    let d = quick_reproduction();
    let out = d.path().join("out/lbc_stepping");
    assert!(header(&out.join("targets.csv"))
        .starts_with("desired_length_m,method,reached_length_m,fell,effort,seconds"));
    let targets = std::fs::read_to_string(out.join("targets.csv")).unwrap();
    // Every method at the quick run's one desired length.
    let methods: Vec<&str> = targets
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap())
        .collect();
    assert_eq!(
        methods,
        ["lbc", "naive", "short", "long", "direct"],
        "{targets}"
    );
    for l in targets.lines().skip(1) {
        let effort: f64 = l.split(',').nth(4).unwrap().parse().unwrap();
        assert!(effort > 0.0 && effort.is_finite(), "{l}");
    }
    // The two DDP examples step to different lengths, the long one further.
    let comp = std::fs::read_to_string(out.join("components.csv")).unwrap();
    let reached: Vec<f64> = comp
        .lines()
        .skip(1)
        .take(2)
        .map(|l| l.split(',').nth(2).unwrap().parse().unwrap())
        .collect();
    assert!(reached[1] > reached[0] + 0.01, "{comp}");
    let weights = std::fs::read_to_string(out.join("weights.csv")).unwrap();
    for l in weights.lines().skip(1) {
        let a: f64 = l.split(',').nth(2).unwrap().parse().unwrap();
        assert!((0.0..=1.0).contains(&a), "{l}");
    }
    assert!(header(&out.join("walk.csv")).starts_with("step,stance_heel_m,foothold_m"));
    assert!(
        std::fs::read_to_string(out.join("walk.csv"))
            .unwrap()
            .lines()
            .count()
            >= 2
    );
    for f in ["lengths.png", "effort.png", "walk.png", "walk_anim.gif"] {
        assert!(
            d.path().join(format!("figs/lbc_stepping_{f}")).exists(),
            "{f}"
        );
    }
}

#[test]
fn lbc_jumping_quick_writes_the_promised_tables_and_two_different_take_offs() {
    let d = quick_reproduction();
    let out = d.path().join("out/lbc_jumping");
    assert!(header(&out.join("jumps.csv")).starts_with("desired,method,takeoff_error,landed"));
    let jumps = std::fs::read_to_string(out.join("jumps.csv")).unwrap();
    let rows: Vec<Vec<&str>> = jumps
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    let methods: Vec<&str> = rows.iter().map(|r| r[1]).collect();
    assert_eq!(
        methods,
        ["lbc", "naive", "low", "high", "reference"],
        "{jumps}"
    );
    for r in &rows {
        let err: f64 = r[2].parse().unwrap();
        let landed: f64 = r[3].parse().unwrap();
        assert!(err >= 0.0 && err.is_finite(), "{r:?}");
        assert!(landed == 0.0 || landed == 1.0, "{r:?}");
    }
    // The desired take-off's own push hits its own take-off state exactly.
    assert_eq!(rows[4][2].parse::<f64>().unwrap(), 0.0, "{jumps}");
    // The two examples jump to different heights, the high one higher.
    let comp = std::fs::read_to_string(out.join("components.csv")).unwrap();
    let h: Vec<f64> = comp
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(2).unwrap().parse().unwrap())
        .collect();
    assert!(h.len() == 2 && h[1] > h[0] + 0.01, "{comp}");
    let weights = std::fs::read_to_string(out.join("weights.csv")).unwrap();
    for l in weights.lines().skip(1) {
        let a: f64 = l.split(',').nth(2).unwrap().parse().unwrap();
        assert!((0.0..=1.0).contains(&a), "{l}");
    }
    for f in [
        "takeoff.png",
        "heights.png",
        "weights.png",
        "jumps.png",
        "jump_anim.gif",
    ] {
        assert!(
            d.path().join(format!("figs/lbc_jumping_{f}")).exists(),
            "{f}"
        );
    }
}

#[test]
fn lbc_grid_quick_combination_is_exact_and_naive_is_worse() {
    let d = quick_reproduction();
    let out = d.path().join("out/lbc_grid_optimality");
    let text = std::fs::read_to_string(out.join("optimality.csv")).unwrap();
    assert!(text.starts_with("comparison,max_abs_diff"), "{text}");
    let get = |name: &str| -> f64 {
        text.lines()
            .find(|l| l.starts_with(&format!("{name},")))
            .unwrap_or_else(|| panic!("no row {name}"))
            .split(',')
            .nth(1)
            .unwrap()
            .parse()
            .unwrap()
    };
    assert!(get("lbc_vs_direct") < 1e-9, "{text}");
    assert!(get("lbc_policy_vs_direct") < 1e-6, "{text}");
    assert!(get("naive_vs_direct") > 1e-2, "{text}");
    assert!(get("naive_policy_vs_direct") > 1e-2, "{text}");
    for f in ["value", "policy"] {
        assert!(d
            .path()
            .join(format!("figs/lbc_grid_optimality_{f}.png"))
            .exists());
    }
}

#[test]
fn lbc_acrobot_quick_lbc_beats_the_naive_blend() {
    let d = quick_reproduction();
    let out = d.path().join("out/lbc_acrobot_swingup");
    let text = std::fs::read_to_string(out.join("final.csv")).unwrap();
    assert!(
        text.starts_with("policy,final_distance,control_cost"),
        "{text}"
    );
    let dist = |name: &str| -> f64 {
        let line = text
            .lines()
            .find(|l| l.starts_with(&format!("{name},")))
            .unwrap_or_else(|| panic!("no {name}"));
        line.split(',').nth(1).unwrap().parse().unwrap()
    };
    for p in ["tracker1", "tracker2", "naive", "lbc"] {
        assert!(!dist(p).is_nan(), "{p}");
    }
    assert!(dist("lbc") < dist("naive"), "{text}");
    assert!(!dist("naive_sum").is_nan(), "{text}");
    assert!(
        header(&out.join("sweep.csv")).starts_with("theta1_deg,theta2_deg,policy,final_distance")
    );
    assert!(header(&out.join("lambda_sweep.csv"))
        .starts_with("lambda,test_final_distance,test_mean_entropy"));
    assert!(header(&out.join("trajectories.csv")).contains("alpha1,alpha_entropy"));
    let swingups = std::fs::read_to_string(out.join("swingups.csv")).unwrap();
    assert!(swingups
        .lines()
        .next()
        .unwrap()
        .contains("first_swing_sign"));
    // Every closed loop of the sweep respects the 9.81 N m hip torque limit of the spec.
    let sweep = std::fs::read_to_string(out.join("sweep.csv")).unwrap();
    let cols: Vec<&str> = sweep.lines().next().unwrap().split(',').collect();
    let m = cols.iter().position(|c| *c == "max_abs_torque").unwrap();
    for line in sweep.lines().skip(1) {
        let v: f64 = line.split(',').nth(m).unwrap().parse().unwrap();
        assert!(v <= 9.81, "{line}");
    }
    for f in ["final_pose", "sweep", "lambda", "filmstrip"] {
        assert!(d
            .path()
            .join(format!("figs/lbc_acrobot_swingup_{f}.png"))
            .exists());
    }
}

#[test]
fn lbc_diver_and_push_quick_runs_write_promised_outputs() {
    let d = quick_reproduction();
    let out = d.path().join("out/lbc_diver_interpolation");
    assert!(
        header(&out.join("interpolation.csv")).starts_with("desired_angle,method,reached_angle")
    );
    let text = std::fs::read_to_string(out.join("interpolation.csv")).unwrap();
    // The component offset the run chose (rule.csv), from the spec's `offsets`.
    let rule = std::fs::read_to_string(out.join("rule.csv")).unwrap();
    let offset: f64 = rule
        .lines()
        .find_map(|l| l.strip_prefix("offset,"))
        .expect("rule.csv names the chosen offset")
        .parse()
        .unwrap();
    // Every method reaches a finite entry angle within the two example dives' targets (±offset;
    // 0.1 rad margin: the examples themselves enter within the entry tolerance of them).
    for line in text.lines().skip(1) {
        let reached: f64 = line.split(',').nth(2).unwrap().parse().unwrap();
        assert!(
            reached.is_finite() && reached.abs() < offset + 0.1,
            "{line} (offset {offset})"
        );
    }
    assert!(d
        .path()
        .join("figs/lbc_diver_interpolation_entry.png")
        .exists());
    let out = d.path().join("out/lbc_diver_coordination");
    assert!(header(&out.join("coordination.csv"))
        .starts_with("initial_omega,method,entry_error,objective"));
    assert!(d
        .path()
        .join("figs/lbc_diver_coordination_entry.png")
        .exists());
    // Fig. 8 as the paper shows it: the final pose of LBC and of the single tracker at every
    // take-off rate, its entry error the coordination table's.
    assert_eq!(
        header(&out.join("poses.csv")),
        "initial_omega,method,entry_error,x,y,torso,neck,shoulder,elbow,hip,knee,ankle"
    );
    let poses = std::fs::read_to_string(out.join("poses.csv")).unwrap();
    let coordination = std::fs::read_to_string(out.join("coordination.csv")).unwrap();
    let first3 = |l: &str| l.split(',').take(3).collect::<Vec<_>>().join(",");
    let (p, c): (Vec<String>, Vec<String>) = (
        poses.lines().skip(1).map(first3).collect(),
        coordination.lines().skip(1).map(first3).collect(),
    );
    assert_eq!(p, c);
    assert!(d
        .path()
        .join("figs/lbc_diver_coordination_poses.png")
        .exists());
    let out = d.path().join("out/lbc_push_recovery");
    assert!(header(&out.join("weights.csv")).starts_with("t,alpha_forward,alpha_backward"));
    assert!(
        header(&out.join("weights.csv")).contains("alpha_forward_mirrored,alpha_forward_baseline")
    );
    let text = std::fs::read_to_string(out.join("weights.csv")).unwrap();
    let alphas: Vec<f64> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
        .collect();
    // The first (forward) tug decides for the forward reach.
    assert!(alphas.iter().any(|&a| a > 0.75), "{alphas:?}");
    assert!(header(&out.join("weights.csv")).ends_with("wall_force,body_angle_no_reach"));
    // The premise is measured and holds: without a reach the tugs topple the body.
    let rule = std::fs::read_to_string(out.join("rule.csv")).unwrap();
    let setting = |k: &str| -> f64 {
        rule.lines()
            .find_map(|l| l.strip_prefix(&format!("{k},")))
            .unwrap()
            .parse()
            .unwrap()
    };
    assert!(setting("no_reach_lean") > setting("fall_angle"));
    assert!(d.path().join("figs/lbc_push_recovery_weights.png").exists());
}

#[test]
fn csvs_are_identical_for_any_thread_count() {
    for id in [
        "physics_validation",
        "lbc_projection",
        "lbc_grid_optimality",
    ] {
        let a = run_quick(id, "1");
        let b = run_quick(id, "2");
        let fa = files_with_ext(&a.path().join("out"), "csv");
        let fb = files_with_ext(&b.path().join("out"), "csv");
        assert!(!fa.is_empty());
        assert_eq!(fa.len(), fb.len());
        for ((na, ba), (nb, bb)) in fa.iter().zip(&fb) {
            assert_eq!(na, nb);
            assert!(ba == bb, "{id}: {na} differs between --jobs 1 and --jobs 2");
        }
    }
}

#[test]
fn sweep_rows_carry_their_parameter_values() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!("{}\n[sweep]\nscale = [1.0, 4.0]\n", spec("lbc_projection"));
    std::fs::write(dir.path().join("s.toml"), text).unwrap();
    ok(&motionlab(
        dir.path(),
        &[
            "run",
            "s.toml",
            "--quick",
            "--out",
            "out",
            "--figures",
            "figs",
        ],
    ));
    let w = std::fs::read_to_string(dir.path().join("out/lbc_projection/weights.csv")).unwrap();
    assert!(w.starts_with("scale,spacing,component,weight"), "{w}");
    let scales: std::collections::BTreeSet<&str> = w
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap())
        .collect();
    assert_eq!(scales.len(), 2, "{w}");
    // --set on the swept key removes the axis.
    ok(&motionlab(
        dir.path(),
        &[
            "run",
            "s.toml",
            "--quick",
            "--set",
            "scale=2.0",
            "--out",
            "out2",
            "--figures",
            "figs",
        ],
    ));
    let w = std::fs::read_to_string(dir.path().join("out2/lbc_projection/weights.csv")).unwrap();
    assert!(w.starts_with("spacing,component,weight"), "{w}");
}

#[test]
fn reproduce_quick_writes_report_with_every_experiment() {
    let d = quick_reproduction();
    let report = std::fs::read_to_string(d.path().join("out/REPORT.md")).unwrap();
    let mut ids = 0;
    for e in std::fs::read_dir(root().join("experiments")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "toml") {
            let id = p.file_stem().unwrap().to_str().unwrap().to_string();
            assert!(report.contains(&format!("## {id}")), "{id}: {report}");
            assert!(
                d.path().join("out").join(&id).join("run.json").is_file(),
                "{id}"
            );
            ids += 1;
        }
    }
    assert_eq!(ids, 28, "the shipped experiments");
    assert!(report.contains("**Paper:**") && report.contains("**Verdict:"));
    assert!(
        report.contains("../figs/lbc_projection_cost.png"),
        "{report}"
    );
}

#[test]
fn list_shows_every_experiment() {
    let dir = tempfile::tempdir().unwrap();
    let exp = root().join("experiments");
    let out = ok(&motionlab(
        dir.path(),
        &["--experiments", exp.to_str().unwrap(), "list"],
    ));
    assert!(
        out.contains("physics_validation") && out.contains("lbc_projection"),
        "{out}"
    );
}

#[test]
fn describe_prints_parameters_with_units() {
    let dir = tempfile::tempdir().unwrap();
    let out = ok(&motionlab(dir.path(), &["describe", "pendulum3"]));
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["model"], "pendulum3");
    assert_eq!(v["state"].as_array().unwrap().len(), 6);
    assert_eq!(v["controls"].as_array().unwrap().len(), 3);
    let params = v["parameters"].as_array().unwrap();
    for name in [
        "link1.mass",
        "link2.length",
        "link3.com",
        "link1.inertia",
        "link2.damping",
        "gravity",
    ] {
        let p = params
            .iter()
            .find(|p| p["name"] == name)
            .unwrap_or_else(|| panic!("no {name}"));
        assert!(!p["unit"].as_str().unwrap().is_empty());
    }
    assert_eq!(v["dt"], 0.01);
    let out = ok(&motionlab(dir.path(), &["describe", "acrobot"]));
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(
        v["state"],
        serde_json::json!(["theta1", "theta2", "omega1", "omega2"])
    );
}

#[test]
fn simulate_writes_named_columns_and_applies_controls() {
    let dir = tempfile::tempdir().unwrap();
    // Hanging acrobot at rest stays at rest.
    ok(&motionlab(
        dir.path(),
        &[
            "simulate",
            "acrobot",
            "--state",
            "-1.5707963267948966,0,0,0",
            "--duration",
            "1",
            "--out",
            "rest.csv",
        ],
    ));
    let text = std::fs::read_to_string(dir.path().join("rest.csv")).unwrap();
    assert_eq!(
        text.lines().next().unwrap(),
        "t,theta1,theta2,omega1,omega2"
    );
    assert_eq!(text.lines().count(), 102);
    let last: Vec<f64> = text
        .lines()
        .last()
        .unwrap()
        .split(',')
        .map(|s| s.parse().unwrap())
        .collect();
    assert!((last[1] + std::f64::consts::FRAC_PI_2).abs() < 1e-9 && last[4].abs() < 1e-9);
    // A hip torque from t = 0.5 s moves the hip only after 0.5 s.
    std::fs::write(dir.path().join("u.csv"), "t,tau\n0,0\n0.5,2.0\n").unwrap();
    ok(&motionlab(
        dir.path(),
        &[
            "simulate",
            "acrobot",
            "--state=-1.5707963267948966,0,0,0",
            "--controls",
            "u.csv",
            "--duration",
            "1",
            "--out",
            "push.csv",
        ],
    ));
    let text = std::fs::read_to_string(dir.path().join("push.csv")).unwrap();
    let theta2 = |t: f64| -> f64 {
        text.lines()
            .skip(1)
            .map(|l| {
                l.split(',')
                    .map(|s| s.parse::<f64>().unwrap())
                    .collect::<Vec<_>>()
            })
            .find(|r| (r[0] - t).abs() < 1e-9)
            .unwrap()[2]
    };
    assert!(theta2(0.5).abs() < 1e-12);
    assert!(theta2(1.0).abs() > 1e-3);
    // Bad control columns are rejected.
    std::fs::write(dir.path().join("bad.csv"), "t,torque\n0,1\n").unwrap();
    let out = motionlab(
        dir.path(),
        &[
            "simulate",
            "acrobot",
            "--state=0,0,0,0",
            "--controls",
            "bad.csv",
            "--duration",
            "1",
        ],
    );
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("torque"));
}

#[test]
fn simulate_blow_up_reports_model_step_and_state() {
    let dir = tempfile::tempdir().unwrap();
    // Explicit Euler with a huge step on a fast-spinning acrobot diverges.
    let out = motionlab(
        dir.path(),
        &[
            "simulate",
            "acrobot",
            "--state=0,3,40,-60",
            "--duration",
            "200",
            "--dt",
            "0.5",
            "--integrator",
            "euler",
        ],
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("acrobot") && err.contains("blew up at step") && err.contains("state"),
        "{err}"
    );
}

#[test]
fn bench_json_is_one_object_of_named_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let out = ok(&motionlab(
        dir.path(),
        &["bench", "--json", "--seconds", "0.01"],
    ));
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    let obj = v.as_object().unwrap();
    assert!(obj.contains_key("sim.pendulum3.steps_per_s"));
    assert!(obj.contains_key("linearize.leaper3d.fd_jacobians_per_s"));
    assert!(obj.values().all(|x| x.as_f64().is_some_and(|f| f > 0.0)));
    // The derived per-knot / per-step metrics are the reciprocals of their rates (400 knots).
    let f = |k: &str| obj[k].as_f64().unwrap();
    let rel = |a: f64, b: f64| ((a - b) / b).abs();
    assert!(
        rel(
            f("ddp.acrobot.us_per_knot"),
            1e6 / (400.0 * f("ddp.acrobot.iters_per_s"))
        ) < 1e-9
    );
    // Ten iterations of the same solve, per knot and iteration: the acrobot problem runs all
    // ten (no early stop), and its first rollout and last stopping test are spread over ten.
    assert!(
        rel(
            f("ddp.acrobot.us_per_knot_iteration"),
            1e6 / (4000.0 * f("ddp.acrobot.solves10_per_s"))
        ) < 1e-9
    );
    assert!(
        rel(
            f("lqr.acrobot.us_per_step"),
            1e6 / (400.0 * f("lqr.acrobot.backward_passes_per_s"))
        ) < 1e-9
    );
    // Multiply–add rates: 2pq + 3qr per example (64,000 examples in the full batch).
    let macs = (2 * 84 * 50 + 3 * 50 * 78) as f64;
    assert!(
        rel(
            f("mlp.84-50-78.full_grad_gmac_per_s"),
            f("mlp.84-50-78.full_grad_per_s") * 64000.0 * macs / 1e9
        ) < 1e-9
    );
    assert!(
        rel(
            f("mlp.84-50-78.train_gmac_per_s"),
            f("mlp.84-50-78.train_examples_per_s") * macs / 1e9
        ) < 1e-9
    );
    assert!(obj.contains_key("bptt.17-50-13.bare.iters_per_s"));
    // Dependent rollouts beside the independent steps, the lander's and the peer's bare net.
    for key in [
        "emulator.17-50-13.rollout_steps_per_s",
        "emulator.17-50-13.bare.rollout_steps_per_s",
    ] {
        assert!(f(key) > 0.0, "{key}");
    }
}

#[test]
fn describe_and_simulate_every_model() {
    let dir = tempfile::tempdir().unwrap();
    for &name in motionlab::physics::MODEL_NAMES {
        let out = ok(&motionlab(dir.path(), &["describe", name]));
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert_eq!(v["model"], name);
        let params = v["parameters"].as_array().unwrap();
        assert!(
            !params.is_empty()
                && params
                    .iter()
                    .all(|p| !p["unit"].as_str().unwrap().is_empty()),
            "{name}"
        );
        // Simulate from the model's rest-like state for a short while: finite and named.
        let n = v["state"].as_array().unwrap().len();
        let mut state = vec![0.0; n];
        if name == "lander" {
            state[3] = 1.0; // unit quaternion
            state[2] = 10.0;
        }
        if name == "dolphin" {
            state = motionlab::physics::dolphin::Dolphin::default().rest_state();
        }
        let csv = ok(&motionlab(
            dir.path(),
            &[
                "simulate",
                name,
                &format!(
                    "--state={}",
                    state
                        .iter()
                        .map(|v| v.to_string())
                        .collect::<Vec<_>>()
                        .join(",")
                ),
                "--duration",
                "0.2",
            ],
        ));
        let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
        assert_eq!(header.len(), n + 1, "{name}");
        assert!(csv
            .lines()
            .skip(1)
            .all(|l| l.split(',').all(|c| c.parse::<f64>().unwrap().is_finite())));
    }
}

#[test]
fn quick_and_ad_hoc_runs_leave_the_committed_results_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let exp = root().join("experiments");
    let exp = exp.to_str().unwrap();
    let committed = dir.path().join("results");
    std::fs::create_dir_all(&committed).unwrap();
    std::fs::write(committed.join("REPORT.md"), "committed").unwrap();
    ok(&motionlab(
        dir.path(),
        &[
            "--experiments",
            exp,
            "reproduce",
            "--quick",
            "--only",
            "lbc_projection",
        ],
    ));
    ok(&motionlab(
        dir.path(),
        &["--experiments", exp, "run", "lbc_projection"],
    ));
    let quick = dir.path().join("quick");
    assert!(quick.join("results/REPORT.md").is_file());
    assert!(quick.join("results/lbc_projection/run.json").is_file());
    assert!(quick
        .join("paper_figures/lbc_projection_cost.png")
        .is_file());
    let runs = dir.path().join("runs");
    assert!(runs.join("results/lbc_projection/weights.csv").is_file());
    assert!(runs.join("paper_figures/lbc_projection_cost.png").is_file());
    // The committed folders are as they were.
    let names: Vec<_> = std::fs::read_dir(&committed)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("REPORT.md")]);
    assert_eq!(
        std::fs::read_to_string(committed.join("REPORT.md")).unwrap(),
        "committed"
    );
    assert!(!dir.path().join("paper_figures").exists());
    // run.json says whether the code had uncommitted changes (null outside a checkout).
    let meta = std::fs::read_to_string(runs.join("results/lbc_projection/run.json")).unwrap();
    assert!(meta.contains("\"git_dirty\""), "{meta}");
}

#[test]
fn x_lbc_emulator_quick_compares_every_method_on_both_substrates() {
    let d = quick_reproduction();
    let out = d.path().join("out/x_lbc_emulator");
    assert_eq!(
        header(&out.join("targets.csv")),
        "desired_target,method,final_error_emulator,final_error_simulator,effort,seconds,weight1,weight2,final_axis_value,mean_entropy"
    );
    let t = std::fs::read_to_string(out.join("targets.csv")).unwrap();
    let rows: Vec<Vec<&str>> = t.lines().skip(1).map(|l| l.split(',').collect()).collect();
    let methods = [
        "lbc",
        "naive",
        "tracker1",
        "tracker2",
        "open_loop1",
        "open_loop2",
        "bptt",
        "bptt_tracked",
    ];
    // quick: three desired targets, every method at each, finite errors on both substrates.
    assert_eq!(rows.len(), 3 * methods.len());
    for r in &rows {
        assert!(methods.contains(&r[1]), "{r:?}");
        for c in [2, 3, 4] {
            assert!(r[c].parse::<f64>().unwrap().is_finite(), "{r:?}");
        }
    }
    // At a component's own target (-3) the projected weights are (1, 0): LBC, the naive blend
    // and tracker 1 are the same policy, so they land in the same state.
    let at = |d: &str, m: &str| {
        rows.iter()
            .find(|r| r[0] == d && r[1] == m)
            .unwrap()
            .clone()
    };
    let (l, n, t1) = (
        at("-3.0", "lbc"),
        at("-3.0", "naive"),
        at("-3.0", "tracker1"),
    );
    let f = |r: &Vec<&str>, c: usize| r[c].parse::<f64>().unwrap();
    assert!(
        (f(&l, 6) - 1.0).abs() < 1e-9 && f(&l, 7).abs() < 1e-9,
        "{l:?}"
    );
    assert!((f(&l, 3) - f(&t1, 3)).abs() < 1e-9 && (f(&n, 3) - f(&t1, 3)).abs() < 1e-9);
    // Strictly between the components both weights are positive.
    let mid = at("0.0", "lbc");
    assert!(f(&mid, 6) > 0.0 && f(&mid, 7) > 0.0, "{mid:?}");
    for f in ["components.csv", "trajectory.csv", "goal.csv", "rule.csv"] {
        assert!(out.join(f).is_file(), "{f}");
    }
    // net_seeds.csv: the run's own seed's rows are targets.csv's under net_seed 1 (quick names
    // no further seed).
    let seeds = std::fs::read_to_string(out.join("net_seeds.csv")).unwrap();
    let mut seed_lines = seeds.lines();
    assert_eq!(
        seed_lines.next().unwrap(),
        format!("net_seed,{}", t.lines().next().unwrap())
    );
    let own: Vec<String> = t.lines().skip(1).map(|l| format!("1,{l}")).collect();
    assert_eq!(seed_lines.map(str::to_string).collect::<Vec<_>>(), own);
    // States by their `describe` names (the lander's), never s0, s1, ...
    assert!(header(&out.join("trajectory.csv"))
        .starts_with("desired_target,method,step,t,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz"));
    assert!(header(&out.join("goal.csv")).starts_with("desired_target,x,y,z,qw"));
    let figs = d.path().join("figs");
    assert!(figs.join("x_lbc_emulator_error.png").is_file());
    assert!(figs.join("x_lbc_emulator_lbc.gif").is_file());
}

/// A run first removes the temporary files an interrupted run left in its output folders
/// (named for a process that is gone and idle for longer than a write takes), and says so;
/// the files it then writes are whole.
#[test]
fn a_run_removes_what_an_interrupted_run_left_half_written() {
    let dir = tempfile::tempdir().unwrap();
    // No process has an id above Linux's largest (2²²).
    let stale = [
        dir.path()
            .join("out/lbc_projection/.motionlab-tmp-4294967295-projection.csv"),
        dir.path()
            .join("figs/.motionlab-tmp-4294967295-lbc_projection_minima.png"),
    ];
    let old = std::time::SystemTime::now() - std::time::Duration::from_secs(3600);
    for f in &stale {
        std::fs::create_dir_all(f.parent().unwrap()).unwrap();
        std::fs::write(f, b"half").unwrap();
        let file = std::fs::File::options().write(true).open(f).unwrap();
        file.set_modified(old).unwrap();
    }
    let exp = root().join("experiments");
    let out = motionlab(
        dir.path(),
        &[
            "--experiments",
            exp.to_str().unwrap(),
            "run",
            "lbc_projection",
            "--quick",
            "--out",
            "out",
            "--figures",
            "figs",
        ],
    );
    ok(&out);
    let err = String::from_utf8_lossy(&out.stderr);
    for f in &stale {
        assert!(!f.exists(), "{} left", f.display());
        let name = f.file_name().unwrap().to_string_lossy();
        assert!(err.contains(&*name), "not reported: {name}\n{err}");
    }
    assert!(dir.path().join("out/lbc_projection/run.json").exists());
}

/// `motionlab list | head -1`: the reader closes the pipe before `list` writes; that is a normal
/// end (exit 0, no panic), not a crash with a backtrace.
#[test]
fn a_closed_output_pipe_is_a_normal_end() {
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_motionlab"))
        .arg("list")
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Close the read end at once: `list` reads 28 experiment files before its first line.
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{:?}: {stderr}", out.status);
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// An experiment file whose id is a path is refused with file, line and key before any work,
/// and nothing is written outside `--out`.
#[test]
fn an_id_that_is_a_path_is_refused_before_any_work() {
    let d = tempfile::tempdir().unwrap();
    let spec = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("experiments/physics_validation.toml"),
    )
    .unwrap()
    .replace("id = \"physics_validation\"", "id = \"../escaped\"");
    let f = d.path().join("bad.toml");
    std::fs::write(&f, spec).unwrap();
    let out = motionlab(
        d.path(),
        &[
            "run",
            f.to_str().unwrap(),
            "--quick",
            "--out",
            "out/results",
            "--figures",
            "out/figs",
        ],
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("bad.toml") && stderr.contains("`id`"),
        "{stderr}"
    );
    assert!(!d.path().join("out/escaped").exists());
    assert!(!d.path().join("escaped").exists());
}
