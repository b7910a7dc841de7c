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
//!
//! ## Walls to catch a fall on
//!
//! [`PushScene`] stands the figure between two vertical walls at x = ±d (the holds of the
//! paper's "grab onto something to maintain balance", §4.2). The hand touches a wall through a
//! frictionless, push-only spring–damper (penalty contact, Kelvin–Voigt):
//!
//! ```text
//! front wall (hand x > d):   F_x = −max(k (x − d) + c ẋ, 0)
//! back wall  (hand x < −d):  F_x =  max(k (−d − x) − c ẋ, 0)
//! ```
//!
//! added to the hand's external force, so a reach that puts the hand on a wall can hold a body
//! leaning beyond what the ankle alone holds, and the scene stays mirror-symmetric. Only the
//! hand touches: a body falling with its arm down leans until it passes any fall angle of
//! interest. The contact is stiff: integrate it with steps of about a millisecond.

use super::planar::{ForcePoint, PlanarLink, PlanarTree};
use super::{Model, Ode, Parameter};
use serde::{Deserialize, Serialize};

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

/// Two vertical walls at x = ±`distance` that the hand can push against.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Walls {
    /// Distance of each wall from the ankle (m).
    pub distance: f64,
    /// Contact stiffness k (N/m).
    pub stiffness: f64,
    /// Contact damping c (N·s/m).
    pub damping: f64,
}

impl Walls {
    /// Horizontal contact force on the hand at position `x` (m) moving at `vx` (m/s): push-only,
    /// frictionless, zero off the walls.
    pub fn force(&self, x: f64, vx: f64) -> f64 {
        // The back wall is the front wall mirrored (x → −x), so the pair is symmetric exactly.
        let (side, x, vx) = if x < 0.0 {
            (-1.0, -x, -vx)
        } else {
            (1.0, x, vx)
        };
        if x > self.distance {
            -side * (self.stiffness * (x - self.distance) + self.damping * vx).max(0.0)
        } else {
            0.0
        }
    }
}

/// The push-recovery figure between two walls (controls as [`push_figure`]'s: three motor
/// torques, then the scripted hand force; the wall force is added to the latter).
#[derive(Debug, Clone, PartialEq)]
pub struct PushScene {
    /// The figure (with its hand force point).
    pub figure: PlanarTree,
    /// The walls.
    pub walls: Walls,
}

impl PushScene {
    /// [`push_figure`] between `walls`.
    pub fn new(walls: Walls) -> Self {
        Self {
            figure: push_figure(),
            walls,
        }
    }

    /// The hand's position (m) and velocity (m/s) at state `x`.
    pub fn hand(&self, x: &[f64]) -> ([f64; 2], [f64; 2]) {
        let l = self.figure.links[HAND_LINK].length;
        self.figure.point_state(x, HAND_LINK, l)
    }

    /// The wall's horizontal force on the hand at state `x` (N).
    pub fn wall_force(&self, x: &[f64]) -> f64 {
        let (p, v) = self.hand(x);
        self.walls.force(p[0], v[0])
    }
}

impl Model for PushScene {
    fn name(&self) -> &str {
        "push_recovery_walls"
    }
    fn state_names(&self) -> Vec<String> {
        self.figure.state_names()
    }
    fn control_names(&self) -> Vec<String> {
        self.figure.control_names()
    }
    fn parameters(&self) -> Vec<Parameter> {
        let mut p = self.figure.parameters();
        p.push(Parameter::new(
            "walls.distance",
            self.walls.distance,
            "m",
            "each wall's distance from the ankle",
        ));
        p.push(Parameter::new(
            "walls.stiffness",
            self.walls.stiffness,
            "N/m",
            "hand-wall contact stiffness",
        ));
        p.push(Parameter::new(
            "walls.damping",
            self.walls.damping,
            "N*s/m",
            "hand-wall contact damping",
        ));
        p
    }
    fn default_dt(&self) -> f64 {
        0.001
    }
}

