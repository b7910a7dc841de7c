//! # Regularization of the emulated dolphin (NeuroAnimator §5.3)
//!
//! Emulation errors accumulate as small non-physical deformations of the body. Between
//! emulation steps, a [`Regularizer`] performs spring-only semi-implicit Euler steps
//!
//! ```text
//! v ← v + δt a(x, v, u),      x ← x + δt (v − v̄),
//! ```
//!
//! with a(x, v, u) the spring, damping and muscle accelerations of a *softened* body (softer
//! springs, more damping, no hydrodynamics) and v̄ the centre-of-mass velocity, taken out of the
//! position update so that regularizing restores the shape without advancing the flight (it
//! consumes no animation time). A [`Schedule`] says how many such steps follow which emulation
//! steps.
//!
//! ## References
//! - R. Grzeszczuk, D. Terzopoulos, G. Hinton, *NeuroAnimator*, SIGGRAPH 1998, §5.3.

use super::MASS_DIM;
use crate::physics::dolphin::{Dolphin, DolphinParams, N_MASSES, N_POS};
use crate::physics::Ode;
use serde::{Deserialize, Serialize};

/// Regularization steps of §5.3 (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Regularizer {
    /// Step δt (s).
    pub dt: f64,
    /// Spring stiffness relative to the simulator's.
    pub stiffness_scale: f64,
    /// Spring damping relative to the simulator's.
    pub damping_scale: f64,
}

/// A [`Regularizer`] bound to a dolphin: its softened, drag-free body.
#[derive(Debug, Clone)]
pub struct BoundRegularizer {
    soft: Dolphin,
    dt: f64,
    dx: Vec<f64>,
}

impl Regularizer {
    /// The softened body of `d` (no drag, no gravity) that the steps use.
    pub fn bind(
        &self,
        d: &Dolphin,
    ) -> Result<BoundRegularizer, crate::physics::dolphin::DolphinError> {
        let mut p: DolphinParams = d.params().clone();
        p.stiffness *= self.stiffness_scale;
        p.muscle_stiffness *= self.stiffness_scale;
        p.damping *= self.damping_scale;
        p.drag = 0.0;
        p.gravity = 0.0;
        Ok(BoundRegularizer {
            soft: Dolphin::new(p)?,
            dt: self.dt,
            dx: vec![0.0; MASS_DIM],
        })
    }
}

impl BoundRegularizer {
    /// Applies `steps` spring-only Euler steps to the mass state `x` under muscle controls `u`.
    pub fn apply(&mut self, x: &mut [f64], u: &[f64], steps: usize) {
        let h = self.dt;
        for _ in 0..steps {
            self.soft.derivative(x, u, &mut self.dx);
            let (q, v) = x.split_at_mut(N_POS);
            for (vk, ak) in v.iter_mut().zip(&self.dx[N_POS..]) {
                *vk += h * ak;
            }
            // Internal forces leave the centre-of-mass velocity unchanged; moving by the
            // velocity relative to it deforms the body without advancing its flight.
            let masses = self.soft.masses();
            let mut vc = [0.0; 3];
            for (i, m) in masses.iter().enumerate() {
                for a in 0..3 {
                    vc[a] += m * v[3 * i + a];
                }
            }
            let total = self.soft.total_mass();
            vc.iter_mut().for_each(|c| *c /= total);
            for i in 0..N_MASSES {
                for a in 0..3 {
                    q[3 * i + a] += h * (v[3 * i + a] - vc[a]);
                }
            }
        }
    }
}

/// When to regularize: `steps` regularization steps after every `every`-th emulation step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Schedule {
    /// Regularization steps each time.
    pub steps: usize,
    /// Emulation steps between regularizations (1 = after each).
    pub every: usize,
}

impl Schedule {
    /// Whether to regularize after emulation step `k` (1-based count of steps taken).
    pub fn due(&self, k: usize) -> bool {
        self.steps > 0 && self.every > 0 && k.is_multiple_of(self.every)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Regularization pulls a distorted body back toward its rest lengths without moving its
    /// centre of mass, and the schedule fires when due.
    #[test]
    fn regularizer_reduces_shape_error() {
        let d = Dolphin::default();
        let mut x = d.rest_state();
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for q in x[..N_POS].iter_mut() {
            *q += rng.random_range(-0.03..0.03);
        }
        let e0 = d.shape_error(&x);
        let c0 = d.centre_of_mass(&x);
        let mut reg = Regularizer {
            dt: 0.005,
            stiffness_scale: 0.1,
            damping_scale: 0.2,
        }
        .bind(&d)
        .unwrap();
        reg.apply(&mut x, &[0.0; 6], 30);
        assert!(
            d.shape_error(&x) < 0.7 * e0,
            "{} vs {e0}",
            d.shape_error(&x)
        );
        assert!((d.centre_of_mass(&x) - c0).norm() < 1e-9);
        let s = Schedule {
            steps: 25,
            every: 5,
        };
        assert!(!s.due(4) && s.due(5) && s.due(10));
        assert!(!Schedule { steps: 0, every: 1 }.due(1));
    }
}
