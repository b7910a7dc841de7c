//! # Blend weights of linear Bellman combination (LBC eq. 1, 11; §5.2)
//!
//! With component value functions v_i and fixed weights w_i, the combined reward is
//! z = Σ w_i exp(−v_i/λ) and the combined policy is π = Σ α_i π_i with
//!
//! α_i(x, t) = w_i exp(−v_i(x, t)/λ) / Σ_j w_j exp(−v_j(x, t)/λ).
//!
//! Costs of a few hundred underflow exp(−v) in double precision, so everything here runs in log
//! space: with m = max_i(−v_i/λ), α_i = w_i e^{−v_i/λ − m} / Σ_j w_j e^{−v_j/λ − m}, and the
//! combined value is v = −λ (m + log Σ_j w_j e^{−v_j/λ − m}). Weights may be negative
//! (projection can produce them) as long as the combined reward stays positive.
//!
//! A *naive blend* for comparison uses the fixed normalized weights w_i / Σ w_j, ignoring
//! the z_i.
//!
//! ## References
//! - M. da Silva, F. Durand, J. Popović, *Linear Bellman Combination for Control of Character
//!   Animation*, SIGGRAPH 2009, eq. 1, 11 and §5.2.

use crate::control::tracker::ValueTracker;

/// Errors of the combination.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CombineError {
    /// The weighted reward Σ w_i z_i is not positive (negative weights dominate).
    #[error("combined reward is not positive (sum of w_i z_i = {0:e} in scaled units)")]
    NonPositiveReward(f64),
    /// A value or weight is NaN or infinite.
    #[error("non-finite value or weight")]
    NonFinite,
    /// Lengths of the inputs differ, or there are no components.
    #[error("expected {expected} components, got {got}")]
    Length {
        /// Number of weights.
        expected: usize,
        /// Number of values or outputs.
        got: usize,
    },
}

/// Writes α_i = w_i e^{−v_i/λ} / Σ_j w_j e^{−v_j/λ} into `alpha`; returns the combined value
/// −λ log Σ_j w_j e^{−v_j/λ}. Stable for costs of any magnitude.
pub fn blend_weights(
    weights: &[f64],
    values: &[f64],
    lambda: f64,
    alpha: &mut [f64],
) -> Result<f64, CombineError> {
    let n = weights.len();
    if n == 0 || values.len() != n || alpha.len() != n {
        return Err(CombineError::Length {
            expected: n,
            got: values.len().min(alpha.len()),
        });
    }
    if !lambda.is_finite() || lambda <= 0.0 {
        return Err(CombineError::NonFinite);
    }
    let mut m = f64::NEG_INFINITY;
    for (&w, &v) in weights.iter().zip(values) {
        if !w.is_finite() || !v.is_finite() {
            return Err(CombineError::NonFinite);
        }
        if w != 0.0 {
            m = m.max(-v / lambda);
        }
    }
    if !m.is_finite() {
        return Err(CombineError::NonPositiveReward(0.0));
    }
    let mut s = 0.0;
    for i in 0..n {
        alpha[i] = weights[i] * crate::portable::exp(-values[i] / lambda - m);
        s += alpha[i];
    }
    if s <= 0.0 || !s.is_finite() {
        return Err(CombineError::NonPositiveReward(s));
    }
    for a in alpha.iter_mut() {
        *a /= s;
    }
    Ok(-lambda * (m + crate::portable::ln(s)))
}

/// The combined value −λ log Σ_i w_i e^{−v_i/λ}.
pub fn combined_value(weights: &[f64], values: &[f64], lambda: f64) -> Result<f64, CombineError> {
    let mut scratch = vec![0.0; weights.len()];
    blend_weights(weights, values, lambda, &mut scratch)
}

/// Fixed normalized weights w_i / Σ w_j of the naive blend.
pub fn naive_weights(weights: &[f64]) -> Vec<f64> {
    let s: f64 = weights.iter().sum();
    weights.iter().map(|w| w / s).collect()
}

