//! The one trace, budget and bookkeeping every search shares.
//!
//! A search reports each objective evaluation and closes each iteration on a `Tracker`; the
//! tracker counts, times, keeps the best point, logs every evaluation ([`Evaluation`]), writes
//! one [`TraceRow`] per iteration and checks the [`Budget`] after it. What a search returns is
//! a [`SearchResult`] over its point type (a box point `Vec<f64>`, a reflex controller, …).

use super::ControlError;
use std::time::Instant;

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

    /// At most (about, see [`super`]) `n` objective evaluations.
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
    /// the hill climber's best point, the BPTT iterate.
    pub current: f64,
}

/// One objective evaluation, in the order the search made them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Evaluation {
    /// The iteration it belongs to (0: the initialization).
    pub iteration: usize,
    /// The objective value J (as the problem returned it; may be non-finite).
    pub value: f64,
    /// The best finite J so far, this evaluation included (+∞ while none was finite).
    pub best: f64,
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

/// What a search over points of type `T` returns.
#[derive(Debug, Clone, PartialEq)]
pub struct SearchResult<T = Vec<f64>> {
    /// The best point evaluated (for a box search: inside the box, NaN when no evaluation was
    /// finite).
    pub best: T,
    /// J at `best` (+∞ when no evaluation was finite).
    pub best_value: f64,
    /// One row per iteration, 0 first.
    pub trace: Vec<TraceRow>,
    /// Every evaluation in order (empty for BPTT, whose rows are its evaluations).
    pub evaluations: Vec<Evaluation>,
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

/// Called with each closed iteration's row (e.g. to move a progress bar).
pub type Progress<'a> = &'a (dyn Fn(&TraceRow) + Sync);

/// The one place where counts, timing, the best point, the evaluation log and budget checks
/// live; every optimizer reports its evaluations and iterations here.
pub(crate) struct Tracker<'a, T> {
    budget: Budget,
    start: Instant,
    offset: Spent,
    evaluations: usize,
    gradients: usize,
    pub(crate) best: T,
    pub(crate) best_value: f64,
    log_best: f64,
    pub(crate) rows: Vec<TraceRow>,
    log: Vec<Evaluation>,
    progress: Option<Progress<'a>>,
}

impl<'a, T: Clone> Tracker<'a, T> {
    /// A tracker whose best point is `placeholder` until a finite evaluation is offered.
    pub(crate) fn new(
        budget: &Budget,
        placeholder: T,
        offset: Spent,
    ) -> Result<Self, ControlError> {
        budget.validate()?;
        Ok(Self {
            budget: *budget,
            start: Instant::now(),
            offset,
            evaluations: 0,
            gradients: 0,
            best: placeholder,
            best_value: f64::INFINITY,
            log_best: f64::INFINITY,
            rows: Vec::new(),
            log: Vec::new(),
            progress: None,
        })
    }

    /// A tracker for a search from `starts` (at least one; the first is the best point until
    /// a finite evaluation is offered).
    pub(crate) fn for_starts(budget: &Budget, starts: &[T]) -> Result<Self, ControlError> {
        match starts.first() {
            Some(first) => Self::new(budget, first.clone(), Spent::default()),
            None => Err(ControlError::InvalidSetting {
                what: "start points",
                value: 0.0,
            }),
        }
    }

    /// Reports every closed row to `progress`.
    pub(crate) fn with_progress(mut self, progress: Option<Progress<'a>>) -> Self {
        self.progress = progress;
        self
    }

    /// Evaluations so far, set-up included.
    pub(crate) fn evaluations(&self) -> usize {
        self.offset.evaluations + self.evaluations
    }

    /// How many of `wanted` evaluations the evaluation limit still allows (at least one).
    pub(crate) fn allowance(&self, wanted: usize) -> usize {
        match self.budget.max_evaluations {
            Some(n) => wanted.min(n.saturating_sub(self.evaluations())).max(1),
            None => wanted,
        }
    }

    /// Counts and logs one evaluation with value `f` whose point is kept elsewhere (offer it
    /// with [`Self::offer`] if it may be the best).
    pub(crate) fn counted(&mut self, f: f64) {
        self.evaluations += 1;
        if f.is_finite() && f < self.log_best {
            self.log_best = f;
        }
        self.log.push(Evaluation {
            iteration: self.rows.len(),
            value: f,
            best: self.log_best,
        });
    }

    /// Offers a point evaluated (and counted) elsewhere as the best one.
    pub(crate) fn offer(&mut self, v: &T, f: f64) {
        if f.is_finite() && f < self.best_value {
            self.best_value = f;
            self.best.clone_from(v);
        }
    }

    /// Evaluates `starts` in parallel, then counts, logs and offers each in order; returns
    /// their values, a NaN ranked as +∞.
    pub(crate) fn evaluate_starts<F>(&mut self, starts: &[T], objective: &F) -> Vec<f64>
    where
        T: Sync,
        F: Fn(&T) -> f64 + Sync,
    {
        use rayon::prelude::*;
        let values: Vec<f64> = starts
            .par_iter()
            .map(|x| super::rank_value(objective(x)))
            .collect();
        for (x, f) in starts.iter().zip(&values) {
            self.evaluated(x, *f);
        }
        values
    }

    /// Counts one evaluation of `v` with value `f` and offers it as the best.
    pub(crate) fn evaluated(&mut self, v: &T, f: f64) {
        self.counted(f);
        self.offer(v, f);
    }

    /// Records the row of `iteration` and returns the limit reached, if any.
    pub(crate) fn close(&mut self, iteration: usize, current: f64) -> Option<StopReason> {
        let row = TraceRow {
            iteration,
            evaluations: self.evaluations(),
            gradients: self.offset.gradients + self.gradients,
            seconds: self.offset.seconds + self.start.elapsed().as_secs_f64(),
            best: self.best_value,
            current,
        };
        self.rows.push(row);
        if let Some(p) = self.progress {
            p(&row);
        }
        self.budget.exhausted(&row)
    }

    pub(crate) fn finish(self, stop: StopReason) -> SearchResult<T> {
        SearchResult {
            best: self.best,
            best_value: self.best_value,
            trace: self.rows,
            evaluations: self.log,
            stop,
        }
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
    fn the_tracker_logs_every_evaluation_and_keeps_the_first_best() {
        let mut tr = Tracker::new(&Budget::evaluations(5), 'x', Spent::default()).unwrap();
        tr.evaluated(&'a', 3.0);
        tr.evaluated(&'b', f64::NAN);
        assert_eq!(tr.close(0, 3.0), None);
        assert_eq!(tr.allowance(10), 3);
        tr.evaluated(&'c', 1.0);
        tr.evaluated(&'d', 1.0);
        tr.counted(0.5);
        assert_eq!(tr.close(1, 1.0), Some(StopReason::Evaluations));
        assert_eq!(tr.allowance(10), 1);
        let r = tr.finish(StopReason::Evaluations);
        assert_eq!((r.best, r.best_value), ('c', 1.0));
        let log: Vec<(usize, f64)> = r
            .evaluations
            .iter()
            .map(|e| (e.iteration, e.best))
            .collect();
        assert_eq!(log, vec![(0, 3.0), (0, 3.0), (1, 1.0), (1, 1.0), (1, 0.5)]);
        assert!(r.evaluations[1].value.is_nan());
        assert_eq!(r.trace.len(), 2);
        assert_eq!(r.trace[1].best, 1.0);
    }
}
