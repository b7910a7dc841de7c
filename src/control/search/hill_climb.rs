//! Parallel hill climbing on a ranked set, generic over the proposal operator (the search of
//! Christensen, Marks, Ngo 1995, Fig. 4; a baseline of NeuroAnimator §6).
//!
//! The paper's loop, on a search set S of N points ranked by J (best first):
//!
//! ```text
//! initialize S with N starting points; rank S
//! for i = 1 … I:
//!     pick a point of S uniformly at random; perturb it and evaluate it
//!     insert it into S by rank; delete the lowest-ranked point of S
//! return the best point of S
//! ```
//!
//! ## Batching, step size and determinism
//!
//! Iteration t evaluates a batch of b consecutive proposals in parallel with rayon
//! ([`climb_batch`]). Proposal i (numbered 1, 2, … across batches) draws everything it needs
//! (the parent's rank in S, the perturbation) from its own ChaCha8 stream
//! [`iteration_rng`]`(seed, i)`. All proposals of a batch pick their parents from S as it
//! stood at the start of the batch; they are evaluated in parallel, then inserted into S one
//! by one in order of i, exactly as the sequential loop would insert them. So:
//!
//! - with b = 1 this *is* the paper's sequential loop;
//! - with b > 1 the only difference is that a proposal cannot descend from another proposal
//!   of the same batch (parents are at most b − 1 insertions stale);
//! - the result depends on the seed and the settings, never on the number of threads.
//!
//! Ties in rank go to the point that was in S first (a new point is inserted after equal
//! ones), so a proposal equal to the worst is the one deleted. The operator's step size
//! adapts: σ_{t+1} = min(grow σ_t, step) after a batch that improved the best point, shrink σ_t
//! otherwise (grow = shrink = 1 keeps it fixed, as the mass-spring operator is). The last
//! batch is cut to the evaluation limit of the budget.
//!
//! [`climb_from`] takes any starting set and operator; [`hill_climb`] is the box form: a set of
//! one, the start point, with Gaussian steps scaled to the box.

use super::{
    check_setting, iteration_rng, rank_value, start_point, Budget, Perturb, Progress,
    SearchProblem, SearchResult, Tracker,
};
use crate::control::ControlError;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::ops::Range;

/// Inserts `(c, v)` into the ranked set `set` (lowest value first) after any equal value, then
/// deletes the lowest-ranked (last) member.
pub fn insert_by_rank<T>(set: &mut Vec<(T, f64)>, c: T, v: f64) {
    let pos = set.partition_point(|(_, w)| *w <= v);
    set.insert(pos, (c, v));
    set.pop();
}

/// One batch of parallel hill climbing on a ranked set (lowest value first, non-empty):
/// proposal i ∈ `proposals` draws, from [`iteration_rng`]`(seed, i)`, a parent uniformly from
/// `set` as it stands at the start of the batch and `perturb`s it; the proposals are evaluated
/// in parallel (non-finite values rank last), then inserted by rank ([`insert_by_rank`]) in
/// order of i. Returns their values in order of i.
pub fn climb_batch<T, F, P>(
    set: &mut Vec<(T, f64)>,
    objective: &F,
    perturb: &P,
    seed: u64,
    proposals: Range<usize>,
) -> Vec<f64>
where
    T: Send + Sync,
    F: Fn(&T) -> f64 + Sync,
    P: Fn(&mut ChaCha8Rng, &T) -> T + Sync,
{
    let snapshot = &*set;
    let evaluated: Vec<(T, f64)> = proposals
        .into_par_iter()
        .map(|i| {
            let mut rng = iteration_rng(seed, i);
            let parent = rng.random_range(0..snapshot.len());
            let c = perturb(&mut rng, &snapshot[parent].0);
            let v = rank_value(objective(&c));
            (c, v)
        })
        .collect();
    let mut values = Vec::with_capacity(evaluated.len());
    for (c, v) in evaluated {
        values.push(v);
        insert_by_rank(set, c, v);
    }
    values
}

/// Settings of [`climb_from`] and [`hill_climb`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClimbConfig {
    /// Proposals per iteration b (evaluated in parallel).
    pub batch: usize,
    /// Initial and largest step σ, in the operator's unit (half-widths of a box).
    pub step: f64,
    /// Step factor after an iteration without improvement, in (0, 1].
    pub shrink: f64,
    /// Step factor after an improvement, ≥ 1.
    pub grow: f64,
}

