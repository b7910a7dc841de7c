//! # Equilibrium anchoring (ours; not in the paper)
//!
//! A model at a known equilibrium, the truck parked with no drive, stays exactly where it is.
//! A net trained on sampled transitions only comes close: the truck net predicted a state
//! change of a few millimetres per second at rest, and from the parking task's start with zero
//! controls it drove 3.5 m in 20 s while the simulator stayed put.
//!
//! An [`Anchor`] makes the net reproduce one example exactly: the network-space input `x₀` of
//! the equilibrium (state and neutral control, through the emulator's local frame and
//! normalization) and the target `y₀` of "no change". The output bias stops being a free
//! weight and becomes a function of the others,
//!
//! ```text
//! b₂ = y₀ − W₂ h(x₀)        so that        N(x₀) = y₀ exactly (to rounding),
//! ```
//!
//! a reparameterization of the p → q → r network with r fewer free weights. Training minimizes
//! the loss L(w) of the projected net ([`Anchor::project`]); its gradient with respect to the
//! remaining weights is the ordinary gradient g plus one backward pass at `x₀` with output
//! cotangent −g_{b₂} ([`Anchor::pull_back`]), which also zeroes the b₂ part. With a local
//! frame, one anchor covers every pose: the truck's frame removes position and heading, so
//! every parked truck encodes to the same `x₀`.
//!
//! The drift check from the anchored state itself then measures the construction, not the
//! fit; `na_table1_structure` adds near-rest checks off the anchor (steered wheels, coasting)
//! for that.

use super::mlp::Mlp;
use super::Transforms;

/// One example the net reproduces exactly: network-space input and target.
#[derive(Debug, Clone, PartialEq)]
pub struct Anchor {
    /// Network input x₀ (normalized, in the local frame).
    pub input: Vec<f64>,
    /// Network target y₀ (normalized state change).
    pub output: Vec<f64>,
}

impl Anchor {
    /// The anchor of the equilibrium `state` under the neutral `control`: the transition
    /// `state → state` encoded by `transforms`.
    pub fn equilibrium(transforms: &Transforms, state: &[f64], control: &[f64]) -> Self {
        let mut input = vec![0.0; state.len() + control.len()];
        let mut output = vec![0.0; state.len()];
        transforms.encode_input(state, control, &mut input);
        transforms.encode_target(state, state, &mut output);
        Self { input, output }
    }

    /// Whether `state` under `control` encodes to this anchor's input (to 1e-12): then the
    /// net's step from it is exact by construction, not by fit.
    pub fn covers(&self, transforms: &Transforms, state: &[f64], control: &[f64]) -> bool {
        let mut z = vec![0.0; self.input.len()];
        transforms.encode_input(state, control, &mut z);
        z.iter()
            .zip(&self.input)
            .all(|(p, q)| (p - q).abs() <= 1e-12)
    }

    /// Sets the output bias of `mlp` so that N(x₀) = y₀.
    pub fn project(&self, mlp: &mut Mlp) {
        let r = mlp.n_out();
        let mut y = vec![0.0; r];
        mlp.forward(&self.input, &mut mlp.scratch(), &mut y);
        let w = mlp.weights_mut();
        let n = w.len();
        for ((b, y), y0) in w[n - r..].iter_mut().zip(&y).zip(&self.output) {
            *b += y0 - y;
        }
    }

    /// [`Anchor::project`] on flat weights of a `(p, q, r)` network.
    pub fn project_weights(&self, (p, q, r): (usize, usize, usize), w: &mut [f64]) {
        let mut mlp = Mlp::from_weights(p, q, r, w.to_vec());
        self.project(&mut mlp);
        w.copy_from_slice(mlp.weights());
    }

