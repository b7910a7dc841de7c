//! The report sections and verdicts of both dive families, read back from the CSVs.

use super::rows::{
    AverageRow, CoordinationRow, CoordinationSweepRow, DiveRow, InterpolationRow,
    InterpolationSweepRow, Method, OffsetRow, Tracking, ValueFunction, ValueRow,
};
use super::{compare_objectives, coordination_rule, CoordinationCounts, CoordinationRule};
use crate::experiment::report::{sig, Findings};
use crate::experiment::rows::read_rows;
use crate::experiment::rule::{shown, Check, Cmp, Null, Partly, Rule};
use crate::experiment::Error;
use crate::families::lbc::{entropy_section, rule_settings};
use std::path::Path;

/// The interpolation's report section and verdict.
pub(super) fn interpolation(dir: &Path) -> Result<Findings, Error> {
    let setting = rule_settings(dir)?;
    let (lambda, sigma, tol_entry, tol_obj, scale) = (
        setting("lambda"),
        setting("torque_noise"),
        setting("entry_tolerance"),
        setting("objective_tolerance"),
        setting("q_spacing2_over_lambda"),
    );
    // The components: the under-rotating dive aims short of vertical (a negative target
    // offset), the over-rotating one past it.
    let dives: Vec<DiveRow> = read_rows(&dir.join("dives.csv"))?;
    let under = dives.iter().find(|r| r.target_offset < 0.0);
    let over = dives.iter().find(|r| r.target_offset > 0.0);
    let (Some(under), Some(over)) = (under, over) else {
        return Err(Error::Other(
            "dives.csv: no under- and over-rotating component dives".into(),
        ));
    };
    let de = [under.entry_angle, over.entry_angle];
    let rows: Vec<InterpolationRow> = read_rows(&dir.join("interpolation.csv"))?;
    let at = |m: Method, gv: f64| {
        rows.iter()
            .find(|r| r.method == m.name() && r.desired_angle == gv)
    };
    let mut md = format!(
        "λ = σ²R = {} from joint-torque noise σ = {} N·m·√s; torque limits in DDP and every closed loop; Q_torso·spacing²/λ = {} (§4.1 asks for about 1). Components: the under-rotating dive enters at {} rad (cost {}), the over-rotating one at {} rad (cost {}).\n\n| desired (rad) | w | LBC reached | naive reached | direct DDP reached | LBC excess objective | naive excess objective | LBC mean entropy of α |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n",
        sig(lambda),
        sig(sigma),
        sig(scale),
        sig(under.entry_angle),
        sig(under.cost),
        sig(over.entry_angle),
        sig(over.cost)
    );
    let (mut le, mut ne, mut n) = (0.0, 0.0, 0usize);
    // Mean |reached - desired| over every target, and where LBC lands farther than naive.
    let (mut lbc_miss, mut naive_miss, mut worse) = (0.0, 0.0, 0usize);
    let mut gs: Vec<f64> = rows.iter().map(|r| r.desired_angle).collect();
    gs.dedup();
    for &gv in &gs {
        let (Some(l), Some(v), Some(d)) = (
            at(Method::Lbc, gv),
            at(Method::Naive, gv),
            at(Method::Direct, gv),
        ) else {
            continue;
        };
        md.push_str(&format!(
            "| {} | ({}, {}) | {} | {} | {} | {} | {} | {} |\n",
            sig(gv),
            sig(l.weight1),
            sig(l.weight2),
            sig(l.reached_angle),
            sig(v.reached_angle),
            sig(d.reached_angle),
            sig(l.excess_objective),
            sig(v.excess_objective),
            sig(l.mean_entropy)
        ));
        le += l.excess_objective;
        ne += v.excess_objective;
        lbc_miss += (l.reached_angle - gv).abs();
        naive_miss += (v.reached_angle - gv).abs();
        worse += usize::from((l.reached_angle - gv).abs() > (v.reached_angle - gv).abs());
        n += 1;
    }
    let (le, ne) = (le / n.max(1) as f64, ne / n.max(1) as f64);
    let (lbc_miss, naive_miss) = (lbc_miss / n.max(1) as f64, naive_miss / n.max(1) as f64);
    let (lv, nv) = (
        at(Method::Lbc, 0.0).map_or(f64::NAN, |r| r.reached_angle.abs()),
        at(Method::Naive, 0.0).map_or(f64::NAN, |r| r.reached_angle.abs()),
    );
    md.push_str(&format!(
        "\nVertical entry (the claim): LBC ends {} rad from vertical, naive {} rad (tolerance {}). Mean excess objective over the direct DDP optimum of the reconstructed cost: LBC {}, naive {} (tolerance {}).\n",
        sig(lv),
        sig(nv),
        sig(tol_entry),
        sig(le),
        sig(ne),
        sig(tol_obj)
    ));
    md.push_str(&lambda_sweep_section(dir)?);
    md.push_str(&average_term(dir, setting("average_scale"), tol_entry)?);
    let (offsets_md, searched) = offsets(dir, setting("offset"), tol_entry)?;
    md.push_str(&offsets_md);
    md.push_str(&entropy_section(
        dir,
        "1 = uniform α; the fixed weights are uniform only at the vertical target, so at the other targets the naive blend's constant entropy is below 1",
        "the naive blend with the same projected weights",
    )?);
    // The search found an offset where the naive blend misses vertical.
    let found = setting("offset_premise_found") == 1.0;
    let miss = Misses {
        lbc_vertical: lv,
        naive_vertical: nv,
        lbc_excess: le,
        naive_excess: ne,
        lbc_miss,
        naive_miss,
        targets: n,
    };
    let rule = interpolation_rule(&de, &miss, (tol_entry, tol_obj), &searched, found)?;
    Ok(Findings {
        ours: md,
        verdict: rule.verdict(),
        rule: rule.clone().into(),
        why: format!(
            "At the vertical target LBC enters {} rad from vertical and the naive blend with the same weights {} rad (tolerance {}); over all {n} desired angles LBC lands on average {} rad from the desired angle, the naive blend {} rad (LBC farther at {worse} of {n}); their mean excess objective over the direct DDP optimum is {} vs {}. paper: with weights projected for a vertical goal, LBC enters vertically and the naive average with the same weights does not.{} Rule (ours, fixed in the spec; the spec's history gives what changed after results): {}",
            sig(lv),
            sig(nv),
            sig(tol_entry),
            sig(lbc_miss),
            sig(naive_miss),
            sig(le),
            sig(ne),
            rule.lines(),
            rule.text(),
        ),
    })
}

