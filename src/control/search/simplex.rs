//! Nelder–Mead simplex over a box, by argmin's [`NelderMead`] (the simplex baseline of
//! NeuroAnimator §6).
//!
//! The simplex lives in ℝᵈ; the box is handled by *projection*: a vertex x is scored
//! c(x) = J(Π x) + penalty · Σ_i ((x_i − (Π x)_i) / h_i)² with Π the projection onto the box
//! and h its half-widths, so the problem is only ever evaluated inside the box. With the
//! default penalty 0 a vertex outside scores as its projection; a positive penalty pulls the
//! simplex back toward the box. The initial simplex is the projected start point x_0 and the
//! d points x_0 ± step · h_i e_i (+ unless that leaves the box). Each argmin iteration
//! (reflection, expansion, contraction or shrink: 1, 2, 2 or d + 2 evaluations) is one trace
//! row, and every cost evaluation is counted.
//!
//! The simplex converges when the standard deviation of its vertex costs falls below
//! `sd_tolerance`; in many dimensions it often does so degenerate, short of a minimum. It is
//! then *restarted*: a fresh simplex is built around the best point (that initialization is
//! one more trace row, d + 1 evaluations), up to `restarts` times and only while the previous
//! run improved the best objective. The search stops on the [`Budget`] or on a convergence
//! that is not restarted.
//!
//! ## References
//! - J. A. Nelder, R. Mead, *A simplex method for function minimization*, The Computer
//!   Journal 7(4), 1965.

use super::{
    check_setting, rank_value, start_point, Budget, SearchBox, SearchProblem, SearchResult, Spent,
    StopReason, Tracker,
};
use crate::control::ControlError;
use argmin::core::{
    CostFunction, Executor, IterState, Problem, Solver, TerminationReason, TerminationStatus, KV,
};
use argmin::solver::neldermead::NelderMead;
use ndarray::Array1;
use std::cell::RefCell;

/// Settings of [`nelder_mead`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimplexConfig {
    /// Edge length of the initial simplex, in half-widths of the box.
    pub step: f64,
    /// Convergence: stop when the standard deviation of the vertex costs is below this (≥ 0).
    pub sd_tolerance: f64,
    /// Weight of the squared distance outside the box (in half-widths) added to a vertex's
    /// cost (≥ 0).
    pub penalty: f64,
    /// Restarts from the best point after a convergence that improved it.
    pub restarts: usize,
}

impl Default for SimplexConfig {
    /// Edges of 0.2 half-widths, tolerance 1e-12, no penalty, up to 20 restarts.
    fn default() -> Self {
        Self {
            step: 0.2,
            sd_tolerance: 1e-12,
            penalty: 0.0,
            restarts: 20,
        }
    }
}

/// The argmin cost: the problem at the projection, plus the penalty; counts every evaluation.
struct ProjectedCost<'a, P: ?Sized> {
    problem: &'a P,
    penalty: f64,
    tracker: RefCell<Tracker<'static, Vec<f64>>>,
    scratch: RefCell<Vec<f64>>,
}

impl<P: SearchProblem + ?Sized> CostFunction for ProjectedCost<'_, P> {
    type Param = Array1<f64>;
    type Output = f64;

    fn cost(&self, x: &Self::Param) -> Result<f64, argmin::core::Error> {
        let bx: &SearchBox = self.problem.search_box();
        let mut y = self.scratch.borrow_mut();
        y.iter_mut().zip(x.iter()).for_each(|(y, x)| *y = *x);
        bx.project(&mut y);
        let f = self.problem.evaluate(&y);
        self.tracker.borrow_mut().evaluated(&y, f);
        let outside: f64 = x
            .iter()
            .zip(y.iter())
            .enumerate()
            .map(|(i, (x, y))| ((x - y) / bx.half_width(i)).powi(2))
            .sum();
        // argmin sorts vertices with partial_cmp: never hand it a NaN.
        Ok(rank_value(f + self.penalty * outside))
    }
}

type NmState = IterState<Array1<f64>, (), (), (), (), f64>;

/// Wraps argmin's solver: one trace row per iteration, the budget checked after each.
struct Traced {
    inner: NelderMead<Array1<f64>, f64>,
    stop: Option<StopReason>,
}

impl<P: SearchProblem + ?Sized> Solver<ProjectedCost<'_, P>, NmState> for Traced {
    fn name(&self) -> &str {
        "Nelder-Mead (traced)"
    }

    fn init(
        &mut self,
        problem: &mut Problem<ProjectedCost<'_, P>>,
        state: NmState,
    ) -> Result<(NmState, Option<KV>), argmin::core::Error> {
        let (state, kv) = self.inner.init(problem, state)?;
        self.close(problem, &state);
        Ok((state, kv))
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<ProjectedCost<'_, P>>,
        state: NmState,
    ) -> Result<(NmState, Option<KV>), argmin::core::Error> {
        let (state, kv) = self.inner.next_iter(problem, state)?;
        self.close(problem, &state);
        Ok((state, kv))
    }

    fn terminate(&mut self, state: &NmState) -> TerminationStatus {
        if self.stop.is_some() {
            return TerminationStatus::Terminated(TerminationReason::SolverExit("budget".into()));
        }
        let inner =
            <NelderMead<Array1<f64>, f64> as Solver<ProjectedCost<'_, P>, NmState>>::terminate(
                &mut self.inner,
                state,
            );
        if inner.terminated() {
            self.stop = Some(StopReason::Converged);
        }
        inner
    }
}

