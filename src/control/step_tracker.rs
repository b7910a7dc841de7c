//! # LQR trackers of discrete differentiable steps: value functions for tapes learned by BPTT
//!
//! A control tape learned by backpropagation through time through a NeuroAnimator emulator
//! ([`super::bptt`]) is open loop: replayed on the physical simulator it meets states where the
//! net is wrong and drifts. Linear Bellman combination also needs a value function, which a
//! tape lacks. Both come from the same construction as for a DDP trajectory (LBC §5.2): along
//! the emulated tape (x̄_0..x̄_N, one state per super-step, ū_k held over super-step k)
//! linearize the emulator, A_k = ∂N/∂s, B_k = ∂N/∂u at (x̄_k, ū_k), exactly, from n
//! vector–Jacobian products through its transforms and network
//! ([`crate::physics::differentiable::jacobians`]), and run the Riccati recursion of
//! [`super::lqr`] for a quadratic cost: gains K_k and the eq. 12 value function
//! v̂(x, k) = v(x̄_k) + p_kᵀ Δx + ½ Δxᵀ P_k Δx. Applied to the simulator, the control
//! u = ū_k + K_k (x − x̄_k) is held over super-step k and the measured state fed back once per
//! super-step.
//!
//! [`AffineControls`] re-expresses a step in scaled controls u = offset + scale ⊙ v (e.g. the
//! normalized controls of NeuroAnimator's effort term, |v| ≤ 1 within the actuator box), so a
//! tracker's cost and limits can be stated in those units.
//!
//! ## References
//! - M. da Silva, F. Durand, J. Popović, *Linear Bellman Combination for Control of Character
//!   Animation*, SIGGRAPH 2009, §5.2 (eq. 12).
//! - R. Grzeszczuk, D. Terzopoulos, G. Hinton, *NeuroAnimator*, SIGGRAPH 1998, §4–§5.

use super::lqr::{track_linearized, TrackingController};
use super::{ControlError, QuadraticCost};
use crate::control::tracker::ValueTracker;
use crate::physics::differentiable::{jacobians, DifferentiableStep};
use nalgebra::DVector;

/// A step driven by scaled controls: N'(s, v) = N(s, offset + scale ⊙ v).
#[derive(Debug, Clone)]
pub struct AffineControls<'a, D> {
    /// The step in its own control units.
    pub inner: &'a D,
    /// Control at v = 0.
    pub offset: Vec<f64>,
    /// Control change per unit of v.
    pub scale: Vec<f64>,
}

impl<D> AffineControls<'_, D> {
    /// u = offset + scale ⊙ v, written into `u`.
    pub fn to_controls(&self, v: &[f64], u: &mut [f64]) {
        for (j, uj) in u.iter_mut().enumerate() {
            *uj = self.offset[j] + self.scale[j] * v[j];
        }
    }
}

/// Scratch of [`AffineControls`]: the inner step's and the unscaled control.
pub struct AffineScratch<S> {
    inner: S,
    u: Vec<f64>,
}