/// LBC at the vertical target over λ (from `lambda_sweep.csv`), empty without rows.
fn lambda_sweep_section(dir: &Path) -> Result<String, Error> {
    let mut md = String::new();
    let sweep: Vec<InterpolationSweepRow> = read_rows(&dir.join("lambda_sweep.csv"))?;
    if !sweep.is_empty() {
        md.push_str("\nLBC at the vertical target over λ (weights re-projected at each λ; entropy 0 is a switch, 1 the naive average):\n\n| λ | reached | mean entropy of α |\n| --- | --- | --- |\n");
        for r in sweep.iter().filter(|r| r.desired_angle == 0.0) {
            md.push_str(&format!(
                "| {} | {} | {} |\n",
                sig(r.lambda),
                sig(r.reached_angle),
                sig(r.mean_entropy)
            ));
        }
    }
    Ok(md)
}

/// How far LBC and the naive blend land from their targets: at the vertical target, in mean
/// excess objective and in mean |entry - desired| over the `targets` desired angles.
struct Misses {
    lbc_vertical: f64,
    naive_vertical: f64,
    lbc_excess: f64,
    naive_excess: f64,
    lbc_miss: f64,
    naive_miss: f64,
    targets: usize,
}

/// The interpolation's rule: the premises (components on either side of vertical, the naive
/// blend missing vertical at the offset judged, `searched` the offset search's summary) and
/// the checks on `miss` with tolerances `(entry, objective)`; `de` are the components' entry
/// angles.
fn interpolation_rule(
    de: &[f64],
    miss: &Misses,
    (tol_entry, tol_obj): (f64, f64),
    searched: &str,
    found: bool,
) -> Result<Rule, Error> {
    let (lv, nv, le, ne) = (
        miss.lbc_vertical,
        miss.naive_vertical,
        miss.lbc_excess,
        miss.naive_excess,
    );
    let (lbc_miss, naive_miss, n) = (miss.lbc_miss, miss.naive_miss, miss.targets);
    Rule::gated(
        vec![
            Check::fact(
                format!(
                    "one component dive enters short of vertical and the other past it, each by more than {} rad",
                    sig(tol_entry)
                ),
                de[0] < -tol_entry && de[1] > tol_entry,
            ),
            Check::fact(
                format!(
                    "at the offset judged the naive blend with the weights projected for vertical misses vertical by more than {} rad (the smallest offset of the spec's list where it does: {searched})",
                    sig(tol_entry)
                ),
                found,
            ),
        ],
        vec![
            Check::new(
                "LBC's |entry| at the vertical target (rad)",
                lv,
                Cmp::AtMost,
                tol_entry,
                Null::new("the naive blend with the same weights", nv),
            ),
            Check::new(
                "the naive blend's mean excess objective over the direct DDP optimum minus LBC's",
                ne - le,
                Cmp::Above,
                tol_obj,
                Null::new("the naive blend itself", 0.0),
            ),
            Check::new(
                format!("LBC's mean |entry - desired| over all {n} targets over the naive blend's"),
                lbc_miss / naive_miss,
                Cmp::Below,
                1.0,
                Null::new("the naive blend itself", 1.0),
            ),
        ],
        Partly::Any,
    )
    .ok_or_else(|| {
        crate::experiment::other(
            "lbc_diver_interpolation: a null passes a check of the rule although the premise holds",
        )
    })
}

