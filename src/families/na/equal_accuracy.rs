//! Table 2 at equal accuracy: the physical time step whose simulation is as
//! far from the truth as the emulator is.
//!
//! The error is the one `na_table1_structure` reports as `rollout40_error_mean`
//! ([`crate::emulator::catalog::rollout_error`]): from `episodes` start states drawn as for
//! training (the same random stream), the truth (the simulator at the net's δt, which made the
//! emulator's training data) and a candidate run `horizon` super-steps Δt = n δt under the same
//! controls (the training control process, read at each super-step's start and held over it);
//! per super-step, the mean over episodes and state variables of ((ŝ_k − s_k)/σ)², σ each
//! variable's spread over the true states; then the mean over the `horizon` steps. A candidate
//! is the emulator (one prediction per super-step) or the same simulator at a coarser step
//! Δt / j (j steps per super-step, j = 1 … n; j = n is the truth itself, error 0).
//! The true rollouts are [`RolloutReference`]'s, the same that score the emulator in
//! `rollout_error`; this module adds the simulator at a coarser step as a candidate.
//! [`match_substeps`] finds the smallest j, i.e. the largest physical step, whose error is at
//! most the emulator's.

use crate::emulator::catalog::RolloutReference;

impl RolloutReference {
    /// Mean error of the simulator at step Δt / `substeps`.
    pub fn physical_error(&self, substeps: usize) -> f64 {
        let spec = self.spec();
        let mut sim = spec.net.model.simulator();
        let dt = if substeps == spec.steps {
            spec.net.physical_dt
        } else {
            spec.super_dt() / substeps as f64
        };
        self.mean_error(|x, u| {
            // A blown-up state stays NaN (some models cannot step a non-finite state).
            for _ in 0..substeps {
                if !x.iter().all(|v| v.is_finite()) {
                    x.fill(f64::NAN);
                    return;
                }
                sim.step(x, u, dt);
            }
        })
    }
}

/// The result of [`match_substeps`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Matched {
    /// Physical steps per super-step, j.
    pub substeps: usize,
    /// The error with j steps (at most the target).
    pub error: f64,
    /// The error with j − 1 steps (above the target); NaN when j = 1.
    pub coarser_error: f64,
}

/// The smallest j in 1 ..= `max_substeps` whose `error(j)` is at most `target`, scanning j
/// upwards (so the bracket error(j) ≤ target < error(j − 1) holds even if the error is not
/// monotone further on); `None` when no j qualifies.
pub fn match_substeps(
    target: f64,
    max_substeps: usize,
    mut error: impl FnMut(usize) -> f64,
) -> Option<Matched> {
    let mut coarser_error = f64::NAN;
    for j in 1..=max_substeps {
        let e = error(j);
        if e <= target {
            return Some(Matched {
                substeps: j,
                error: e,
                coarser_error,
            });
        }
        coarser_error = e;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emulator::catalog::{rollout_error, train_emulator, BuildSpec, NetModel, NetSpec};

    fn spec(steps: usize) -> BuildSpec {
        let net: NetSpec = serde_json::from_value(serde_json::json!({
            "model": "pendulum_passive", "hidden": 6, "examples": 150, "method": "lbfgs",
            "physical_dt": 0.002
        }))
        .unwrap();
        assert_eq!(net.model, NetModel::PendulumPassive);
        let settings = serde_json::from_value(serde_json::json!({
            "held_out_fraction": 0.25, "cg_max_iters": 40, "max_epochs": 5, "patience": 5,
            "min_improvement": 0.001, "learning_rate": 0.05, "momentum": 0.9, "batch_size": 30
        }))
        .unwrap();
        BuildSpec {
            net,
            steps,
            settings,
            seed: 7,
        }
    }

    #[test]
    fn emulator_error_is_table1s_rollout_error() {
        let s = spec(25);
        let trained = train_emulator(&s).unwrap();
        let reference = RolloutReference::sample(&s, 3, 8).unwrap();
        let ours = reference.errors(|x, u| {
            let mut scratch = trained.emulator.scratch();
            let mut next = vec![0.0; x.len()];
            trained.emulator.predict(x, u, &mut scratch, &mut next);
            x.copy_from_slice(&next);
        });
        assert_eq!(ours, rollout_error(&trained.emulator, &s, 3, 8).unwrap());
        let mean = ours.iter().sum::<f64>() / 8.0;
        assert_eq!(reference.emulator_error(&trained.emulator), mean);
    }

    #[test]
    fn search_brackets_the_target_on_the_pendulum() {
        // N10 at 0.002 s: a 0.02 s super-step, which RK4 takes stably in one step (the
        // pendulum's stiffest decay, 101/s, times 0.02 s is 2.0, inside RK4's 2.78).
        let s = spec(10);
        let reference = RolloutReference::sample(&s, 4, 10).unwrap();
        // The truth itself scores 0; coarser RK4 steps score more, falling with j (order 4).
        assert_eq!(reference.physical_error(10), 0.0);
        let errs: Vec<f64> = (1..=5).map(|j| reference.physical_error(j)).collect();
        eprintln!("pendulum RK4 error at Δt/j, j = 1..5: {errs:?}");
        assert!(errs.windows(2).all(|w| w[1] < w[0]), "{errs:?}");
        assert!(errs[1] < errs[0] / 8.0, "not high order: {errs:?}");
        let target = (errs[0] * errs[4]).sqrt();
        let m = match_substeps(target, 10, |j| reference.physical_error(j)).unwrap();
        assert!(m.substeps > 1 && m.substeps <= 5, "{m:?}");
        assert!(
            m.error <= target && m.coarser_error > target,
            "{m:?} vs {target}"
        );
        assert_eq!(m.error, errs[m.substeps - 1]);
        // A target below anything reachable short of the truth still matches (at j = n).
        assert_eq!(
            match_substeps(0.0, 10, |j| reference.physical_error(j)).map(|m| m.substeps),
            Some(10)
        );
        assert_eq!(match_substeps(-1.0, 3, |j| j as f64), None);
    }
}
