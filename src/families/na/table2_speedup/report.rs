//! The report: Table 2 as measured beside the paper's step cost ratios, the equal-accuracy
//! comparison, and the verdict rule (N100 at least 50x, every rigid-body N50 at least 10x).

use super::job::{EqualAccuracyRow, SpeedupRow};
use super::{Table2Rule, DOLPHIN_IMPLICIT};
use crate::experiment::output::written_csv;
use crate::experiment::report::{sig, Findings};
use crate::experiment::rows::{read_rows, TableRow};
use crate::experiment::rule::{rule_settings, shown, Check, Cmp, Null, Partly, Rule};
use crate::experiment::Error;
use std::path::Path;

/// The verdict's rule: the slowest N100 speedup and the slowest rigid-body N50 speedup at
/// `r`'s bars (null: the physical simulator itself, speedup 1); held when both pass, partly
/// when one does. `None` when a bar is not above 1.
pub fn table2_rule(n100_slowest: f64, n50_slowest: f64, r: &Table2Rule) -> Option<Rule> {
    let itself = || Null::new("the physical simulator itself", 1.0);
    let held = vec![
        Check::new(
            "the slowest N100 speedup",
            n100_slowest,
            Cmp::AtLeast,
            r.n100_min,
            itself(),
        ),
        Check::new(
            "the slowest rigid-body N50 speedup",
            n50_slowest,
            Cmp::AtLeast,
            r.n50_min,
            itself(),
        ),
    ];
    Rule::gated(vec![], held, Partly::Any)
}

/// The paper's step cost ratio for a Table 2 cell: (physical s / 20,000) / (emulator s / (20,000 / n)).
fn paper_ratio(model: &str, emulator: &str) -> Option<f64> {
    let (physical, emulator_s, n) = match (model, emulator) {
        ("pendulum_passive", "N25") => (4.70, 0.10, 25.0),
        ("pendulum_passive", "N50") => (4.70, 0.05, 50.0),
        ("pendulum_passive", "N100") => (4.70, 0.02, 100.0),
        ("pendulum_active", "N25") => (4.52, 0.12, 25.0),
        ("pendulum_active", "N50") => (4.52, 0.06, 50.0),
        ("pendulum_active", "N100") => (4.52, 0.03, 100.0),
        ("truck", "N50") => (4.88, 0.07, 50.0),
        ("lander", "N50") => (6.44, 0.12, 50.0),
        ("dolphin", "N50") => (63.0, 0.95, 50.0),
        ("dolphin", "N50_reg") => (63.0, 2.48, 50.0),
        _ => return None,
    };
    Some(physical / (emulator_s * n))
}

/// The findings from the run folder `dir`.
pub(super) fn findings(dir: &Path) -> Result<Findings, Error> {
    let rows: Vec<SpeedupRow> = read_rows(&dir.join("speedup.csv"))?;
    let mut md = String::from(
            "| model | physical integrator, δt (s) | emulator | physical s | emulator s | speedup | = n | × step cost ratio | paper's ratio | physical step s | emulator step s |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
        );
    for r in &rows {
        let paper = paper_ratio(&r.model, &r.emulator).map_or("—".to_string(), sig);
        md.push_str(&format!(
            "| {} | {}, {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            r.model,
            r.physical_integrator,
            r.physical_dt,
            r.emulator,
            sig(r.physical_s),
            sig(r.emulator_s),
            sig(r.speedup),
            r.n,
            sig(r.step_cost_ratio),
            paper,
            sig(r.physical_step_s),
            sig(r.emulator_step_s)
        ));
    }
    let n100: Vec<f64> = rows
        .iter()
        .filter(|r| r.emulator == "N100")
        .map(|r| r.speedup)
        .collect();
    let n50_min = rows
        .iter()
        .filter(|r| r.emulator == "N50" && r.model != "dolphin")
        .map(|r| r.speedup)
        .fold(f64::INFINITY, f64::min);
    // NaN when no N100 ran: the check then fails.
    let n100_slowest = if n100.is_empty() {
        f64::NAN
    } else {
        n100.iter().copied().fold(f64::INFINITY, f64::min)
    };
    let dolphin = |e: &str, implicit: bool| {
        rows.iter().find(|r| {
            r.model == "dolphin"
                && r.emulator == e
                && (r.physical_integrator == DOLPHIN_IMPLICIT) == implicit
        })
    };
    let dolphin_text = match (dolphin("N50", false), dolphin("N50_reg", false)) {
            (Some(a), Some(b)) => format!(
                " Dolphin: N50 {}x, N50 with regularization {}x over our semi-implicit Euler at δt = {} s (paper: 66x and 25x over its [18]).",
                sig(a.speedup),
                sig(b.speedup),
                a.physical_dt
            ),
            _ => " Dolphin rows not built.".into(),
        };
    let implicit_text = match dolphin("N50", true) {
            Some(r) => format!(
                " Against the implicit (backward Euler) integrator at the paper's δt = {} s, one step costs {} s ({}x an N50 step), n = {}, so N50 is {}x faster (paper: 63.0 s / 0.95 s = 66x).",
                r.physical_dt,
                sig(r.physical_step_s),
                sig(r.step_cost_ratio),
                r.n,
                sig(r.speedup)
            ),
            None => String::new(),
        };
    let (equal_md, equal_text) = equal_accuracy_section(dir)?;
    md.push_str(&equal_md);
    let pend: Vec<f64> = rows
        .iter()
        .filter(|r| r.model.starts_with("pendulum"))
        .map(|r| r.step_cost_ratio)
        .collect();
    let pend_lo = sig(pend.iter().copied().fold(f64::INFINITY, f64::min));
    let pend_hi = sig(pend.iter().copied().fold(f64::NEG_INFINITY, f64::max));
    let ratio_of = |m: &str| {
        rows.iter()
            .find(|r| r.model == m)
            .map_or("—".to_string(), |r| sig(r.step_cost_ratio))
    };
    let (truck_ratio, lander_ratio) = (ratio_of("truck"), ratio_of("lander"));
    let settings = rule_settings(dir)?;
    let bars = Table2Rule {
        n100_min: settings("n100_min"),
        n50_min: settings("n50_min"),
    };
    let rule = table2_rule(n100_slowest, n50_min, &bars);
    let (verdict, lines, text) = shown(rule.as_ref(), " No rule: a bar is not above 1.");
    Ok(Findings {
            ours: md,
            verdict,
            rule: rule.clone(),
            why: format!(
                "N100 speedups {} (paper: 50-100x and more); the slowest rigid-body N50 speedup is {} (paper: one to two orders of magnitude); speedup = n x step cost ratio (physical step s / emulator step s); the paper's ratios, from its Table 2, are 1.1-2.4 (0.5 with regularization), ours {pend_lo}-{pend_hi} for the pendulums, {truck_ratio} for the truck, {lander_ratio} for the lander (a 13-variable rigid body: one RK4 step costs less than a 17-50-13 net).{dolphin_text}{implicit_text}{equal_text} Checks:{lines} Rule (thresholds ours, from the paper's words, in the spec's [params.rule]): {text}",
                n100.iter().map(|s| sig(*s)).collect::<Vec<_>>().join(", "),
                sig(n50_min)
            ),
        })
}