impl<D: DifferentiableStep> DifferentiableStep for AffineControls<'_, D> {
    type Scratch = AffineScratch<D::Scratch>;
    fn state_dim(&self) -> usize {
        self.inner.state_dim()
    }
    fn control_dim(&self) -> usize {
        self.inner.control_dim()
    }
    fn scratch(&self) -> Self::Scratch {
        AffineScratch {
            inner: self.inner.scratch(),
            u: vec![0.0; self.inner.control_dim()],
        }
    }
    fn step(&self, s: &[f64], v: &[f64], scratch: &mut Self::Scratch, s_next: &mut [f64]) {
        self.to_controls(v, &mut scratch.u);
        self.inner.step(s, &scratch.u, &mut scratch.inner, s_next);
    }
    fn vjp(
        &self,
        s: &[f64],
        v: &[f64],
        s_next_bar: &[f64],
        scratch: &mut Self::Scratch,
        s_bar: &mut [f64],
        v_bar: &mut [f64],
    ) {
        self.to_controls(v, &mut scratch.u);
        self.inner
            .vjp(s, &scratch.u, s_next_bar, &mut scratch.inner, s_bar, v_bar);
        for (b, c) in v_bar.iter_mut().zip(&self.scale) {
            *b *= c;
        }
    }
    fn tape_len(&self) -> usize {
        self.inner.tape_len()
    }
    fn step_taped(
        &self,
        s: &[f64],
        v: &[f64],
        scratch: &mut Self::Scratch,
        s_next: &mut [f64],
        tape: &mut [f64],
    ) {
        self.to_controls(v, &mut scratch.u);
        self.inner
            .step_taped(s, &scratch.u, &mut scratch.inner, s_next, tape);
    }
    fn vjp_taped(
        &self,
        s: &[f64],
        v: &[f64],
        tape: &[f64],
        s_next_bar: &[f64],
        scratch: &mut Self::Scratch,
        s_bar: &mut [f64],
        v_bar: &mut [f64],
    ) {
        self.to_controls(v, &mut scratch.u);
        self.inner.vjp_taped(
            s,
            &scratch.u,
            tape,
            s_next_bar,
            &mut scratch.inner,
            s_bar,
            v_bar,
        );
        for (b, c) in v_bar.iter_mut().zip(&self.scale) {
            *b *= c;
        }
    }
}

/// The LQR tracker of a tape of a discrete differentiable step (an emulator), with its
/// quadratic value function (eq. 12); control step k lasts `hold` seconds (one super-step).
#[derive(Debug, Clone, PartialEq)]
pub struct StepTracker {
    /// Gains, reference and value function, in the step's own state and control units.
    pub lqr: TrackingController,
    /// Duration of one control step (s): the emulator's super-step Δt.
    pub hold: f64,
}

impl StepTracker {
    /// Linearizes `step` along the tape (`xs`: N + 1 states, `us`: N controls; e.g. an
    /// emulator's rollout of a learned tape) by its exact Jacobians and solves the Riccati
    /// recursion for `cost`.
    pub fn build<D: DifferentiableStep>(
        step: &D,
        cost: &QuadraticCost,
        xs: &[DVector<f64>],
        us: &[DVector<f64>],
        hold: f64,
    ) -> Result<Self, ControlError> {
        if !(hold.is_finite() && hold > 0.0) {
            return Err(ControlError::InvalidTimeStep(hold));
        }
        let (n, m) = (step.state_dim(), step.control_dim());
        let mut scratch = step.scratch();
        let (mut adjoint, mut s_bar, mut u_bar) = (vec![0.0; n], vec![0.0; n], vec![0.0; m]);
        let lqr = track_linearized((n, m), cost, xs, us, &mut |_, x, u, a, b| {
            jacobians(
                step,
                x.as_slice(),
                u.as_slice(),
                &mut scratch,
                a,
                b,
                &mut adjoint,
                (&mut s_bar, &mut u_bar),
            )
        })?;
        Ok(Self { lqr, hold })
    }
}

