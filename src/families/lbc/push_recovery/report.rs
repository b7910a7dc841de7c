//! The report section and verdict, read back from the CSVs.

use super::job::{LambdaRow, ReachRow, ReachScaleRow, WeightRow};
use super::measures::{mirror_gap, swings, window_gap, window_range};
use super::COMMITTED;
use crate::experiment::report::{sig, Findings};
use crate::experiment::rows::{read_rows, written_rows};
use crate::experiment::rule::{shown, Check, Cmp, Null, Partly, Rule};
use crate::experiment::Error;
use crate::families::lbc::{entropy_section, rule_settings};
use std::f64::consts::FRAC_PI_2;
use std::path::Path;

/// The report section: the reaches, the premise, the swings, settling and mirroring, the λ
/// sweep and the verdict.
pub(super) fn report(dir: &Path) -> Result<Findings, Error> {
    let setting = rule_settings(dir)?;
    let weights: Vec<WeightRow> = read_rows(&dir.join("weights.csv"))?;
    // The measures read whole columns.
    let col = |f: fn(&WeightRow) -> f64| weights.iter().map(f).collect::<Vec<f64>>();
    let (t, a, f, body) = (
        col(|r| r.t_s),
        col(|r| r.alpha_forward),
        col(|r| r.force_x_n),
        col(|r| r.body_angle_rad),
    );
    let (am, ab, bm) = (
        col(|r| r.alpha_forward_mirrored),
        col(|r| r.alpha_forward_baseline),
        col(|r| r.body_angle_mirrored_rad),
    );
    let (w0, w1) = (setting("settle_start"), setting("settle_end"));
    let last_tug = (0..t.len())
        .rev()
        .find(|&k| f[k] != 0.0)
        .map_or(0.0, |k| t[k]);
    // Side-to-side swings before the settling window, tugged and without tugs.
    let (tugged_swings, baseline_swings) = (swings(&t, &a, w0), swings(&t, &ab, w0));
    let window: Vec<usize> = (0..t.len()).filter(|&k| t[k] >= w0 && t[k] <= w1).collect();
    let settle_gap = window_gap(&t, &a, &ab, [w0, w1]);
    // Settled: the tugged and the mirrored weights each stay within the tolerance over the
    // window (one strategy kept, whichever it is).
    let settle_range = window_range(&t, &a, [w0, w1]).max(window_range(&t, &am, [w0, w1]));
    // Mirrored tugs must give the mirrored choice: α_backward(mirrored) = 1 − α_fwd(mirrored).
    let mirror_gap = mirror_gap(&a, &am);
    let lean = body
        .iter()
        .chain(&bm)
        .map(|b| (b - FRAC_PI_2).abs())
        .fold(0.0, f64::max);
    let (min_swings, settle_tol, mirror_tol, fall) = (
        setting("min_swings"),
        setting("settle_tolerance"),
        setting("mirror_tolerance"),
        setting("fall_angle"),
    );
    // An empty window says nothing about settling.
    let settle_range = if window.is_empty() {
        f64::NAN
    } else {
        settle_range
    };
    // At rest over the window: the body's largest angular rate (finite differences of the
    // body angle, tugged and mirrored runs).
    let rest_rate = setting("rest_rate");
    let rate = window
        .windows(2)
        .map(|k| {
            let dt = t[k[1]] - t[k[0]];
            ((body[k[1]] - body[k[0]]) / dt)
                .abs()
                .max(((bm[k[1]] - bm[k[0]]) / dt).abs())
        })
        .fold(0.0, f64::max);
    let at_rest = rate < rest_rate;
    let reaches: Vec<ReachRow> = read_rows(&dir.join("reaches.csv"))?;
    let mut md = format!(
        "λ = σ²R = {} from motor noise σ = {} N·m·√s. Reaches (torque-limited DDP, run to convergence): {}.\n\n",
        sig(setting("lambda")),
        sig(setting("torque_noise")),
        reaches
            .iter()
            .map(|r| format!("{} cost {} ({})", r.reach, sig(r.cost), r.termination))
            .collect::<Vec<_>>()
            .join(", ")
    );
    md.push_str(&format!(
        "The last tug ends at t = {} s. Walls at ±{} m from the ankle. Beside the rule: the tugged weight's largest distance from the no-tug baseline's over the settling window [{}, {}] s is {} (the tugs may change which strategy is kept); the body's largest rate there {} rad/s.\n",
        sig(last_tug),
        sig(setting("walls_distance")),
        sig(w0),
        sig(w1),
        sig(settle_gap),
        sig(rate)
    ));
    // When the tugged weight first leaves the undecided middle, and for which reach; where
    // the hand is when the first tug ends.
    let hand_x = col(|r| r.hand_x_m);
    let walls = setting("walls_distance");
    md.push_str(&commitment_line(&t, &a, &f, &hand_x, tugged_swings, walls));
    let range = |v: &[f64]| window_range(&t, v, [w0, w1]);
    let mean = |v: &[f64]| window.iter().map(|&k| v[k]).sum::<f64>() / window.len() as f64;
    md.push_str(&format!(
        "\nOver the window the tugged forward weight varies by {} (mean {}); the no-tug baseline's by {} (mean {}); the mirrored run's by {} (mean {}).\n",
        sig(range(&a)),
        sig(mean(&a)),
        sig(range(&ab)),
        sig(mean(&ab)),
        sig(range(&am)),
        sig(mean(&am))
    ));
    md.push_str(&lambda_sweep_section(dir)?);
    // The premise: without a reach the tugs topple the body (a fall is what the reaches
    // prevent).
    let no_reach = setting("no_reach_lean");
    let premise = no_reach > fall;
    md.push_str(&no_reach_line(no_reach, premise, fall));
    let (scales_md, found) = reach_scales(dir, setting("reach_scale"))?;
    md.push_str(&scales_md);
    md.push_str(&entropy_section(
        dir,
        "the fixed weights are w = (1, 1), so their entropy is 1: uniform α",
        "the fixed average of the two reaches",
    )?);
    let rule = push_rule(
        &PushFacts {
            swings: (tugged_swings as f64, baseline_swings as f64),
            settle_range,
            mirror_gap,
            lean: (lean, no_reach),
            at_rest,
            committed_late: found,
        },
        &PushBars {
            min_swings,
            settle_tolerance: settle_tol,
            mirror_tolerance: mirror_tol,
            fall_angle: fall,
        },
    );
    let (verdict, lines, text) = shown(rule.as_ref(), " No rule: a bar its null meets.");
    Ok(Findings {
        ours: md,
        verdict,
        rule: rule.clone(),
        why: format!(
            "paper: the blend weight swings as the arm is tugged back and forth, then settles (Fig. 9). Ours: the weight swings {} times under the tugs (the no-tug baseline {}), keeps one reach over the window (range {}), mirrors (gap {}); with LBC the body leans at most {} rad, without a reach the same tugs lean it {} rad.{lines} Rule (thresholds ours, in the spec; a swing is the weight crossing from below 0.25 to above 0.75 or back before the settling window; the reach scale is the first at which, with the first tug alone, neither reach's weight exceeds {} before the second tug): {text}",
            tugged_swings,
            baseline_swings,
            sig(settle_range),
            sig(mirror_gap),
            sig(lean),
            sig(no_reach),
            sig(COMMITTED),
        ),
    })
}

