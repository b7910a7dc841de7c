//! `lbc_jumping`'s verdict and report section.

use super::rows::{JumpComponentRow, JumpRow};
use crate::experiment::output::Table;
use crate::experiment::report::{sig, yes_no, Findings, Verdict};
use crate::experiment::rows::{read_rows, TableRow};
use crate::experiment::rule::{Check, Cmp, Null, Partly, Rule};
use crate::experiment::Error;
use crate::families::lbc::{entropy_section, rule_settings};
use std::path::Path;

/// Jump heights (m, the centre of mass's apex above the crouch's).
#[derive(Debug, Clone, PartialEq)]
pub struct JumpHeights {
    /// The low example's.
    pub low: f64,
    /// The high example's.
    pub high: f64,
    /// Every desired jump's.
    pub desired: Vec<f64>,
}

/// What the rule reads from a run.
#[derive(Debug, Clone, PartialEq)]
pub struct JumpFacts {
    /// Each example's tracker alone: its take-off error against its own target.
    pub examples: [f64; 2],
    /// The examples' jump heights and the desired ones.
    pub heights: JumpHeights,
    /// Whether each desired jump's landing tracker lands from the desired take-off itself.
    pub reference_landed: Vec<bool>,
    /// LBC at every desired jump: (take-off error, landed).
    pub lbc: Vec<(f64, bool)>,
    /// The naive blend likewise.
    pub naive: Vec<(f64, bool)>,
    /// Each example's tracker alone (low, high) at every desired jump, handed to the same
    /// landing trackers.
    pub alone: [Vec<(f64, bool)>; 2],
}

fn landed(v: &[(f64, bool)]) -> usize {
    v.iter().filter(|r| r.1).count()
}

fn mean_error(v: &[(f64, bool)]) -> f64 {
    v.iter().map(|r| r.0).sum::<f64>() / v.len().max(1) as f64
}

/// The verdict's rule with the examples' take-off tolerance `tol`. Premise: each example's
/// tracker reaches its own take-off within `tol`, each desired jump's landing tracker lands from
/// the desired take-off itself, the desired heights lie between the examples', and neither
/// example alone lands every desired jump (else there is nothing to combine). (a) LBC lands
/// every desired jump (null: the better example alone); (b) LBC lands more than the naive
/// blend; (c) LBC's mean take-off error is below the naive blend's and each example's alone.
/// Held: all three; partly: any. `None` when a check the premise should rule out is refused
/// although the premise holds (which would be a bug).
pub fn jump_rule(f: &JumpFacts, tol: f64) -> Option<Rule> {
    let JumpHeights {
        low: lo,
        high: hi,
        ref desired,
    } = f.heights;
    let n = f.lbc.len();
    let best_alone = f.alone.iter().map(|v| landed(v)).max().unwrap_or(0);
    let premise = vec![
        Check::fact(
            format!(
                "each example's tracker alone reaches its own take-off within {}",
                sig(tol)
            ),
            f.examples.iter().all(|&e| e <= tol),
        ),
        Check::fact(
            "each desired jump's landing tracker lands from the desired take-off itself",
            !f.reference_landed.is_empty() && f.reference_landed.iter().all(|&l| l),
        ),
        Check::fact(
            format!(
                "the desired heights lie between the examples' {} m and {} m",
                sig(lo),
                sig(hi)
            ),
            desired.iter().all(|&h| h > lo && h < hi),
        ),
        Check::new(
            "desired jumps the better example alone lands",
            best_alone as f64,
            Cmp::Below,
            n as f64,
            Null::new("a controller that lands them all", n as f64),
        )
        .ok()?,
    ];
    let others = f
        .alone
        .iter()
        .map(|v| mean_error(v))
        .fold(mean_error(&f.naive), f64::min);
    let held = vec![
        Check::new(
            "desired jumps LBC lands",
            landed(&f.lbc) as f64,
            Cmp::AtLeast,
            n as f64,
            Null::new("the better example alone", best_alone as f64),
        ),
        Check::new(
            "desired jumps LBC lands beyond the naive blend's",
            landed(&f.lbc) as f64 - landed(&f.naive) as f64,
            Cmp::Above,
            0.0,
            Null::new("the naive blend itself", 0.0),
        ),
        Check::new(
            "LBC's mean take-off error over the lowest of the naive blend's and each example's alone",
            mean_error(&f.lbc) / others,
            Cmp::Below,
            1.0,
            Null::new("the best of the naive blend and the examples alone", 1.0),
        ),
    ];
    Rule::gated(premise, held, Partly::Any)
}