impl Default for ClimbConfig {
    /// 8 proposals of σ = 0.2 half-widths, shrinking by 0.7 on failure, growing by 1.3 on
    /// success.
    fn default() -> Self {
        Self {
            batch: 8,
            step: 0.2,
            shrink: 0.7,
            grow: 1.3,
        }
    }
}

impl ClimbConfig {
    /// Batches of `batch` proposals of an operator with a fixed size (σ = 1 throughout).
    pub fn fixed_step(batch: usize) -> Self {
        Self {
            batch,
            step: 1.0,
            shrink: 1.0,
            grow: 1.0,
        }
    }

    fn validate(&self) -> Result<(), ControlError> {
        check_setting("batch", self.batch as f64, 1.0, f64::MAX, true)?;
        check_setting("step", self.step, 0.0, f64::MAX, false)?;
        check_setting("shrink", self.shrink, 0.0, 1.0, false)?;
        check_setting("grow", self.grow, 1.0, f64::MAX, true)
    }
}

/// Parallel hill climbing minimizing `objective` on the ranked set of `starts` (evaluated in
/// parallel) with proposals from `operator`, within `budget`; `progress` sees every row.
pub fn climb_from<T, F, P>(
    objective: &F,
    operator: &P,
    starts: Vec<T>,
    cfg: &ClimbConfig,
    seed: u64,
    budget: &Budget,
    progress: Option<Progress<'_>>,
) -> Result<SearchResult<T>, ControlError>
where
    T: Clone + Send + Sync,
    F: Fn(&T) -> f64 + Sync,
    P: Perturb<T> + ?Sized,
{
    cfg.validate()?;
    let mut tr = Tracker::for_starts(budget, &starts)?.with_progress(progress);
    let values = tr.evaluate_starts(&starts, objective);
    let mut set: Vec<(T, f64)> = starts.into_iter().zip(values).collect();
    // Rank: the stable sort keeps the initial order among ties.
    set.sort_by(|a, b| a.1.total_cmp(&b.1));
    let mut stop = tr.close(0, set[0].1);
    let mut sigma = cfg.step;
    let mut t = 0;
    while stop.is_none() {
        t += 1;
        let before = set[0].1;
        let s = sigma;
        let perturb = |rng: &mut ChaCha8Rng, x: &T| operator.perturb(rng, x, s);
        let first = (t - 1) * cfg.batch + 1;
        let size = tr.allowance(cfg.batch);
        for v in climb_batch(&mut set, objective, &perturb, seed, first..first + size) {
            tr.counted(v);
        }
        if set[0].1 < before {
            tr.offer(&set[0].0, set[0].1);
            sigma = (sigma * cfg.grow).min(cfg.step);
        } else {
            sigma *= cfg.shrink;
        }
        stop = tr.close(t, set[0].1);
    }
    Ok(tr.finish(stop.expect("the loop ends on a stop reason")))
}

/// Parallel hill climbing minimizing a box `problem` from `x0` (projected onto the box; a set
/// of one) within `budget`; needs only the objective.
pub fn hill_climb<P: SearchProblem + ?Sized>(
    problem: &P,
    x0: &[f64],
    cfg: &ClimbConfig,
    seed: u64,
    budget: &Budget,
) -> Result<SearchResult, ControlError> {
    let bx = problem.search_box();
    let x = start_point(bx, x0)?;
    climb_from(
        &|v: &Vec<f64>| problem.evaluate(v),
        bx,
        vec![x],
        cfg,
        seed,
        budget,
        None,
    )
}

#[cfg(test)]
mod tests {
    use super::super::test_problems::*;
    use super::super::StopReason;
    use super::*;