/// When the tugged weight `a` first leaves the undecided middle, and for which reach; where
/// the hand is when the first tug (force `f`) ends.
fn commitment_line(
    t: &[f64],
    a: &[f64],
    f: &[f64],
    hand_x: &[f64],
    tugged_swings: usize,
    walls: f64,
) -> String {
    let first = (0..t.len()).find(|&k| a[k] > 0.75 || a[k] < 0.25);
    let tug_on = (0..t.len()).find(|&k| f[k] != 0.0);
    let tug_off = tug_on.and_then(|k0| (k0..t.len()).find(|&k| f[k] == 0.0));
    match first {
        Some(k) => format!(
            "\nThe tugged weight first leaves the undecided middle (0.25 to 0.75) at t = {} s, for the {} reach{}; when the first tug ends (t = {} s) the hand is at x = {} m (walls at ±{} m).\n",
            sig(t[k]),
            if a[k] > 0.75 { "forward" } else { "backward" },
            if tugged_swings == 0 {
                ", and never swings to the other side afterwards"
            } else {
                ""
            },
            tug_off.map_or("n/a".into(), |j| sig(t[j])),
            tug_off.map_or("n/a".into(), |j| sig(hand_x[j])),
            sig(walls)
        ),
        None => "\nThe tugged weight never leaves the undecided middle (0.25 to 0.75).\n".into(),
    }
}

