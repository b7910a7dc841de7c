//! # Parallel hill climbing (Christensen, Marks, Ngo 1995, §2.3, Fig. 4)
//!
//! The paper's loop, on a search set S of N controllers ranked by objective (best first):
//!
//! ```text
//! initialize S with N random controllers; rank S
//! for i = 1 … I:
//!     pick a controller of S uniformly at random; perturb it (Table 2) and evaluate it
//!     insert it into S by rank; delete the lowest-ranked controller of S
//! return the best controller of S
//! ```
//!
//! ## Batching and determinism
//!
//! Evaluations (each a full simulation over T) run in parallel with rayon in batches of
//! `batch` consecutive iterations ([`climb_batch`], shared with the box searches). Iteration i draws everything it needs (the parent's rank
//! in S, the perturbation kind and its values) from its own ChaCha8 stream: seed `seed`,
//! stream 2⁴⁰ + i (the initial controller j uses stream j). All proposals of a batch pick
//! their parents from S as it stood at the start of the batch; the proposals are evaluated
//! in parallel, then inserted into S one by one in iteration order, exactly as the
//! sequential loop would insert them. So:
//!
//! - with `batch = 1` this *is* the paper's sequential loop;
//! - with `batch = b` the only difference is that a proposal cannot descend from another
//!   proposal of the same batch (parents are at most b − 1 insertions stale);
//! - the result depends on `(seed, batch)` only, never on the number of threads, because each
//!   iteration's randomness comes from its own stream and insertion order is fixed.
//!
//! Ties in rank go to the controller that was in S first (a new controller is inserted after
//! equal ones), so a proposal equal to the worst is the one deleted.

use super::controller::Controller;
use super::perturb::{perturb, random_controller};
use crate::control::search::climb_batch;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// Settings of parallel hill climbing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HillClimbConfig {
    /// Size N of the search set (the paper: 100).
    pub set_size: usize,
    /// Iterations I: perturb-evaluate-insert steps after initialization (the paper: 25,000).
    pub iterations: usize,
    /// Iterations evaluated in parallel per batch (1: the sequential loop).
    pub batch: usize,
    /// Regimes C per controller.
    pub regimes: usize,
    /// Period t_per (s).
    pub period: f64,
}

/// One evaluation of a search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Evaluation {
    /// Iteration (0 for the evaluations of the initial controllers).
    pub iteration: usize,
    /// Objective of the evaluated controller.
    pub objective: f64,
    /// Best objective found so far, this evaluation included.
    pub best: f64,
}

/// What a search returns.
#[derive(Debug, Clone)]
pub struct SearchResult {
    /// The best controller found.
    pub best: Controller,
    /// Its objective.
    pub best_value: f64,
    /// Every evaluation in order.
    pub trace: Vec<Evaluation>,
    /// The final search set, best first, with objectives (hill climbing; for simulated
    /// annealing the final current controller).
    pub set: Vec<(Controller, f64)>,
}

/// The random streams of initial controller `j` (also used by simulated annealing) and of
/// iteration `i` ≥ 1, and the ranked insertion: shared with the box searches of
/// [`crate::control::search`].
pub use crate::control::search::{init_rng, insert_by_rank, iteration_rng};

/// `n` random controllers from streams 0..n, evaluated in parallel; returned in order.
pub fn initial_set<F>(
    evaluate: &F,
    n: usize,
    regimes: usize,
    period: f64,
    seed: u64,
) -> Vec<(Controller, f64)>
where
    F: Fn(&Controller) -> f64 + Sync,
{
    (0..n)
        .into_par_iter()
        .map(|j| {
            let c = random_controller(&mut init_rng(seed, j), regimes, period);
            let v = evaluate(&c);
            (c, v)
        })
        .collect()
}

