//! Experiments beyond the papers (`physics_validation`, `x_lbc_emulator`).

pub mod physics_validation;
pub mod x_lbc_emulator;