/// The offset search's table (from `offsets.csv`) and a phrase on its
/// outcome for the verdict's reason.
fn offsets(dir: &Path, chosen: f64, tol: f64) -> Result<(String, String), Error> {
    let rows: Vec<OffsetRow> = read_rows(&dir.join("offsets.csv"))?;
    let mut md = format!(
        "\nThe offset search (rule fixed in the spec before the run: components at ±δ for δ in ascending order, each built as a run at δ builds them, §6.1 scale chosen by its rule; the first δ where the components straddle vertical by more than {t} rad each and the naive blend with the weights projected for vertical misses vertical by more than {t} rad is judged, and the search stops there):\n\n| δ (rad) | §6.1 scale | under-rotating entry | over-rotating entry | naive vertical entry | LBC vertical entry | premise holds | torso terminal weight (1/rad²) |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n",
        t = sig(tol)
    );
    for r in &rows {
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} |\n",
            sig(r.offset),
            sig(r.average_scale),
            sig(r.under_entry),
            sig(r.over_entry),
            sig(r.naive_vertical_entry),
            sig(r.lbc_vertical_entry),
            if r.premise_holds == 1 { "yes" } else { "no" },
            sig(r.torso_weight)
        ));
    }
    let outcome = match rows.iter().find(|r| r.premise_holds == 1) {
        Some(r) => format!(
            "δ = {} rad, where the naive blend enters {} rad from vertical",
            sig(r.offset),
            sig(r.naive_vertical_entry)
        ),
        None => format!(
            "none of δ = {} did; the tables above use the largest, {} rad",
            rows.iter()
                .map(|r| sig(r.offset))
                .collect::<Vec<_>>()
                .join(", "),
            sig(chosen)
        ),
    };
    md.push_str(&format!("\nOutcome: {outcome}.\n"));
    Ok((md, outcome))
}

