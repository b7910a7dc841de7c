//! # Gradient-free and gradient searches: one problem, one trace, one budget
//!
//! NeuroAnimator §6 compares control learning by backpropagation through time with
//! gradient-free searches — simulated annealing and the simplex method — on the same
//! controller; mass-spring motion synthesis (Christensen, Marks, Ngo 1995) finds reflex
//! controllers by parallel hill climbing, with annealing as our baseline. This module is the
//! one library both use:
//!
//! - a search minimizes J over points of some type T — a box point v ∈ B = [low, high] ⊂ ℝᵈ
//!   ([`SearchProblem`], [`SearchBox`]) or a reflex controller ([`crate::synthesis`]);
//! - the gradient-free searches are generic over a *proposal operator* ([`Perturb`]): how a
//!   neighbour of a point is drawn, with a step size the search may cool or adapt. A box
//!   perturbs by Gaussian steps scaled to its half-widths; a reflex controller by the
//!   perturbation mix of the mass-spring paper's Table 2;
//! - every optimizer spends a [`Budget`] (iterations, objective evaluations, wall seconds) and
//!   returns the same [`SearchResult`]: one [`TraceRow`] per iteration with the cumulative
//!   evaluations, gradients and seconds and the best objective so far, and every
//!   [`Evaluation`] in order;
//! - [`time_to_target`] reads off the first iteration (evaluations, seconds) at which the best
//!   objective reached a target.
//!
//! The optimizers: [`anneal_from`] (simulated annealing from a set of candidate starts) and
//! [`climb_from`] (parallel hill climbing on a ranked set), generic over T and the operator;
//! their box forms [`anneal`] (starts: x₀ and perturbed copies) and [`hill_climb()`] (a set
//! of one, with an adaptive step); [`nelder_mead`] (argmin's Nelder–Mead simplex, evaluated at
//! the projection onto the box) and [`bptt_search`] (plain or momentum descent of
//! [`super::bptt::learn_until`] under the same budget). The adapters [`BpttProblem`] (an
//! emulator rollout, with its BPTT gradient) and [`ReplayProblem`] (the same knots replayed on
//! a physical simulator) make a control problem a search problem, so each method runs on
//! either substrate with the same objective.
//!
//! ## Counting
//!
//! - *Evaluations* count objective evaluations J(v): one emulator or simulator rollout each.
//!   A gradient (one forward rollout and one backward pass) counts one evaluation and one
//!   *gradient*; rows carry both counts.
//! - *Seconds* are wall-clock seconds from the start of the optimizer call (plus any
//!   [`Spent`] set-up, such as the BPTT step-scale estimate) to the end of the iteration,
//!   bookkeeping included. They are the only non-deterministic field of a trace.
//! - Iteration 0 is the initialization (the start points, e.g. annealing's spread samples,
//!   hill climbing's initial set or the initial simplex); iteration k ≥ 1 is one proposal
//!   (annealing), one reflection / expansion / contraction / shrink step (simplex), one batch
//!   (hill climbing) or one gradient step (BPTT).
//! - Budgets are checked at the end of every iteration (iteration 0 included), so an
//!   iteration is never cut short: evaluations can exceed `max_evaluations` by less than one
//!   iteration's worth (a simplex shrink costs d + 2). Hill climbing, whose batch can be split
//!   freely, cuts its last batch to the evaluation limit.
//!
//! Non-finite objective values (a simulation that blew up) rank worse than every finite one;
//! they are never the best point.
//!
//! ## Determinism
//!
//! Randomness comes from ChaCha8 streams of one seed: stream j for the j-th initial sample
//! ([`init_rng`]), stream 2⁴⁰ + i for proposal i ([`iteration_rng`]). Proposals evaluated in
//! parallel are combined in a fixed order, so a result depends on the seed and the settings,
//! never on the number of threads.

pub mod adapters;
pub mod annealing;
pub mod hill_climb;
pub mod simplex;
pub mod trace;

pub use adapters::{
    bptt_search, trace_from_bptt, BpttProblem, ReplayProblem, ReplayRollout, StateMap,
};
pub use annealing::{anneal, anneal_from, robust_scale, AnnealingConfig, Geometric};
pub use hill_climb::{climb_batch, climb_from, hill_climb, insert_by_rank, ClimbConfig};
pub use simplex::{nelder_mead, SimplexConfig};
pub use trace::{
    time_to_target, Budget, Evaluation, Progress, Reached, SearchResult, Spent, StopReason,
    TraceRow,
};

use super::ControlError;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use trace::Tracker;

/// A proposal operator: how a gradient-free search draws a neighbour of a point of type `T`.
pub trait Perturb<T>: Sync {
    /// A neighbour of `x`, drawn from `rng`, at step size `scale` (in the operator's own unit;
    /// an operator with a fixed size ignores it).
    fn perturb(&self, rng: &mut ChaCha8Rng, x: &T, scale: f64) -> T;
}

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

