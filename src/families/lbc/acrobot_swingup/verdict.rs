//! The verdict rule: success counts over the start-state sweep, on all starts and where both
//! trackers fail, and the spec's grade of them.

use super::setup::POLICIES;
use crate::experiment::rule::{Check, Cmp, Null, Partly, Rule, RuleError};

/// Counts over the start-state sweep: per policy successes, and on the subset where both
/// trackers fail.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SweepCounts {
    /// Starts in the sweep.
    pub starts: usize,
    /// Starts where both trackers fail.
    pub both_fail: usize,
    /// Successes over the whole sweep, per policy (in `POLICIES` order).
    pub successes: Vec<usize>,
    /// Successes on the both-fail subset, per policy.
    pub rescued: Vec<usize>,
}

/// [`SweepCounts`] from per-start success flags `ok[start][policy]` (policies in `POLICIES`
/// order).
pub fn sweep_counts(ok: &[Vec<bool>]) -> SweepCounts {
    let np = ok.first().map_or(0, |r| r.len());
    let mut c = SweepCounts {
        starts: ok.len(),
        successes: vec![0; np],
        rescued: vec![0; np],
        ..Default::default()
    };
    for r in ok {
        let both_fail = !r[0] && !r[1];
        c.both_fail += both_fail as usize;
        for (p, &s) in r.iter().enumerate() {
            c.successes[p] += s as usize;
            c.rescued[p] += (s && both_fail) as usize;
        }
    }
    c
}

/// The premise of the spec's rule on sweep counts `c`: swing-ups of one family (aligned
/// examples), and starts where both torque-limited trackers fail (null: trackers that swing up
/// from every start).
pub fn premise_checks(c: &SweepCounts, same_family: bool) -> Result<Vec<Check>, RuleError> {
    Ok(vec![
        Check::fact("swing-ups of one family (aligned examples)", same_family),
        Check::new(
            "sweep starts where both torque-limited trackers fail",
            c.both_fail as f64,
            Cmp::AtLeast,
            1.0,
            Null::new("trackers that swing up from every start", 0.0),
        )?,
    ])
}

/// The sweep's checks of the spec's rule on counts `c`: (1) LBC swings up from at least
/// `partly_fraction` and (2) `held_fraction` of the starts where both trackers fail (null:
/// the trackers alone, 0); (3) from more of them than the better naive blend (null: that blend
/// itself); (4) from more sweep starts than the better tracker (null: that tracker itself).
/// The partly fraction was set after seeing results (the spec's history).
pub fn sweep_checks(
    c: &SweepCounts,
    held_fraction: f64,
    partly_fraction: f64,
) -> Vec<Result<Check, RuleError>> {
    let (t1, t2, nv, lbc, ns) = (0, 1, 2, 3, 4);
    let better_tracker = c.successes[t1].max(c.successes[t2]);
    let rescued = c.rescued[lbc];
    let naive = c.rescued[nv].max(c.rescued[ns]);
    let share = rescued as f64 / c.both_fail.max(1) as f64;
    let none = |label: &str| Null::new(label, 0.0);
    vec![
        Check::new(
            "share of the both-fail sweep starts LBC swings up from (partly)",
            share,
            Cmp::AtLeast,
            partly_fraction,
            none("the trackers alone"),
        ),
        Check::new(
            "share of the both-fail sweep starts LBC swings up from (held)",
            share,
            Cmp::AtLeast,
            held_fraction,
            none("the trackers alone"),
        ),
        Check::new(
            "both-fail sweep starts LBC swings up from beyond the better naive blend's",
            rescued as f64 - naive as f64,
            Cmp::Above,
            0.0,
            none("the better naive blend itself"),
        ),
        Check::new(
            "sweep starts LBC swings up from over the better tracker's",
            c.successes[lbc] as f64 / better_tracker.max(1) as f64,
            Cmp::Above,
            1.0,
            Null::new("the better tracker itself", 1.0),
        ),
    ]
}

/// The spec's rule on the sweep alone (the value models' table, which has no test start):
/// [`premise_checks`] and [`sweep_checks`], partly on (1).
pub fn sweep_rule(
    c: &SweepCounts,
    same_family: bool,
    held_fraction: f64,
    partly_fraction: f64,
) -> Option<Rule> {
    let premise = premise_checks(c, same_family).ok()?;
    let held = sweep_checks(c, held_fraction, partly_fraction);
    Rule::gated(premise, held, Partly::All(vec![0]))
}

