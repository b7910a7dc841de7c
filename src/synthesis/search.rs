//! # Searching reflex controllers (Christensen, Marks, Ngo 1995, §2.3, Fig. 4 and 6)
//!
//! The paper's parallel hill climbing and our simulated-annealing baseline, run by the shared
//! search library ([`crate::control::search`]) over reflex controllers: the proposal operator
//! is the perturbation mix of Table 2 ([`ReflexPerturbation`]; it has no step size), the
//! initial set is N random controllers drawn from streams 0 … N − 1
//! ([`random_controllers`]), and the library minimizes −objective (the paper maximizes).
//!
//! - Hill climbing ([`hill_climb`]): a search set of N controllers, I perturb–evaluate–insert
//!   iterations evaluated in batches ([`mod@crate::control::search::hill_climb`] explains why the
//!   result does not depend on the thread count, and that batch 1 is the paper's loop).
//! - Simulated annealing ([`anneal`]): starts from the best of the same N random controllers
//!   (same streams, so both methods spend the same evaluations) and cools geometrically from
//!   T_0 to T_1 (in units of the robust spread of the initial objectives) over the I
//!   iterations.
//!
//! [`learning_curve`] turns a result back into the paper's terms: every evaluation with its
//! iteration number (0 for the initial set, then 1 … I) and the objective, larger is better.

use super::controller::Controller;
use super::free::{random_free_controllers, FreeController, FreePerturbation};
use super::perturb::{perturb_with, random_controller, PerturbationMix};
use crate::control::search::{
    anneal_from, climb_from, init_rng, AnnealingConfig, Budget, ClimbConfig, Evaluation, Geometric,
    Perturb, SearchResult, TraceRow,
};
use crate::control::ControlError;
use rand_chacha::ChaCha8Rng;

/// The perturbation mix (Table 2 by default) as a search operator (its size is fixed: the
/// step size a search passes is ignored).
#[derive(Debug, Clone, Copy, Default)]
pub struct ReflexPerturbation {
    /// The kinds' probabilities.
    pub mix: PerturbationMix,
}

impl Perturb<Controller> for ReflexPerturbation {
    fn perturb(&self, rng: &mut ChaCha8Rng, c: &Controller, _scale: f64) -> Controller {
        perturb_with(rng, c, &self.mix).0
    }
}

/// `n` random controllers with `regimes` regimes and period `period`, controller j drawn from
/// stream j ([`init_rng`]).
pub fn random_controllers(n: usize, regimes: usize, period: f64, seed: u64) -> Vec<Controller> {
    (0..n)
        .map(|j| random_controller(&mut init_rng(seed, j), regimes, period))
        .collect()
}

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
    /// Perturbation probabilities (Table 2 in the paper).
    pub mix: PerturbationMix,
}

/// Settings of simulated annealing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnnealConfig {
    /// Random controllers evaluated first (the start is the best of them).
    pub initial: usize,
    /// Iterations (one evaluation each).
    pub iterations: usize,
    /// Initial temperature τ_0 as a multiple of the initial objectives' robust spread.
    pub start_temperature: f64,
    /// Final temperature τ_1, same unit.
    pub end_temperature: f64,
    /// Regimes C per controller.
    pub regimes: usize,
    /// Period t_per (s).
    pub period: f64,
    /// Perturbation probabilities (Table 2 in the paper).
    pub mix: PerturbationMix,
}

