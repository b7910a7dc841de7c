//! # Push-recovery figure (linear Bellman combination, Fig. 9)
//!
//! A standing body balanced on an ankle pivot with a two-link arm, built on [`PlanarTree`]
//! (fixed base): body (root; pivot at the ankle, angle from +x, π/2 upright), upper arm at the
//! shoulder, forearm at the elbow. Motors at the ankle, shoulder and elbow; an external force at
//! the hand (controls `forearm_fx`, `forearm_fy`) scripts the tugs of the paper's push
//! experiment. A recovery controller catches the fall by reaching the hand to a hold in front
//! of or behind the body.
//!
//! Parameters are ours: a 60 kg, 1.6 m body (centre of mass at 0.9 m), 2.5 kg / 0.3 m upper
//! arm and 2 kg / 0.35 m forearm attached at 1.4 m.

use super::planar::{ForcePoint, PlanarLink, PlanarTree};

/// Builds the push-recovery figure.
pub fn push_figure() -> PlanarTree {
    let link = |name: &str,
                parent: Option<usize>,
                attach: f64,
                mass: f64,
                length: f64,
                com: f64,
                inertia: f64| PlanarLink {
        name: name.into(),
        parent,
        attach,
        mass,
        length,
        com,
        inertia,
        damping: 1.0,
        actuated: true,
    };
    PlanarTree {
        name: "push_recovery".into(),
        links: vec![
            link("body", None, 0.0, 60.0, 1.6, 0.9, 60.0 * 0.3f64.powi(2)),
            link(
                "upper_arm",
                Some(0),
                1.4,
                2.5,
                0.3,
                0.13,
                2.5 * 0.09f64.powi(2),
            ),
            link(
                "forearm",
                Some(1),
                0.3,
                2.0,
                0.35,
                0.15,
                2.0 * 0.1f64.powi(2),
            ),
        ],
        floating: false,
        gravity: 9.81,
        forces: vec![ForcePoint {
            link: 2,
            offset: 0.35,
        }],
    }
}

/// Index of the forearm, whose tip is the hand.
pub const HAND_LINK: usize = 2;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{Model, Ode};
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn upright_with_arm_hanging_is_an_equilibrium() {
        let p = push_figure();
        p.validate().unwrap();
        assert_eq!(p.state_dim(), 6);
        assert_eq!(
            p.control_names(),
            [
                "body_torque",
                "upper_arm_torque",
                "forearm_torque",
                "forearm_fx",
                "forearm_fy"
            ]
        );
        // Body upright (π/2), arm pointing down (−π relative to the body), forearm straight.
        let x = [FRAC_PI_2, -std::f64::consts::PI, 0.0, 0.0, 0.0, 0.0];
        let mut dx = [1.0; 6];
        p.derivative(&x, &[0.0; 5], &mut dx);
        assert!(dx.iter().all(|v| v.abs() < 1e-9), "{dx:?}");
        // A forward tug on the hand tips the body forward (towards +x: angle decreases).
        p.derivative(&x, &[0.0, 0.0, 0.0, 50.0, 0.0], &mut dx);
        assert!(dx[3] < 0.0, "{dx:?}");
    }
}
