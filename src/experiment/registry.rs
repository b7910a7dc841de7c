//! Every experiment family, by the name experiment files use in `experiment = "…"`.

use super::{lbc_grid, lbc_projection, ms_lattices, ms_motion, physics_validation, Experiment};

static FAMILIES: &[&dyn Experiment] = &[
    &physics_validation::PhysicsValidation,
    &lbc_projection::LbcProjection,
    &lbc_grid::LbcGrid,
    &ms_lattices::MsLattices,
    &ms_motion::MsMotion,
    &ms_motion::MsLearning,
];

/// All families.
pub fn families() -> &'static [&'static dyn Experiment] {
    FAMILIES
}

/// The family called `kind`.
pub fn family(kind: &str) -> Option<&'static dyn Experiment> {
    FAMILIES.iter().copied().find(|f| f.kind() == kind)
}