/// The tracker-setting rule (ours, written in the spec before the run): of the trials
/// `(scale, tracker 1's final distance, tracker 2's)` from the test start, in the order tried,
/// the index of the first where each tracker alone fails (distance not below `success`; a
/// diverged loop's NaN or infinite distance fails); `None` when at every scale one succeeds.
pub fn choose_scale(trials: &[(f64, f64, f64)], success: f64) -> Option<usize> {
    trials
        .iter()
        .position(|&(_, d1, d2)| !(d1 < success) && !(d2 < success))
}

/// The paper's claim at the test start (ours, written in the spec): LBC ends within `success`
/// of the handstand and closer than both naive blends (average `naive`, paper's sum `sum`;
/// a diverged blend's NaN or infinite distance is beaten by any finite one).
pub fn judge_test_start(lbc: f64, naive: f64, sum: f64, success: f64) -> bool {
    let beats = |other: f64| other.is_nan() || lbc < other;
    lbc < success && beats(naive) && beats(sum)
}

/// Per-start success flags (in `POLICIES` order) of a long table's rows `(θ1, θ2, policy,
/// success)`, starts in order of first appearance.
pub(super) fn start_flags<'a>(
    rows: impl IntoIterator<Item = (f64, f64, &'a str, bool)>,
) -> Vec<Vec<bool>> {
    let mut starts: Vec<(f64, f64)> = Vec::new();
    let mut flags: Vec<Vec<bool>> = Vec::new();
    for (a, b, p, s) in rows {
        let key = (a, b);
        let i = match starts.iter().position(|&k| k == key) {
            Some(i) => i,
            None => {
                starts.push(key);
                flags.push(vec![false; POLICIES.len()]);
                starts.len() - 1
            }
        };
        if let Some(pi) = POLICIES.iter().position(|&q| q == p) {
            flags[i][pi] = s;
        }
    }
    flags
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::report::Verdict;

    /// Counts over a 121-start sweep with 26 starts where both trackers fail; per policy
    /// (tracker1, tracker2, naive, lbc, naive_sum) successes overall and on those 26.
    fn counts(successes: [usize; 5], rescued: [usize; 5]) -> SweepCounts {
        SweepCounts {
            starts: 121,
            both_fail: 26,
            successes: successes.to_vec(),
            rescued: rescued.to_vec(),
        }
    }

    fn grade(c: &SweepCounts, same_family: bool) -> Verdict {
        sweep_rule(c, same_family, 0.5, 0.25).unwrap().verdict()
    }

    #[test]
    fn lbc_rescuing_few_starts_is_not_partly_held() {
        // The committed sweep's counts: LBC rescues 2 of 26, the naive sum 7, though LBC
        // covers more starts overall than the better tracker (84 vs 66).
        let c = counts([46, 66, 28, 84, 41], [0, 0, 1, 2, 7]);
        assert_eq!(grade(&c, true), Verdict::NotHeld);
        // One rescue of 26 is no clear share, even with no naive rescue.
        let c = counts([46, 66, 28, 84, 41], [0, 0, 0, 1, 0]);
        assert_eq!(grade(&c, true), Verdict::NotHeld);
    }

    #[test]
    fn a_clear_share_is_partly_and_half_beating_the_naive_blends_held() {
        let c = counts([46, 66, 28, 84, 41], [0, 0, 1, 8, 8]);
        assert_eq!(grade(&c, true), Verdict::Partly);
        let c = counts([46, 66, 28, 84, 41], [0, 0, 1, 13, 7]);
        assert_eq!(grade(&c, true), Verdict::Held);
        // Held also needs the swing-ups of one family and LBC to cover the better tracker.
        assert_eq!(grade(&c, false), Verdict::PremiseNotReproduced);
        let c = counts([46, 66, 28, 60, 41], [0, 0, 1, 13, 7]);
        assert_eq!(grade(&c, true), Verdict::Partly);
        // No start where both trackers fail: the premise fails.
        let c = SweepCounts {
            both_fail: 0,
            rescued: vec![0; 5],
            ..counts([46, 66, 28, 84, 41], [0; 5])
        };
        assert_eq!(grade(&c, true), Verdict::PremiseNotReproduced);
    }
}
