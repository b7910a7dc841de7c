//! The learned controls replayed on a physical simulator ([`replay`]): the gap between the
//! emulated and the simulated final state.

use crate::physics::Dynamics;

/// The learned controls replayed on a physical simulator.
#[derive(Debug, Clone, PartialEq)]
pub struct Replay {
    /// Simulated states at the emulator step times (M + 1, n each).
    pub states: Vec<f64>,
    /// |s_M^emulated − s_M^simulated| (Euclidean, state units).
    pub final_gap: f64,
}

/// Drives `sim` from `x0` with per-step `controls` (m each), each held for `substeps` physical
/// steps of `physical_dt`; compares the final state with `emulated_final`.
pub fn replay(
    sim: &mut dyn Dynamics,
    x0: &[f64],
    controls: &[f64],
    physical_dt: f64,
    substeps: usize,
    emulated_final: &[f64],
) -> Replay {
    let m = sim.control_dim();
    let mut x = x0.to_vec();
    let mut states = x.clone();
    for u in controls.chunks_exact(m.max(1)) {
        for _ in 0..substeps {
            sim.step(&mut x, &u[..m], physical_dt);
        }
        states.extend_from_slice(&x);
    }
    let gap = x
        .iter()
        .zip(emulated_final)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        .sqrt();
    Replay {
        states,
        final_gap: gap,
    }
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::linear;
    use super::*;
    use crate::control::bptt::{learn, Bounds, Bptt, Descent, Knots};
    use crate::control::objective::{FinalState, Objective};

    #[test]
    fn bounds_are_respected_and_replay_on_the_same_system_has_no_gap() {
        let sys = linear();
        let obj = Objective::default().with(FinalState {
            mu: 1.0,
            target: vec![50.0, 50.0, 50.0],
            weights: vec![1.0; 3],
        });
        let knots = Knots {
            steps: 8,
            per_actuator: 2,
            m: 2,
        };
        let bounds = Bounds::new(vec![-1.0, -2.0], vec![1.0, 0.5]);
        let mut b = Bptt::new(&sys, &obj, knots, bounds.clone(), &[0.0; 3]).unwrap();
        let v0 = vec![0.0; b.dim()];
        let lambda = b.curvature(&v0, 30);
        let r = learn(&mut b, &v0, Descent::Plain { eta: 1.0 }, lambda, 30);
        for u in r.controls.chunks(2) {
            assert!(u[0] >= -1.0 - 1e-12 && u[0] <= 1.0 + 1e-12);
            assert!(u[1] >= -2.0 - 1e-12 && u[1] <= 0.5 + 1e-12);
        }
        assert!(r.final_objective() < r.trace[0].objective);
        // The same linear map as Dynamics: replay reproduces the final state.
        let last = &r.states[r.states.len() - 3..];
        let rep = replay(&mut linear(), &[0.0; 3], &r.controls, 0.1, 1, last);
        assert!(rep.final_gap < 1e-12);
        assert_eq!(rep.states.len(), 9 * 3);
    }
}
