//! Linear Bellman combination (da Silva, Durand, Popović 2009), experiment ids `lbc_*`.

pub mod acrobot_swingup;
pub mod diver;
pub mod grid_optimality;
pub mod projection;
pub mod push_recovery;