impl Traced {
    fn close<P: SearchProblem + ?Sized>(
        &mut self,
        problem: &mut Problem<ProjectedCost<'_, P>>,
        state: &NmState,
    ) {
        if let Some(cost) = &problem.problem {
            let mut tracker = cost.tracker.borrow_mut();
            let iteration = tracker.rows.len();
            self.stop = tracker.close(iteration, state.get_cost());
        }
    }
}

/// Nelder–Mead minimizing `problem` from `x0` (projected onto the box) within `budget`;
/// needs only the objective. Deterministic (no randomness).
pub fn nelder_mead<P: SearchProblem + ?Sized>(
    problem: &P,
    x0: &[f64],
    cfg: &SimplexConfig,
    budget: &Budget,
) -> Result<SearchResult, ControlError> {
    check_setting("simplex step", cfg.step, 0.0, f64::MAX, false)?;
    check_setting("sd tolerance", cfg.sd_tolerance, 0.0, f64::MAX, true)?;
    check_setting("penalty", cfg.penalty, 0.0, f64::MAX, true)?;
    let bx = problem.search_box();
    let mut start = start_point(bx, x0)?;
    let d = start.len();
    let mut tracker = Tracker::new(budget, start.clone(), Spent::default())?;
    let mut restarts = cfg.restarts;
    loop {
        let before = tracker.best_value;
        let mut simplex = vec![Array1::from_vec(start.clone())];
        for i in 0..d {
            let mut v = start.clone();
            let h = cfg.step * bx.half_width(i);
            v[i] = if start[i] + h <= bx.high[i] {
                start[i] + h
            } else {
                start[i] - h
            };
            simplex.push(Array1::from_vec(v));
        }
        let inner = NelderMead::new(simplex)
            .with_sd_tolerance(cfg.sd_tolerance)
            .expect("tolerance checked above");
        let cost = ProjectedCost {
            problem,
            penalty: cfg.penalty,
            tracker: RefCell::new(tracker),
            scratch: RefCell::new(vec![0.0; d]),
        };
        let res = Executor::new(cost, Traced { inner, stop: None })
            .run()
            .expect("the projected cost never fails");
        let stop = res.solver.stop.unwrap_or(StopReason::Converged);
        tracker = res
            .problem
            .problem
            .expect("the executor hands the problem back")
            .tracker
            .into_inner();
        if stop == StopReason::Converged && restarts > 0 && tracker.best_value < before {
            restarts -= 1;
            start.copy_from_slice(&tracker.best);
        } else {
            return Ok(tracker.finish(stop));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_problems::*;
    use super::*;

    #[test]
    fn nelder_mead_minimizes_a_shifted_sphere_deterministically() {
        let run = || {
            let p = Checked::new(ShiftedSphere::new(10));
            let r = nelder_mead(
                &p,
                &[-0.8; 10],
                &SimplexConfig::default(),
                &Budget::iterations(1500),
            )
            .unwrap();
            check_trace(&p, &r);
            r
        };
        let (a, b) = (run(), run());
        assert_eq!(untimed(&a.trace), untimed(&b.trace));
        assert_eq!(a.trace[0].evaluations, 11);
        assert!(a.trace.len() <= 1501);
        let f0 = a.trace[0].current;
        assert!(a.best_value < 1e-4 * f0, "{} from {f0}", a.best_value);
        // The simplex's current point is its best vertex, the best evaluated.
        assert!(a.trace.iter().all(|r| r.current == r.best));
    }

    #[test]
    fn nelder_mead_minimizes_rosenbrock_in_a_box_with_projection_or_penalty() {
        for penalty in [0.0, 10.0] {
            let p = Checked::new(Rosenbrock::new());
            let cfg = SimplexConfig {
                penalty,
                ..SimplexConfig::default()
            };
            let r = nelder_mead(&p, &[-1.5, 1.8], &cfg, &Budget::evaluations(600)).unwrap();
            check_trace(&p, &r);
            assert!(r.best_value < 1e-6, "penalty {penalty}: {}", r.best_value);
            let last = r.trace.last().unwrap();
            assert!(
                r.stop == StopReason::Converged
                    || (r.stop == StopReason::Evaluations && last.evaluations < 600 + 3)
            );
        }
    }

    #[test]
    fn a_start_on_the_upper_bound_steps_inward_and_the_budget_binds() {
        let p = Checked::new(ShiftedSphere::new(2));
        let r = nelder_mead(
            &p,
            &[5.0, 5.0],
            &SimplexConfig::default(),
            &Budget::iterations(10),
        )
        .unwrap();
        check_trace(&p, &r);
        assert_eq!(r.stop, StopReason::Iterations);
        assert_eq!(r.trace.len(), 11);
        assert!(r.best_value < 0.5 * r.trace[0].best, "{}", r.best_value);
    }

    #[test]
    fn an_optimum_in_a_corner_of_the_box_is_found() {
        // The shifted sphere's centre (0.3, 0.35) lies outside [−1, 0.2]²: the box optimum
        // is the corner (0.2, 0.2).
        let mut s = ShiftedSphere::new(2);
        s.bx = SearchBox::cube(2, -1.0, 0.2).unwrap();
        let p = Checked::new(s);
        let r = nelder_mead(
            &p,
            &[-1.0, -1.0],
            &SimplexConfig::default(),
            &Budget::iterations(500),
        )
        .unwrap();
        check_trace(&p, &r);
        assert_eq!(r.stop, StopReason::Converged);
        assert!((r.best_value - 0.0325).abs() < 1e-9, "{}", r.best_value);
    }
}