impl Ode for PushScene {
    fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let mut with_wall = [0.0; 5];
        with_wall.copy_from_slice(u);
        with_wall[3] += self.wall_force(x);
        self.figure.derivative(x, &with_wall, dx);
    }
    fn position_dim(&self) -> Option<usize> {
        Some(self.figure.dof())
    }
}

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

    const WALLS: Walls = Walls {
        distance: 0.8,
        stiffness: 1e4,
        damping: 200.0,
    };

    #[test]
    fn walls_only_push_and_are_mirror_symmetric() {
        let w = WALLS;
        assert_eq!(w.force(0.5, 3.0), 0.0);
        assert_eq!(w.force(-0.79, -3.0), 0.0);
        assert!(w.force(0.81, 0.0) < 0.0 && w.force(-0.81, 0.0) > 0.0);
        // Leaving the wall fast: the damper would pull, the contact does not.
        assert_eq!(w.force(0.801, -1.0), 0.0);
        for (x, v) in [(0.82, 0.3), (0.9, -0.1), (0.805, 2.0)] {
            assert_eq!(w.force(x, v), -w.force(-x, -v));
        }
    }

    /// Passive falls (ankle motor off) from a small forward lean.
    fn fall(arm_forward: bool, seconds: f64) -> Vec<[f64; 6]> {
        use crate::physics::integrate::Integrator;
        use crate::physics::IntegratorKind;
        let scene = PushScene::new(WALLS);
        let arm = if arm_forward { 0.0 } else { -FRAC_PI_2 };
        // Body leaning 0.05 rad forward, arm absolute angle `arm`, forearm straight.
        let body = FRAC_PI_2 - 0.05;
        let mut x = [body, arm - body, 0.0, 0.0, 0.0, 0.0];
        let mut rk = Integrator::new(IntegratorKind::Rk4, 6);
        let mut out = Vec::new();
        // The arm joints held by a stiff PD (so the arm stays a strut: the frictionless wall lets
        // a yielding arm fold and slide down), the ankle passive; 0.2 ms steps for the PD held
        // over each.
        let x0 = x;
        for _ in 0..(seconds / 2e-4) as usize {
            let u = [
                0.0,
                -2000.0 * (x[1] - x0[1]) - 20.0 * x[4],
                -2000.0 * (x[2] - x0[2]) - 20.0 * x[5],
                0.0,
                0.0,
            ];
            rk.step(&scene, &mut x, &u, 2e-4);
            assert!(x.iter().all(|v| v.is_finite()));
            out.push(x);
        }
        out
    }

    #[test]
    fn an_arm_on_the_wall_catches_a_fall_and_a_hanging_arm_does_not() {
        let caught = fall(true, 2.0);
        let lean = |x: &[f64; 6]| FRAC_PI_2 - x[0];

        let max_caught = caught.iter().map(lean).fold(0.0, f64::max);
        // The horizontal arm's hand meets the wall (0.8 m) at 1.4 sin(lean) + 0.65 = 0.8, a lean
        // of 0.107 rad: the body stops well inside 0.3 rad and comes to rest against the wall.
        assert!(max_caught < 0.3, "caught lean {max_caught}");
        let last = caught.last().unwrap();
        assert!(last[3].abs() < 0.05, "still moving: {last:?}");
        let fallen = fall(false, 2.0);
        let max_fallen = fallen.iter().map(lean).fold(0.0, f64::max);
        // With the arm down the hand reaches the wall only near 0.4 rad of lean.
        assert!(max_fallen > 0.3, "hanging-arm lean {max_fallen}");
    }

    #[test]
    fn the_scene_is_the_figure_off_the_walls() {
        let scene = PushScene::new(WALLS);
        let x = [FRAC_PI_2 - 0.05, -2.0, 0.3, 0.1, -0.2, 0.4];
        let u = [3.0, -2.0, 1.0, 5.0, 0.0];
        let (mut a, mut b) = ([0.0; 6], [0.0; 6]);
        scene.derivative(&x, &u, &mut a);
        push_figure().derivative(&x, &u, &mut b);
        assert_eq!(a, b);
        assert_eq!(scene.wall_force(&x), 0.0);
    }
}
