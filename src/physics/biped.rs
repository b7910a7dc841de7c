//! # `biped`: a planar 7-link biped on the ground (LBC §6.3, SIMBICON's 2-D model)
//!
//! The body is a floating [`PlanarTree`]: a torso (the root; its joint is the pelvis, where both
//! hips sit), two thighs, two shins and two feet, six actuated joints (hips, knees, ankles). The
//! generalized coordinates are the pelvis position (x, y), the torso's absolute angle (from +x,
//! counter-clockwise, so upright is π/2) and the six relative joint angles, left leg first.
//!
//! Each foot touches the ground at two points, heel and toe, through the penalty contact of
//! [`super::ground`]; [`Biped`] is this body ([`SimbiconBody`]) on that ground.
//!
//! Parameters: link masses, lengths and inertias and the ground's stiffness and damping follow
//! SIMBICON's planar biped (Yin, Loken and van de Panne 2007, its published 2-D applet) as
//! [`simbicon_links`] and [`super::ground::Contact::default`] document; the friction constants and the contact
//! smoothing are ours (each says so).

use super::ground::{BodyPlan, FallLimits, OnGround};
use super::planar::{ForcePoint, PlanarLink, PlanarTree};

/// Index of each link in the tree.
pub mod link {
    /// Torso (root; its joint is the pelvis).
    pub const TORSO: usize = 0;
    /// Left thigh.
    pub const LEFT_THIGH: usize = 1;
    /// Left shin.
    pub const LEFT_SHIN: usize = 2;
    /// Left foot.
    pub const LEFT_FOOT: usize = 3;
    /// Right thigh.
    pub const RIGHT_THIGH: usize = 4;
    /// Right shin.
    pub const RIGHT_SHIN: usize = 5;
    /// Right foot.
    pub const RIGHT_FOOT: usize = 6;
}

/// Index of each contact point in [`OnGround::contact_points`]' order.
pub mod point {
    /// Left heel.
    pub const LEFT_HEEL: usize = 0;
    /// Left toe.
    pub const LEFT_TOE: usize = 1;
    /// Right heel.
    pub const RIGHT_HEEL: usize = 2;
    /// Right toe.
    pub const RIGHT_TOE: usize = 3;
}

/// A side of the body.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// The left leg.
    Left,
    /// The right leg.
    Right,
}

impl Side {
    /// The other side.
    pub fn other(self) -> Side {
        match self {
            Side::Left => Side::Right,
            Side::Right => Side::Left,
        }
    }
}

/// A leg's joint coordinates in q (and, offset by [`DOF`], their rates in the state).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Leg {
    /// The hip's coordinate.
    pub hip: usize,
    /// The knee's.
    pub knee: usize,
    /// The ankle's.
    pub ankle: usize,
}

impl Leg {
    /// Hip, knee and ankle, in that order.
    pub const fn joints(self) -> [usize; 3] {
        [self.hip, self.knee, self.ankle]
    }
}

/// SIMBICON's planar biped links (torso, left thigh, shin, foot, right thigh, shin, foot).
///
/// From the UBC SIMBICON 2-D applet (Yin, Loken and van de Panne 2007; its `Bip7` constants, as
/// published in the applet's Java source): torso 70 kg, 1.475 kg·m², centre of mass 0.24 m
/// above the hip, 0.48 m tall; thighs 5 kg, 0.0885 kg·m², 0.45 m; shins 4 kg, 0.0696 kg·m²,
/// 0.45 m; feet 1 kg, 0.01 kg·m², heel 0.04 m behind and toe 0.12 m ahead of the ankle. Ours:
/// the planar tree puts a link's points on its axis, so the foot's axis is its sole and the
/// ankle sits on it (the applet's sole is 0.04 m below the ankle, its foot's centre of mass
/// (0.04, −0.02) from it: here 0.04 along the sole); the hips are 0.04 m lower than the
/// applet's for it. Gravity 9.81 m/s² (the applet's 9.8).
pub fn simbicon_links() -> Vec<PlanarLink> {
    let link = |name: &str, parent: Option<usize>, attach: f64, body: [f64; 4]| PlanarLink {
        name: name.into(),
        parent,
        attach,
        mass: body[0],
        length: body[1],
        com: body[2],
        inertia: body[3],
        damping: 0.0,
        actuated: parent.is_some(),
    };
    // [mass kg, length m, com m from joint, inertia kg m²]
    let torso = [70.0, 0.48, 0.24, 1.475];
    let thigh = [5.0, 0.45, 0.225, 0.0885];
    let shin = [4.0, 0.45, 0.225, 0.0696];
    let foot = [1.0, FOOT_TOE, 0.04, 0.01];
    vec![
        link("torso", None, 0.0, torso),
        link("left_thigh", Some(link::TORSO), 0.0, thigh),
        link("left_shin", Some(link::LEFT_THIGH), thigh[1], shin),
        link("left_foot", Some(link::LEFT_SHIN), shin[1], foot),
        link("right_thigh", Some(link::TORSO), 0.0, thigh),
        link("right_shin", Some(link::RIGHT_THIGH), thigh[1], shin),
        link("right_foot", Some(link::RIGHT_SHIN), shin[1], foot),
    ]
}

