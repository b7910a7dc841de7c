//! # Box-bounded search: one problem, one trace, one budget (NeuroAnimator §6)
//!
//! NeuroAnimator §6 compares control learning by backpropagation through time with
//! gradient-free searches — simulated annealing and the simplex method — on the same
//! controller: the gradient-free methods need 500–3,500 iterations, BPTT about 20. This module
//! is the common ground for that comparison:
//!
//! - a problem is a function J(v) over a box B = [low, high] ⊂ ℝᵈ ([`SearchProblem`],
//!   [`SearchBox`]), optionally with a gradient;
//! - every optimizer spends a [`Budget`] (iterations, objective evaluations, wall seconds) and
//!   returns the same trace: one [`TraceRow`] per iteration with the cumulative evaluations,
//!   gradients and seconds and the best objective so far;
//! - [`time_to_target`] reads off the first iteration (evaluations, seconds) at which the best
//!   objective reached a target.
//!
//! The optimizers: [`anneal`] (simulated annealing with Gaussian proposals scaled to the box),
//! [`nelder_mead`] (argmin's Nelder–Mead simplex, evaluated at the projection onto the box),
//! [`hill_climb()`] (parallel hill climbing: a batch of perturbations of the best point per
//! iteration, evaluated with rayon) and [`bptt_search`] (plain or momentum descent of
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
//! - Iteration 0 is the initialization (the start point, plus annealing's spread samples or
//!   the initial simplex); iteration k ≥ 1 is one proposal (annealing), one reflection /
//!   expansion / contraction / shrink step (simplex), one batch (hill climbing) or one
//!   gradient step (BPTT).
//! - Budgets are checked at the end of every iteration (iteration 0 included), so an
//!   iteration is never cut short: evaluations can exceed `max_evaluations` by less than one
//!   iteration's worth (a simplex shrink costs d + 2, a hill-climbing batch its size).
//!
//! Non-finite objective values (a simulation that blew up) rank worse than every finite one;
//! they are never the best point.
//!
//! ## Determinism
//!
//! Randomness comes from ChaCha8 streams of one seed: stream j for the j-th initial sample
//! ([`init_rng`]), stream 2⁴⁰ + i for proposal i ([`iteration_rng`]); the mass-spring
//! searches of [`crate::synthesis`] use the same streams and the same ranked insertion
//! ([`climb_batch`]). Proposals evaluated in parallel are combined in a fixed order, so a
//! result depends on the seed and the settings, never on the number of threads.

pub mod adapters;
pub mod annealing;
pub mod hill_climb;
pub mod simplex;

pub use adapters::{
    bptt_search, trace_from_bptt, BpttProblem, ReplayProblem, ReplayRollout, StateMap,
};
pub use annealing::{anneal, robust_scale, AnnealingConfig};
pub use hill_climb::{
    climb_batch, hill_climb, init_rng, insert_by_rank, iteration_rng, ClimbConfig,
};
pub use simplex::{nelder_mead, SimplexConfig};

use super::ControlError;
use std::time::Instant;

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

/// Why a search stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// The iteration limit was reached.
    Iterations,
    /// The evaluation limit was reached (possibly exceeded within the last iteration).
    Evaluations,
    /// The wall-clock limit was reached.
    Seconds,
    /// The method converged (the simplex's vertex values agree to its tolerance).
    Converged,
    /// BPTT met a non-finite objective and cannot take a step.
    NonFinite,
}

/// Limits on a search; it stops at the end of the first iteration at which any set limit is
/// reached. At least one must be set.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Budget {
    /// Iterations after the initialization (iteration 0).
    pub max_iterations: Option<usize>,
    /// Objective evaluations, the initialization's included.
    pub max_evaluations: Option<usize>,
    /// Wall-clock seconds (timing-dependent: the other two are reproducible).
    pub max_seconds: Option<f64>,
}

impl Budget {
    /// At most `n` iterations.
    pub fn iterations(n: usize) -> Self {
        Self {
            max_iterations: Some(n),
            ..Self::default()
        }
    }