/// Runs parallel hill climbing maximizing `evaluate`; `progress(done)` is called after each
/// batch with the number of iterations done.
pub fn hill_climb<F>(
    evaluate: &F,
    cfg: &HillClimbConfig,
    seed: u64,
    progress: &(dyn Fn(usize) + Sync),
) -> SearchResult
where
    F: Fn(&Controller) -> f64 + Sync,
{
    let n = cfg.set_size.max(1);
    let init = initial_set(evaluate, n, cfg.regimes, cfg.period, seed);
    let mut trace = Vec::with_capacity(n + cfg.iterations);
    let mut best = f64::NEG_INFINITY;
    for (_, v) in &init {
        best = best.max(*v);
        trace.push(Evaluation {
            iteration: 0,
            objective: *v,
            best,
        });
    }
    let mut set = init;
    // Rank: stable sort keeps the initial order among ties.
    set.sort_by(|a, b| b.1.total_cmp(&a.1));
    let batch = cfg.batch.max(1);
    let mut i0 = 1;
    while i0 <= cfg.iterations {
        let i1 = (i0 + batch).min(cfg.iterations + 1);
        let scores = climb_batch(
            &mut set,
            evaluate,
            &|rng: &mut ChaCha8Rng, c: &Controller| perturb(rng, c).0,
            seed,
            i0..i1,
        );
        for (k, v) in scores.into_iter().enumerate() {
            best = best.max(v);
            trace.push(Evaluation {
                iteration: i0 + k,
                objective: v,
                best,
            });
        }
        progress(i1 - 1);
        i0 = i1;
    }
    SearchResult {
        best: set[0].0.clone(),
        best_value: set[0].1,
        trace,
        set,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthesis::controller::Regime;

    /// A cheap synthetic objective over controllers: prefer reflex 5 with α = 1 at times
    /// near 0.3 t_per.
    fn toy(c: &Controller) -> f64 {
        c.regimes
            .iter()
            .map(|r: &Regime| {
                (if r.reflex == 5 { 1.0 } else { 0.0 }) + r.alpha - (r.time / c.period - 0.3).abs()
            })
            .sum()
    }

    fn cfg(batch: usize) -> HillClimbConfig {
        HillClimbConfig {
            set_size: 20,
            iterations: 500,
            batch,
            regimes: 3,
            period: 1.0,
        }
    }

    fn run_in_pool(threads: usize, batch: usize) -> SearchResult {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| hill_climb(&toy, &cfg(batch), 42, &|_| {}))
    }

    #[test]
    fn insert_by_rank_keeps_order_and_size() {
        let c = Controller {
            period: 1.0,
            regimes: vec![Regime {
                time: 0.0,
                reflex: 0,
                alpha: 0.0,
            }],
        };
        let mut set: Vec<(Controller, f64)> =
            [5.0, 3.0, 1.0].iter().map(|&v| (c.clone(), v)).collect();
        insert_by_rank(&mut set, c.clone(), 4.0);
        assert_eq!(
            set.iter().map(|s| s.1).collect::<Vec<_>>(),
            vec![5.0, 4.0, 3.0]
        );
        insert_by_rank(&mut set, c.clone(), 0.0);
        assert_eq!(
            set.iter().map(|s| s.1).collect::<Vec<_>>(),
            vec![5.0, 4.0, 3.0]
        );
        insert_by_rank(&mut set, c, 9.0);
        assert_eq!(
            set.iter().map(|s| s.1).collect::<Vec<_>>(),
            vec![9.0, 5.0, 4.0]
        );
    }

    #[test]
    fn deterministic_across_thread_counts_and_improves() {
        for batch in [1, 8] {
            let a = run_in_pool(1, batch);
            let b = run_in_pool(2, batch);
            assert_eq!(a.best, b.best);
            assert_eq!(a.trace, b.trace);
            assert_eq!(a.trace.len(), 20 + 500);
            let init_best = a.trace[19].best;
            assert!(
                a.best_value > init_best + 0.5,
                "{} vs {init_best}",
                a.best_value
            );
            // Best-so-far is monotone and ends at the best of the set.
            assert!(a.trace.windows(2).all(|w| w[1].best >= w[0].best));
            assert_eq!(a.trace.last().unwrap().best, a.best_value);
            assert!(a.set.windows(2).all(|w| w[0].1 >= w[1].1));
        }
    }
}
