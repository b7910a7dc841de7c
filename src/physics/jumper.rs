//! # `jumper`: the planar diver with ground contact at its feet (LBC §6.3's jumping body)
//!
//! "A version of the diver with both sets of extremities was used for the broad jump examples
//! that land" (LBC §6.3): the seven-link diver of [`super::diver`] (torso, head, arms, legs,
//! left and right limbs lumped as in a symmetric jump) whose foot touches the ground at its heel
//! and toe through the same penalty contact as the biped ([`Contact::force`]: spring-damper
//! normal force, regularized Coulomb friction, SIMBICON's ground constants). Six joint torques
//! (neck, shoulder, elbow, hip, knee, ankle); state as the diver's (hip position, torso angle,
//! six joint angles and their rates).
//!
//! The foot's sole is its axis: the heel 5 cm behind the ankle and the toe 18 cm ahead (ours:
//! the diver's foot is 20 cm long from the ankle).

use super::diver::diver;
use super::ground::{BodyPlan, FallLimits, OnGround};
use super::planar::{ForcePoint, PlanarTree};
use crate::portable::{atan2, cos, sin_cos};
use std::f64::consts::{FRAC_PI_2, PI};

/// Heel contact point behind the ankle (m).
pub const HEEL: f64 = 0.05;
/// Toe contact point ahead of the ankle (m).
pub const TOE: f64 = 0.18;
/// Generalized coordinates (hip x, y, torso angle, six joints).
pub const DOF: usize = 9;
/// Joint torques.
pub const TORQUES: usize = 6;

/// Index of each link in the diver's tree ([`super::diver::diver`]).
pub mod link {
    /// Torso (root; its joint is the hip).
    pub const TORSO: usize = 0;
    /// Head.
    pub const HEAD: usize = 1;
    /// Upper arm.
    pub const UPPER_ARM: usize = 2;
    /// Forearm.
    pub const FOREARM: usize = 3;
    /// Thigh.
    pub const THIGH: usize = 4;
    /// Shank.
    pub const SHANK: usize = 5;
    /// Foot.
    pub const FOOT: usize = 6;
}

/// The jumping diver's description: the diver's links, its heel and toe, its fall limits.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DiverBody;

impl BodyPlan for DiverBody {
    const DOF: usize = DOF;
    const TORQUES: usize = TORQUES;
    const HEEL: f64 = HEEL;
    const TOE: f64 = TOE;
    /// The hip lower than 0.4 m above the ground (the crouch's hip is about 0.7 m high) or the
    /// torso more than 1.2 rad from upright (ours).
    const FALL: FallLimits = FallLimits {
        min_height: 0.4,
        max_tilt: 1.2,
    };
    fn tree() -> PlanarTree {
        let mut tree = diver();
        tree.name = "jumper".into();
        tree.forces = vec![
            ForcePoint {
                link: link::FOOT,
                offset: -HEEL,
            },
            ForcePoint {
                link: link::FOOT,
                offset: TOE,
            },
        ];
        tree
    }
}

/// The jumping diver on its terrain: heel and toe are its contact points.
pub type Jumper = OnGround<DiverBody, 2>;

impl Jumper {
    /// A crouch on level ground facing +x: the torso tipped forward by `lean` from upright, the
    /// shank tipped forward by `shin` (rad, the knee ahead of the ankle) over a flat foot, the
    /// arms swung back by `arm` (rad) from hanging straight down, the hip placed (thigh and knee following) so that the body's centre of mass lies
    /// above the middle of the sole where the thigh reaches, the ankle at x = `x` and the sole
    /// just on the ground.
    pub fn crouch(&self, x: f64, lean: f64, shin: f64, arm: f64) -> Vec<f64> {
        let mid = (TOE - HEEL) / 2.0;
        let mut hip_x = mid;
        let mut s = self.crouch_at(x, lean, shin, arm, hip_x);
        for _ in 0..50 {
            let e = self.tree.center_of_mass(&s[..DOF])[0] - (x + mid);
            if e.abs() < 1e-12 {
                break;
            }
            // The hip carries most of the mass: move it against the error (within the thigh's
            // reach of the knee).
            hip_x -= e;
            let (lt, ls) = (
                self.tree.links[link::THIGH].length,
                self.tree.links[link::SHANK].length,
            );
            let knee_x = -ls * cos(1.5 * PI - shin);
            hip_x = hip_x.clamp(knee_x - 0.95 * lt, knee_x + 0.95 * lt);
            s = self.crouch_at(x, lean, shin, arm, hip_x);
        }
        s
    }