    fn run(threads: usize, batch: usize) -> (SearchResult, usize) {
        let p = Checked::new(ShiftedSphere::new(10));
        let cfg = ClimbConfig {
            batch,
            ..ClimbConfig::default()
        };
        let r = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| hill_climb(&p, &[-0.8; 10], &cfg, 7, &Budget::iterations(100)))
            .unwrap();
        check_trace(&p, &r);
        (r, p.calls())
    }

    #[test]
    fn hill_climbing_improves_a_shifted_sphere_the_same_on_any_thread_count() {
        let (a, calls) = run(1, 8);
        let (b, _) = run(2, 8);
        assert_eq!(untimed(&a.trace), untimed(&b.trace));
        assert_eq!(a.best, b.best);
        assert_eq!(calls, 1 + 100 * 8);
        assert_eq!(a.trace.len(), 101);
        assert_eq!(a.stop, StopReason::Iterations);
        let f0 = a.trace[0].best;
        assert!(a.best_value < 1e-3 * f0, "{} from {f0}", a.best_value);
        // The hill climber's point is its best point.
        assert!(a.trace.iter().all(|r| r.current == r.best));
    }

    #[test]
    fn hill_climbing_minimizes_rosenbrock_in_a_box_within_the_exact_evaluation_limit() {
        let p = Checked::new(Rosenbrock::new());
        let cfg = ClimbConfig::default();
        let r = hill_climb(&p, &[-1.5, 1.8], &cfg, 3, &Budget::evaluations(4000)).unwrap();
        check_trace(&p, &r);
        assert_eq!(r.stop, StopReason::Evaluations);
        // 1 + 499 batches of 8 + a last batch cut to 7.
        assert_eq!(p.calls(), 4000);
        assert!(r.best_value < 0.05, "{}", r.best_value);
        assert!((r.trace[0].best - 26.5).abs() < 1e-9);
    }

    #[test]
    fn a_ranked_set_climbs_like_the_sequential_loop_for_batch_one() {
        // Points are integers, the objective their distance to 40, the operator ±1..3; a set
        // of 5 starts. Batch 1 and batch 4 both improve and agree on any thread count.
        struct Step;
        impl Perturb<i64> for Step {
            fn perturb(&self, rng: &mut ChaCha8Rng, x: &i64, _: f64) -> i64 {
                x + rng.random_range(-3..=3)
            }
        }
        let f = |x: &i64| (x - 40).abs() as f64;
        let starts = vec![0, 3, -2, 7, 1];
        for batch in [1, 4] {
            let cfg = ClimbConfig::fixed_step(batch);
            let go = |threads: usize| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap()
                    .install(|| {
                        climb_from(
                            &f,
                            &Step,
                            starts.clone(),
                            &cfg,
                            9,
                            &Budget::evaluations(405),
                            None,
                        )
                    })
                    .unwrap()
            };
            let (a, b) = (go(1), go(2));
            assert_eq!(a.evaluations, b.evaluations);
            assert_eq!(a.evaluations.len(), 405);
            assert_eq!(a.best, 40, "batch {batch}");
            assert_eq!(a.best_value, 0.0);
            assert!(a.evaluations.windows(2).all(|w| w[1].best <= w[0].best));
        }
    }

    #[test]
    fn climb_batch_inserts_proposals_in_order() {
        // A set of one, proposals valued by minus their stream index: the last is best.
        let mut set = vec![(0usize, 0.0)];
        let values = climb_batch(
            &mut set,
            &|c: &usize| -(*c as f64),
            &|rng: &mut ChaCha8Rng, _: &usize| rng.get_stream() as usize - (1 << 40),
            1,
            3..6,
        );
        assert_eq!(values, vec![-3.0, -4.0, -5.0]);
        assert_eq!(set, vec![(5, -5.0)]);
        let mut set: Vec<(u8, f64)> = vec![(0, 1.0), (1, 3.0), (2, 5.0)];
        insert_by_rank(&mut set, 3, 3.0);
        assert_eq!(set, vec![(0, 1.0), (1, 3.0), (3, 3.0)]);
        insert_by_rank(&mut set, 4, 0.0);
        assert_eq!(set, vec![(4, 0.0), (0, 1.0), (1, 3.0)]);
    }

    #[test]
    fn invalid_settings_are_reported() {
        let p = ShiftedSphere::new(2);
        let bad = ClimbConfig {
            shrink: 1.5,
            ..ClimbConfig::default()
        };
        assert_eq!(
            hill_climb(&p, &[0.0; 2], &bad, 1, &Budget::iterations(1)).unwrap_err(),
            ControlError::InvalidSetting {
                what: "shrink",
                value: 1.5
            }
        );
        assert!(matches!(
            hill_climb(
                &p,
                &[0.0; 3],
                &ClimbConfig::default(),
                1,
                &Budget::iterations(1)
            ),
            Err(ControlError::DimensionMismatch { .. })
        ));
    }
}
