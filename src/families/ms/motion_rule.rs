//! The verdict of the `ms_motion` family over seeds: each seed's motion measured from its
//! `measures` table ([`MotionFacts`]), the seeds judged together by one rule object
//! ([`motion_rule`]) whose bars are the spec's `[params.rule]`.
//!
//! Per motion, the measure and the conditions that go with each bar:
//!
//! | motion | measure | held also needs | partly also needs |
//! | --- | --- | --- | --- |
//! | leap | centre of mass's travel along +x (m) | upright, off the ground once | upright |
//! | somersault | backward turns | forward travel, on the ground at T, no rolling or turning beyond 45° | forward travel |
//! | pirouette | turn about the vertical (degrees) | upright, a jump, on the ground at T | upright |
//!
//! Held needs the median measure over the seeds at least the held bar (a 95% bootstrap
//! interval that straddles it is inconclusive) and a strict majority of seeds meeting the held
//! bar with its conditions; partly the same at the partly bar. The null of every check is a
//! body at rest: no travel, no turn, on no seed.

use super::rows::MeasureRow;
use super::search::Motion;
use crate::experiment::resolve::{ensure, ParamError};
use crate::experiment::rows::read_rows;
use crate::experiment::rows::Swept;
use crate::experiment::rule::{majority, Check, Cmp, Null, Partly, Rule};
use crate::experiment::stats::{median, median_interval};
use crate::experiment::Error;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

/// The bars of the verdict (ours), in the motion's unit: metres along +x for the leap,
/// backward turns for the somersault, degrees about the vertical for the pirouette.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionRule {
    /// The held bar.
    pub held: f64,
    /// The partly bar (below the held bar).
    pub partly: f64,
}

impl MotionRule {
    /// Both bars positive (a body at rest scores 0 and must fail), partly below held.
    pub fn validate(&self) -> Result<(), ParamError> {
        ensure(
            self.partly > 0.0 && self.partly.is_finite(),
            "rule.partly",
            "must be positive: a body at rest scores 0",
        )?;
        ensure(
            self.held > self.partly && self.held.is_finite(),
            "rule.held",
            "must be above rule.partly",
        )
    }
}

/// A motion's measure with its unit, as the report writes it.
pub fn unit(motion: Motion) -> &'static str {
    match motion {
        Motion::Leap => "travel along +x (m)",
        Motion::Somersault => "backward turns",
        Motion::Pirouette => "turn about the vertical (degrees)",
    }
}

/// One seed's motion: its measure and whether the conditions of each bar hold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionFacts {
    /// The measure, in the motion's unit.
    pub measure: f64,
    /// The conditions that go with the held bar.
    pub held_conditions: bool,
    /// The conditions that go with the partly bar.
    pub partly_conditions: bool,
}

impl MotionFacts {
    /// The facts of `motion` from a run's measures (by name; NaN where missing).
    pub fn from_measures(motion: Motion, mv: impl Fn(&str) -> f64) -> Self {
        let upright = mv("uprightness_loss_60") == 0.0;
        let airborne = mv("hops") >= 1.0 || mv("min_contacts") == 0.0;
        let ground = mv("on_ground") == 1.0;
        match motion {
            Motion::Leap => Self {
                measure: mv("displacement_x"),
                held_conditions: upright && airborne,
                partly_conditions: upright,
            },
            Motion::Somersault => {
                let forward = mv("displacement_x") > 0.0;
                Self {
                    measure: mv("rotation_back_y") / (2.0 * PI),
                    held_conditions: forward && ground && mv("left_right_loss_45") == 0.0,
                    partly_conditions: forward,
                }
            }
            Motion::Pirouette => Self {
                measure: mv("rotation_z").abs().to_degrees(),
                held_conditions: upright && ground && airborne,
                partly_conditions: upright,
            },
        }
    }

    /// Whether it meets the held bar with its conditions.
    pub fn held(&self, r: &MotionRule) -> bool {
        self.measure >= r.held && self.held_conditions
    }

    /// Whether it meets the partly bar with its conditions.
    pub fn partly(&self, r: &MotionRule) -> bool {
        self.measure >= r.partly && self.partly_conditions
    }
}

/// The bootstrap stream of the intervals (any fixed value: the report is the same everywhere).
const BOOTSTRAP_SEED: u64 = 1;

/// The rule over the seeds' `facts` (module docs); `None` without seeds.
pub fn motion_rule(motion: Motion, facts: &[MotionFacts], r: &MotionRule) -> Option<Rule> {
    if facts.is_empty() {
        return None;
    }
    let m: Vec<f64> = facts.iter().map(|f| f.measure).collect();
    let med = median(&m);
    let (_, lo, hi) = median_interval(&m, BOOTSTRAP_SEED);
    let k = facts.len();
    let need = majority(k) as f64;
    let rest = |what: &str| Null::new(format!("a body at rest ({what})"), 0.0);
    let unit = unit(motion);
    let count = |f: &dyn Fn(&MotionFacts) -> bool| facts.iter().filter(|x| f(x)).count() as f64;
    let held = vec![
        Check::new(
            format!("the median over {k} seeds of the {unit}, at the held bar"),
            med,
            Cmp::AtLeast,
            r.held,
            rest("no motion"),
        )
        .map(|c| c.with_interval(lo, hi)),
        Check::new(
            format!("seeds of {k} meeting the held bar with its conditions"),
            count(&|x| x.held(r)),
            Cmp::AtLeast,
            need,
            rest("on no seed"),
        ),
        Check::new(
            format!("the median over {k} seeds of the {unit}, at the partly bar"),
            med,
            Cmp::AtLeast,
            r.partly,
            rest("no motion"),
        )
        .map(|c| c.with_interval(lo, hi)),
        Check::new(
            format!("seeds of {k} meeting the partly bar with its conditions"),
            count(&|x| x.partly(r)),
            Cmp::AtLeast,
            need,
            rest("on no seed"),
        ),
    ];
    Rule::gated(vec![], held, Partly::All(vec![2, 3]))
}