/// Heel distance behind the ankle along the foot (m; the applet's 0.04).
pub const FOOT_HEEL: f64 = 0.04;
/// Toe distance ahead of the ankle along the foot (m; the applet's 0.12).
pub const FOOT_TOE: f64 = 0.12;

/// The SIMBICON biped's description: its links, contact points and fall limits.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SimbiconBody;

impl BodyPlan for SimbiconBody {
    const DOF: usize = DOF;
    const TORQUES: usize = TORQUES;
    const HEEL: f64 = FOOT_HEEL;
    const TOE: f64 = FOOT_TOE;
    /// The pelvis lower than 0.55 m above the ground under it, or the torso more than 1 rad from
    /// upright (ours; the applet switches off at 2 rad or on a non-foot contact).
    const FALL: FallLimits = FallLimits {
        min_height: 0.55,
        max_tilt: 1.0,
    };
    fn tree() -> PlanarTree {
        let p = |link: usize, offset: f64| ForcePoint { link, offset };
        PlanarTree {
            name: "biped".into(),
            links: simbicon_links(),
            floating: true,
            gravity: 9.81,
            forces: vec![
                p(link::LEFT_FOOT, -FOOT_HEEL),
                p(link::LEFT_FOOT, FOOT_TOE),
                p(link::RIGHT_FOOT, -FOOT_HEEL),
                p(link::RIGHT_FOOT, FOOT_TOE),
            ],
        }
    }
}

/// The planar biped on its terrain: the tree's force points are the four contact points (left
/// heel, left toe, right heel, right toe; [`point`]).
pub type Biped = OnGround<SimbiconBody, 4>;

/// Generalized coordinates of the biped (pelvis x, y, torso angle, six joints).
pub const DOF: usize = 9;
/// Joint torques.
pub const TORQUES: usize = 6;

impl Biped {
    /// The joint coordinates of the leg on `side` in q (2 + the thigh's link index: q starts
    /// with the pelvis x, y and the torso's angle).
    pub const fn leg(side: Side) -> Leg {
        let first = match side {
            Side::Left => link::LEFT_THIGH,
            Side::Right => link::RIGHT_THIGH,
        };
        Leg {
            hip: 2 + first,
            knee: 3 + first,
            ankle: 4 + first,
        }
    }

    /// The state `x` with its legs swapped (left ↔ right hip, knee, ankle, angles and rates):
    /// the same motion seen with the other stance leg (the body is symmetric).
    pub fn mirror(x: &[f64]) -> Vec<f64> {
        let (l, r) = (
            Self::leg(Side::Left).joints(),
            Self::leg(Side::Right).joints(),
        );
        let mut m = x.to_vec();
        for base in [0, DOF] {
            for j in 0..3 {
                m.swap(base + l[j], base + r[j]);
            }
        }
        m
    }

    /// A standing pose: torso upright, straight legs leaning back by [`Biped::stance_lean`] so
    /// that the middle of each sole is under the pelvis, feet flat, the pelvis over x = `x` at
    /// the height where the soles just touch level ground of height h(x) (plus `lift` m).
    pub fn standing(&self, x: f64, lift: f64) -> Vec<f64> {
        let mut s = vec![0.0; 2 * DOF];
        let half_pi = std::f64::consts::FRAC_PI_2;
        let lean = self.stance_lean();
        let (h, _) = self.terrain.height_slope(x);
        s[0] = x;
        s[1] = h + self.leg_length() * crate::portable::cos(lean) + lift;
        s[2] = half_pi; // torso up
                        // Thighs down (relative to the torso, −π), leaning back by `lean`.
        s[3] = -std::f64::consts::PI - lean;
        s[6] = -std::f64::consts::PI - lean;
        // Feet forward (+x), flat: absolute 0.
        s[5] = half_pi + lean;
        s[8] = half_pi + lean;
        s
    }

    /// Hip to ankle with the knee straight (m).
    pub fn leg_length(&self) -> f64 {
        self.tree.links[link::LEFT_THIGH].length + self.tree.links[link::LEFT_SHIN].length
    }

