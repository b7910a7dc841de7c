//! # Linear Bellman combination (da Silva, Durand, Popović 2009)
//!
//! Combining optimal controllers through their rewards z = exp(−v): since the Bellman equation
//! is linear in z for control-affine dynamics with quadratic control cost, Σ w_i z_i solves the
//! problem with terminal reward Σ w_i h_i. This module holds the pieces of that combination;
//! [`projection`] computes the fixed weights w for a desired terminal cost, [`combine`] the
//! time-varying blend weights α in log space, and [`grid_dp`] solves low-dimensional problems
//! on a grid (linearly-solvable and ordinary Bellman backups). It combines whatever implements
//! the value-function contract [`crate::control::tracker::ValueTracker`] (DDP/LQR and
//! emulator-derived trackers), without knowing where a tracker came from.

pub mod combine;
pub mod grid_dp;
pub mod projection;