/// A box-bounded minimization problem over a flat vector v ∈ [low, high] ⊂ ℝᵈ.
///
/// `evaluate` takes `&self` and the problem is `Send + Sync`, so proposals can be evaluated in
/// parallel; implementations keep per-call scratch in a pool or on the stack.
pub trait SearchProblem: Send + Sync {
    /// The box (d coordinates).
    fn search_box(&self) -> &SearchBox;
    /// Dimension d.
    fn dim(&self) -> usize {
        self.search_box().dim()
    }
    /// J(v) for v inside the box (non-finite when the rollout blew up).
    fn evaluate(&self, v: &[f64]) -> f64;
    /// J(v), with ∇J(v) written to `grad`, when the problem has a gradient; `None` otherwise.
    fn gradient(&self, _v: &[f64], _grad: &mut [f64]) -> Option<f64> {
        None
    }
}

/// The box [low, high] of a search; a side may be infinite.
#[derive(Debug, Clone, PartialEq)]
pub struct SearchBox {
    /// Lower bound per coordinate (may be −∞).
    pub low: Vec<f64>,
    /// Upper bound per coordinate (may be +∞).
    pub high: Vec<f64>,
}

impl SearchBox {
    /// The box [low, high]; lengths must agree and low ≤ high (no NaN).
    pub fn new(low: Vec<f64>, high: Vec<f64>) -> Result<Self, ControlError> {
        if low.len() != high.len() {
            return Err(ControlError::DimensionMismatch {
                what: "upper bounds",
                expected: low.len(),
                found: high.len(),
            });
        }
        for (index, (&lower, &upper)) in low.iter().zip(&high).enumerate() {
            if lower.is_nan() || upper.is_nan() || lower > upper {
                return Err(ControlError::InvalidBounds {
                    index,
                    lower,
                    upper,
                });
            }
        }
        Ok(Self { low, high })
    }

    /// The cube [lo, hi]ᵈ.
    pub fn cube(d: usize, lo: f64, hi: f64) -> Result<Self, ControlError> {
        Self::new(vec![lo; d], vec![hi; d])
    }

    /// Dimension d.
    pub fn dim(&self) -> usize {
        self.low.len()
    }

    /// The unit of coordinate i for step sizes: half the width of its interval, or 1 when the
    /// interval is unbounded on a side (as [`super::bptt::Bounds::affine`]).
    pub fn half_width(&self, i: usize) -> f64 {
        let (lo, hi) = (self.low[i], self.high[i]);
        if lo.is_finite() && hi.is_finite() {
            0.5 * (hi - lo)
        } else {
            1.0
        }
    }

    /// Clamps `v` onto the box, in place.
    pub fn project(&self, v: &mut [f64]) {
        for ((x, lo), hi) in v.iter_mut().zip(&self.low).zip(&self.high) {
            *x = x.clamp(*lo, *hi);
        }
    }

    /// Whether `v` has d coordinates, all inside the box.
    pub fn contains(&self, v: &[f64]) -> bool {
        v.len() == self.dim()
            && v.iter()
                .zip(self.low.iter().zip(&self.high))
                .all(|(x, (lo, hi))| *x >= *lo && *x <= *hi)
    }
}

/// Gaussian steps scaled to the box: y = Π(x + σ h ⊙ z), z ~ N(0, I), h the half-widths and Π
/// the projection onto the box; σ is the `scale`.
impl Perturb<Vec<f64>> for SearchBox {
    fn perturb(&self, rng: &mut ChaCha8Rng, x: &Vec<f64>, scale: f64) -> Vec<f64> {
        let mut y = x.clone();
        for (i, y) in y.iter_mut().enumerate() {
            let z = crate::portable::standard_normal(rng);
            *y += scale * self.half_width(i) * z;
        }
        self.project(&mut y);
        y
    }
}

/// Non-finite values rank last: NaN becomes +∞.
fn rank_value(f: f64) -> f64 {
    if f.is_nan() {
        f64::INFINITY
    } else {
        f
    }
}

/// Checks a start point's length and projects a copy onto the box.
fn start_point(bx: &SearchBox, x0: &[f64]) -> Result<Vec<f64>, ControlError> {
    if x0.len() != bx.dim() {
        return Err(ControlError::DimensionMismatch {
            what: "start point",
            expected: bx.dim(),
            found: x0.len(),
        });
    }
    let mut x = x0.to_vec();
    bx.project(&mut x);
    Ok(x)
}

/// Checks that a setting is finite and inside (lo, hi] (or [lo, hi] when `closed_low`).
fn check_setting(
    what: &'static str,
    value: f64,
    lo: f64,
    hi: f64,
    closed_low: bool,
) -> Result<(), ControlError> {
    let above = if closed_low { value >= lo } else { value > lo };
    if value.is_finite() && above && value <= hi {
        Ok(())
    } else {
        Err(ControlError::InvalidSetting { what, value })
    }
}

