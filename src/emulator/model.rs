//! The emulator type ([`Emulator`]): transforms and network composed into one super
//! timestep, its construction, accessors, prediction, Jacobians and one-step error.

use super::mlp::Mlp;
use super::{predict_with, EmulatorError, EmulatorScratch, Transforms, Transitions};
use ndarray::{Array2, ArrayView2};

/// A NeuroAnimator: transforms + network, one call = one super timestep Δt.
#[derive(Debug, Clone)]
pub struct Emulator {
    pub(super) transforms: Transforms,
    pub(super) mlp: Mlp,
    pub(super) dt: f64,
    pub(super) scratch: EmulatorScratch,
}

impl Emulator {
    /// Composes `transforms` and `mlp` into an emulator with super timestep `dt` seconds.
    pub fn new(transforms: Transforms, mlp: Mlp, dt: f64) -> Result<Self, EmulatorError> {
        let (n, m) = (transforms.state_dim, transforms.control_dim);
        if !(dt.is_finite() && dt > 0.0) {
            return Err(EmulatorError::TimeStep(dt));
        }
        if mlp.n_in() != n + m {
            return Err(EmulatorError::Dimension {
                what: "network inputs",
                expected: n + m,
                got: mlp.n_in(),
            });
        }
        if mlp.n_out() != n {
            return Err(EmulatorError::Dimension {
                what: "network outputs",
                expected: n,
                got: mlp.n_out(),
            });
        }
        let scratch = Self::make_scratch(&mlp, n, m);
        Ok(Self {
            transforms,
            mlp,
            dt,
            scratch,
        })
    }

    pub(super) fn make_scratch(mlp: &Mlp, n: usize, m: usize) -> EmulatorScratch {
        EmulatorScratch {
            z: vec![0.0; n + m],
            y: vec![0.0; n],
            z_bar: vec![0.0; n + m],
            y_bar: vec![0.0; n],
            t1: vec![0.0; n],
            t2: vec![0.0; n],
            s_next: vec![0.0; n],
            mlp: mlp.scratch(),
        }
    }

    /// Scratch for [`Emulator::predict`] and [`crate::physics::DifferentiableStep::vjp`] (one per thread).
    pub fn scratch(&self) -> EmulatorScratch {
        Self::make_scratch(
            &self.mlp,
            self.transforms.state_dim,
            self.transforms.control_dim,
        )
    }

    /// The super timestep Δt in seconds.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// The transforms.
    pub fn transforms(&self) -> &Transforms {
        &self.transforms
    }

    /// The network.
    pub fn mlp(&self) -> &Mlp {
        &self.mlp
    }

    /// The network, mutably (e.g. to load trained weights; the shape must not change).
    pub fn mlp_mut(&mut self) -> &mut Mlp {
        &mut self.mlp
    }

    /// One super timestep: writes s_{t+Δt} for state `s` and control `u` into `s_next`.
    pub fn predict(&self, s: &[f64], u: &[f64], scratch: &mut EmulatorScratch, s_next: &mut [f64]) {
        predict_with(&self.transforms, &self.mlp, s, u, scratch, s_next);
    }

    /// Jacobians A = ∂s'/∂s (n × n) and B = ∂s'/∂u (n × m) at (s, u), one VJP per row.
    pub fn jacobians(&self, s: &[f64], u: &[f64]) -> (Array2<f64>, Array2<f64>) {
        let (n, m) = (self.transforms.state_dim, self.transforms.control_dim);
        let mut a = Array2::zeros((n, n));
        let mut b = Array2::zeros((n, m));
        let mut scratch = self.scratch();
        let mut e = vec![0.0; n];
        let mut sb = vec![0.0; n];
        let mut ub = vec![0.0; m];
        for i in 0..n {
            e.fill(0.0);
            e[i] = 1.0;
            crate::physics::DifferentiableStep::vjp(self, s, u, &e, &mut scratch, &mut sb, &mut ub);
            a.row_mut(i).assign(&ndarray::ArrayView1::from(&sb));
            b.row_mut(i).assign(&ndarray::ArrayView1::from(&ub));
        }
        (a, b)
    }

    /// Mean squared error per state variable of one-step predictions on `data`, in world units.
    pub fn one_step_error(&self, data: &Transitions) -> f64 {
        let n = self.transforms.state_dim;
        let mut scratch = self.scratch();
        let mut s1 = vec![0.0; n];
        let mut total = 0.0;
        for r in 0..data.len() {
            let s = data.states.row(r).to_vec();
            let u = data.controls.row(r).to_vec();
            self.predict(&s, &u, &mut scratch, &mut s1);
            total += s1
                .iter()
                .zip(data.next_states.row(r))
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>();
        }
        total / (data.len() * n).max(1) as f64
    }

    /// Batch of network inputs for `states`/`controls` rows (for inspection and tests).
    pub fn encode_inputs(
        &self,
        states: ArrayView2<'_, f64>,
        controls: ArrayView2<'_, f64>,
    ) -> Array2<f64> {
        let (n, m) = (self.transforms.state_dim, self.transforms.control_dim);
        let mut out = Array2::zeros((states.nrows(), n + m));
        let mut z = vec![0.0; n + m];
        for r in 0..states.nrows() {
            let s = states.row(r).to_vec();
            let u = controls.row(r).to_vec();
            self.transforms.encode_input(&s, &u, &mut z);
            out.row_mut(r).assign(&ndarray::ArrayView1::from(&z));
        }
        out
    }
}
