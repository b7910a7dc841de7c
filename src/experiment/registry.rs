//! Every experiment family, by the name experiment files use in `experiment = "…"`.

use super::{
    lbc_acrobot, lbc_diver, lbc_grid, lbc_projection, lbc_push, ms_lattices, ms_motion,
    na_baselines, na_control, na_error, na_momentum, na_regularization, na_speedup, na_structure,
    physics_validation, Experiment,
};

static FAMILIES: &[&dyn Experiment] = &[
    &physics_validation::PhysicsValidation,
    &lbc_projection::LbcProjection,
    &lbc_grid::LbcGrid,
    &lbc_acrobot::LbcAcrobot,
    &lbc_diver::LbcDiverInterpolation,
    &lbc_diver::LbcDiverCoordination,
    &lbc_push::LbcPush,
    &na_structure::NaStructure,
    &na_speedup::NaSpeedup,
    &na_error::NaError,
    &ms_lattices::MsLattices,
    &ms_motion::MsMotion,
    &ms_motion::MsLearning,
    &na_momentum::NaMomentum,
    &na_control::NaControl,
    &na_regularization::NaRegularization,
    &na_baselines::NaBaselines,
];

/// All families.
pub fn families() -> &'static [&'static dyn Experiment] {
    FAMILIES
}

/// The family called `kind`.
pub fn family(kind: &str) -> Option<&'static dyn Experiment> {
    FAMILIES.iter().copied().find(|f| f.kind() == kind)
}
