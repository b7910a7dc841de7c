//! `lbc_walking`'s verdict and report section.

use super::job::part_means;
use super::rows::{SweepRow, WalkRow, WeightRow};
use crate::experiment::output::Tables;
use crate::experiment::report::{sig, Findings, Verdict};
use crate::experiment::rows::read_rows;
use crate::experiment::rule::{Check, Cmp, Null, Partly, Rule};
use crate::experiment::Error;
use crate::families::lbc::{rule_setting, rule_settings};
use crate::physics::ground::Terrain;
use std::path::Path;

pub(super) const TERRAINS: [&str; 3] = ["flat", "incline", "flat_then_hill"];
pub(super) const CONTROLLERS: [&str; 4] = ["flat", "hill", "naive", "lbc"];

/// What the rule reads from a run (module docs of the family).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WalkingFacts {
    /// The flat walker on the incline: (distance m, fell).
    pub flat_on_incline: (f64, bool),
    /// The hill walker on the incline: (distance m, fell).
    pub hill_on_incline: (f64, bool),
    /// LBC on the flat-then-hill track: (distance m, fell).
    pub lbc_on_track: (f64, bool),
    /// The flat walker alone on the track: (distance m, fell).
    pub flat_on_track: (f64, bool),
    /// The hill walker alone on the track: (distance m, fell).
    pub hill_on_track: (f64, bool),
    /// LBC's mean α_hill on the track's flat and hill parts.
    pub alpha_flat_part: f64,
    /// (see `alpha_flat_part`)
    pub alpha_hill_part: f64,
}

/// The verdict's rule with the thresholds `advance_fraction`, the distance LBC must reach
/// (`reach_m` = hill start + climb) and `shift`. Premise (the paper's): the hill walker climbs
/// the incline without falling, and the flat walker "does not fall, but fails to advance"
/// there (covers less than `advance_fraction` of the hill walker's distance). (a) LBC walks the
/// track to `reach_m` without falling (null: the flat walker alone on the track); (b) its
/// weights shift to the hill walker: α_hill on the hill part at least `shift` above the flat
/// part's (null: fixed weights, no shift) and (c) at least one half there; (d) LBC walks the
/// track at least as far as the hill walker alone (null: the flat walker alone). Held: all;
/// partly: (a), (b) and (c). `None` when a null passes its check.
pub fn walking_rule(
    f: &WalkingFacts,
    advance_fraction: f64,
    reach_m: f64,
    shift: f64,
) -> Option<Rule> {
    let walked = |w: (f64, bool)| {
        if w.1 {
            f64::min(w.0, reach_m - 1e-9)
        } else {
            w.0
        }
    };
    let premise = vec![
        Check::fact(
            "the hill walker climbs the incline without falling",
            !f.hill_on_incline.1 && f.hill_on_incline.0 > 0.0,
        ),
        Check::fact(
            "the flat walker does not fall on the incline (the paper)",
            !f.flat_on_incline.1,
        ),
        Check::new(
            "the flat walker's distance on the incline over the hill walker's (it fails to advance)",
            f.flat_on_incline.0 / f.hill_on_incline.0,
            Cmp::Below,
            advance_fraction,
            Null::new("a walker that climbs as the hill walker does", 1.0),
        )
        .ok()?,
    ];
    let held = vec![
        Check::new(
            "LBC's distance on the flat-then-hill track without falling (m)",
            walked(f.lbc_on_track),
            Cmp::AtLeast,
            reach_m,
            Null::new("the flat walker alone", walked(f.flat_on_track)),
        )
        .ok()?,
        Check::new(
            "LBC's mean weight of the hill walker, hill part minus flat part",
            f.alpha_hill_part - f.alpha_flat_part,
            Cmp::AtLeast,
            shift,
            Null::new("fixed weights (the naive blend)", 0.0),
        )
        .ok()?,
        Check::new(
            "LBC's mean weight of the hill walker on the hill part",
            f.alpha_hill_part,
            Cmp::AtLeast,
            0.5,
            Null::new("the flat walker alone (weight 0)", 0.0),
        )
        .ok()?,
        Check::new(
            "LBC's distance on the track over the hill walker's alone",
            walked(f.lbc_on_track) / f.hill_on_track.0,
            Cmp::AtLeast,
            1.0,
            Null::new(
                "the flat walker alone",
                walked(f.flat_on_track) / f.hill_on_track.0,
            ),
        )
        .ok()?,
    ];
    Some(Rule {
        premise,
        held,
        partly: Partly::All(vec![0, 1, 2]),
    })
}