/// The same checks over λ (from `lambda_sweep.csv`), empty without rows.
fn lambda_sweep_section(dir: &Path) -> Result<String, Error> {
    let mut md = String::new();
    let rows: Vec<LambdaRow> = read_rows(&dir.join("lambda_sweep.csv"))?;
    if !rows.is_empty() {
        md.push_str("\nThe same checks over λ (not judged; entropy of α normalized to [0, 1], 0 a switch, 1 uniform):\n\n| λ | swings | range over the window | gap to the no-tug baseline | mirror gap | mean entropy of α under the tugs | largest lean (rad) |\n| --- | --- | --- | --- | --- | --- | --- |\n");
        for r in &rows {
            md.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} |\n",
                sig(r.lambda),
                r.swings,
                sig(r.settle_range),
                sig(r.settle_gap),
                sig(r.mirror_gap),
                sig(r.mean_entropy),
                sig(r.max_lean_rad)
            ));
        }
    }
    Ok(md)
}

/// How far the tugs lean the body without a reach (`no_reach`), against the fall angle.
fn no_reach_line(no_reach: f64, premise: bool, fall: f64) -> String {
    format!(
        "\nWithout a reach (arm held at its start pose, the ankle pushing back to upright, both torque-limited), the same tugs and the mirrored ones lean the body at most {} rad from upright: {} the fall angle {} rad, so {}.\n",
        sig(no_reach),
        if premise { "beyond" } else { "within" },
        sig(fall),
        if premise {
            "the tugs would topple it and the reaches prevent a fall (the paper's premise holds)"
        } else {
            "the tugs do not threaten a fall here and the paper's premise (a reach is needed to prevent a fall) does not hold"
        }
    )
}

/// What [`push_rule`] reads.
pub struct PushFacts {
    /// Side-to-side swings of the weight before the settling window: tugged, no-tug baseline.
    pub swings: (f64, f64),
    /// The weight's largest range over the window, tugged or mirrored.
    pub settle_range: f64,
    /// max |α_fwd − α_bwd(mirrored)|.
    pub mirror_gap: f64,
    /// The body's largest lean from upright (rad): with LBC, and without a reach.
    pub lean: (f64, f64),
    /// At rest over the window.
    pub at_rest: bool,
    /// At the chosen reach scale LBC's weights had not committed before the second tug.
    pub committed_late: bool,
}

/// The spec's bars [`push_rule`] reads.
pub struct PushBars {
    /// Swings needed.
    pub min_swings: f64,
    /// Settled: the range over the window below this.
    pub settle_tolerance: f64,
    /// Mirrored: the gap below this.
    pub mirror_tolerance: f64,
    /// A lean beyond this (rad) is a fall.
    pub fall_angle: f64,
}