#[cfg(test)]
pub(crate) mod test_problems {
    //! Test functions, and a wrapper that checks every evaluated point is in the box.
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// J(v) = Σ (v_i − c_i)², c_i = 0.3 + 0.05 i, in [−1, 1]ᵈ.
    pub struct ShiftedSphere {
        pub bx: SearchBox,
    }

    impl ShiftedSphere {
        pub fn new(d: usize) -> Self {
            Self {
                bx: SearchBox::cube(d, -1.0, 1.0).unwrap(),
            }
        }
    }

    impl SearchProblem for ShiftedSphere {
        fn search_box(&self) -> &SearchBox {
            &self.bx
        }
        fn evaluate(&self, v: &[f64]) -> f64 {
            v.iter()
                .enumerate()
                .map(|(i, x)| (x - 0.3 - 0.05 * i as f64).powi(2))
                .sum()
        }
    }

    /// The 2-D Rosenbrock function in [−2, 2]², minimum 0 at (1, 1).
    pub struct Rosenbrock {
        pub bx: SearchBox,
    }

    impl Rosenbrock {
        pub fn new() -> Self {
            Self {
                bx: SearchBox::cube(2, -2.0, 2.0).unwrap(),
            }
        }
    }

    impl SearchProblem for Rosenbrock {
        fn search_box(&self) -> &SearchBox {
            &self.bx
        }
        fn evaluate(&self, v: &[f64]) -> f64 {
            (1.0 - v[0]).powi(2) + 100.0 * (v[1] - v[0] * v[0]).powi(2)
        }
    }

    /// Counts evaluations and the points outside the box.
    pub struct Checked<P> {
        pub inner: P,
        pub calls: AtomicUsize,
        pub outside: AtomicUsize,
    }

    impl<P> Checked<P> {
        pub fn new(inner: P) -> Self {
            Self {
                inner,
                calls: AtomicUsize::new(0),
                outside: AtomicUsize::new(0),
            }
        }
        pub fn calls(&self) -> usize {
            self.calls.load(Ordering::SeqCst)
        }
        pub fn outside(&self) -> usize {
            self.outside.load(Ordering::SeqCst)
        }
    }

    impl<P: SearchProblem> SearchProblem for Checked<P> {
        fn search_box(&self) -> &SearchBox {
            self.inner.search_box()
        }
        fn evaluate(&self, v: &[f64]) -> f64 {
            self.calls.fetch_add(1, Ordering::SeqCst);
            if !self.inner.search_box().contains(v) {
                self.outside.fetch_add(1, Ordering::SeqCst);
            }
            self.inner.evaluate(v)
        }
    }

    /// The objectives of a trace (everything but the seconds).
    pub fn untimed(trace: &[TraceRow]) -> Vec<(usize, usize, usize, f64, f64)> {
        trace
            .iter()
            .map(|r| (r.iteration, r.evaluations, r.gradients, r.best, r.current))
            .collect()
    }

    /// Common checks: counts match the calls, best is monotone and equals J(best).
    pub fn check_trace<P: SearchProblem>(p: &Checked<P>, r: &SearchResult) {
        assert_eq!(p.outside(), 0, "points outside the box were evaluated");
        let last = r.trace.last().unwrap();
        assert_eq!(last.evaluations, p.calls());
        assert_eq!(r.evaluations.len(), p.calls());
        assert!(r.evaluations.windows(2).all(|w| w[1].best <= w[0].best));
        assert_eq!(r.evaluations.last().unwrap().best, r.best_value);
        assert!(r.trace.windows(2).all(|w| w[1].best <= w[0].best));
        assert!(r.trace.windows(2).all(|w| w[1].seconds >= w[0].seconds));
        assert!(r
            .trace
            .iter()
            .enumerate()
            .all(|(i, row)| row.iteration == i));
        assert_eq!(last.best, r.best_value);
        assert!(p.inner.search_box().contains(&r.best));
        assert_eq!(p.inner.evaluate(&r.best), r.best_value);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn search_box_projects_and_checks() {
        let b = SearchBox::new(vec![-1.0, 0.0, f64::NEG_INFINITY], vec![1.0, 4.0, 2.0]).unwrap();
        assert_eq!(
            (b.half_width(0), b.half_width(1), b.half_width(2)),
            (1.0, 2.0, 1.0)
        );
        let mut v = vec![3.0, -1.0, -1e9];
        assert!(!b.contains(&v));
        b.project(&mut v);
        assert_eq!(v, vec![1.0, 0.0, -1e9]);
        assert!(b.contains(&v));
        assert!(!b.contains(&v[..2]));
        assert!(matches!(
            SearchBox::new(vec![1.0], vec![0.0]),
            Err(ControlError::InvalidBounds { index: 0, .. })
        ));
        assert!(SearchBox::new(vec![0.0], vec![1.0, 2.0]).is_err());
    }
}
