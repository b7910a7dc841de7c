//! # Experiment families, by paper
//!
//! A *family* is the code that runs one kind of experiment: its typed parameters (a
//! [`crate::experiment::Job`]), its figures and its `REPORT.md` section — a
//! [`crate::experiment::Family`], and through it an [`Experiment`]. Experiment files name it in
//! `experiment = "…"`; the harness ([`crate::experiment`]) finds it in the [`registry`] that
//! `main.rs` hands it (the harness itself names no family). Each
//! paper has a folder, and each file is named after the experiment id it runs, without the
//! paper prefix:
//!
//! | experiment id | family (`experiment = "…"`) | file |
//! | --- | --- | --- |
//! | `physics_validation` | `physics_validation` | [`beyond::physics_validation`] |
//! | `x_lbc_emulator` | `x_lbc_emulator` | [`beyond::x_lbc_emulator`] |
//! | `lbc_projection` | `lbc_projection` | [`lbc::projection`] |
//! | `lbc_grid_optimality` | `lbc_grid_optimality` | [`lbc::grid_optimality`] |
//! | `lbc_acrobot_swingup` | `lbc_acrobot_swingup` | [`lbc::acrobot_swingup`] |
//! | `lbc_diver_interpolation` | `lbc_diver_interpolation` | [`lbc::diver`] (both dive families) |
//! | `lbc_diver_coordination` | `lbc_diver_coordination` | [`lbc::diver`] |
//! | `lbc_dive_disturbance` | `lbc_dive_disturbance` | [`lbc::diver`] (`disturbance.rs`) |
//! | `lbc_push_recovery` | `lbc_push_recovery` | [`lbc::push_recovery`] |
//! | `lbc_walking` | `lbc_walking` | [`lbc::walking`] (+ its gaits' value functions: [`crate::control::gait_value`]) |
//! | `lbc_stepping` | `lbc_stepping` | [`lbc::stepping`] |
//! | `lbc_jumping` | `lbc_jumping` | [`lbc::jumping`] |
//! | `na_table1_structure` | `na_table1_structure` | [`na::table1_structure`] |
//! | `na_table2_speedup` | `na_table2_speedup` | [`na::table2_speedup`] |
//! | `na_regularization` | `na_regularization` | [`na::regularization`] |
//! | `na_fig12_error` | `na_fig12_error` | [`na::fig12_error`] |
//! | `na_fig13_control` | `na_fig13_control` | [`na::fig13_control`] (+ its GIFs: `fig13_control/anim*`) |
//! | `na_fig14_momentum` | `na_fig14_momentum` | [`na::fig14_momentum`] |
//! | `na_baselines_swim` | `na_baselines_swim` | [`na::baselines_swim`] |
//! | `na_transforms_ablation` | `na_transforms_ablation` | [`na::transforms_ablation`] |
//! | `na_training_methods` | `na_training_methods` | [`na::training_methods`] |
//! | `ms_lattices` | `ms_lattices` | [`ms::lattices`] |
//! | `ms_spider_leap`, `ms_poodle_somersault`, `ms_table_pirouette` | `ms_motion` | [`ms::motion`] (one family, three experiment files) |
//! | `ms_fig6_learning_plot` | `ms_learning` | [`ms::fig6_learning_plot`] |
//! | `ms_representation` | `ms_representation` | [`ms::representation`] |
//! | `ms_search_settings` | `ms_search_settings` | [`ms::settings`] (a sweep over set size, mix and seeds) |
//!
//! Helpers shared by several families of one paper sit beside them under a descriptive name:
//! [`na::swim`] (the dolphin swim task of `na_fig13_control` and `na_baselines_swim`),
//! [`ms::lattice_draw`] (3-D lattice figures, filmstrips and GIFs).
//!
//! To add an experiment: a file in the paper's folder (`beyond/` for experiments beyond the
//! papers, ids `x_*`) named after the id, its `mod` line in that folder's `mod.rs`, and one line
//! in `FAMILIES` below (listed by [`families`] and [`registry`]).

use crate::experiment::{Experiment, Registry};

pub mod beyond;
pub mod lbc;
pub mod ms;
pub mod na;

/// Every family, in the order `motionlab` lists unknown-family errors.
static FAMILIES: &[&dyn Experiment] = &[
    &beyond::physics_validation::PhysicsValidation,
    &lbc::projection::LbcProjection,
    &lbc::grid_optimality::LbcGrid,
    &lbc::acrobot_swingup::LbcAcrobot,
    &lbc::diver::LbcDiverInterpolation,
    &lbc::diver::LbcDiverCoordination,
    &lbc::diver::LbcDiveDisturbance,
    &lbc::push_recovery::LbcPush,
    &lbc::walking::LbcWalking,
    &lbc::stepping::LbcStepping,
    &lbc::jumping::LbcJumping,
    &na::table1_structure::NaStructure,
    &na::table2_speedup::NaSpeedup,
    &na::fig12_error::NaError,
    &ms::lattices::MsLattices,
    &ms::motion::MsMotion,
    &ms::fig6_learning_plot::MsLearning,
    &ms::representation::MsRepresentation,
    &ms::settings::MsSearchSettings,
    &na::fig14_momentum::NaMomentum,
    &na::fig13_control::NaControl,
    &na::regularization::NaRegularization,
    &na::baselines_swim::NaBaselines,
    &na::transforms_ablation::NaTransforms,
    &na::training_methods::NaTrainingMethods,
    &beyond::x_lbc_emulator::XLbcEmulator,
];

/// Every family as the registry the harness runs from (`main.rs` hands it to
/// [`crate::experiment::resolve::resolve`]).
pub fn registry() -> Registry {
    Registry::new(FAMILIES)
}

/// All families.
pub fn families() -> &'static [&'static dyn Experiment] {
    FAMILIES
}

/// The family called `kind`.
pub fn family(kind: &str) -> Option<&'static dyn Experiment> {
    registry().find(kind)
}
