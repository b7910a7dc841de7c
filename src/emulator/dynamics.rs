//! The emulator as a simulator ([`Dynamics`]) and as a differentiable step for
//! backpropagation through time ([`crate::physics::DifferentiableStep`]).

use super::step::{step_through, vjp_from_forward};
use super::{predict_with, step_vjp, Emulator, EmulatorScratch};
use crate::physics::Dynamics;

impl Dynamics for Emulator {
    fn state_dim(&self) -> usize {
        self.transforms.state_dim
    }

    fn control_dim(&self) -> usize {
        self.transforms.control_dim
    }

    /// One super timestep.
    ///
    /// # Panics
    ///
    /// When `dt` differs from the emulator's Δt by more than 1e-9 relative: an emulator can
    /// only take the step it was trained for.
    fn step(&mut self, x: &mut [f64], u: &[f64], dt: f64) {
        assert!(
            (dt - self.dt).abs() <= 1e-9 * self.dt.abs().max(1.0),
            "emulator trained for Δt = {} s was stepped with dt = {dt} s",
            self.dt
        );
        let Self {
            transforms,
            mlp,
            scratch,
            ..
        } = self;
        let mut s_next = std::mem::take(&mut scratch.s_next);
        predict_with(transforms, mlp, x, u, scratch, &mut s_next);
        x.copy_from_slice(&s_next);
        scratch.s_next = s_next;
    }
}

/// The emulator as a differentiable step for backpropagation through time (§4.3).
impl crate::physics::DifferentiableStep for Emulator {
    type Scratch = EmulatorScratch;
    fn state_dim(&self) -> usize {
        Dynamics::state_dim(self)
    }
    fn control_dim(&self) -> usize {
        Dynamics::control_dim(self)
    }
    fn scratch(&self) -> EmulatorScratch {
        Emulator::scratch(self)
    }
    fn step(&self, s: &[f64], u: &[f64], scratch: &mut EmulatorScratch, s_next: &mut [f64]) {
        self.predict(s, u, scratch, s_next);
    }
    /// Vector–Jacobian product of one step: given s̄' = ∂J/∂s_{t+Δt}, writes
    /// `s_bar` = (∂s'/∂s)ᵀ s̄' and `u_bar` = (∂s'/∂u)ᵀ s̄' (both overwritten). Recomputes the
    /// forward pass at (s, u). Does not allocate.
    fn vjp(
        &self,
        s: &[f64],
        u: &[f64],
        s_next_bar: &[f64],
        scratch: &mut EmulatorScratch,
        s_bar: &mut [f64],
        u_bar: &mut [f64],
    ) {
        s_bar.fill(0.0);
        step_vjp(
            &self.transforms,
            &self.mlp,
            s,
            u,
            s_next_bar,
            scratch,
            s_bar,
            u_bar,
            None,
        );
    }
    /// The network input z, output y and hidden activations h of the step, and what the frame
    /// keeps of itself ([`Transforms::frame_tape_len`]).
    ///
    /// [`Transforms::frame_tape_len`]: super::Transforms::frame_tape_len
    fn tape_len(&self) -> usize {
        let (n, m) = (self.transforms.state_dim, self.transforms.control_dim);
        (n + m) + n + self.mlp.n_hidden() + self.transforms.frame_tape_len()
    }
    fn step_taped(
        &self,
        s: &[f64],
        u: &[f64],
        scratch: &mut EmulatorScratch,
        s_next: &mut [f64],
        tape: &mut [f64],
    ) {
        let (z, rest) = tape.split_at_mut(self.transforms.state_dim + self.transforms.control_dim);
        let (y, rest) = rest.split_at_mut(self.transforms.state_dim);
        let (h, frame) = rest.split_at_mut(self.mlp.n_hidden());
        step_through(
            &self.transforms,
            &self.mlp,
            s,
            u,
            (z, y, h),
            frame,
            &mut scratch.t1,
            s_next,
        );
    }
    fn vjp_taped(
        &self,
        s: &[f64],
        u: &[f64],
        tape: &[f64],
        s_next_bar: &[f64],
        scratch: &mut EmulatorScratch,
        s_bar: &mut [f64],
        u_bar: &mut [f64],
    ) {
        let _ = u;
        let n = self.transforms.state_dim;
        let (z, rest) = tape.split_at(n + self.transforms.control_dim);
        let (y, rest) = rest.split_at(n);
        let (h, frame) = rest.split_at(self.mlp.n_hidden());
        s_bar.fill(0.0);
        vjp_from_forward(
            &self.transforms,
            &self.mlp,
            s,
            (z, y, h),
            Some(frame),
            s_next_bar,
            scratch,
            s_bar,
            u_bar,
            None,
        );
    }
}
