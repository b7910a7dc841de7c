//! Mass-spring motion synthesis (Christensen, Marks, Ngo 1995), experiment ids `ms_*`.

pub mod fig6_learning_plot;
pub mod lattice_draw;
pub mod lattices;
pub mod motion;
pub mod motion_rule;
pub mod representation;
pub mod rows;
pub mod search;
pub mod settings;

// The moved search jobs still call `super::other`, as written before the move, so that the
// concurrent search refactor merges cleanly; new code imports `crate::experiment::other`.
#[allow(unused_imports)]
use crate::experiment::other;
