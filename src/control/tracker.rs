//! # The value-function contract of linear Bellman combination (LBC §5.2)
//!
//! Linear Bellman combination needs, of each component controller i, a policy π_i(x, k) and its
//! value function v_i(x, k); nothing else. [`ValueTracker`] is that contract: a time-indexed
//! feedback policy with its value, over a horizon of N control steps. Two kinds implement it:
//!
//! - [`crate::control::lqr::TrackingController`]: the eq. 12 tracker of a DDP trajectory of a
//!   physical model (RK4 map, analytic or finite-difference Jacobians);
//! - [`crate::control::step_tracker::StepTracker`]: the same Riccati recursion along a tape
//!   learned by backpropagation through time through a NeuroAnimator emulator, linearized by
//!   the emulator's own exact Jacobians (one control step per emulator super-step).
//!
//! Linear Bellman combination (`bellman::combine::TrackerBlend`) combines any implementors
//! (also mixed, through `&dyn ValueTracker`) without knowing where they came from; the
//! contract lives here, beside the trackers, so control knows nothing of its combiner.

/// A time-varying feedback policy with its value function: what linear Bellman combination
/// needs of a component controller.
pub trait ValueTracker {
    /// Horizon N: the policy is defined for steps k = 0..N, the value for k = 0..=N.
    fn horizon(&self) -> usize;
    /// Number of state variables.
    fn state_dim(&self) -> usize;
    /// Number of control variables.
    fn control_dim(&self) -> usize;
    /// Writes the control π(x, k) (k < N) into `u`. Does not allocate.
    fn policy_into(&self, x: &[f64], k: usize, u: &mut [f64]);
    /// The value v(x, k), the cost to go from x at step k.
    fn value(&self, x: &[f64], k: usize) -> f64;
}

impl<T: ValueTracker + ?Sized> ValueTracker for &T {
    fn horizon(&self) -> usize {
        (**self).horizon()
    }
    fn state_dim(&self) -> usize {
        (**self).state_dim()
    }
    fn control_dim(&self) -> usize {
        (**self).control_dim()
    }
    fn policy_into(&self, x: &[f64], k: usize, u: &mut [f64]) {
        (**self).policy_into(x, k, u)
    }
    fn value(&self, x: &[f64], k: usize) -> f64 {
        (**self).value(x, k)
    }
}

impl ValueTracker for crate::control::lqr::TrackingController {
    fn horizon(&self) -> usize {
        crate::control::lqr::TrackingController::horizon(self)
    }
    fn state_dim(&self) -> usize {
        crate::control::lqr::TrackingController::state_dim(self)
    }
    fn control_dim(&self) -> usize {
        crate::control::lqr::TrackingController::control_dim(self)
    }
    fn policy_into(&self, x: &[f64], k: usize, u: &mut [f64]) {
        crate::control::lqr::TrackingController::policy_into(self, x, k, u)
    }
    fn value(&self, x: &[f64], k: usize) -> f64 {
        crate::control::lqr::TrackingController::value(self, x, k)
    }
}
