//! Report of `x_lbc_emulator`: the verdict rule (LBC within tolerance, against the naive blend,
//! and along the axis) and the tables of final errors and distances.

use super::METHODS;
use crate::experiment::output::{df_f64, df_str, read_csv};
use crate::experiment::report::{sig, Findings, Verdict};
use crate::experiment::Error;
use crate::families::lbc::{entropy_section, rule_settings};
use std::path::Path;

/// What the rule reads over the desired targets strictly between the components.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RuleInputs {
    /// In-between targets with an LBC landing.
    pub targets: usize,
    /// Of those, LBC's landings within tolerance on the simulator (final error <= 1).
    pub within: usize,
    /// The spec's `within_fraction`.
    pub within_fraction: f64,
    /// LBC's mean simulator error over those targets.
    pub lbc_error: f64,
    /// The naive blend's mean simulator error there.
    pub naive_error: f64,
    /// The spec's `naive_margin` (tolerance units).
    pub naive_margin: f64,
    /// LBC's mean distance of the final x from the desired x there (m).
    pub lbc_axis: f64,
    /// The naive blend's (m).
    pub naive_axis: f64,
    /// The spec's `axis_margin` (m).
    pub axis_margin: f64,
}

/// The spec's rule: (held, partly). Held: (1) LBC within tolerance on at least
/// `within_fraction` of the in-between targets, (2) its mean simulator error no worse than the
/// naive blend's + `naive_margin`, (3) its mean distance from the desired x no more than
/// naive's + `axis_margin`. Partly (rewritten 2026-11-28 after seeing the committed results,
/// issue 56; it was "one of the three"): (2) and (3), LBC not beaten by the naive blend on
/// either measure.
pub fn rule(r: &RuleInputs) -> (bool, bool) {
    let any = r.targets > 0;
    let need = (r.within_fraction * r.targets as f64).ceil() as usize;
    let ok_within = any && r.within >= need;
    let ok_naive = any && r.lbc_error <= r.naive_error + r.naive_margin;
    let ok_axis = any && r.lbc_axis <= r.naive_axis + r.axis_margin;
    (ok_within && ok_naive && ok_axis, ok_naive && ok_axis)
}

