//! Simulated annealing, generic over the proposal operator (the gradient-free baseline of
//! NeuroAnimator §6 and of our mass-spring learning plot).
//!
//! Initialization (iteration 0): the candidate starts are evaluated (in parallel); the search
//! starts from the first best of them, and the temperature scale is their spread
//! s = [`robust_scale`] of the values. Iteration k ≥ 1 (stream [`iteration_rng`]`(seed, k)`)
//! proposes y = perturb(x, σ_k) and accepts it by the Metropolis rule for minimization,
//! J(y) ≤ J(x) or u < exp(−(J(y) − J(x)) / T_k) with u ~ U(0, 1), where temperature and step
//! follow geometric schedules ([`Geometric`]),
//!
//! ```text
//! T_k = s · T_1 · r_T^((k − 1)/S_T),      σ_k = σ_1 · r_σ^((k − 1)/S_σ).
//! ```
//!
//! Non-finite proposals are never accepted (unless the current point is non-finite too).
//! [`anneal_from`] takes any starts and operator; [`anneal`] is the box form: the starts are
//! x_0 and `initial_samples` perturbed copies Π(x_0 + σ_1 h ⊙ z_j) (stream j, [`init_rng`]).
//!
//! ## References
//! - S. Kirkpatrick, C. D. Gelatt, M. P. Vecchi, *Optimization by simulated annealing*,
//!   Science 220, 1983.

use super::{
    check_setting, init_rng, iteration_rng, rank_value, start_point, Budget, Perturb, Progress,
    SearchProblem, SearchResult, Tracker,
};
use crate::control::ControlError;
use rand::Rng;

/// A robust standard deviation of `v`: 1.4826 × the median absolute deviation (a few
/// failed simulations scored with a huge penalty must not set a temperature scale); 1 when
/// that is zero or not finite.
pub fn robust_scale(v: &[f64]) -> f64 {
    let median = |mut x: Vec<f64>| -> f64 {
        x.sort_by(f64::total_cmp);
        let n = x.len();
        if n == 0 {
            0.0
        } else if n % 2 == 1 {
            x[n / 2]
        } else {
            0.5 * (x[n / 2 - 1] + x[n / 2])
        }
    };
    let m = median(v.to_vec());
    let mad = median(v.iter().map(|x| (x - m).abs()).collect());
    let s = 1.4826 * mad;
    if s.is_finite() && s > 0.0 {
        s
    } else {
        1.0
    }
}

/// A geometric schedule x_k = start · ratio^((k − 1) / span), k = 1, 2, … (it keeps falling
/// past a planned length).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometric {
    /// x_1.
    pub start: f64,
    /// The factor over `span` iterations.
    pub ratio: f64,
    /// Iterations over which the value changes by `ratio`.
    pub span: f64,
}

impl Geometric {
    /// From `start` at iteration 1 to `end` at iteration `iterations` (at least 2).
    pub fn over(start: f64, end: f64, iterations: usize) -> Self {
        Self {
            start,
            ratio: end / start,
            span: (iterations.max(2) - 1) as f64,
        }
    }

    /// From `start`, multiplied by `factor` every iteration.
    pub fn per_iteration(start: f64, factor: f64) -> Self {
        Self {
            start,
            ratio: factor,
            span: 1.0,
        }
    }

    /// The constant `value`.
    pub fn constant(value: f64) -> Self {
        Self::per_iteration(value, 1.0)
    }

    /// `scale` · x_k (k ≥ 1), computed as (scale · start) · ratio^((k − 1) / span).
    pub fn at(&self, scale: f64, k: usize) -> f64 {
        scale * self.start * crate::portable::powf(self.ratio, (k - 1) as f64 / self.span)
    }

    fn validate(&self, what: &'static str) -> Result<(), ControlError> {
        check_setting(what, self.start, 0.0, f64::MAX, false)?;
        check_setting(what, self.ratio, 0.0, f64::MAX, false)?;
        check_setting(what, self.span, 0.0, f64::MAX, false)
    }
}

/// Settings of [`anneal_from`] and [`anneal`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnnealingConfig {
    /// Perturbed copies of the start point evaluated first to measure the objective's spread
    /// (box form [`anneal`] only: [`anneal_from`] is given its starts).
    pub initial_samples: usize,
    /// Temperature T_k in units of that spread.
    pub temperature: Geometric,
    /// Proposal step size σ_k, in the operator's unit (half-widths of a box).
    pub step: Geometric,
}

impl Default for AnnealingConfig {
    /// 8 spread samples, T_1 = 0.5 spread cooling by 0.99 per iteration, σ_1 = 0.1 half-widths
    /// cooling by 0.998.
    fn default() -> Self {
        Self {
            initial_samples: 8,
            temperature: Geometric::per_iteration(0.5, 0.99),
            step: Geometric::per_iteration(0.1, 0.998),
        }
    }
}

impl AnnealingConfig {
    fn validate(&self) -> Result<(), ControlError> {
        self.temperature.validate("temperature")?;
        self.step.validate("step")
    }
}