impl ValueTracker for StepTracker {
    fn horizon(&self) -> usize {
        self.lqr.horizon()
    }
    fn state_dim(&self) -> usize {
        ValueTracker::state_dim(&self.lqr)
    }
    fn control_dim(&self) -> usize {
        ValueTracker::control_dim(&self.lqr)
    }
    fn policy_into(&self, x: &[f64], k: usize, u: &mut [f64]) {
        self.lqr.policy_into(x, k, u)
    }
    fn value(&self, x: &[f64], k: usize) -> f64 {
        self.lqr.value(x, k)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::control::bptt::fixtures::{lander_emulator, linear};
    use nalgebra::DMatrix;

    /// Central differences of `step` in each state and control component.
    fn fd_jacobians<D: DifferentiableStep>(
        step: &D,
        s: &[f64],
        u: &[f64],
        h: f64,
    ) -> (DMatrix<f64>, DMatrix<f64>) {
        let (n, m) = (step.state_dim(), step.control_dim());
        let mut sc = step.scratch();
        let (mut a, mut b) = (DMatrix::zeros(n, n), DMatrix::zeros(n, m));
        let (mut p, mut q) = (vec![0.0; n], vec![0.0; n]);
        for c in 0..n + m {
            let (mut sp, mut sm, mut up, mut um) = (s.to_vec(), s.to_vec(), u.to_vec(), u.to_vec());
            let d = if c < n {
                let d = h * s[c].abs().max(1.0);
                sp[c] += d;
                sm[c] -= d;
                d
            } else {
                let d = h * u[c - n].abs().max(1.0);
                up[c - n] += d;
                um[c - n] -= d;
                d
            };
            step.step(&sp, &up, &mut sc, &mut p);
            step.step(&sm, &um, &mut sc, &mut q);
            for r in 0..n {
                let v = (p[r] - q[r]) / (2.0 * d);
                if c < n {
                    a[(r, c)] = v;
                } else {
                    b[(r, c - n)] = v;
                }
            }
        }
        (a, b)
    }

    fn vjp_jacobians<D: DifferentiableStep>(
        step: &D,
        s: &[f64],
        u: &[f64],
    ) -> (DMatrix<f64>, DMatrix<f64>) {
        let (n, m) = (step.state_dim(), step.control_dim());
        let (mut a, mut b) = (DMatrix::zeros(n, n), DMatrix::zeros(n, m));
        let (mut adj, mut sb, mut ub) = (vec![0.0; n], vec![0.0; n], vec![0.0; m]);
        jacobians(
            step,
            s,
            u,
            &mut step.scratch(),
            &mut a,
            &mut b,
            &mut adj,
            (&mut sb, &mut ub),
        );
        (a, b)
    }

    pub(crate) fn lander_affine(
        e: &crate::emulator::Emulator,
    ) -> AffineControls<'_, crate::emulator::Emulator> {
        AffineControls {
            inner: e,
            offset: vec![9000.0, 0.0, 0.0, 0.0],
            scale: vec![9000.0, 400.0, 400.0, 400.0],
        }
    }

    #[test]
    fn emulator_jacobians_from_vjps_match_central_differences() {
        let (e, _, x0) = lander_emulator();
        let step = lander_affine(&e);
        for v in [[0.0, 0.0, 0.0, 0.0], [0.3, -0.5, 0.2, 0.7]] {
            let (a, b) = vjp_jacobians(&step, &x0, &v);
            let (fa, fb) = fd_jacobians(&step, &x0, &v, 1e-6);
            let scale = a.abs().max().max(b.abs().max()).max(1.0);
            let (ea, eb) = ((&a - &fa).abs().max(), (&b - &fb).abs().max());
            assert!(
                ea < 1e-6 * scale && eb < 1e-6 * scale,
                "A off by {ea}, B off by {eb} (scale {scale})"
            );
            // The affine controls scale B's columns and leave A alone.
            let (ai, bi) = vjp_jacobians(
                &e,
                &x0,
                &[
                    9000.0 * (1.0 + v[0]),
                    400.0 * v[1],
                    400.0 * v[2],
                    400.0 * v[3],
                ],
            );
            assert!((&ai - &a).abs().max() == 0.0);
            for c in 0..4 {
                for r in 0..13 {
                    assert!((bi[(r, c)] * step.scale[c] - b[(r, c)]).abs() <= 1e-12 * scale);
                }
            }
        }
    }

    /// Quadratic cost with effort weight `r`, terminal weight `qf` on every state, target `x_t`.
    pub(crate) fn cost(
        dt: f64,
        n: usize,
        m: usize,
        r: f64,
        qf: f64,
        x_t: DVector<f64>,
    ) -> QuadraticCost {
        QuadraticCost {
            dt,
            r: DMatrix::identity(m, m) * r,
            state: None,
            q_final: DMatrix::identity(n, n) * qf,
            x_final: x_t,
        }
    }