    /// The backward lean of a standing leg that puts the middle of the sole under the hip (rad):
    /// asin(offset / leg), through the portable arctangent (the same bits on every machine).
    pub fn stance_lean(&self) -> f64 {
        let s = (FOOT_TOE - FOOT_HEEL) / 2.0 / self.leg_length();
        crate::portable::atan(s / (1.0 - s * s).sqrt())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::ground::{Contact, Terrain};
    use crate::physics::{IntegratorKind, Model, Ode, Simulator};

    fn run(b: &Biped, x0: &[f64], seconds: f64, u: &[f64]) -> Vec<f64> {
        let dt = b.default_dt();
        let steps = (seconds / dt).round() as usize;
        let mut sim = Simulator::new(b.clone(), IntegratorKind::Rk4);
        let mut x = x0.to_vec();
        sim.rollout(
            x0,
            dt,
            steps,
            |_, _, _, c| c.copy_from_slice(u),
            |_, _, s| x.copy_from_slice(s),
        )
        .expect("finite");
        x
    }

    /// A rigid pose (joints locked by stiff PD torques) dropped from 5 cm: it lands, stops
    /// bouncing and rests on the soles, sunk by less than 5 mm, never through the ground.
    #[test]
    fn a_dropped_body_comes_to_rest_on_the_ground() {
        let b = Biped::default();
        let x0 = b.standing(0.0, 0.05);
        let q0 = x0[..DOF].to_vec();
        let dt = b.default_dt();
        let mut sim = Simulator::new(b.clone(), IntegratorKind::Rk4);
        let mut lowest = f64::INFINITY;
        let mut last = x0.clone();
        sim.rollout(
            &x0,
            dt,
            (1.5 / dt) as usize,
            |_, _, x, u| {
                for j in 0..TORQUES {
                    let c = 3 + j;
                    u[j] = -3000.0 * (x[c] - q0[c]) - 100.0 * x[DOF + c];
                }
            },
            |_, _, x| {
                for p in b.contact_points(&x[..DOF]) {
                    lowest = lowest.min(p[1]);
                }
                last.copy_from_slice(x);
            },
        )
        .expect("finite");
        assert!(lowest > -0.01, "sank through: {lowest}");
        let soles: Vec<f64> = b
            .contact_points(&last[..DOF])
            .iter()
            .map(|p| p[1])
            .collect();
        assert!(soles.iter().all(|&y| y < 0.0 && y > -0.005), "{soles:?}");
        let speed: f64 = last[DOF..].iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!(speed < 0.05, "still moving: {speed}");
        // The ground carries the weight.
        let total: f64 = b.contact_forces(&last).iter().map(|f| f[1]).sum();
        let weight: f64 = b.tree.links.iter().map(|l| l.mass).sum::<f64>() * 9.81;
        assert!(
            (total - weight).abs() < 0.02 * weight,
            "{total} vs {weight}"
        );
    }

    /// The body standing upright on an incline, joints locked, feet flat on it: below the
    /// friction angle it only creeps (the regularized friction's creep, slip speed ×
    /// atanh(tan θ / μ), about 9 mm/s at half the angle), under 2 cm in a second; above it, it
    /// slides away, more than 30 cm.
    #[test]
    fn friction_holds_below_the_friction_angle_and_slides_above() {
        let contact = Contact::default();
        let angle = contact.friction.atan().to_degrees();
        let slide = |deg: f64| {
            let b = Biped::new(Terrain::Slope { degrees: deg }, contact);
            let mut x0 = b.standing(0.0, 0.0);
            // Feet flat on the incline, the body upright above them.
            x0[5] += deg.to_radians();
            x0[8] += deg.to_radians();
            let gap = b
                .contact_points(&x0[..DOF])
                .iter()
                .map(|p| p[1] - b.terrain.height_slope(p[0]).0)
                .fold(f64::INFINITY, f64::min);
            x0[1] -= gap;
            let q0 = x0[..DOF].to_vec();
            let dt = b.default_dt();
            let mut sim = Simulator::new(b.clone(), IntegratorKind::Rk4);
            let mut last = x0.clone();
            sim.rollout(
                &x0,
                dt,
                (1.0 / dt) as usize,
                |_, _, x, u| {
                    for j in 0..TORQUES {
                        let c = 3 + j;
                        u[j] = -3000.0 * (x[c] - q0[c]) - 100.0 * x[DOF + c];
                    }
                },
                |_, _, x| last.copy_from_slice(x),
            )
            .expect("finite");
            ((last[0] - x0[0]).powi(2) + (last[1] - x0[1]).powi(2)).sqrt()
        };
        let held = slide(0.5 * angle);
        let slid = slide((angle + 12.0).min(59.0));
        assert!(held < 0.02, "moved {held} m below the friction angle");
        assert!(slid > 0.3, "moved only {slid} m above the friction angle");
    }

    /// With contact off and no damping, the flying body's energy does not grow (RK4, 2 s of
    /// joint torques that sum to zero work over the run aside: here no torques at all).
    #[test]
    fn energy_does_not_grow_with_contacts_off() {
        let contact = Contact {
            enabled: false,
            ..Contact::default()
        };
        let b = Biped::new(Terrain::Flat, contact);
        let mut x0 = b.standing(0.0, 2.0);
        for (i, v) in x0[DOF..].iter_mut().enumerate() {
            *v = 0.3 * ((i as f64) * 1.7).sin();
        }
        x0[3] += 0.4;
        x0[7] -= 0.6;
        let e0 = b.energy(&x0).unwrap();
        let x1 = run(&b, &x0, 0.5, &[0.0; TORQUES]);
        let e1 = b.energy(&x1).unwrap();
        assert!(e1 <= e0 + 1e-6 * e0.abs().max(1.0), "{e0} -> {e1}");
        assert!((e1 - e0).abs() < 1e-5 * e0.abs(), "{e0} -> {e1}");
    }
}