/// Simulated annealing minimizing `objective` from the best of `starts` (evaluated in
/// parallel) with proposals from `operator`, within `budget`; `progress` sees every row.
pub fn anneal_from<T, F, P>(
    objective: &F,
    operator: &P,
    starts: Vec<T>,
    cfg: &AnnealingConfig,
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
    // The first of the lowest values.
    let start = (0..values.len()).fold(0, |s, j| if values[j] < values[s] { j } else { s });
    let spread = robust_scale(&values);
    let mut fx = values[start];
    let mut x = starts.into_iter().nth(start).expect("start indexes starts");
    let mut stop = tr.close(0, fx);
    let mut k = 0;
    while stop.is_none() {
        k += 1;
        let mut rng = iteration_rng(seed, k);
        let y = operator.perturb(&mut rng, &x, cfg.step.at(1.0, k));
        let fy = rank_value(objective(&y));
        tr.evaluated(&y, fy);
        let u: f64 = rng.random();
        if fy <= fx || u < crate::portable::exp(-(fy - fx) / cfg.temperature.at(spread, k)) {
            x = y;
            fx = fy;
        }
        stop = tr.close(k, fx);
    }
    Ok(tr.finish(stop.expect("the loop ends on a stop reason")))
}

/// Simulated annealing minimizing a box `problem` from `x0` (projected onto the box) and
/// `initial_samples` perturbed copies, within `budget`; needs only the objective.
pub fn anneal<P: SearchProblem + ?Sized>(
    problem: &P,
    x0: &[f64],
    cfg: &AnnealingConfig,
    seed: u64,
    budget: &Budget,
) -> Result<SearchResult, ControlError> {
    let bx = problem.search_box();
    let x = start_point(bx, x0)?;
    let sigma = cfg.step.at(1.0, 1);
    let copies = (0..cfg.initial_samples).map(|j| bx.perturb(&mut init_rng(seed, j), &x, sigma));
    let starts: Vec<Vec<f64>> = std::iter::once(x.clone()).chain(copies).collect();
    anneal_from(
        &|v: &Vec<f64>| problem.evaluate(v),
        bx,
        starts,
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

    #[test]
    fn annealing_improves_a_shifted_sphere_reproducibly() {
        let cfg = AnnealingConfig {
            temperature: Geometric::over(0.5, 0.5e-4, 2000),
            step: Geometric::over(0.2, 0.01, 2000),
            ..AnnealingConfig::default()
        };
        let run = || {
            let p = Checked::new(ShiftedSphere::new(10));
            let r = anneal(&p, &[-0.8; 10], &cfg, 11, &Budget::iterations(2000)).unwrap();
            check_trace(&p, &r);
            assert_eq!(p.calls(), 9 + 2000);
            r
        };
        let a = run();
        let b = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap()
            .install(run);
        assert_eq!(untimed(&a.trace), untimed(&b.trace));
        assert_eq!(a.best, b.best);
        assert_eq!(a.stop, StopReason::Iterations);
        let f0 = a.trace[0].current;
        assert!(a.best_value < 1e-2 * f0, "{} from {f0}", a.best_value);
        // A different seed gives a different path.
        let p = ShiftedSphere::new(10);
        let c = anneal(&p, &[-0.8; 10], &cfg, 12, &Budget::iterations(2000)).unwrap();
        assert_ne!(untimed(&a.trace), untimed(&c.trace));
    }

    #[test]
    fn annealing_minimizes_rosenbrock_in_a_box() {
        let cfg = AnnealingConfig {
            temperature: Geometric::over(0.5, 0.5e-5, 3000),
            step: Geometric::over(0.1, 0.005, 3000),
            ..AnnealingConfig::default()
        };
        let p = Checked::new(Rosenbrock::new());
        let budget = Budget::evaluations(3009);
        let r = anneal(&p, &[-1.5, 1.8], &cfg, 5, &budget).unwrap();
        check_trace(&p, &r);
        assert_eq!(r.stop, StopReason::Evaluations);
        assert_eq!(p.calls(), 3009);
        assert!(r.best_value < 0.1, "{}", r.best_value);
    }

    #[test]
    fn a_zero_second_budget_stops_after_the_initialization() {
        let p = ShiftedSphere::new(3);
        let r = anneal(
            &p,
            &[0.0; 3],
            &AnnealingConfig::default(),
            1,
            &Budget::seconds(0.0),
        )
        .unwrap();
        assert_eq!(r.trace.len(), 1);
        assert_eq!(r.stop, StopReason::Seconds);
        assert_eq!(r.trace[0].evaluations, 9);
    }

    #[test]
    fn geometric_schedules_hit_their_ends() {
        let g = Geometric::over(2.0, 0.02, 101);
        assert_eq!(g.at(1.0, 1), 2.0);
        assert!((g.at(1.0, 101) - 0.02).abs() < 1e-15);
        assert!((g.at(3.0, 51) - 0.6).abs() < 1e-14);
        let p = Geometric::per_iteration(1.0, 0.5);
        assert_eq!(p.at(1.0, 4), 0.125);
        assert_eq!(Geometric::constant(0.3).at(1.0, 1000), 0.3);
    }

    #[test]
    fn robust_scale_ignores_outliers() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0, -1.0e6];
        let s = robust_scale(&v);
        assert!(s > 1.0 && s < 4.0, "{s}");
        assert_eq!(robust_scale(&[2.0, 2.0]), 1.0);
    }
}