/// The verdict's rule. Premise: without a reach the tugs lean the body beyond the fall angle
/// (null: a body that does not lean), and at the chosen reach scale LBC's weights have not
/// committed before the second tug. Held: (a) the weight swings at least `min_swings` times
/// (null: the no-tug baseline's swings) and (b) more than the baseline (null: the baseline, 0
/// more); (c) it settles, its range over the window below `settle_tolerance` (null: a weight
/// sweeping the whole range, 1); (d) mirrored tugs give the mirrored choice, gap below
/// `mirror_tolerance` (null: the same reach under mirrored tugs, 1); (e) no fall, the lean
/// below the fall angle (null: the body without a reach), and (f) at rest over the window.
/// Partly: (a) and (d), the swings with mirrored choices.
pub fn push_rule(f: &PushFacts, b: &PushBars) -> Option<Rule> {
    let premise = vec![
        Check::new(
            "without a reach, the tugs' largest lean from upright (rad)",
            f.lean.1,
            Cmp::Above,
            b.fall_angle,
            Null::new("a body that does not lean", 0.0),
        )
        .ok()?,
        Check::fact(
            "at the chosen reach scale, LBC's weights have not committed before the second tug",
            f.committed_late,
        ),
    ];
    let baseline = "the no-tug baseline";
    let held = vec![
        Check::new(
            "side-to-side swings of the weight under the tugs",
            f.swings.0,
            Cmp::AtLeast,
            b.min_swings,
            Null::new(baseline, f.swings.1),
        ),
        Check::new(
            "swings beyond the no-tug baseline's",
            f.swings.0 - f.swings.1,
            Cmp::Above,
            0.0,
            Null::new(baseline, 0.0),
        ),
        Check::new(
            "the weight's range over the settling window",
            f.settle_range,
            Cmp::Below,
            b.settle_tolerance,
            Null::new("a weight sweeping the whole range", 1.0),
        ),
        Check::new(
            "mirror gap max |alpha_fwd - alpha_bwd(mirrored)|",
            f.mirror_gap,
            Cmp::Below,
            b.mirror_tolerance,
            Null::new("the same reach under mirrored tugs", 1.0),
        ),
        Check::new(
            "largest lean from upright with LBC (rad)",
            f.lean.0,
            Cmp::Below,
            b.fall_angle,
            Null::new("the body without a reach", f.lean.1),
        ),
        Ok(Check::fact("at rest over the settling window", f.at_rest)),
    ];
    Rule::gated(premise, held, Partly::All(vec![0, 3]))
}

/// The reach-scale search's table (from `reach_scales.csv`, when the spec lists scales) and
/// whether the rule found a scale (true when no search was asked for).
fn reach_scales(dir: &Path, chosen: f64) -> Result<(String, bool), Error> {
    let Some(rows) = written_rows::<ReachScaleRow>(dir, "reach_scales.csv")? else {
        return Ok((String::new(), true));
    };
    let mut md = format!(
        "\nReach scale (rule fixed in the spec before the run: the reaches' state weights × scale, scales in the listed order; the first at which, with the first tug alone, neither reach's weight exceeds {} before the second tug starts; every table here uses it):\n\n| scale | largest weight before the second tug | committed |\n| --- | --- | --- |\n",
        sig(COMMITTED)
    );
    for r in &rows {
        md.push_str(&format!(
            "| {} | {} | {} |\n",
            sig(r.reach_scale),
            sig(r.max_weight_before_second_tug),
            if r.committed == 1 { "yes" } else { "no" }
        ));
    }
    let found = rows.iter().any(|r| r.committed == 0);
    md.push_str(&if found {
        format!("\nChosen: scale {}.\n", sig(chosen))
    } else {
        format!(
            "\nThe weights commit before the second tug at every scale tried: premise not reproduced; the tables use scale {}.\n",
            sig(chosen)
        )
    });
    Ok((md, found))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::report::Verdict;

    const BARS: PushBars = PushBars {
        min_swings: 2.0,
        settle_tolerance: 0.1,
        mirror_tolerance: 0.05,
        fall_angle: 0.5,
    };

    fn facts(swings: f64, no_reach: f64) -> PushFacts {
        PushFacts {
            swings: (swings, 0.0),
            settle_range: 0.01,
            mirror_gap: 1e-6,
            lean: (0.1, no_reach),
            at_rest: true,
            committed_late: true,
        }
    }

    #[test]
    fn swings_with_mirrored_choices_are_partly_and_every_check_held() {
        let v = |f: &PushFacts| push_rule(f, &BARS).map(|r| r.verdict());
        assert_eq!(v(&facts(3.0, 0.9)), Some(Verdict::Held));
        // No swings under the tugs: not even partly.
        assert_eq!(v(&facts(0.0, 0.9)), Some(Verdict::NotHeld));
        let unsettled = PushFacts {
            settle_range: 0.5,
            ..facts(3.0, 0.9)
        };
        assert_eq!(v(&unsettled), Some(Verdict::Partly));
        // Tugs that would not topple the body without a reach: the premise fails.
        assert_eq!(v(&facts(3.0, 0.2)), Some(Verdict::PremiseNotReproduced));
        // A no-tug baseline that swings as often as the bar: the swing check cannot fail.
        let baseline = PushFacts {
            swings: (3.0, 2.0),
            ..facts(3.0, 0.9)
        };
        assert!(push_rule(&baseline, &BARS).is_none());
    }
}
