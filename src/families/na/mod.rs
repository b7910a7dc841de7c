//! NeuroAnimator (Grzeszczuk, Terzopoulos, Hinton 1998), experiment ids `na_*`.

pub mod baselines_swim;
pub mod control_task;
pub mod equal_accuracy;
pub mod fig12_error;
pub mod fig13_control;
pub mod fig14_momentum;
pub mod regularization;
pub mod swim;
pub mod table1_structure;
pub mod table2_speedup;
pub mod training_methods;
pub mod transforms_ablation;

// The moved search jobs still call `super::other`, as written before the move, so that the
// concurrent search refactor merges cleanly; new code imports `crate::experiment::other`.
#[allow(unused_imports)]
use crate::experiment::other;