    /// At most (about, see the module doc) `n` objective evaluations.
    pub fn evaluations(n: usize) -> Self {
        Self {
            max_evaluations: Some(n),
            ..Self::default()
        }
    }

    /// At most `s` wall-clock seconds.
    pub fn seconds(s: f64) -> Self {
        Self {
            max_seconds: Some(s),
            ..Self::default()
        }
    }

    /// This budget with an evaluation limit as well.
    pub fn with_evaluations(mut self, n: usize) -> Self {
        self.max_evaluations = Some(n);
        self
    }

    /// This budget with a wall-clock limit as well.
    pub fn with_seconds(mut self, s: f64) -> Self {
        self.max_seconds = Some(s);
        self
    }

    /// Checks that some limit is set and the seconds are not NaN or negative.
    pub fn validate(&self) -> Result<(), ControlError> {
        if self.max_iterations.is_none()
            && self.max_evaluations.is_none()
            && self.max_seconds.is_none()
        {
            return Err(ControlError::UnboundedBudget);
        }
        if let Some(s) = self.max_seconds {
            if s.is_nan() || s < 0.0 {
                return Err(ControlError::InvalidSetting {
                    what: "budget seconds",
                    value: s,
                });
            }
        }
        Ok(())
    }

    /// The limit that a search reaches with `row` as its latest row, if any (iterations, then
    /// evaluations, then seconds).
    pub fn exhausted(&self, row: &TraceRow) -> Option<StopReason> {
        if self.max_iterations.is_some_and(|n| row.iteration >= n) {
            Some(StopReason::Iterations)
        } else if self.max_evaluations.is_some_and(|n| row.evaluations >= n) {
            Some(StopReason::Evaluations)
        } else if self.max_seconds.is_some_and(|s| row.seconds >= s) {
            Some(StopReason::Seconds)
        } else {
            None
        }
    }
}

/// One iteration of a search, with cumulative costs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceRow {
    /// Iteration (0: the initialization).
    pub iteration: usize,
    /// Objective evaluations so far (a gradient counts one).
    pub evaluations: usize,
    /// Gradient evaluations (backward passes) so far; 0 for gradient-free methods.
    pub gradients: usize,
    /// Wall-clock seconds so far.
    pub seconds: f64,
    /// Best objective evaluated so far (+∞ while none was finite).
    pub best: f64,
    /// Objective at the method's current point: the annealing state, the best simplex vertex,
    /// the hill climber's point, the BPTT iterate.
    pub current: f64,
}

/// Set-up costs charged to a search before its first iteration (e.g. the BPTT step-scale
/// estimate); they offset every row's counts.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Spent {
    /// Objective evaluations.
    pub evaluations: usize,
    /// Gradient evaluations.
    pub gradients: usize,
    /// Wall-clock seconds.
    pub seconds: f64,
}

/// What a search returns.
#[derive(Debug, Clone, PartialEq)]
pub struct SearchResult {
    /// The best point evaluated (inside the box).
    pub best: Vec<f64>,
    /// J at `best` (+∞ when no evaluation was finite).
    pub best_value: f64,
    /// One row per iteration, 0 first.
    pub trace: Vec<TraceRow>,
    /// Why it stopped.
    pub stop: StopReason,
}

/// Where a trace first reached a target objective.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reached {
    /// Iteration.
    pub iteration: usize,
    /// Objective evaluations spent by then.
    pub evaluations: usize,
    /// Seconds spent by then.
    pub seconds: f64,
}

/// The first row of `trace` whose best objective is ≤ `target`, or `None` if none is.
pub fn time_to_target(trace: &[TraceRow], target: f64) -> Option<Reached> {
    trace.iter().find(|r| r.best <= target).map(|r| Reached {
        iteration: r.iteration,
        evaluations: r.evaluations,
        seconds: r.seconds,
    })
}

/// Non-finite values rank last: NaN becomes +∞.
fn rank_value(f: f64) -> f64 {
    if f.is_nan() {
        f64::INFINITY
    } else {
        f
    }
}

