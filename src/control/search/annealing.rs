//! Simulated annealing over a box (the gradient-free baseline of NeuroAnimator §6).
//!
//! Initialization (iteration 0): the start point x_0 and `initial_samples` points
//! Π(x_0 + σ_1 h ⊙ z_j) (stream j, [`init_rng`]) are evaluated; the search starts from the
//! best of them, and the temperature scale is their spread s = [`robust_scale`] of the values.
//! Iteration k ≥ 1 (stream [`iteration_rng`]`(seed, k)`) proposes
//!
//! ```text
//! y = Π(x + σ_k h ⊙ z),   z ~ N(0, I),   σ_k = step · step_cooling^(k−1)
//! ```
//!
//! (h the half-widths of the box, Π the projection onto it) and accepts it by the Metropolis
//! rule for minimization, f(y) ≤ f(x) or u < exp(−(f(y) − f(x)) / T_k) with u ~ U(0, 1), at
//! the geometrically cooled temperature T_k = start_temperature · s · cooling^(k−1).
//! Non-finite proposals are never accepted (unless the current point is non-finite too).
//!
//! ## References
//! - S. Kirkpatrick, C. D. Gelatt, M. P. Vecchi, *Optimization by simulated annealing*,
//!   Science 220, 1983.

use super::{
    check_setting, init_rng, iteration_rng, rank_value, start_point, Budget, SearchProblem,
    SearchResult, Spent, Tracker,
};
use crate::control::ControlError;
use rand::Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;

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

/// Settings of [`anneal`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnnealingConfig {
    /// Perturbed copies of the start point evaluated first to measure the objective's spread.
    pub initial_samples: usize,
    /// Initial temperature T_1 as a multiple of that spread.
    pub start_temperature: f64,
    /// Temperature factor per iteration, in (0, 1].
    pub cooling: f64,
    /// Initial proposal standard deviation σ_1, in half-widths of the box.
    pub step: f64,
    /// Step factor per iteration, in (0, 1].
    pub step_cooling: f64,
}

impl Default for AnnealingConfig {
    /// 8 spread samples, T_1 = 0.5 spread cooling by 0.99, σ_1 = 0.1 half-widths cooling by
    /// 0.998.
    fn default() -> Self {
        Self {
            initial_samples: 8,
            start_temperature: 0.5,
            cooling: 0.99,
            step: 0.1,
            step_cooling: 0.998,
        }
    }
}

impl AnnealingConfig {
    /// The factor per iteration that takes a quantity from `start` to `end` over `iterations`
    /// iterations (geometric cooling over a planned length).
    pub fn factor_over(start: f64, end: f64, iterations: usize) -> f64 {
        (end / start).powf(1.0 / iterations.max(2).saturating_sub(1) as f64)
    }

    fn validate(&self) -> Result<(), ControlError> {
        check_setting(
            "start temperature",
            self.start_temperature,
            0.0,
            f64::MAX,
            false,
        )?;
        check_setting("cooling", self.cooling, 0.0, 1.0, false)?;
        check_setting("step", self.step, 0.0, f64::MAX, false)?;
        check_setting("step cooling", self.step_cooling, 0.0, 1.0, false)
    }
}

/// Writes Π(x + σ h ⊙ z) into `y`, z drawn from `rng`.
fn propose<R: Rng>(rng: &mut R, bx: &super::SearchBox, x: &[f64], sigma: f64, y: &mut [f64]) {
    for (i, (y, x)) in y.iter_mut().zip(x).enumerate() {
        let z: f64 = rng.sample(StandardNormal);
        *y = x + sigma * bx.half_width(i) * z;
    }
    bx.project(y);
}

/// Simulated annealing minimizing `problem` from `x0` (projected onto the box) within
/// `budget`; needs only the objective. The initial samples are evaluated in parallel, the
/// iterations one after another.
pub fn anneal<P: SearchProblem + ?Sized>(
    problem: &P,
    x0: &[f64],
    cfg: &AnnealingConfig,
    seed: u64,
    budget: &Budget,
) -> Result<SearchResult, ControlError> {
    cfg.validate()?;
    let bx = problem.search_box();
    let x_start = start_point(bx, x0)?;
    let d = x_start.len();
    let mut tr = Tracker::new(budget, d, Spent::default())?;
    let samples: Vec<(Vec<f64>, f64)> = (0..=cfg.initial_samples)
        .into_par_iter()
        .map(|j| {
            let mut y = x_start.clone();
            if j > 0 {
                propose(&mut init_rng(seed, j - 1), bx, &x_start, cfg.step, &mut y);
            }
            let f = problem.evaluate(&y);
            (y, f)
        })
        .collect();
    let mut start = 0;
    for (j, (y, f)) in samples.iter().enumerate() {
        tr.evaluated(y, *f);
        if rank_value(*f) < rank_value(samples[start].1) {
            start = j;
        }
    }
    let values: Vec<f64> = samples.iter().map(|s| s.1).collect();
    let spread = robust_scale(&values);
    let (mut x, mut fx) = (samples[start].0.clone(), rank_value(samples[start].1));
    drop(samples);
    let mut y = vec![0.0; d];
    let mut stop = tr.close(0, fx);
    let (mut temp, mut sigma) = (cfg.start_temperature * spread, cfg.step);
    let mut k = 0;
    while stop.is_none() {
        k += 1;
        let mut rng = iteration_rng(seed, k);
        propose(&mut rng, bx, &x, sigma, &mut y);
        let fy = rank_value(problem.evaluate(&y));
        tr.evaluated(&y, fy);
        let u: f64 = rng.random();
        if fy <= fx || u < (-(fy - fx) / temp).exp() {
            std::mem::swap(&mut x, &mut y);
            fx = fy;
        }
        temp *= cfg.cooling;
        sigma *= cfg.step_cooling;
        stop = tr.close(k, fx);
    }
    Ok(tr.finish(stop.expect("the loop ends on a stop reason")))
}

#[cfg(test)]
mod tests {
    use super::super::test_problems::*;
    use super::super::StopReason;
    use super::*;

    #[test]
    fn annealing_improves_a_shifted_sphere_reproducibly() {
        let cfg = AnnealingConfig {
            cooling: AnnealingConfig::factor_over(1.0, 1e-4, 2000),
            step_cooling: AnnealingConfig::factor_over(0.2, 0.01, 2000),
            step: 0.2,
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
            cooling: AnnealingConfig::factor_over(1.0, 1e-5, 3000),
            step_cooling: AnnealingConfig::factor_over(0.1, 0.005, 3000),
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
}