crate::result_rows! {
    /// The seed of a row of the top folder's `measures.csv`, a column the harness adds in a
    /// run over seeds.
    struct SeedRow {
        /// The seed.
        seed: Swept<f64> = "seed",
    }
}

/// The folders holding each seed's tables: `seeds/<seed>/` for every seed of a run over seeds
/// (the top folder's `measures` table has a `seed` column), else the folder itself.
pub fn seed_folders(dir: &Path) -> Result<Vec<(Option<u64>, PathBuf)>, Error> {
    let rows: Vec<SeedRow> = read_rows(&dir.join("measures.csv"))?;
    let Some(column) = rows
        .iter()
        .map(|r| r.seed.0)
        .collect::<Option<Vec<f64>>>()
        .filter(|c| !c.is_empty())
    else {
        return Ok(vec![(None, dir.to_path_buf())]);
    };
    let mut seeds: Vec<u64> = Vec::new();
    for s in column {
        let s = s as u64;
        if !seeds.contains(&s) {
            seeds.push(s);
        }
    }
    Ok(seeds
        .into_iter()
        .map(|s| (Some(s), dir.join("seeds").join(s.to_string())))
        .collect())
}

/// A run folder's measures by name (NaN where missing).
pub fn measures(dir: &Path) -> Result<impl Fn(&str) -> f64, Error> {
    let rows: Vec<MeasureRow> = read_rows(&dir.join("measures.csv"))?;
    Ok(move |n: &str| {
        rows.iter()
            .find(|r| r.measure == n)
            .map_or(f64::NAN, |r| r.value)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::report::Verdict;

    const LEAP: MotionRule = MotionRule {
        held: 1.0,
        partly: 0.3,
    };

    fn leap(measure: f64, airborne: bool) -> MotionFacts {
        MotionFacts {
            measure,
            held_conditions: airborne,
            partly_conditions: true,
        }
    }

    #[test]
    fn the_seeds_are_judged_together_and_one_lucky_seed_is_not_enough() {
        let good: Vec<MotionFacts> = (0..5).map(|i| leap(2.0 + f64::from(i), true)).collect();
        let v = |f: &[MotionFacts]| motion_rule(Motion::Leap, f, &LEAP).unwrap().verdict();
        assert_eq!(v(&good), Verdict::Held);
        // One seed far past the bar, the others at rest: the median and the majority fail.
        let lucky = [leap(10.0, true), leap(0.0, false), leap(0.0, false)];
        assert_eq!(v(&lucky), Verdict::NotHeld);
        // Travelling but never leaving the ground: partly.
        let ground: Vec<MotionFacts> = (0..5).map(|i| leap(2.0 + f64::from(i), false)).collect();
        assert_eq!(v(&ground), Verdict::Partly);
        // Seeds on both sides of the held bar: its median interval straddles it.
        let split = [
            leap(0.5, true),
            leap(0.6, true),
            leap(1.5, true),
            leap(1.6, true),
            leap(0.55, true),
        ];
        let r = motion_rule(Motion::Leap, &split, &LEAP).unwrap();
        assert_eq!(
            r.held[0].outcome(),
            crate::experiment::rule::Outcome::Inconclusive
        );
        assert_eq!(majority(5), 3);
        assert_eq!(majority(4), 3);
    }

    #[test]
    fn bars_at_or_below_rest_are_refused() {
        assert!(LEAP.validate().is_ok());
        assert!(MotionRule {
            held: 1.0,
            partly: 0.0
        }
        .validate()
        .is_err());
        assert!(MotionRule {
            held: 0.3,
            partly: 0.3
        }
        .validate()
        .is_err());
    }

    #[test]
    fn the_facts_read_each_motion_in_its_unit() {
        let mv = |n: &str| match n {
            "rotation_back_y" => PI,
            "rotation_z" => -PI / 2.0,
            "displacement_x" => 0.5,
            "uprightness_loss_60" | "left_right_loss_45" | "min_contacts" => 0.0,
            "on_ground" | "hops" => 1.0,
            _ => f64::NAN,
        };
        let s = MotionFacts::from_measures(Motion::Somersault, mv);
        assert!((s.measure - 0.5).abs() < 1e-12 && s.held_conditions);
        let p = MotionFacts::from_measures(Motion::Pirouette, mv);
        assert!((p.measure - 90.0).abs() < 1e-9 && p.held_conditions);
        let l = MotionFacts::from_measures(Motion::Leap, mv);
        assert!((l.measure - 0.5).abs() < 1e-12 && l.partly(&LEAP) && !l.held(&LEAP));
    }
}
