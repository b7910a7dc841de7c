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

/// The spec's rule on sweep counts: (held, partly). Held: same-family swing-ups, LBC succeeds
/// on at least `held_fraction` of the starts where both trackers fail and on more of them than
/// either naive blend, and over the whole sweep on at least as many starts as the better
/// tracker. Partly: LBC rescues a start where both trackers fail, or covers more starts than
/// the better tracker.
pub fn judge(c: &SweepCounts, same_family: bool, held_fraction: f64) -> (bool, bool) {
    let (t1, t2, nv, lbc, ns) = (0, 1, 2, 3, 4);
    let better_tracker = c.successes[t1].max(c.successes[t2]);
    let rescued = c.rescued[lbc];
    let premise = c.both_fail > 0;
    let enough = premise && rescued as f64 >= held_fraction * c.both_fail as f64;
    let beats_naive = rescued > c.rescued[nv].max(c.rescued[ns]);
    let covers = c.successes[lbc] >= better_tracker;
    let held = same_family && enough && beats_naive && covers;
    let partly = (premise && rescued > 0) || c.successes[lbc] > better_tracker;
    (held, partly)
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
