//! # Motion synthesis for mass-spring lattices (Christensen, Marks, Ngo 1995)
//!
//! Controllers that pick one of the 12 actuation reflexes as a function of elapsed time
//! ([`controller`]), objective functions built from the terms of the paper's Table 1
//! ([`objective`]), the perturbation operator of Table 2 ([`perturb`]), and two gradient-free
//! searches over the controller space, run by the shared library of
//! [`crate::control::search`] ([`search`]): the paper's parallel hill climbing (Fig. 4) and
//! simulated annealing as a baseline.
//!
//! The searches need only an evaluation `controller → objective value`; [`Problem`] bundles
//! the simulation setup and the objective and evaluates one controller by simulating the
//! lattice over the horizon.
//!
//! ## References
//! - J. Christensen, J. Marks, J. T. Ngo, *Automatic Motion Synthesis for 3D Mass-Spring
//!   Models*, The Visual Computer 13(1), 1997 (MERL TR95-01).

pub mod controller;
pub mod free;
pub mod objective;
pub mod perturb;
pub mod search;

use crate::physics::lattice::LatticeError;
use crate::physics::BlowUp;
use controller::{simulate, Controller, SimSetup, Trajectory};
use objective::Objective;

/// Errors of controller synthesis.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SynthesisError {
    /// A parameter out of range (what, value).
    #[error("invalid {0}: {1}")]
    Invalid(&'static str, f64),
    /// The lattice rejected a reflex or rest lengths.
    #[error(transparent)]
    Lattice(#[from] LatticeError),
    /// The simulation needed more internal RK45 steps than its budget (steps taken).
    #[error("simulation exceeded its budget of RK45 steps ({0} taken)")]
    Budget(u64),
    /// The simulation produced a non-finite state.
    #[error(transparent)]
    BlowUp(Box<BlowUp>),
}

/// Value given to a controller whose simulation blew up or exceeded its step budget (worse
/// than any real motion).
pub const BLOWUP_OBJECTIVE: f64 = -1.0e6;

/// A synthesis problem: simulate the lattice under a controller, score the trajectory.
#[derive(Debug, Clone)]
pub struct Problem {
    /// What an evaluation simulates.
    pub setup: SimSetup,
    /// How the trajectory is scored (larger is better).
    pub objective: Objective,
}

impl Problem {
    /// Simulates `c` and returns its trajectory.
    pub fn trajectory(&self, c: &Controller) -> Result<Trajectory, SynthesisError> {
        simulate(&self.setup, c)
    }

    /// The objective value of `c` (larger is better); [`BLOWUP_OBJECTIVE`] when the
    /// simulation fails.
    pub fn evaluate(&self, c: &Controller) -> f64 {
        self.score(simulate(&self.setup, c))
    }

    /// The objective value of a simulation's outcome; [`BLOWUP_OBJECTIVE`] when it failed.
    pub fn score(&self, outcome: Result<Trajectory, SynthesisError>) -> f64 {
        match outcome {
            Ok(tr) => {
                let v = self.objective.total(&tr);
                if v.is_finite() {
                    v
                } else {
                    BLOWUP_OBJECTIVE
                }
            }
            Err(_) => BLOWUP_OBJECTIVE,
        }
    }
}