/// Σ_i α_i u_i: the blend of component controls `controls[i]` (each of length m) into `out`.
pub fn blend_controls(alpha: &[f64], controls: &[&[f64]], out: &mut [f64]) {
    out.iter_mut().for_each(|o| *o = 0.0);
    for (a, u) in alpha.iter().zip(controls) {
        for (o, &ui) in out.iter_mut().zip(u.iter()) {
            *o += a * ui;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_stay_finite_for_large_costs() {
        let mut a = [0.0; 3];
        let v = blend_weights(&[1.0, 1.0, 1.0], &[1e4, 1e4 + 1.0, 2e4], 1.0, &mut a).unwrap();
        assert!(a.iter().all(|x| x.is_finite()));
        let e = (1.0f64).exp();
        assert!((a[0] - e / (e + 1.0)).abs() < 1e-12, "{a:?}");
        assert!(a[2] == 0.0 || a[2] < 1e-300);
        // v = 1e4 - log(1 + e^-1)
        assert!(
            (v - (1e4 - (1.0 + (-1.0f64).exp()).ln())).abs() < 1e-9,
            "{v}"
        );
    }

    #[test]
    fn matches_direct_formula_for_moderate_costs() {
        let w = [0.3, 1.2, 0.5];
        let v = [2.0, 3.5, 0.7];
        let lambda = 0.8;
        let mut a = [0.0; 3];
        let cv = blend_weights(&w, &v, lambda, &mut a).unwrap();
        let z: Vec<f64> = w
            .iter()
            .zip(&v)
            .map(|(w, v)| w * (-v / lambda).exp())
            .collect();
        let s: f64 = z.iter().sum();
        for i in 0..3 {
            assert!((a[i] - z[i] / s).abs() < 1e-14);
        }
        assert!((cv + lambda * s.ln()).abs() < 1e-12);
        assert!((a.iter().sum::<f64>() - 1.0).abs() < 1e-14);
    }

    #[test]
    fn negative_weights_allowed_while_reward_positive() {
        let mut a = [0.0; 2];
        assert!(blend_weights(&[1.5, -0.2], &[0.0, 0.0], 1.0, &mut a).is_ok());
        assert!(matches!(
            blend_weights(&[0.1, -0.2], &[0.0, 0.0], 1.0, &mut a),
            Err(CombineError::NonPositiveReward(_))
        ));
        assert!(matches!(
            blend_weights(&[1.0], &[f64::NAN], 1.0, &mut a[..1]),
            Err(CombineError::NonFinite)
        ));
    }

    #[test]
    fn lambda_scales_between_a_switch_and_a_uniform_blend() {
        // Values of three components; component 1 is cheapest.
        let (w, v) = ([1.0, 1.0, 1.0], [12.0, 3.0, 7.5]);
        let mut a = [0.0; 3];
        let mut last_entropy = -1.0;
        for lambda in [0.01, 0.1, 1.0, 10.0, 100.0, 1e4] {
            blend_weights(&w, &v, lambda, &mut a).unwrap();
            let h = normalized_entropy(&a);
            assert!(
                h > last_entropy,
                "entropy must grow with lambda: {h} at {lambda}"
            );
            last_entropy = h;
        }
        // Small lambda: a switch to the cheapest component.
        blend_weights(&w, &v, 0.01, &mut a).unwrap();
        assert!(a[1] > 1.0 - 1e-12 && normalized_entropy(&a) < 1e-9, "{a:?}");
        // Large lambda: uniform (the fixed weights).
        blend_weights(&w, &v, 1e6, &mut a).unwrap();
        assert!(a.iter().all(|x| (x - 1.0 / 3.0).abs() < 1e-5), "{a:?}");
        assert!(normalized_entropy(&a) > 1.0 - 1e-9);
        // Large lambda with unequal weights tends to w / sum(w), the naive blend.
        blend_weights(&[3.0, 1.0, 0.0], &v, 1e6, &mut a).unwrap();
        assert!(
            (a[0] - 0.75).abs() < 1e-5 && (a[1] - 0.25).abs() < 1e-5,
            "{a:?}"
        );
        // Only value differences matter: shifting every value leaves alpha unchanged.
        let mut b = [0.0; 3];
        blend_weights(&w, &v, 2.0, &mut a).unwrap();
        blend_weights(&w, &[v[0] + 1e3, v[1] + 1e3, v[2] + 1e3], 2.0, &mut b).unwrap();
        for i in 0..3 {
            assert!((a[i] - b[i]).abs() < 1e-12);
        }
    }

    #[test]
    fn blend_controls_is_a_weighted_sum() {
        let mut out = [0.0; 2];
        blend_controls(&[0.25, 0.75], &[&[4.0, 0.0], &[0.0, 8.0]], &mut out);
        assert_eq!(out, [1.0, 6.0]);
    }

    #[test]
    fn an_emulator_tracker_and_a_ddp_tracker_combine_through_one_blend() {
        use crate::control::bptt::fixtures::lander_emulator;
        use crate::control::lqr::track;
        use crate::control::step_tracker::tests::{cost, lander_affine, rollout};
        use crate::control::step_tracker::StepTracker;
        use crate::control::test_models::LinearOde;
        use crate::control::{Rk4Map, StateCost};
        use nalgebra::{DMatrix, DVector};
        // An emulator-derived tracker (13 states, 4 controls) and an LQR/DDP tracker of a linear
        // ODE of the same dimensions, over the same horizon.
        let (e, _, x0) = lander_emulator();
        let step = lander_affine(&e);
        let horizon = 6;
        let us: Vec<DVector<f64>> = (0..horizon)
            .map(|_| DVector::from_element(4, 0.1))
            .collect();
        let xs = rollout(&step, &x0, &us);
        let c = cost(0.5, 13, 4, 0.02, 0.05, xs[horizon].clone());
        let emu = StepTracker::build(&step, &c, &xs, &us, 0.5).unwrap();
        let ode = LinearOde {
            a: DMatrix::from_fn(13, 13, |i, j| if j == (i + 1) % 13 { 0.1 } else { 0.0 }),
            b: DMatrix::from_fn(13, 4, |i, j| if i % 4 == j { 1.0 } else { 0.0 }),
        };
        let map = Rk4Map::new(ode, 0.5).unwrap();
        let mut c2 = c.clone();
        c2.state = Some(StateCost {
            weight: DMatrix::identity(13, 13) * 0.01,
            reference: vec![xs[0].clone()],
        });
        let xs2 = map.rollout(&xs[0], &us).unwrap();
        c2.x_final = &xs2[horizon] + DVector::from_element(13, 0.5);
        let ddp = track(&map, &c2, &xs2, &us).unwrap();
        let parts: [&dyn ValueTracker; 2] = [&emu, &ddp];
        let x: Vec<f64> = xs[2]
            .iter()
            .zip(xs2[2].iter())
            .map(|(a, b)| 0.5 * (a + b))
            .collect();
        let (mut u, mut alpha, mut ui) = ([0.0; 4], [0.0; 2], [0.0; 4]);
        let (mut u1, mut u2) = ([0.0; 4], [0.0; 4]);
        emu.policy_into(&x, 2, &mut u1);
        ddp.policy_into(&x, 2, &mut u2);
        let (w, lambda) = ([0.7, 0.4], 3.0);
        let mut expect = [0.0; 2];
        blend_weights(
            &w,
            &[emu.value(&x, 2), ddp.value(&x, 2)],
            lambda,
            &mut expect,
        )
        .unwrap();
        assert!(expect[0] > 1e-3 && expect[1] > 1e-3, "{expect:?}");
        for (mode, a) in [
            (BlendMode::Lbc, expect),
            (BlendMode::Naive, [w[0] / 1.1, w[1] / 1.1]),
            (BlendMode::Single(1), [0.0, 1.0]),
        ] {
            let blend = TrackerBlend {
                trackers: &parts,
                weights: w.to_vec(),
                lambda,
                mode,
                limits: None,
            };
            blend.control(&x, 2, &mut u, &mut alpha, &mut ui).unwrap();
            for j in 0..4 {
                let want = a[0] * u1[j] + a[1] * u2[j];
                assert!(
                    (u[j] - want).abs() < 1e-12 * want.abs().max(1.0),
                    "{mode:?}"
                );
            }
            for i in 0..2 {
                assert!(
                    (alpha[i] - a[i]).abs() < 1e-12,
                    "{mode:?}: {alpha:?} vs {a:?}"
                );
            }
        }
    }
}

/// How the component controllers of a [`TrackerBlend`] are combined.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BlendMode {
    /// One component alone.
    Single(usize),
    /// Fixed normalized weights w_i / Σ w_j (the naive blend as an average).
    Naive,
    /// Fixed weights w_i, not normalized: Σ w_i π_i (with w = 1, the sum of the component
    /// controls, the naive blend as LBC §6.2 describes it: "simply sums the results").
    Sum,
    /// Linear Bellman combination: α_i ∝ w_i exp(−v̂_i(x, t)/λ).
    Lbc,
}

/// A policy combining tracking controllers (LBC §5.2):
/// π(x, t) = Σ α_i(x, t) π_i(x, t), e.g. π_i = ū_i(t) + K_i(t) Δx_i. The components are any
/// [`ValueTracker`]s (DDP/LQR trackers, emulator-derived trackers, or a mix through
/// `&dyn ValueTracker`); the blend asks only for their policies and values.
#[derive(Debug, Clone)]
pub struct TrackerBlend<'a, T = crate::control::lqr::TrackingController> {
    /// The component trackers (same state and control dimensions and horizon).
    pub trackers: &'a [T],
    /// Fixed weights w.
    pub weights: Vec<f64>,
    /// Temperature λ of z = exp(−v/λ).
    pub lambda: f64,
    /// How to combine.
    pub mode: BlendMode,
    /// Symmetric actuator limits |u_j| ≤ `limits[j]` applied to the blended control (the
    /// combined policy drives the same torque-limited character as its components).
    pub limits: Option<&'a [f64]>,
}