/// The one place where counts, timing, the best point and budget checks live; every optimizer
/// reports its evaluations and iterations here.
struct Tracker {
    budget: Budget,
    start: Instant,
    offset: Spent,
    evaluations: usize,
    gradients: usize,
    best: Vec<f64>,
    best_value: f64,
    rows: Vec<TraceRow>,
}

impl Tracker {
    fn new(budget: &Budget, d: usize, offset: Spent) -> Result<Self, ControlError> {
        budget.validate()?;
        Ok(Self {
            budget: *budget,
            start: Instant::now(),
            offset,
            evaluations: 0,
            gradients: 0,
            best: vec![f64::NAN; d],
            best_value: f64::INFINITY,
            rows: Vec::new(),
        })
    }

    /// Counts `n` evaluations.
    fn count(&mut self, n: usize) {
        self.evaluations += n;
    }

    /// Offers a point evaluated (and counted) elsewhere as the best one.
    fn offer(&mut self, v: &[f64], f: f64) {
        if f.is_finite() && f < self.best_value {
            self.best_value = f;
            self.best.copy_from_slice(v);
        }
    }

    /// Counts one evaluation of `v` with value `f` and offers it as the best.
    fn evaluated(&mut self, v: &[f64], f: f64) {
        self.count(1);
        self.offer(v, f);
    }

    /// Records the row of `iteration` and returns the limit reached, if any.
    fn close(&mut self, iteration: usize, current: f64) -> Option<StopReason> {
        let row = TraceRow {
            iteration,
            evaluations: self.offset.evaluations + self.evaluations,
            gradients: self.offset.gradients + self.gradients,
            seconds: self.offset.seconds + self.start.elapsed().as_secs_f64(),
            best: self.best_value,
            current,
        };
        self.rows.push(row);
        self.budget.exhausted(&row)
    }

    fn finish(self, stop: StopReason) -> SearchResult {
        SearchResult {
            best: self.best,
            best_value: self.best_value,
            trace: self.rows,
            stop,
        }
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

    fn row(iteration: usize, evaluations: usize, seconds: f64, best: f64) -> TraceRow {
        TraceRow {
            iteration,
            evaluations,
            gradients: 0,
            seconds,
            best,
            current: best,
        }
    }

    #[test]
    fn time_to_target_finds_the_first_row_at_or_below_the_target() {
        let t = [
            row(0, 5, 0.1, 10.0),
            row(1, 6, 0.2, 4.0),
            row(2, 9, 0.4, 2.0),
            row(3, 10, 0.5, 2.0),
        ];
        let r = time_to_target(&t, 2.0).unwrap();
        assert_eq!((r.iteration, r.evaluations, r.seconds), (2, 9, 0.4));
        assert_eq!(time_to_target(&t, 100.0).unwrap().iteration, 0);
        assert_eq!(time_to_target(&t, 4.0).unwrap().evaluations, 6);
        assert!(time_to_target(&t, 1.9).is_none());
        assert!(time_to_target(&[], 1.0).is_none());
    }

    #[test]
    fn budgets_stop_at_the_first_limit_reached() {
        let b = Budget::iterations(3).with_evaluations(10);
        assert_eq!(b.exhausted(&row(2, 9, 0.0, 1.0)), None);
        assert_eq!(
            b.exhausted(&row(3, 9, 0.0, 1.0)),
            Some(StopReason::Iterations)
        );
        assert_eq!(
            b.exhausted(&row(2, 11, 0.0, 1.0)),
            Some(StopReason::Evaluations)
        );
        assert_eq!(
            Budget::seconds(0.0).exhausted(&row(0, 1, 0.0, 1.0)),
            Some(StopReason::Seconds)
        );
        assert_eq!(
            Budget::default().validate(),
            Err(ControlError::UnboundedBudget)
        );
        assert!(Budget::seconds(f64::NAN).validate().is_err());
        assert!(b.validate().is_ok());
    }

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
