//! Parallel hill climbing over a box, and the ranked-set batch step it shares with the
//! mass-spring search of [`crate::synthesis::hill_climb`].
//!
//! Iteration t proposes a batch of b perturbations of the current point x,
//! y_p = Π(x + σ_t h ⊙ z_p) with z_p ~ N(0, I), h the half-widths of the box and Π the
//! projection onto it; the batch is evaluated in parallel and its best proposal replaces x if
//! it is strictly better (ties go to the earliest proposal). The step adapts:
//! σ_{t+1} = min(grow σ_t, step) after an improvement, shrink σ_t otherwise.
//!
//! This is [`climb_batch`] on a ranked set of one point: proposal i (numbered 1, 2, … across
//! batches) draws from its own stream [`iteration_rng`]`(seed, i)`, and the proposals are
//! inserted in order of i, so the result does not depend on the number of threads.

use super::{
    check_setting, rank_value, start_point, Budget, SearchProblem, SearchResult, Spent, Tracker,
};
use crate::control::ControlError;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;
use std::ops::Range;

/// The random stream of initial sample `j`: ChaCha8 seeded with `seed`, stream j.
pub fn init_rng(seed: u64, j: usize) -> ChaCha8Rng {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    r.set_stream(j as u64);
    r
}

/// The random stream of iteration (proposal) `i` ≥ 1: ChaCha8 seeded with `seed`, stream
/// 2⁴⁰ + i.
pub fn iteration_rng(seed: u64, i: usize) -> ChaCha8Rng {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    r.set_stream((1u64 << 40) + i as u64);
    r
}

/// Inserts `(c, v)` into the ranked set `set` (highest score first) after any equal score,
/// then deletes the lowest-ranked member.
pub fn insert_by_rank<T>(set: &mut Vec<(T, f64)>, c: T, v: f64) {
    let pos = set.partition_point(|(_, w)| *w >= v);
    set.insert(pos, (c, v));
    set.pop();
}

/// One batch of parallel hill climbing on a ranked set (highest `score` first, non-empty):
/// proposal i ∈ `proposals` draws, from [`iteration_rng`]`(seed, i)`, a parent uniformly from
/// `set` as it stands at the start of the batch and `perturb`s it; the proposals are scored in
/// parallel, then inserted by rank ([`insert_by_rank`]) in order of i. Returns their scores in
/// order of i.
pub fn climb_batch<T, F, P>(
    set: &mut Vec<(T, f64)>,
    score: &F,
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
            let v = score(&c);
            (c, v)
        })
        .collect();
    let mut scores = Vec::with_capacity(evaluated.len());
    for (c, v) in evaluated {
        scores.push(v);
        insert_by_rank(set, c, v);
    }
    scores
}

/// Settings of [`hill_climb`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClimbConfig {
    /// Proposals per iteration b (evaluated in parallel).
    pub batch: usize,
    /// Initial and largest step σ, in half-widths of the box.
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
    fn validate(&self) -> Result<(), ControlError> {
        check_setting("batch", self.batch as f64, 1.0, f64::MAX, true)?;
        check_setting("step", self.step, 0.0, f64::MAX, false)?;
        check_setting("shrink", self.shrink, 0.0, 1.0, false)?;
        check_setting("grow", self.grow, 1.0, f64::MAX, true)
    }
}

/// Parallel hill climbing minimizing `problem` from `x0` (projected onto the box) within
/// `budget`; needs only the objective.
pub fn hill_climb<P: SearchProblem + ?Sized>(
    problem: &P,
    x0: &[f64],
    cfg: &ClimbConfig,
    seed: u64,
    budget: &Budget,
) -> Result<SearchResult, ControlError> {
    cfg.validate()?;
    let bx = problem.search_box();
    let x = start_point(bx, x0)?;
    let mut tr = Tracker::new(budget, x.len(), Spent::default())?;
    let f0 = problem.evaluate(&x);
    tr.evaluated(&x, f0);
    let mut set = vec![(x, -rank_value(f0))];
    let mut stop = tr.close(0, -set[0].1);
    let mut sigma = cfg.step;
    let mut t = 0;
    let score = |y: &Vec<f64>| -rank_value(problem.evaluate(y));
    while stop.is_none() {
        t += 1;
        let before = set[0].1;
        let s = sigma;
        let perturb = |rng: &mut ChaCha8Rng, x: &Vec<f64>| {
            let mut y = x.clone();
            for (i, y) in y.iter_mut().enumerate() {
                let z: f64 = rng.sample(StandardNormal);
                *y += s * bx.half_width(i) * z;
            }
            bx.project(&mut y);
            y
        };
        let first = (t - 1) * cfg.batch + 1;
        climb_batch(&mut set, &score, &perturb, seed, first..first + cfg.batch);
        tr.count(cfg.batch);
        if set[0].1 > before {
            tr.offer(&set[0].0, -set[0].1);
            sigma = (sigma * cfg.grow).min(cfg.step);
        } else {
            sigma *= cfg.shrink;
        }
        stop = tr.close(t, -set[0].1);
    }
    Ok(tr.finish(stop.expect("the loop ends on a stop reason")))
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
    fn hill_climbing_minimizes_rosenbrock_in_a_box() {
        let p = Checked::new(Rosenbrock::new());
        let cfg = ClimbConfig::default();
        let r = hill_climb(&p, &[-1.5, 1.8], &cfg, 3, &Budget::evaluations(4000)).unwrap();
        check_trace(&p, &r);
        assert_eq!(r.stop, StopReason::Evaluations);
        assert!(r.best_value < 0.05, "{}", r.best_value);
        assert!((r.trace[0].best - 26.5).abs() < 1e-9);
    }

    #[test]
    fn climb_batch_inserts_proposals_in_order() {
        // A set of one, proposals scored by their stream index: the last is best.
        let mut set = vec![(0usize, 0.0)];
        let scores = climb_batch(
            &mut set,
            &|c: &usize| *c as f64,
            &|rng: &mut ChaCha8Rng, _: &usize| rng.get_stream() as usize - (1 << 40),
            1,
            3..6,
        );
        assert_eq!(scores, vec![3.0, 4.0, 5.0]);
        assert_eq!(set, vec![(5, 5.0)]);
        let mut set: Vec<(u8, f64)> = vec![(0, 5.0), (1, 3.0), (2, 1.0)];
        insert_by_rank(&mut set, 3, 3.0);
        assert_eq!(set, vec![(0, 5.0), (1, 3.0), (3, 3.0)]);
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