/// The verdict (not assessed where [`walking_rule`] cannot be built).
pub fn verdict_of(f: &WalkingFacts, advance_fraction: f64, reach_m: f64, shift: f64) -> Verdict {
    walking_rule(f, advance_fraction, reach_m, shift).map_or(Verdict::NotAssessed, |r| r.verdict())
}

/// (distance, fell) of `controller` on `terrain` in a run's `walks.csv` rows.
fn walk_of(walks: &[WalkRow], terrain: &str, controller: &str) -> Result<(f64, bool), Error> {
    walks
        .iter()
        .find(|r| r.terrain == terrain && r.controller == controller)
        .map(|r| (r.distance_m, r.fell != 0))
        .ok_or_else(|| Error::Other(format!("walks.csv: no {controller} on {terrain}")))
}

/// The flat-then-hill track of a run, from its `rule` table.
pub(super) fn track_of(tables: &Tables) -> Terrain {
    let get = |k: &str, default: f64| rule_setting(tables, k).unwrap_or(default);
    Terrain::FlatThenHill {
        start_m: get("hill_start_m", f64::NAN),
        degrees: get("incline_degrees", f64::NAN),
        smoothing_m: get("hill_smoothing_m", 0.5),
    }
}

pub(super) fn report(dir: &Path) -> Result<Findings, Error> {
    let rule = rule_settings(dir)?;
    let weights: Vec<WeightRow> = read_rows(&dir.join("weights.csv"))?;
    let track: Vec<(f64, f64)> = weights
        .iter()
        .filter(|r| r.terrain == "flat_then_hill")
        .map(|r| (r.x_m, r.alpha_hill))
        .collect();
    let walks: Vec<WalkRow> = read_rows(&dir.join("walks.csv"))?;
    let (start, margin) = (rule("hill_start_m"), rule("margin_m"));
    let (af, ah) = part_means(&track, start - margin, start + margin);
    let facts = WalkingFacts {
        flat_on_incline: walk_of(&walks, "incline", "flat")?,
        hill_on_incline: walk_of(&walks, "incline", "hill")?,
        lbc_on_track: walk_of(&walks, "flat_then_hill", "lbc")?,
        flat_on_track: walk_of(&walks, "flat_then_hill", "flat")?,
        hill_on_track: walk_of(&walks, "flat_then_hill", "hill")?,
        alpha_flat_part: af,
        alpha_hill_part: ah,
    };
    let (adv, climb, shift) = (rule("advance_fraction"), rule("climb_m"), rule("shift"));
    let Some(walk_rule) = walking_rule(&facts, adv, start + climb, shift) else {
        return Err(crate::experiment::other(
            "lbc_walking: a null passes a check of the rule (the flat walker alone walks the track, or fixed weights shift)",
        ));
    };
    let verdict = walk_rule.verdict();
    let mut md = String::from(
        "| terrain | controller | distance (m) | fell | mean speed (m/s) | steps |\n| --- | --- | --- | --- | --- | --- |\n",
    );
    for r in &walks {
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} |\n",
            r.terrain,
            r.controller,
            sig(r.distance_m),
            if r.fell != 0 {
                format!("yes, at {} s", sig(r.fell_at_s))
            } else {
                "no".into()
            },
            sig(r.mean_speed_m_s),
            r.steps
        ));
    }
    let sweep: Vec<SweepRow> = read_rows(&dir.join("lambda_sweep.csv"))?;
    md.push_str("\nLBC at every temperature tried (`lambda_sweep.csv`; distance in m, a cross when it fell; α_hill's mean on the track's flat and hill parts):\n\n| λ | flat | incline | flat-then-hill | α_hill, flat part | α_hill, hill part |\n| --- | --- | --- | --- | --- | --- |\n");
    let mut lambdas: Vec<f64> = sweep.iter().map(|r| r.lambda).collect();
    lambdas.dedup();
    for l in lambdas {
        let at = |terrain: &str| sweep.iter().find(|r| r.lambda == l && r.terrain == terrain);
        let cell = |terrain: &str| {
            at(terrain).map_or("–".to_string(), |r| {
                format!(
                    "{}{}",
                    sig(r.distance_m),
                    if r.fell != 0 { " ✗" } else { "" }
                )
            })
        };
        let track = at("flat_then_hill");
        let g = |x: fn(&SweepRow) -> f64| track.map_or("–".to_string(), |r| sig(x(r)));
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} |\n",
            sig(l),
            cell("flat"),
            cell("incline"),
            cell("flat_then_hill"),
            g(|r| r.alpha_hill_flat_part),
            g(|r| r.alpha_hill_hill_part)
        ));
    }
    let why = format!(
        "On the flat-then-hill track LBC (λ = {lam}) walks {ld} m{lfall}, its weight of the hill walker {af} on the flat part and {ah} on the hill; alone, the hill walker walks the track {htd} m and the flat walker {ftd} m; on the {deg}° incline the flat walker {flat_alone} and the hill walker walks {hd} m ({hf}).{lines} Rule (ours, fixed in the spec; the spec's history gives what changed after results): {text} The hill walker is the grid point of `search.csv` that walks furthest up the incline; λ is the smallest of the sweep at which LBC walks all three terrains without falling. Value functions: the cost of the time-varying LQR that tracks each walker's own periodic gait on its own ground over the next {h} s, in coordinates that include the ground's slope (src/control/gait_value.rs).",
        deg = sig(rule("incline_degrees")),
        hd = sig(facts.hill_on_incline.0),
        hf = if facts.hill_on_incline.1 { "fell" } else { "standing" },
        lam = sig(rule("lambda")),
        ld = sig(facts.lbc_on_track.0),
        ah = sig(ah),
        af = sig(af),
        h = sig(rule("horizon_s")),
        lfall = if facts.lbc_on_track.1 { " and falls" } else { " without falling" },
        flat_alone = if facts.flat_on_incline.1 {
            format!("falls after {} m (the paper: it does not fall)", sig(facts.flat_on_incline.0))
        } else {
            format!("stays up, covering {} m", sig(facts.flat_on_incline.0))
        },
        htd = sig(facts.hill_on_track.0),
        ftd = sig(facts.flat_on_track.0),
        lines = walk_rule.lines(),
        text = walk_rule.text(),
    );
    Ok(Findings {
        ours: md,
        verdict,
        rule: Some(walk_rule.clone()),
        why,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn facts(flat: (f64, bool), lbc: (f64, bool), af: f64, ah: f64) -> WalkingFacts {
        WalkingFacts {
            flat_on_incline: flat,
            hill_on_incline: (10.0, false),
            lbc_on_track: lbc,
            flat_on_track: (5.0, true),
            hill_on_track: (11.0, false),
            alpha_flat_part: af,
            alpha_hill_part: ah,
        }
    }

    #[test]
    fn the_rule_needs_a_standing_flat_walker_the_climb_the_shift_and_the_hill_walkers_reach() {
        let v = |f: &WalkingFacts| verdict_of(f, 0.25, 7.0, 0.25);
        // The paper's story: the flat walker stands but stalls, LBC climbs, weights shift.
        assert_eq!(
            v(&facts((1.0, false), (12.0, false), 0.1, 0.8)),
            Verdict::Held
        );
        // The flat walker falls on the incline: the paper's premise is not ours.
        assert_eq!(
            v(&facts((1.0, true), (12.0, false), 0.1, 0.8)),
            Verdict::PremiseNotReproduced
        );
        // The hill walker alone walks farther than LBC: partly.
        assert_eq!(
            v(&facts((1.0, false), (9.0, false), 0.1, 0.8)),
            Verdict::Partly
        );
        // Weights that do not shift, or an LBC that falls short: not held.
        assert_eq!(
            v(&facts((1.0, false), (12.0, false), 0.4, 0.6)),
            Verdict::NotHeld
        );
        assert_eq!(
            v(&facts((1.0, false), (6.0, true), 0.1, 0.8)),
            Verdict::NotHeld
        );
        // A flat walker that climbs (premise): untested.
        assert_eq!(
            v(&facts((9.0, false), (12.0, false), 0.1, 0.8)),
            Verdict::PremiseNotReproduced
        );
        // A flat walker that walks the track alone passes (a): the rule is refused.
        let mut f = facts((1.0, false), (12.0, false), 0.1, 0.8);
        f.flat_on_track = (8.0, false);
        assert!(walking_rule(&f, 0.25, 7.0, 0.25).is_none());
    }
}