    /// Turns `grad`, the gradient of a loss with respect to all weights of the projected net
    /// `mlp` (b₂ treated as free), into the gradient of the loss of the projected net with
    /// respect to the weights: adds the backward pass at x₀ with cotangent −∂L/∂b₂, which
    /// leaves the b₂ part zero.
    pub fn pull_back(&self, mlp: &Mlp, grad: &mut [f64]) {
        let r = mlp.n_out();
        let n = grad.len();
        let y_bar: Vec<f64> = grad[n - r..].iter().map(|g| -g).collect();
        let mut scratch = mlp.scratch();
        let mut y = vec![0.0; r];
        mlp.forward(&self.input, &mut scratch, &mut y);
        mlp.backward(&self.input, &mut scratch, &y_bar, Some(grad), None);
        // Exactly zero (the sum g + (−g) is exact; this only removes a −0.0).
        grad[n - r..].iter_mut().for_each(|g| *g = 0.0);
    }

    /// Largest |N(x₀) − y₀| of `mlp` (network units; 0 to rounding after [`Anchor::project`]).
    pub fn residual(&self, mlp: &Mlp) -> f64 {
        let mut y = vec![0.0; mlp.n_out()];
        mlp.forward(&self.input, &mut mlp.scratch(), &mut y);
        y.iter()
            .zip(&self.output)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emulator::mlp::WeightInit;
    use ndarray::Array2;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn net_and_anchor(seed: u64) -> (Mlp, Anchor, Array2<f64>, Array2<f64>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mlp = Mlp::new(5, 7, 3, WeightInit::FanIn, &mut rng);
        let mut v = |n: usize| (0..n).map(|_| rng.random::<f64>() * 2.0 - 1.0).collect();
        let anchor = Anchor {
            input: v(5),
            output: v(3),
        };
        let x = Array2::from_shape_vec((9, 5), v(45)).unwrap();
        let t = Array2::from_shape_vec((9, 3), v(27)).unwrap();
        (mlp, anchor, x, t)
    }

    #[test]
    fn projection_makes_the_anchor_exact_and_keeps_the_other_weights() {
        let (mut mlp, anchor, _, _) = net_and_anchor(1);
        let before = mlp.weights().to_vec();
        assert!(anchor.residual(&mlp) > 0.1);
        anchor.project(&mut mlp);
        assert!(anchor.residual(&mlp) < 1e-14, "{}", anchor.residual(&mlp));
        let n = before.len();
        assert_eq!(&mlp.weights()[..n - 3], &before[..n - 3]);
        // Idempotent up to rounding.
        let once = mlp.weights().to_vec();
        anchor.project(&mut mlp);
        for (a, b) in mlp.weights().iter().zip(&once) {
            assert!((a - b).abs() < 1e-14);
        }
    }

    /// The pulled-back gradient is the derivative of w ↦ loss(project(w)), checked by central
    /// differences on every weight; its b₂ part is zero.
    #[test]
    fn pulled_back_gradient_matches_finite_differences_of_the_projected_loss() {
        let (mlp, anchor, x, t) = net_and_anchor(2);
        let shape = (5, 7, 3);
        let loss = |w: &[f64]| {
            let mut w = w.to_vec();
            anchor.project_weights(shape, &mut w);
            Mlp::from_weights(5, 7, 3, w).loss(x.view(), t.view())
        };
        let mut w = mlp.weights().to_vec();
        anchor.project_weights(shape, &mut w);
        let projected = Mlp::from_weights(5, 7, 3, w.clone());
        let mut g = vec![0.0; w.len()];
        projected.loss_grad(x.view(), t.view(), &mut g);
        anchor.pull_back(&projected, &mut g);
        let n = w.len();
        assert!(g[n - 3..].iter().all(|v| *v == 0.0));
        let h = 1e-6;
        for k in 0..n {
            let (mut a, mut b) = (w.clone(), w.clone());
            a[k] += h;
            b[k] -= h;
            let fd = (loss(&a) - loss(&b)) / (2.0 * h);
            assert!(
                (fd - g[k]).abs() <= 1e-7 * (1.0 + fd.abs()),
                "weight {k}: finite difference {fd}, gradient {}",
                g[k]
            );
        }
    }
}
