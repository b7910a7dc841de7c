//! The verdict rule: success counts over the start-state sweep, on all starts and where both
//! trackers fail, and the spec's grade of them.

use super::setup::POLICIES;

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

/// The share of the starts where both trackers fail that LBC must rescue for "partly" (ours,
/// issue 56, 2026-11-28: a clear share, a quarter, rather than any one start).
pub const PARTLY_FRACTION: f64 = 0.25;

/// The spec's rule on sweep counts: (held, partly). Held: same-family swing-ups, LBC succeeds
/// on at least `held_fraction` of the starts where both trackers fail and on more of them than
/// either naive blend, and over the whole sweep on at least as many starts as the better
/// tracker. Partly (rewritten 2026-11-28 after seeing the committed results, issue 56; it was
/// "LBC rescues a start where both trackers fail, or covers more starts than the better
/// tracker"): LBC rescues at least [`PARTLY_FRACTION`] of the starts where both trackers fail
/// and at least as many of them as the better naive blend (average or sum), so that the naive
/// blend doing better contradicts it.
pub fn judge(c: &SweepCounts, same_family: bool, held_fraction: f64) -> (bool, bool) {
    let (t1, t2, nv, lbc, ns) = (0, 1, 2, 3, 4);
    let better_tracker = c.successes[t1].max(c.successes[t2]);
    let rescued = c.rescued[lbc];
    let naive = c.rescued[nv].max(c.rescued[ns]);
    let premise = c.both_fail > 0;
    let share = |f: f64| premise && rescued as f64 >= f * c.both_fail as f64;
    let covers = c.successes[lbc] >= better_tracker;
    let held = same_family && share(held_fraction) && rescued > naive && covers;
    let partly = share(PARTLY_FRACTION) && rescued >= naive;
    (held, partly)
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
pub(super) fn start_flags(a: &[f64], b: &[f64], p: &[String], s: &[f64]) -> Vec<Vec<bool>> {
    let mut starts: Vec<(f64, f64)> = Vec::new();
    let mut flags: Vec<Vec<bool>> = Vec::new();
    for r in 0..a.len() {
        let key = (a[r], b[r]);
        let i = match starts.iter().position(|&k| k == key) {
            Some(i) => i,
            None => {
                starts.push(key);
                flags.push(vec![false; POLICIES.len()]);
                starts.len() - 1
            }
        };
        if let Some(pi) = POLICIES.iter().position(|&q| q == p[r]) {
            flags[i][pi] = s[r] == 1.0;
        }
    }
    flags
}

#[cfg(test)]
mod tests {
    use super::*;

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

    #[test]
    fn lbc_rescuing_few_starts_while_the_naive_sum_rescues_more_is_not_partly_held() {
        // The committed sweep's counts: LBC rescues 2 of 26, the naive sum 7, though LBC
        // covers more starts overall than the better tracker (84 vs 66).
        let c = counts([46, 66, 28, 84, 41], [0, 0, 1, 2, 7]);
        assert_eq!(judge(&c, true, 0.5), (false, false));
        // One rescue of 26 is no clear share, even with no naive rescue.
        let c = counts([46, 66, 28, 84, 41], [0, 0, 0, 1, 0]);
        assert_eq!(judge(&c, true, 0.5), (false, false));
        // A clear share (8 of 26) that the naive sum beats (9) is not partly either.
        let c = counts([46, 66, 28, 84, 41], [0, 0, 1, 8, 9]);
        assert_eq!(judge(&c, true, 0.5), (false, false));
    }

    #[test]
    fn a_clear_share_at_least_the_naive_blends_is_partly_and_half_beating_them_held() {
        let c = counts([46, 66, 28, 84, 41], [0, 0, 1, 8, 8]);
        assert_eq!(judge(&c, true, 0.5), (false, true));
        let c = counts([46, 66, 28, 84, 41], [0, 0, 1, 13, 7]);
        assert_eq!(judge(&c, true, 0.5), (true, true));
        // Held also needs the swing-ups of one family and LBC to cover the better tracker.
        assert_eq!(judge(&c, false, 0.5), (false, true));
        let c = counts([46, 66, 28, 60, 41], [0, 0, 1, 13, 7]);
        assert_eq!(judge(&c, true, 0.5), (false, true));
    }
}