/// Parallel hill climbing maximizing `evaluate`; `progress(done)` is called after each batch
/// with the number of iterations done.
pub fn hill_climb<F>(
    evaluate: &F,
    cfg: &HillClimbConfig,
    seed: u64,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<SearchResult<Controller>, ControlError>
where
    F: Fn(&Controller) -> f64 + Sync,
{
    let n = cfg.set_size.max(1);
    let starts = random_controllers(n, cfg.regimes, cfg.period, seed);
    climb_set(
        evaluate,
        &ReflexPerturbation { mix: cfg.mix },
        starts,
        cfg,
        seed,
        progress,
    )
}

/// Parallel hill climbing of free rest-length controllers ([`super::free`]) with the same set,
/// iterations, batches and perturbation mix as [`hill_climb`]; `springs` entries per vector.
pub fn hill_climb_free<F>(
    evaluate: &F,
    cfg: &HillClimbConfig,
    springs: usize,
    seed: u64,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<SearchResult<FreeController>, ControlError>
where
    F: Fn(&FreeController) -> f64 + Sync,
{
    let n = cfg.set_size.max(1);
    let starts = random_free_controllers(n, cfg.regimes, cfg.period, springs, seed);
    climb_set(
        evaluate,
        &FreePerturbation { mix: cfg.mix },
        starts,
        cfg,
        seed,
        progress,
    )
}

/// The hill climb of [`hill_climb`] from a given initial set, maximizing `evaluate`.
fn climb_set<T, F, P>(
    evaluate: &F,
    operator: &P,
    starts: Vec<T>,
    cfg: &HillClimbConfig,
    seed: u64,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<SearchResult<T>, ControlError>
where
    T: Clone + Send + Sync,
    F: Fn(&T) -> f64 + Sync,
    P: Perturb<T>,
{
    let n = starts.len();
    let budget = Budget::evaluations(n + cfg.iterations);
    let observe = |row: &TraceRow| progress(row.evaluations.saturating_sub(n));
    climb_from(
        &|c: &T| -evaluate(c),
        operator,
        starts,
        &ClimbConfig::fixed_step(cfg.batch.max(1)),
        seed,
        &budget,
        Some(&observe),
    )
}

/// Simulated annealing maximizing `evaluate`; `progress(done)` is called after each iteration.
pub fn anneal<F>(
    evaluate: &F,
    cfg: &AnnealConfig,
    seed: u64,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<SearchResult<Controller>, ControlError>
where
    F: Fn(&Controller) -> f64 + Sync,
{
    let n = cfg.initial.max(1);
    let starts = random_controllers(n, cfg.regimes, cfg.period, seed);
    let settings = AnnealingConfig {
        initial_samples: 0,
        temperature: Geometric::over(cfg.start_temperature, cfg.end_temperature, cfg.iterations),
        step: Geometric::constant(1.0),
    };
    let observe = |row: &TraceRow| progress(row.evaluations.saturating_sub(n));
    anneal_from(
        &|c: &Controller| -evaluate(c),
        &ReflexPerturbation { mix: cfg.mix },
        starts,
        &settings,
        seed,
        &Budget::iterations(cfg.iterations),
        Some(&observe),
    )
}

/// The evaluations of a controller search in the paper's terms: `iteration` 0 for the initial
/// set, then the iteration (proposal) number 1 … I; `value` the objective and `best` the best
/// objective so far (larger is better).
pub fn learning_curve<T>(r: &SearchResult<T>) -> Vec<Evaluation> {
    let initial = r.evaluations.iter().filter(|e| e.iteration == 0).count();
    r.evaluations
        .iter()
        .enumerate()
        .map(|(n, e)| Evaluation {
            iteration: if e.iteration == 0 { 0 } else { n + 1 - initial },
            value: -e.value,
            best: -e.best,
        })
        .collect()
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

    fn in_pool<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(f)
    }

    #[test]
    fn hill_climbing_is_deterministic_across_thread_counts_and_improves() {
        for batch in [1, 8] {
            let cfg = HillClimbConfig {
                set_size: 20,
                iterations: 500,
                batch,
                regimes: 3,
                period: 1.0,
                mix: PerturbationMix::TABLE_2,
            };
            let run = |threads| in_pool(threads, || hill_climb(&toy, &cfg, 42, &|_| {}).unwrap());
            let (a, b) = (run(1), run(2));
            assert_eq!(a.best, b.best);
            let (ca, cb) = (learning_curve(&a), learning_curve(&b));
            assert_eq!(ca, cb);
            assert_eq!(ca.len(), 20 + 500);
            assert_eq!(ca.last().unwrap().iteration, 500);
            assert!(ca[20..]
                .iter()
                .enumerate()
                .all(|(k, e)| e.iteration == k + 1));
            let init_best = ca[19].best;
            let best = -a.best_value;
            assert!(best > init_best + 0.5, "{best} vs {init_best}");
            // Best-so-far is monotone and ends at the best controller's objective.
            assert!(ca.windows(2).all(|w| w[1].best >= w[0].best));
            assert_eq!(ca.last().unwrap().best, best);
            assert_eq!(toy(&a.best), best);
        }
    }

    #[test]
    fn annealing_improves_and_is_reproducible() {
        let cfg = AnnealConfig {
            initial: 20,
            iterations: 800,
            start_temperature: 0.5,
            end_temperature: 0.005,
            regimes: 3,
            period: 1.0,
            mix: PerturbationMix::TABLE_2,
        };
        let a = anneal(&toy, &cfg, 9, &|_| {}).unwrap();
        let b = in_pool(2, || anneal(&toy, &cfg, 9, &|_| {}).unwrap());
        let (ca, cb) = (learning_curve(&a), learning_curve(&b));
        assert_eq!(ca, cb);
        assert_eq!(ca.len(), 820);
        assert_eq!(ca[819].iteration, 800);
        let best = -a.best_value;
        assert!(best > ca[19].best + 0.5);
        assert!(best <= 6.0 + 1e-12);
        assert_eq!(toy(&a.best), best);
    }

    #[test]
    fn a_shorter_climb_is_a_prefix_of_a_longer_one() {
        // `ms_search_settings` reads the iteration count off one long run's best-so-far curve:
        // that is valid only if a run of I iterations equals the first I of a longer run.
        let cfg = |iterations| HillClimbConfig {
            set_size: 12,
            iterations,
            batch: 8,
            regimes: 3,
            period: 1.0,
            mix: PerturbationMix::ONE_REGIME_ONLY,
        };
        let short = learning_curve(&hill_climb(&toy, &cfg(37), 5, &|_| {}).unwrap());
        let long = learning_curve(&hill_climb(&toy, &cfg(200), 5, &|_| {}).unwrap());
        assert_eq!(short.len(), 12 + 37);
        assert_eq!(short[..], long[..short.len()]);
        // The free representation's climb too.
        let free = |c: &FreeController| {
            c.regimes
                .iter()
                .map(|r| r.alpha * r.vector[0] - (r.time - 0.5).abs())
                .sum::<f64>()
        };
        let fs = hill_climb_free(&free, &cfg(37), 4, 5, &|_| {}).unwrap();
        let fl = hill_climb_free(&free, &cfg(200), 4, 5, &|_| {}).unwrap();
        let (cs, cl) = (learning_curve(&fs), learning_curve(&fl));
        assert_eq!(cs[..], cl[..cs.len()]);
        assert!(
            -fl.best_value > cl[11].best + 0.5,
            "the free climb improves"
        );
    }

    #[test]
    fn progress_counts_iterations_after_the_initial_set() {
        let cfg = HillClimbConfig {
            set_size: 4,
            iterations: 10,
            batch: 4,
            regimes: 2,
            period: 1.0,
            mix: PerturbationMix::TABLE_2,
        };
        let seen = std::sync::Mutex::new(Vec::new());
        hill_climb(&toy, &cfg, 1, &|done| seen.lock().unwrap().push(done)).unwrap();
        assert_eq!(seen.into_inner().unwrap(), vec![0, 4, 8, 10]);
    }
}
