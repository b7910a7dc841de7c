//! # Sampling and training the dolphin hierarchy (NeuroAnimator §3.4, §3.5, Table 1)
//!
//! Training data are episodes of 20 s ([`EPISODE_S`]) from the rest shape at a random position,
//! heading, pitch and roll ([`start_state`]), driven by travelling muscle waves
//! ([`control_process`]) and sampled at random lags; sampling runs in parallel chunks, each from
//! its own seeded stream ([`crate::seed::mix_seed`]), so the data do not depend on the thread
//! count ([`sample_dolphin`]). The global net learns the segment-frame transitions
//! ([`global_transitions`]); each local net learns, with teacher forcing (the true next frame
//! as its parent input), the change of its masses' local coordinates from frame F₀ to F₁, with
//! normalization by quantity groups. [`train_hierarchy`] trains the seven nets in parallel;
//! [`build_dolphin`] reuses them from the emulator cache under a key hashed from everything
//! that determines them ([`HierarchySpec`], the dolphin, [`super::HIERARCHY_FORMAT`]).
//!
//! The sampling runs are in `sampling`, the nets' data and training in `nets`, the cache and
//! the assembled hierarchy in `build`, and its fidelity measures in `fidelity`.
//!
//! ## References
//! - R. Grzeszczuk, D. Terzopoulos, G. Hinton, *NeuroAnimator*, SIGGRAPH 1998, §3.4–3.5,
//!   Table 1.

mod build;
mod fidelity;
mod nets;
mod sampling;

pub use build::{build_dolphin, build_global, net_name, BuiltDolphin, NetReport};
pub(super) use build::{cache_key, global_emulator, shape};
pub use fidelity::{global_heldout_errors, hierarchy_rollout_error};
pub use nets::{global_training_data, train_hierarchy};
pub use sampling::{
    control_limits, control_process, global_transitions, head, sample_dolphin, simulator,
    start_state, EPISODE_S,
};

use crate::emulator::catalog::{TrainMethod, TrainSettings, TransformSet};
use serde::{Deserialize, Serialize};

/// Size and data of one net of the hierarchy.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HierarchyNet {
    /// Hidden units.
    pub hidden: usize,
    /// Training examples.
    pub examples: usize,
    /// How to train.
    pub method: TrainMethod,
    /// Mini-batch epoch limit of this net, overriding the settings' `max_epochs` (left out of
    /// cache keys when not set).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_epochs: Option<usize>,
}

impl HierarchyNet {
    /// The training settings `s` with this net's own epoch limit, if it has one.
    pub fn settings(&self, s: &TrainSettings) -> TrainSettings {
        TrainSettings {
            max_epochs: self.max_epochs.unwrap_or(s.max_epochs),
            ..*s
        }
    }
}

/// Everything that determines the trained dolphin hierarchy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HierarchySpec {
    /// The global net (Table 1: 50 hidden, 64,000 examples).
    pub global: HierarchyNet,
    /// Each local net (Table 1: 40 hidden, 32,000 examples).
    pub local: HierarchyNet,
    /// Physical step δt of the simulator (s).
    pub physical_dt: f64,
    /// Physical steps per emulator step n.
    pub steps: usize,
    /// Training settings.
    pub settings: TrainSettings,
    /// Seed of sampling, initialization and shuffles.
    pub seed: u64,
    /// Which of §3.2's transforms wrap the global net (`na_transforms_ablation`); the whole
    /// chain (the default) is left out of cache keys. Only [`build_global`] trains a global net
    /// with another set; the local nets never depend on it.
    #[serde(default, skip_serializing_if = "TransformSet::is_full")]
    pub global_transforms: TransformSet,
}

impl HierarchySpec {
    /// Super timestep Δt = n δt (s).
    pub fn super_dt(&self) -> f64 {
        self.steps as f64 * self.physical_dt
    }

    fn held_out(&self) -> usize {
        ((self.global.examples as f64 * self.settings.held_out_fraction).round() as usize).max(2)
    }
}

/// The settings of a small hierarchy of `examples` examples, shared by the tests.
#[cfg(test)]
mod fixtures {
    use super::*;

    pub(in super::super) fn spec(examples: usize) -> HierarchySpec {
        HierarchySpec {
            global: HierarchyNet {
                hidden: 8,
                examples,
                method: TrainMethod::Lbfgs,
                max_epochs: None,
            },
            local: HierarchyNet {
                hidden: 6,
                examples: examples / 2,
                method: TrainMethod::Lbfgs,
                max_epochs: None,
            },
            physical_dt: 0.002,
            steps: 10,
            settings: TrainSettings::for_tests(5, 2, 3),
            seed: 3,
            global_transforms: TransformSet::Full,
        }
    }
}