/// The §6.1 average-trajectory term's table (from `average_term.csv`): per scale, the
/// components' worst entry error and, at the vertical target, where LBC and the naive blend
/// enter and how far LBC's dive strays from the components' average trajectory.
fn average_term(dir: &Path, chosen: f64, tol_entry: f64) -> Result<String, Error> {
    let rows: Vec<AverageRow> = read_rows(&dir.join("average_term.csv"))?;
    let mut md = format!(
        "\nThe §6.1 average-trajectory term (each component re-optimized with the running cost scale·(x−x̄)ᵀQ(x−x̄), x̄ the components' mean trajectory without it). Rule (fixed in the spec before the sweep): the tables above use the largest scale at which both components still enter within {} rad of their targets; chosen: {}.\n\n| scale | worst component entry error (rad) | LBC vertical entry (rad) | naive vertical entry (rad) | LBC RMS deviation from x̄ (rad) |\n| --- | --- | --- | --- | --- |\n",
        sig(tol_entry),
        sig(chosen)
    );
    let mut scales: Vec<f64> = rows.iter().map(|r| r.average_scale).collect();
    scales.dedup();
    for &sc in &scales {
        let at = || rows.iter().filter(move |r| r.average_scale == sc);
        let worst = at()
            .filter(|r| r.method == Method::Component.name())
            .map(|r| r.entry_error)
            .fold(f64::NEG_INFINITY, f64::max);
        let find = |m: Method| at().find(|r| r.method == m.name() && r.desired_angle == 0.0);
        let (l, v) = (find(Method::Lbc), find(Method::Naive));
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} |\n",
            sig(sc),
            sig(worst),
            l.map_or("–".into(), |r| sig(r.reached_angle)),
            v.map_or("–".into(), |r| sig(r.reached_angle)),
            l.map_or("–".into(), |r| sig(r.angle_deviation))
        ));
    }
    Ok(md)
}