/// The findings ([`crate::experiment::Family::report`]).
pub(super) fn report(dir: &Path) -> Result<Findings, Error> {
    let setting = rule_settings(dir)?;
    let (c1, c2, frac, margin, lambda, axis_margin) = (
        setting("component1"),
        setting("component2"),
        setting("within_fraction"),
        setting("naive_margin"),
        setting("lambda"),
        setting("axis_margin"),
    );
    let between = |x: f64| x > c1 && x < c2;
    let df = read_csv(&dir.join("targets.csv"))?;
    let (d, meth, es, ee, secs, reached) = (
        df_f64(&df, "desired_target")?,
        df_str(&df, "method")?,
        df_f64(&df, "final_error_simulator")?,
        df_f64(&df, "final_error_emulator")?,
        df_f64(&df, "seconds")?,
        df_f64(&df, "final_axis_value")?,
    );
    let miss = |mm: &str| -> Vec<f64> {
        (0..d.len())
            .filter(|&r| meth[r] == mm && between(d[r]))
            .map(|r| (reached[r] - d[r]).abs())
            .collect()
    };
    let errs = |mm: &str| -> Vec<f64> {
        (0..d.len())
            .filter(|&r| meth[r] == mm && between(d[r]))
            .map(|r| es[r])
            .collect()
    };
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let lbc = errs("lbc");
    let within = lbc.iter().filter(|&&e| e <= 1.0).count();
    let (ml, mn) = (mean(&lbc), mean(&errs("naive")));
    let (xl, xn) = (mean(&miss("lbc")), mean(&miss("naive")));
    let (held, partly) = rule(&RuleInputs {
        targets: lbc.len(),
        within,
        within_fraction: frac,
        lbc_error: ml,
        naive_error: mn,
        naive_margin: margin,
        lbc_axis: xl,
        naive_axis: xn,
        axis_margin,
    });
    let verdict = Verdict::graded(held, partly);
    let mut md = String::from(
        "Final error (RMS of (s − s_d)/tolerance, ≤ 1 within tolerance) on the simulator / emulator, per desired target and method:\n\n| desired x (m) |",
    );
    for mm in METHODS {
        md.push_str(&format!(" {mm} |"));
    }
    md.push_str("\n| --- |");
    md.push_str(&" --- |".repeat(METHODS.len()));
    md.push('\n');
    let mut targets: Vec<f64> = Vec::new();
    for &x in &d {
        if !targets.contains(&x) {
            targets.push(x);
        }
    }
    for &x in &targets {
        md.push_str(&format!("| {} |", sig(x)));
        for mm in METHODS {
            let r = (0..d.len()).find(|&r| d[r] == x && meth[r] == mm);
            match r {
                Some(r) => md.push_str(&format!(" {} / {} |", sig(es[r]), sig(ee[r]))),
                None => md.push_str(" – |"),
            }
        }
        md.push('\n');
    }
    let bptt_s: Vec<f64> = (0..d.len())
        .filter(|&r| meth[r] == "bptt")
        .map(|r| secs[r])
        .collect();
    let comps = read_csv(&dir.join("components.csv"))?;
    let (cl, co, ct) = (
        df_f64(&comps, "learn_seconds")?,
        df_f64(&comps, "open_loop_simulator_error")?,
        df_f64(&comps, "tracked_simulator_error")?,
    );
    md.push_str(&format!(
        "\nComponents (targets x = {} and {} m): open-loop replay error on the simulator {} and {}, with the emulator-derived tracker in closed loop {} and {}; learned in {} s and {} s. BPTT re-optimized per desired target: mean {} s. λ = {} (from the stated control noise). Mean simulator error over the in-between targets: LBC {}, naive {}, BPTT open loop {}, BPTT tracked {}.\n",
        sig(c1),
        sig(c2),
        sig(co[0]),
        sig(co[1]),
        sig(ct[0]),
        sig(ct[1]),
        sig(cl[0]),
        sig(cl[1]),
        sig(mean(&bptt_s)),
        sig(lambda),
        sig(ml),
        sig(mn),
        sig(mean(&errs("bptt"))),
        sig(mean(&errs("bptt_tracked"))),
    ));
    md.push_str(
        "\nThe error is an RMS over all 13 state variables, so it dilutes a miss along the axis (a landing 3 m off the desired x alone gives 0.83): the mean distance of the final x from the desired x (m) on the simulator over the in-between targets, per method:\n\n| method | mean distance to the desired x (m) | mean final error |\n| --- | --- | --- |\n",
    );
    for mm in METHODS {
        md.push_str(&format!(
            "| {mm} | {} | {} |\n",
            sig(mean(&miss(mm))),
            sig(mean(&errs(mm)))
        ));
    }
    md.push_str(&entropy_section(
        dir,
        "1 = uniform α; the projected weights are uniform only at the midpoint target, so elsewhere the naive blend's constant entropy is below 1, and beyond the components a negative weight leaves it undefined (NaN)",
        "the naive blend with the same projected weights",
    )?);
    Ok(Findings {
        ours: md,
        verdict,
        why: format!(
            "On the simulator, over the {} targets between the components, LBC ends within tolerance at {}, with mean final error {} against the naive blend's {} and mean distance from the desired x {} m against {} m. Rule (ours, fixed in the spec): held needs LBC's simulator error ≤ 1 on at least {} of the {} targets strictly between the components ({} were), LBC's mean simulator error there no worse than the naive blend's + {} ({} vs {}), and LBC's mean distance from the desired x no more than naive's + {} m ({} vs {} m; this third condition was added after the first full run showed that the RMS error dilutes a miss along x); partly needs the last two, LBC not beaten by the naive blend on either measure (this partly rule was rewritten on 2026-11-28 after seeing the committed results, issue 56: it was \"one of the three\", which held with the naive blend landing nearer the desired x).",
            lbc.len(),
            within,
            sig(ml),
            sig(mn),
            sig(xl),
            sig(xn),
            sig(frac),
            lbc.len(),
            within,
            sig(margin),
            sig(ml),
            sig(mn),
            sig(axis_margin),
            sig(xl),
            sig(xn)
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The committed run's numbers over the 5 in-between targets.
    fn committed() -> RuleInputs {
        RuleInputs {
            targets: 5,
            within: 2,
            within_fraction: 0.6,
            lbc_error: 0.876,
            naive_error: 0.959,
            naive_margin: 0.05,
            lbc_axis: 0.254,
            naive_axis: 0.0442,
            axis_margin: 0.1,
        }
    }

    #[test]
    fn naive_beating_lbc_on_a_main_measure_is_not_partly_held() {
        // LBC's error is lower, but the naive blend lands 0.21 m nearer the desired x.
        assert_eq!(rule(&committed()), (false, false));
        // Naive better on both measures (issue 56's 0.29 vs 0.33 error, within the error
        // margin, and 0.0065 vs 0.18 m along x, beyond the axis margin), even with LBC within
        // tolerance on every target: not partly.
        let both = RuleInputs {
            within: 5,
            lbc_error: 0.33,
            naive_error: 0.29,
            lbc_axis: 0.18,
            naive_axis: 0.0065,
            ..committed()
        };
        assert_eq!(rule(&both), (false, false));
        // Naive's error lower by more than the margin, LBC nearer along x: not partly.
        let error = RuleInputs {
            lbc_error: 0.5,
            naive_error: 0.3,
            lbc_axis: 0.01,
            ..committed()
        };
        assert_eq!(rule(&error), (false, false));
        // Naive nearer along x only, LBC within tolerance everywhere: still not partly.
        let axis = RuleInputs {
            within: 5,
            ..committed()
        };
        assert_eq!(rule(&axis), (false, false));
    }

    #[test]
    fn lbc_matching_naive_is_partly_and_within_tolerance_too_held() {
        let matched = RuleInputs {
            lbc_axis: 0.1,
            ..committed()
        };
        assert_eq!(rule(&matched), (false, true));
        let held = RuleInputs {
            within: 3,
            ..matched
        };
        assert_eq!(rule(&held), (true, true));
        assert_eq!(rule(&RuleInputs { targets: 0, ..held }), (false, false));
    }
}