/// The equal-accuracy table (`equal_accuracy.csv`; data, not part of the verdict) and its
/// sentence, both empty when the run wrote no such table.
fn equal_accuracy_section(dir: &Path) -> Result<(String, String), Error> {
    let (mut md, mut equal_text) = (String::new(), String::new());
    if let Some(df) = written_csv(dir, "equal_accuracy.csv")? {
        let eq = EqualAccuracyRow::from_frame(&df).map_err(|e| {
            Error::Other(format!("{}: {e}", dir.join("equal_accuracy.csv").display()))
        })?;
        md.push_str("\n**Equal accuracy** (data, not part of the verdict): error = mean over 40 super-steps of the per-step mean squared state error in units of each variable's spread (Table 1's `rollout40_error_mean`), against the simulator at the training δt; the physical step is the largest Δt/j (j = 1 … n) whose error is at most the emulator's.\n\n| model | emulator | emulator error | j | matched δt (s) | its error | error at Δt/(j−1) | physical s | emulator s | speedup |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
        for r in &eq {
            md.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                r.model,
                r.emulator,
                sig(r.emulator_error),
                r.substeps,
                sig(r.matched_dt),
                sig(r.matched_error),
                if r.coarser_error.is_nan() {
                    "— (j = 1)".to_string()
                } else {
                    sig(r.coarser_error)
                },
                sig(r.physical_s),
                sig(r.emulator_s),
                sig(r.speedup)
            ));
        }
        let at_one = eq.iter().filter(|r| r.substeps == 1).count();
        equal_text = format!(
                " At equal accuracy the speedups are {} ({} of {} emulators are matched by one physical step per super-step, so their equal-accuracy speedup is only the step cost ratio, an upper bound on the emulator's advantage).",
                eq.iter().map(|r| sig(r.speedup)).collect::<Vec<_>>().join(", "),
                at_one,
                eq.len()
            );
    }
    Ok((md, equal_text))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::report::Verdict;

    const BARS: Table2Rule = Table2Rule {
        n100_min: 50.0,
        n50_min: 10.0,
    };

    #[test]
    fn both_speedups_hold_one_is_partly_and_no_n100_fails() {
        let verdict = |a, b| table2_rule(a, b, &BARS).map(|r| r.verdict());
        assert_eq!(verdict(234.0, 18.6), Some(Verdict::Held));
        assert_eq!(verdict(49.0, 18.6), Some(Verdict::Partly));
        assert_eq!(verdict(234.0, 9.9), Some(Verdict::Partly));
        assert_eq!(verdict(f64::NAN, 9.9), Some(Verdict::NotHeld));
        // A bar the simulator itself meets is refused.
        let low = Table2Rule {
            n100_min: 1.0,
            n50_min: 10.0,
        };
        assert!(table2_rule(234.0, 18.6, &low).is_none());
    }
}