/// The coordination's report section and verdict.
pub(super) fn coordination(dir: &Path) -> Result<Findings, Error> {
    let setting = rule_settings(dir)?;
    let (lambda, sigma, tol_entry, tol_obj) = (
        setting("lambda"),
        setting("torque_noise"),
        setting("entry_tolerance"),
        setting("objective_tolerance"),
    );
    let bars = CoordinationRule {
        better_share: setting("better_share"),
        partly_worse_margin: setting("partly_worse_margin"),
    };
    let rows: Vec<CoordinationRow> = read_rows(&dir.join("coordination.csv"))?;
    let mut md = format!(
        "λ = σ²R = {} from joint-torque noise σ = {} N·m·√s; torque limits in DDP and every closed loop. Vertical: |entry| ≤ {} rad; objectives compared with a relative tolerance of {}.\n\n| initial ω (rad/s) | LBC entry error | single entry error | LBC objective | single objective | LBC vs single | LBC mean entropy of α | max torque / limit (LBC, single) |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n",
        sig(lambda),
        sig(sigma),
        sig(tol_entry),
        sig(tol_obj)
    );
    let (mut better, mut worse, mut much_worse, mut lv, mut sv, mut n) = (0, 0, 0, 0, 0, 0);
    let (lbc, single) = (Tracking::Lbc.name(), Tracking::Single.name());
    for r in rows.iter().filter(|r| r.method == lbc) {
        let Some(q) = rows
            .iter()
            .find(|q| q.method == single && q.initial_omega == r.initial_omega)
        else {
            continue;
        };
        n += 1;
        better += (r.objective_outcome == "better") as usize;
        worse += (r.objective_outcome == "worse") as usize;
        much_worse += (compare_objectives(r.objective, q.objective, bars.partly_worse_margin)
            == "worse") as usize;
        lv += (r.entry_error <= tol_entry) as usize;
        sv += (q.entry_error <= tol_entry) as usize;
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} | ({}, {}) |\n",
            sig(r.initial_omega),
            sig(r.entry_error),
            sig(q.entry_error),
            sig(r.objective),
            sig(q.objective),
            r.objective_outcome,
            sig(r.mean_entropy),
            sig(r.max_torque_fraction),
            sig(q.max_torque_fraction)
        ));
    }
    md.push_str(&format!(
        "\nLBC's objective is better in {better}, worse in {worse} and tied in {} of {n} take-off rates; LBC enters vertically from {lv}, the single tracker from {sv}.\n",
        n - better - worse
    ));
    let sweep: Vec<CoordinationSweepRow> = read_rows(&dir.join("lambda_sweep.csv"))?;
    let mut lams: Vec<f64> = sweep.iter().map(|r| r.lambda).collect();
    lams.sort_by(f64::total_cmp);
    lams.dedup();
    if !lams.is_empty() {
        md.push_str("\nLBC over λ (vs the single tracker, same tolerance):\n\n| λ | better | worse | tied | mean entropy of α |\n| --- | --- | --- | --- | --- |\n");
        for &l in &lams {
            let rs: Vec<&CoordinationSweepRow> = sweep.iter().filter(|r| r.lambda == l).collect();
            let c = |s: &str| rs.iter().filter(|r| r.objective_outcome == s).count();
            let hm = rs.iter().map(|r| r.mean_entropy).sum::<f64>() / rs.len().max(1) as f64;
            md.push_str(&format!(
                "| {} | {} | {} | {} | {} |\n",
                sig(l),
                c("better"),
                c("worse"),
                c("tie"),
                sig(hm)
            ));
        }
    }
    let values: Vec<ValueRow> = read_rows(&dir.join("value_comparison.csv"))?;
    let find = |w: f64, f: ValueFunction, m: Tracking| {
        values
            .iter()
            .find(|r| r.initial_omega == w && r.value_function == f.name() && r.method == m.name())
    };
    if setting("ddp_value_built") != 1.0 {
        md.push_str("\nThe DDP value function (second-order dynamics terms) could not be built for every dive (Q_uu not positive definite), so its comparison is left out.\n");
    }
    md.push_str("\nTrackers with DDP's value function and gains (second-order dynamics terms, LBC §5.2) beside the LQR ones (not judged):\n\n| initial ω (rad/s) | LBC objective, LQR value | LBC objective, DDP value | single, LQR | single, DDP | LBC entry error, LQR / DDP |\n| --- | --- | --- | --- | --- | --- |\n");
    let mut ws: Vec<f64> = values.iter().map(|r| r.initial_omega).collect();
    ws.dedup();
    let (lqr, ddp) = (ValueFunction::Lqr, ValueFunction::Ddp);
    for &x in &ws {
        let (Some(a), Some(b), Some(c), Some(e)) = (
            find(x, lqr, Tracking::Lbc),
            find(x, ddp, Tracking::Lbc),
            find(x, lqr, Tracking::Single),
            find(x, ddp, Tracking::Single),
        ) else {
            continue;
        };
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} / {} |\n",
            sig(x),
            sig(a.objective),
            sig(b.objective),
            sig(c.objective),
            sig(e.objective),
            sig(a.entry_error),
            sig(b.entry_error)
        ));
    }
    md.push_str(&entropy_section(
        dir,
        "the fixed weights are w = 1 for each of the three trackers, so their entropy is 1: uniform α",
        "the fixed-weight average of the three trackers",
    )?);
    let rule = coordination_rule(
        &CoordinationCounts {
            rates: n,
            better,
            worse,
            much_worse,
            lbc_vertical: lv,
            single_vertical: sv,
        },
        &bars,
    );
    let (verdict, lines, text) = shown(rule.as_ref(), " No rule: a bar its null meets.");
    Ok(Findings {
        ours: md,
        verdict,
        rule: rule.clone(),
        why: format!("Over {n} take-off rates LBC's objective is better than the single tracker's at {better} and worse at {worse} ({much_worse} by more than {} of the smaller), and LBC enters vertically from {lv} rates against the single tracker's {sv}. paper: the combination recovers a vertical entry better than one tracker, with a better objective in every case.{lines} Rule (fixed in the spec; its partly grade rewritten after results, see the rule history): {text}", sig(bars.partly_worse_margin)),
    })
}