    pub(crate) fn rollout<D: DifferentiableStep>(
        d: &D,
        x0: &[f64],
        us: &[DVector<f64>],
    ) -> Vec<DVector<f64>> {
        let mut sc = d.scratch();
        let mut xs = vec![DVector::from_column_slice(x0)];
        let mut next = vec![0.0; x0.len()];
        for u in us {
            d.step(
                xs.last().unwrap().as_slice(),
                u.as_slice(),
                &mut sc,
                &mut next,
            );
            xs.push(DVector::from_column_slice(&next));
        }
        xs
    }

    #[test]
    fn emulator_tracker_value_is_the_remaining_cost_along_its_tape() {
        let (e, _, x0) = lander_emulator();
        let step = lander_affine(&e);
        let us: Vec<DVector<f64>> = (0..12)
            .map(|k| DVector::from_vec(vec![0.1 * (k as f64 * 0.7).sin(), 0.2, -0.1, 0.05]))
            .collect();
        let xs = rollout(&step, &x0, &us);
        let mut target = x0.clone();
        target[0] += 3.0;
        let c = cost(0.5, 13, 4, 0.02, 0.5, DVector::from_vec(target));
        let t = StepTracker::build(&step, &c, &xs, &us, 0.5).unwrap();
        assert_eq!(t.horizon(), 12);
        for k in 0..=12 {
            let remaining = c.total(&xs[k..], &us[k..]);
            // `total` indexes running costs from 0; with no state cost they do not depend on k.
            let v = t.value(xs[k].as_slice(), k);
            assert!(
                (v - remaining).abs() <= 1e-12 * remaining.abs().max(1.0),
                "k = {k}: {v} vs {remaining}"
            );
        }
        // On the tape the policy is the tape.
        let mut u = [0.0; 4];
        t.policy_into(xs[5].as_slice(), 5, &mut u);
        assert_eq!(u.as_slice(), us[5].as_slice());
    }

    #[test]
    fn on_a_linear_step_the_value_is_the_closed_loop_cost_of_a_perturbed_start() {
        let lin = linear();
        let step = AffineControls {
            inner: &lin,
            offset: vec![0.5, -0.2],
            scale: vec![2.0, 0.5],
        };
        let us: Vec<DVector<f64>> = (0..20)
            .map(|k| DVector::from_vec(vec![(k as f64 * 0.4).cos(), 0.3]))
            .collect();
        let x0 = [0.2, -0.1, 0.4];
        let xs = rollout(&step, &x0, &us);
        let c = cost(0.1, 3, 2, 0.3, 2.0, DVector::from_vec(vec![1.0, 0.0, -1.0]));
        let t = StepTracker::build(&step, &c, &xs, &us, 0.1).unwrap();
        for k0 in [0, 7, 19] {
            let mut x: Vec<f64> = xs[k0].iter().map(|v| v + 0.3).collect();
            let predicted = t.value(&x, k0);
            let (mut total, mut sc, mut next, mut u) =
                (0.0, step.scratch(), vec![0.0; 3], vec![0.0; 2]);
            for k in k0..20 {
                t.policy_into(&x, k, &mut u);
                total += c.running(
                    k,
                    &DVector::from_column_slice(&x),
                    &DVector::from_column_slice(&u),
                );
                step.step(&x, &u, &mut sc, &mut next);
                x.copy_from_slice(&next);
            }
            total += c.terminal(&DVector::from_column_slice(&x));
            assert!(
                (predicted - total).abs() < 1e-10 * total.max(1.0),
                "k0 = {k0}: {predicted} vs {total}"
            );
        }
        assert!(matches!(
            StepTracker::build(&step, &c, &xs, &us, 0.0),
            Err(ControlError::InvalidTimeStep(_))
        ));
    }
}