impl<T: ValueTracker> TrackerBlend<'_, T> {
    /// Writes the control at state `x`, step `k` into `u` (clamped to `limits`) and the blend
    /// weights into `alpha` (scratch `ui` of the control's length). Does not allocate.
    pub fn control(
        &self,
        x: &[f64],
        k: usize,
        u: &mut [f64],
        alpha: &mut [f64],
        ui: &mut [f64],
    ) -> Result<(), CombineError> {
        let n = self.trackers.len();
        match self.mode {
            BlendMode::Single(i) => {
                alpha
                    .iter_mut()
                    .enumerate()
                    .for_each(|(j, a)| *a = (j == i) as u8 as f64);
            }
            BlendMode::Naive => {
                let s: f64 = self.weights.iter().sum();
                for (a, w) in alpha.iter_mut().zip(&self.weights) {
                    *a = w / s;
                }
            }
            BlendMode::Sum => alpha.copy_from_slice(&self.weights),
            BlendMode::Lbc => {
                let mut values = [0.0f64; 16];
                assert!(n <= values.len(), "at most 16 components");
                for (v, t) in values.iter_mut().zip(self.trackers) {
                    *v = t.value(x, k);
                }
                blend_weights(&self.weights, &values[..n], self.lambda, alpha)?;
            }
        }
        u.iter_mut().for_each(|v| *v = 0.0);
        for (t, &a) in self.trackers.iter().zip(alpha.iter()) {
            if a == 0.0 {
                continue;
            }
            t.policy_into(x, k, ui);
            for (o, &c) in u.iter_mut().zip(ui.iter()) {
                *o += a * c;
            }
        }
        if let Some(limits) = self.limits {
            for (o, &l) in u.iter_mut().zip(limits) {
                *o = o.clamp(-l, l);
            }
        }
        Ok(())
    }
}

/// Normalized entropy −Σ α_i ln α_i / ln n of blend weights, in [0, 1]: 0 when one component
/// has all the weight (a switch), 1 when the weights are uniform. 0 for a single component.
pub fn normalized_entropy(alpha: &[f64]) -> f64 {
    if alpha.len() < 2 {
        return 0.0;
    }
    let h: f64 = alpha
        .iter()
        .filter(|&&a| a > 0.0)
        .map(|&a| -a * crate::portable::ln(a))
        .sum();
    // + 0.0 turns the −0 of a single full weight into 0.
    h / crate::portable::ln(alpha.len() as f64) + 0.0
}