    /// [`Jumper::crouch`] with the hip `hip_x` ahead of the ankle.
    fn crouch_at(&self, x: f64, lean: f64, shin: f64, arm: f64, hip_x: f64) -> Vec<f64> {
        let mut s = vec![0.0; 2 * DOF];
        // Absolute angles from +x (forward), counter-clockwise: the torso up and tipped forward,
        // the shank down with its top (the knee) forward.
        let torso = FRAC_PI_2 - lean;
        let shank_abs = 1.5 * PI - shin;
        let (lt, ls) = (
            self.tree.links[link::THIGH].length,
            self.tree.links[link::SHANK].length,
        );
        // Knee relative to the ankle (the shank points from the knee down to the ankle).
        let (sin_s, cos_s) = sin_cos(shank_abs);
        let knee = [-ls * cos_s, -ls * sin_s];
        let dx = hip_x - knee[0];
        let dy = (lt * lt - dx * dx).max(0.0).sqrt();
        let hip = [hip_x, knee[1] + dy];
        // The thigh points from the hip down to the knee, in (π, 2π).
        let mut thigh_abs = atan2(knee[1] - hip[1], knee[0] - hip[0]);
        if thigh_abs < 0.0 {
            thigh_abs += 2.0 * PI;
        }
        s[0] = x + hip[0];
        s[1] = self.terrain.height_slope(x).0 + hip[1];
        s[2] = torso;
        s[3] = 0.0; // head in line
        s[4] = 1.5 * PI - arm - torso; // arms hanging, swung back (toward −x) by `arm`
        s[5] = 0.0;
        s[6] = thigh_abs - torso;
        s[7] = shank_abs - thigh_abs;
        s[8] = 2.0 * PI - shank_abs; // foot flat (absolute angle 2π)
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{Dynamics, IntegratorKind, Model, Simulator};

    /// Holds the crouch's joint angles with stiff PD servos for `seconds` from `x0`.
    fn hold(j: &Jumper, x0: &[f64], seconds: f64) -> Vec<f64> {
        let dt = j.default_dt();
        let mut sim = Simulator::new(j.clone(), IntegratorKind::Rk4);
        let mut x = x0.to_vec();
        let target = x0[3..DOF].to_vec();
        let mut u = [0.0; TORQUES];
        for _ in 0..(seconds / dt).round() as usize {
            for i in 0..TORQUES {
                u[i] = 2000.0 * (target[i] - x[3 + i]) - 100.0 * x[DOF + 3 + i];
            }
            sim.step(&mut x, &u, dt);
        }
        x
    }

    #[test]
    fn the_crouch_puts_a_flat_sole_on_the_ground_under_the_hip() {
        let j = Jumper::default();
        let x = j.crouch(0.3, 0.3, 0.3, 0.2);
        let [heel, toe] = j.contact_points(&x[..DOF]);
        assert!(
            heel[1].abs() < 1e-12 && toe[1].abs() < 1e-12,
            "{heel:?} {toe:?}"
        );
        assert!((heel[0] - (0.3 - HEEL)).abs() < 1e-12, "{heel:?} {x:?}");
        let com = j.tree.center_of_mass(&x[..DOF])[0];
        assert!((com - (heel[0] + toe[0]) / 2.0).abs() < 1e-9, "{com}");
        // Facing +x: the knee ahead of the ankle, the neck ahead of the hip, the hands behind
        // the shoulders.
        let p = |link: usize, r: f64| j.tree.point(&x[..DOF], link, r);
        assert!(
            p(link::SHANK, 0.0)[0] > p(link::FOOT, 0.0)[0],
            "knee behind the ankle"
        );
        assert!(
            p(link::TORSO, j.tree.links[link::TORSO].length)[0] > x[0],
            "torso tipped back"
        );
        assert!(
            p(link::FOREARM, j.tree.links[link::FOREARM].length)[0] < p(link::UPPER_ARM, 0.0)[0],
            "arms forward"
        );
    }

    #[test]
    fn a_held_crouch_dropped_on_the_ground_rests_on_it_without_sinking_or_bouncing() {
        let j = Jumper::default();
        let mut x0 = j.crouch(0.0, 0.3, 0.3, 0.2);
        x0[1] += 0.03;
        let x = hold(&j, &x0, 1.0);
        let [heel, toe] = j.contact_points(&x[..DOF]);
        // 70 kg on two points of 1e5 N/m: a few mm of compression; not sunk, not in the air.
        for p in [heel, toe] {
            assert!(p[1] > -0.01, "sank: {p:?}");
        }
        assert!(heel[1].min(toe[1]) < 0.0, "bounced off: {heel:?} {toe:?}");
        // The fall has stopped: the hip barely moves up or down, the ground carries the weight.
        assert!(x[DOF + 1].abs() < 0.05, "{x:?}");
        let f = j.contact_forces(&x);
        let weight: f64 = j.tree.links.iter().map(|l| l.mass).sum::<f64>() * 9.81;
        assert!(((f[0][1] + f[1][1]) / weight - 1.0).abs() < 0.1, "{f:?}");
    }

    #[test]
    fn contact_forces_vanish_in_the_air_and_push_up_when_pressed() {
        let j = Jumper::default();
        let mut x = j.crouch(0.0, 0.3, 0.3, 0.0);
        x[1] += 0.1;
        let f = j.contact_forces(&x);
        // The normal force's 1 N smoothing leaves ln 2 N at zero penetration rate.
        assert!(
            f.iter().all(|p| p[0].abs() < 1e-6 && p[1].abs() < 1.0),
            "{f:?}"
        );
        x[1] -= 0.105;
        let f = j.contact_forces(&x);
        assert!(f.iter().all(|p| p[1] > 100.0), "{f:?}");
    }
}
