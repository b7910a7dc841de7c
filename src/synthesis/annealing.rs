//! # Simulated annealing on reflex controllers (baseline for §3, Fig. 6)
//!
//! The same controller space and the same perturbation operator (Table 2) as hill climbing,
//! with a single current controller x and the Metropolis rule for maximization: a proposal
//! y = perturb(x) is accepted when f(y) ≥ f(x), else with probability exp((f(y) − f(x)) / T_k).
//! The temperature falls geometrically over the iterations k = 1 … I,
//!
//! T_k = σ · τ_0 · (τ_1 / τ_0)^((k − 1) / (I − 1)),
//!
//! where σ is a robust standard deviation (1.4826 × median absolute deviation) of the
//! objective over the initial random controllers
//! (so τ_0, τ_1 are dimensionless) — the same N random controllers hill climbing starts from,
//! evaluated with the same streams, so both methods spend the same number of evaluations.
//! Annealing starts from the best of them. Iteration k draws from its own stream (as in
//! [`super::hill_climb`]); the loop is sequential and so the same for any thread count.
//!
//! ## References
//! - S. Kirkpatrick, C. D. Gelatt, M. P. Vecchi, *Optimization by simulated annealing*,
//!   Science 220, 1983.

use super::controller::Controller;
use super::hill_climb::{initial_set, iteration_rng, Evaluation, SearchResult};
use super::perturb::perturb;
use rand::Rng;

/// Settings of simulated annealing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnnealConfig {
    /// Random controllers evaluated first (the start is the best of them).
    pub initial: usize,
    /// Iterations (one evaluation each).
    pub iterations: usize,
    /// Initial temperature τ_0 as a multiple of the initial objectives' standard deviation.
    pub start_temperature: f64,
    /// Final temperature τ_1, same unit.
    pub end_temperature: f64,
    /// Regimes C per controller.
    pub regimes: usize,
    /// Period t_per (s).
    pub period: f64,
}

/// A robust standard deviation of the initial objectives (1.4826 × the median absolute
/// deviation, so a few failed simulations scored [`super::BLOWUP_OBJECTIVE`] do not set the
/// temperature scale); shared with the box annealing of [`crate::control::search`].
pub use crate::control::search::robust_scale;

/// Runs simulated annealing maximizing `evaluate`; `progress(done)` is called every 100
/// iterations.
pub fn anneal<F>(
    evaluate: &F,
    cfg: &AnnealConfig,
    seed: u64,
    progress: &(dyn Fn(usize) + Sync),
) -> SearchResult
where
    F: Fn(&Controller) -> f64 + Sync,
{
    let init = initial_set(evaluate, cfg.initial.max(1), cfg.regimes, cfg.period, seed);
    let mut trace = Vec::with_capacity(init.len() + cfg.iterations);
    let mut best_v = f64::NEG_INFINITY;
    let mut best_c = init[0].0.clone();
    for (c, v) in &init {
        if *v > best_v {
            best_v = *v;
            best_c = c.clone();
        }
        trace.push(Evaluation {
            iteration: 0,
            objective: *v,
            best: best_v,
        });
    }
    let sigma = robust_scale(&init.iter().map(|p| p.1).collect::<Vec<_>>());
    let (mut cur, mut cur_v) = (best_c.clone(), best_v);
    let span = (cfg.iterations.max(2) - 1) as f64;
    for k in 1..=cfg.iterations {
        let temp = sigma
            * cfg.start_temperature
            * (cfg.end_temperature / cfg.start_temperature).powf((k - 1) as f64 / span);
        let mut rng = iteration_rng(seed, k);
        let (y, _) = perturb(&mut rng, &cur);
        let v = evaluate(&y);
        let accept = v >= cur_v || rng.random::<f64>() < ((v - cur_v) / temp).exp();
        if v > best_v {
            best_v = v;
            best_c = y.clone();
        }
        if accept {
            cur = y;
            cur_v = v;
        }
        trace.push(Evaluation {
            iteration: k,
            objective: v,
            best: best_v,
        });
        if k % 100 == 0 || k == cfg.iterations {
            progress(k);
        }
    }
    SearchResult {
        best: best_c,
        best_value: best_v,
        trace,
        set: vec![(cur, cur_v)],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn toy(c: &Controller) -> f64 {
        c.regimes
            .iter()
            .map(|r| (if r.reflex == 5 { 1.0 } else { 0.0 }) + r.alpha)
            .sum()
    }

    #[test]
    fn robust_scale_ignores_outliers() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0, -1.0e6];
        let s = robust_scale(&v);
        assert!(s > 1.0 && s < 4.0, "{s}");
        assert_eq!(robust_scale(&[2.0, 2.0]), 1.0);
    }

    #[test]
    fn anneal_improves_and_is_reproducible() {
        let cfg = AnnealConfig {
            initial: 20,
            iterations: 800,
            start_temperature: 0.5,
            end_temperature: 0.005,
            regimes: 3,
            period: 1.0,
        };
        let a = anneal(&toy, &cfg, 9, &|_| {});
        let b = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap()
            .install(|| anneal(&toy, &cfg, 9, &|_| {}));
        assert_eq!(a.trace, b.trace);
        assert_eq!(a.trace.len(), 820);
        assert!(a.best_value > a.trace[19].best + 0.5);
        assert!(a.best_value <= 6.0 + 1e-12);
        assert_eq!(toy(&a.best), a.best_value);
    }
}
