//! The settings of each method: the BPTT runs, the gradient-free searches' budgets per
//! substrate, simulated annealing, Nelder–Mead and parallel hill climbing.

use crate::control::search::{AnnealingConfig, Budget, Geometric};
use crate::experiment::resolve::{ensure, positive, ParamError};
use serde::{Deserialize, Serialize};

/// The BPTT runs.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BpttSettings {
    /// Gradient steps per run (the paper: about 20).
    pub iterations: usize,
    /// Momentum learning rate η (units of 1/λ).
    pub eta: f64,
    /// Momentum α.
    pub alpha: f64,
    /// Plain-descent learning rate η (units of 1/λ).
    pub plain_eta: f64,
}

/// The budget of every gradient-free search on one substrate.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SearchBudget {
    /// Objective evaluations (rollouts), the initialization's included.
    pub evaluations: usize,
    /// Optional wall-clock limit per search (s); makes the traces timing-dependent.
    #[serde(default)]
    pub seconds: Option<f64>,
}

impl SearchBudget {
    pub(super) fn budget(&self) -> Budget {
        let b = Budget::evaluations(self.evaluations);
        match self.seconds {
            Some(s) => b.with_seconds(s),
            None => b,
        }
    }

    pub(super) fn validate(&self, key: &str) -> Result<(), ParamError> {
        ensure(
            self.evaluations >= 2,
            &format!("{key}.evaluations"),
            "must be >= 2",
        )?;
        if let Some(s) = self.seconds {
            positive(&format!("{key}.seconds"), s)?;
        }
        Ok(())
    }
}

/// Budgets per substrate.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Budgets {
    /// Searches on the global net.
    pub emulator: SearchBudget,
    /// Searches on the physical simulator.
    pub simulator: SearchBudget,
}

/// Simulated annealing ([`AnnealingConfig`]); temperature and step cool geometrically from
/// their start to their end values over the substrate's evaluation budget.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AnnealingSettings {
    /// Perturbed copies of the start evaluated first (they set the temperature scale).
    pub initial_samples: usize,
    /// Initial temperature, in units of the spread of those samples' J.
    pub start_temperature: f64,
    /// Final temperature (same units).
    pub end_temperature: f64,
    /// Initial proposal standard deviation, in half-widths of the box.
    pub step: f64,
    /// Final proposal standard deviation.
    pub end_step: f64,
}

impl AnnealingSettings {
    pub(super) fn config(&self, evaluations: usize) -> AnnealingConfig {
        let planned = evaluations.saturating_sub(self.initial_samples + 1).max(2);
        AnnealingConfig {
            initial_samples: self.initial_samples,
            temperature: Geometric::over(self.start_temperature, self.end_temperature, planned),
            step: Geometric::over(self.step, self.end_step, planned),
        }
    }
}

/// Nelder–Mead ([`SimplexConfig`](crate::control::search::SimplexConfig)).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimplexSettings {
    /// Edge of the initial simplex, in half-widths.
    pub step: f64,
    /// Convergence tolerance on the vertex values' standard deviation.
    pub sd_tolerance: f64,
    /// Weight of the squared distance outside the box.
    pub penalty: f64,
    /// Restarts after a convergence that improved the best point.
    pub restarts: usize,
}

/// Parallel hill climbing ([`ClimbConfig`](crate::control::search::ClimbConfig)).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClimbSettings {
    /// Proposals per iteration.
    pub batch: usize,
    /// Initial and largest step, in half-widths.
    pub step: f64,
    /// Step factor after a batch without improvement.
    pub shrink: f64,
    /// Step factor after an improvement.
    pub grow: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn annealing_cools_from_start_to_end_over_the_budget() {
        let a = AnnealingSettings {
            initial_samples: 8,
            start_temperature: 0.5,
            end_temperature: 0.005,
            step: 0.1,
            end_step: 0.01,
        };
        let c = a.config(1009);
        assert_eq!(c.temperature.at(1.0, 1), 0.5);
        assert!((c.temperature.at(1.0, 1000) - 0.005).abs() < 1e-9);
        assert!((c.step.at(1.0, 1000) - 0.01).abs() < 1e-9);
    }
}
