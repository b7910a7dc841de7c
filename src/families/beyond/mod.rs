//! Experiments beyond the papers (`physics_validation`, future `x_*` ids).

pub mod physics_validation;
pub mod x_lbc_emulator;