/// The verdict of `f` (not assessed where [`jump_rule`] cannot be built).
pub fn verdict_of(f: &JumpFacts, tol: f64) -> Verdict {
    jump_rule(f, tol).map_or(Verdict::NotAssessed, |r| r.verdict())
}

/// `jumps.csv`'s rows, with the rows of one take-off controller picked out.
pub(super) struct Jumps(pub(super) Vec<JumpRow>);

impl Jumps {
    fn read(dir: &Path) -> Result<Self, Error> {
        Ok(Self(read_rows(&dir.join("jumps.csv"))?))
    }

    pub(super) fn of(t: &Table) -> Self {
        Self(JumpRow::from_table(t))
    }

    pub(super) fn rows<'a>(&'a self, method: &'a str) -> impl Iterator<Item = &'a JumpRow> + 'a {
        self.0.iter().filter(move |r| r.method == method)
    }

    fn outcomes(&self, method: &str) -> Vec<(f64, bool)> {
        self.rows(method)
            .map(|r| (r.takeoff_error, r.landed != 0.0))
            .collect()
    }
}

pub(super) fn report(dir: &Path) -> Result<Findings, Error> {
    let rule = rule_settings(dir)?;
    let tol = rule("takeoff_tolerance");
    let t = Jumps::read(dir)?;
    let comp: Vec<JumpComponentRow> = read_rows(&dir.join("components.csv"))?;
    let own = |i: usize| comp.get(i).map_or(f64::INFINITY, |c| c.takeoff_error);
    let facts = JumpFacts {
        examples: [own(0), own(1)],
        heights: JumpHeights {
            low: rule("low_height_m"),
            high: rule("high_height_m"),
            desired: t.rows("lbc").map(|r| r.desired_height_m).collect(),
        },
        reference_landed: t.rows("reference").map(|r| r.landed != 0.0).collect(),
        lbc: t.outcomes("lbc"),
        naive: t.outcomes("naive"),
        alone: [t.outcomes("low"), t.outcomes("high")],
    };
    let Some(jump) = jump_rule(&facts, tol) else {
        return Err(crate::experiment::other(
            "lbc_jumping: a check of the rule is passed by its null although the premise holds",
        ));
    };
    let verdict = jump.verdict();
    let mut md = String::from(
        "| desired height (m) | method | take-off error | speed error (m/s) | height reached (m) | landed | fell | effort |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n",
    );
    for r in &t.0 {
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} |\n",
            sig(r.desired_height_m),
            r.method,
            sig(r.takeoff_error),
            sig(r.speed_error_m_s),
            sig(r.height_m),
            yes_no(Some(r.landed != 0.0)),
            yes_no(Some(r.fell != 0.0)),
            sig(r.effort),
        ));
    }
    md.push_str("\nThe take-off examples (`components.csv`; DDP from the crouch; the take-off error is each tracker alone on the simulator against its own target):\n\n| example | jump height (m) | take-off error | DDP iterations |\n| --- | --- | --- | --- |\n");
    for c in &comp {
        md.push_str(&format!(
            "| {} | {} | {} | {} |\n",
            c.component,
            sig(c.height_m),
            sig(c.takeoff_error),
            c.iterations
        ));
    }
    md.push_str(&entropy_section(
        dir,
        "runs are the desired jump heights; the naive blend's α is its fixed weights",
        "the naive blend",
    )?);
    let n = facts.lbc.len();
    let why = format!(
        "LBC's take-offs land {ll} of {n} desired jumps at mean take-off error {le}, the naive blend's with the same weights {nl} of {n} at {ne}; each example's tracker alone, handed to the same landing trackers, lands {lo_l} (low) and {hi_l} (high) of {n} at mean take-off errors {lo_e} and {hi_e} (examples' own take-off errors {e0} and {e1}; {rl} of {n} landing trackers land their own take-off).{lines} Rule (ours, fixed in the spec; the spec's history gives the rule before): {text} λ = {lam} by §4.1's scale rule; take-off {ts} s, landing {tl} s, then the PD landing holds for {th} s.",
        ll = landed(&facts.lbc),
        lo_l = landed(&facts.alone[0]),
        hi_l = landed(&facts.alone[1]),
        lo_e = sig(mean_error(&facts.alone[0])),
        hi_e = sig(mean_error(&facts.alone[1])),
        nl = landed(&facts.naive),
        le = sig(mean_error(&facts.lbc)),
        ne = sig(mean_error(&facts.naive)),
        e0 = sig(facts.examples[0]),
        e1 = sig(facts.examples[1]),
        rl = facts.reference_landed.iter().filter(|&&l| l).count(),
        lines = jump.lines(),
        text = jump.text(),
        lam = sig(rule("lambda")),
        ts = sig(rule("takeoff_s")),
        tl = sig(rule("landing_s")),
        th = sig(rule("hold_s")),
    );
    Ok(Findings {
        ours: md,
        verdict,
        rule: Some(jump.clone()),
        why,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::rule::Outcome;

    fn facts(lbc_landed: usize, naive_landed: usize, lbc_err: f64, naive_err: f64) -> JumpFacts {
        JumpFacts {
            examples: [0.5, 0.5],
            heights: JumpHeights {
                low: 0.2,
                high: 0.3,
                desired: vec![0.22, 0.25, 0.28],
            },
            reference_landed: vec![true; 3],
            lbc: (0..3).map(|i| (lbc_err, i < lbc_landed)).collect(),
            naive: (0..3).map(|i| (naive_err, i < naive_landed)).collect(),
            alone: [
                (0..3).map(|i| (3.0, i < 1)).collect(),
                (0..3).map(|i| (3.0, i < 2)).collect(),
            ],
        }
    }

    #[test]
    fn the_rule_needs_lbc_to_land_where_the_examples_alone_and_the_naive_blend_do_not() {
        assert_eq!(verdict_of(&facts(3, 1, 0.5, 2.0), 1.0), Verdict::Held);
        let r = jump_rule(&facts(3, 3, 0.5, 2.0), 1.0).unwrap();
        let outcomes: Vec<Outcome> = r.held.iter().map(Check::outcome).collect();
        assert_eq!(outcomes, [Outcome::Pass, Outcome::Fail, Outcome::Pass]);
        assert_eq!(verdict_of(&facts(1, 2, 2.0, 1.0), 1.0), Verdict::NotHeld);
        assert_eq!(verdict_of(&facts(2, 1, 0.5, 2.0), 1.0), Verdict::Partly);
        let mut f = facts(3, 1, 0.5, 2.0);
        f.reference_landed[1] = false;
        assert_eq!(verdict_of(&f, 1.0), Verdict::PremiseNotReproduced);
        let mut f = facts(3, 1, 0.5, 2.0);
        f.examples[0] = 1.5;
        assert_eq!(verdict_of(&f, 1.0), Verdict::PremiseNotReproduced);
        let mut f = facts(3, 1, 0.5, 2.0);
        f.heights.desired[0] = 0.35;
        assert_eq!(
            verdict_of(&f, 1.0),
            Verdict::PremiseNotReproduced,
            "extrapolation"
        );
        // An example alone that lands every desired jump: nothing to combine.
        let mut f = facts(3, 1, 0.5, 2.0);
        f.alone[0] = vec![(1.0, true); 3];
        assert_eq!(verdict_of(&f, 1.0), Verdict::PremiseNotReproduced);
        // An example alone with a lower take-off error than LBC fails (c).
        let mut f = facts(3, 1, 0.5, 2.0);
        f.alone[1] = (0..3).map(|i| (0.4, i < 2)).collect();
        assert_eq!(verdict_of(&f, 1.0), Verdict::Partly);
    }
}
