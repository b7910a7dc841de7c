//! # `biped`: a planar 7-link biped on terrain with penalty contact (LBC §6.3, SIMBICON's 2-D model)
//!
//! The body is a floating [`PlanarTree`]: a torso (the root; its joint is the pelvis, where both
//! hips sit), two thighs, two shins and two feet, six actuated joints (hips, knees, ankles). The
//! generalized coordinates are the pelvis position (x, y), the torso's absolute angle (from +x,
//! counter-clockwise, so upright is π/2) and the six relative joint angles, left leg first.
//!
//! Each foot touches the ground at two points, heel and toe, through **penalty forces**, as the
//! LBC paper simulates contact (§6.3: "penalty-based", chosen because it keeps the dynamics
//! smooth enough for DDP). For a contact point p with velocity v over terrain of height h(x):
//!
//! ```text
//! d     = (p_y − h(p_x)) cos θ            signed distance along the terrain normal n (θ its slope)
//! pen   = ε softplus(−d / ε)              smooth penetration (≈ max(0, −d), ε = `smoothing`)
//! gate  = σ(−d / ε)                       smooth in-contact indicator
//! f_n   = F softplus((k pen − c gate (v·n)) / F)   normal force ≥ 0 (F = 1 N smoothing)
//! f_t   = −μ f_n tanh((v·t) / v_s)        regularized Coulomb friction along the tangent t
//! ```
//!
//! so the forces, and hence the dynamics, are infinitely differentiable in the state; their
//! derivatives are checked against finite differences in the tests. The forces enter the
//! equations of motion through the points' Jacobians ([`PlanarTree`]'s force points), and the
//! model's controls are the six joint torques only.
//!
//! Terrain ([`Terrain`]): flat, a constant incline, or flat then a hill starting at a given x
//! (the corner rounded over `smoothing_m`, so the height is smooth too).
//!
//! Parameters: link masses, lengths and inertias and the ground's stiffness and damping follow
//! SIMBICON's planar biped (Yin, Loken and van de Panne 2007, its published 2-D applet) as
//! [`simbicon_links`] and [`Contact::default`] document; the friction constants and the contact
//! smoothing are ours (each says so).

use super::planar::{ForcePoint, PlanarLink, PlanarTree};
use super::{Model, Ode, Parameter};
use crate::portable::{exp, ln, tanh};
use serde::{Deserialize, Serialize};

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

/// Ground shape under the biped.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Terrain {
    /// Level ground at height 0.
    Flat,
    /// A constant incline through the origin, rising toward +x (degrees; negative: downhill).
    Slope {
        /// Incline (degrees).
        degrees: f64,
    },
    /// Level up to `start_m`, then rising at `degrees`, the corner rounded over `smoothing_m`.
    FlatThenHill {
        /// Where the hill begins (m).
        start_m: f64,
        /// Incline of the hill (degrees).
        degrees: f64,
        /// Length over which the corner is rounded (m).
        smoothing_m: f64,
    },
}

impl Terrain {
    fn tan(deg: f64) -> f64 {
        let r = deg.to_radians();
        let (s, c) = crate::portable::sin_cos(r);
        s / c
    }

    /// Height h(x) (m) and slope dh/dx at `x`.
    pub fn height_slope(&self, x: f64) -> (f64, f64) {
        match *self {
            Terrain::Flat => (0.0, 0.0),
            Terrain::Slope { degrees } => {
                let t = Self::tan(degrees);
                (t * x, t)
            }
            Terrain::FlatThenHill {
                start_m,
                degrees,
                smoothing_m,
            } => {
                // h = tan θ · s(x − start), s(z) = (z + √(z² + w²))/2 − w/2: a smooth max(0, z)
                // shifted down by w/2, so −w/2 far before the corner (level there) and z − w/2
                // far after; w = smoothing_m.
                let t = Self::tan(degrees);
                let (z, w) = (x - start_m, smoothing_m.max(1e-9));
                let r = (z * z + w * w).sqrt();
                (t * ((z + r) / 2.0 - w / 2.0), t * (1.0 + z / r) / 2.0)
            }
        }
    }

    /// Checks the terrain's numbers.
    pub fn validate(&self) -> Result<(), String> {
        let deg_ok = |d: f64| d.is_finite() && d.abs() < 60.0;
        match *self {
            Terrain::Flat => Ok(()),
            Terrain::Slope { degrees } if deg_ok(degrees) => Ok(()),
            Terrain::FlatThenHill {
                start_m,
                degrees,
                smoothing_m,
            } if deg_ok(degrees) && start_m.is_finite() && smoothing_m > 0.0 => Ok(()),
            _ => Err(format!(
                "terrain {self:?}: inclines within ±60°, finite start, positive smoothing"
            )),
        }
    }
}

/// The largest RK4 step (s) on the default ground ([`Contact::default`]): its 6000 N·s/m of
/// damping per point makes RK4 unstable at larger steps for the lightest links.
pub const GROUND_RK4_MAX_DT: f64 = 4.5e-4;

/// Penalty contact constants.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Contact {
    /// Normal stiffness k per contact point (N/m).
    pub stiffness: f64,
    /// Normal damping c per contact point (N·s/m).
    pub damping: f64,
    /// Coulomb friction coefficient μ.
    pub friction: f64,
    /// Slip speed v_s of the regularized friction (m/s): below it friction grows linearly.
    pub slip_speed: f64,
    /// Length ε over which contact switches on (m).
    pub smoothing: f64,
    /// Whether contact acts at all (off: the body passes through the ground, for tests).
    pub enabled: bool,
}

impl Default for Contact {
    /// Stiffness and damping are the SIMBICON applet's ground (`KpGnd` 1e5 N/m, `KdGnd`
    /// 6000 N·s/m per point); the applet's tangential spring holds a touching point where it
    /// landed (no slip at all), which is not smooth, so the friction here is regularized Coulomb
    /// (the LBC paper's "Coulomb friction") with μ = 0.9 and slip speed 0.02 m/s, and contact
    /// switches on over 0.5 mm: those three are ours.
    fn default() -> Self {
        Self {
            stiffness: 100_000.0,
            damping: 6_000.0,
            friction: 0.9,
            slip_speed: 0.02,
            smoothing: 5e-4,
            enabled: true,
        }
    }
}

/// A softplus ε·ln(1 + exp(z/ε)) computed without overflow.
fn softplus(z: f64, eps: f64) -> f64 {
    let a = z / eps;
    if a > 30.0 {
        z
    } else if a < -30.0 {
        eps * exp(a)
    } else {
        eps * ln(1.0 + exp(a))
    }
}

/// The logistic σ(a) computed without overflow.
fn sigmoid(a: f64) -> f64 {
    if a >= 0.0 {
        1.0 / (1.0 + exp(-a))
    } else {
        let e = exp(a);
        e / (1.0 + e)
    }
}

impl Contact {
    /// Checks the constants.
    pub fn validate(&self) -> Result<(), String> {
        let pos = |v: f64| v > 0.0 && v.is_finite();
        if pos(self.stiffness)
            && self.damping >= 0.0
            && self.damping.is_finite()
            && self.friction >= 0.0
            && self.friction.is_finite()
            && pos(self.slip_speed)
            && pos(self.smoothing)
        {
            Ok(())
        } else {
            Err(format!("contact {self:?}: stiffness, slip speed and smoothing > 0, damping and friction >= 0"))
        }
    }

    /// The constants as model parameters (for `describe`).
    pub fn parameters(&self) -> Vec<Parameter> {
        vec![
            Parameter::new(
                "contact.stiffness",
                self.stiffness,
                "N/m",
                "penalty normal stiffness per contact point",
            ),
            Parameter::new(
                "contact.damping",
                self.damping,
                "N*s/m",
                "penalty normal damping per contact point",
            ),
            Parameter::new(
                "contact.friction",
                self.friction,
                "1",
                "Coulomb friction coefficient (regularized)",
            ),
            Parameter::new(
                "contact.slip_speed",
                self.slip_speed,
                "m/s",
                "slip speed of the regularized friction",
            ),
            Parameter::new(
                "contact.smoothing",
                self.smoothing,
                "m",
                "distance over which contact switches on",
            ),
        ]
    }

    /// The ground's force (N, world x and y) on a point at `p` moving at `v`.
    pub fn force(&self, terrain: &Terrain, p: [f64; 2], v: [f64; 2]) -> [f64; 2] {
        if !self.enabled {
            return [0.0, 0.0];
        }
        let (h, slope) = terrain.height_slope(p[0]);
        let norm = (1.0 + slope * slope).sqrt();
        let n = [-slope / norm, 1.0 / norm];
        let t = [1.0 / norm, slope / norm];
        let d = (p[1] - h) / norm;
        let pen = softplus(-d, self.smoothing);
        let gate = sigmoid(-d / self.smoothing);
        let vn = v[0] * n[0] + v[1] * n[1];
        let vt = v[0] * t[0] + v[1] * t[1];
        let fn_raw = self.stiffness * pen - self.damping * gate * vn;
        let f_n = softplus(fn_raw, 1.0);
        let f_t = -self.friction * f_n * tanh(vt / self.slip_speed);
        [f_n * n[0] + f_t * t[0], f_n * n[1] + f_t * t[1]]
    }
}

/// A foot's contact points as model parameters: the heel `heel` m behind the ankle and the toe
/// `toe` m ahead of it.
pub(crate) fn sole_parameters(heel: f64, toe: f64) -> [Parameter; 2] {
    [
        Parameter::new(
            "foot.heel",
            heel,
            "m",
            "heel contact point behind the ankle",
        ),
        Parameter::new("foot.toe", toe, "m", "toe contact point ahead of the ankle"),
    ]
}

/// The equations of motion of `tree` under joint `torques` and the ground's `forces` on its
/// force points (in their order): ẋ into `dx`. At most 8 torques and 4 points.
pub(crate) fn driven_by_ground(
    tree: &PlanarTree,
    torques: &[f64],
    forces: &[[f64; 2]],
    x: &[f64],
    dx: &mut [f64],
) {
    let mut all = [0.0; 16];
    let m = torques.len();
    all[..m].copy_from_slice(torques);
    for (k, f) in forces.iter().enumerate() {
        all[m + 2 * k] = f[0];
        all[m + 2 * k + 1] = f[1];
    }
    tree.derivative(x, &all[..m + 2 * forces.len()], dx);
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
        link("left_thigh", Some(0), 0.0, thigh),
        link("left_shin", Some(1), thigh[1], shin),
        link("left_foot", Some(2), shin[1], foot),
        link("right_thigh", Some(0), 0.0, thigh),
        link("right_shin", Some(4), thigh[1], shin),
        link("right_foot", Some(5), shin[1], foot),
    ]
}

/// Heel distance behind the ankle along the foot (m; the applet's 0.04).
pub const FOOT_HEEL: f64 = 0.04;
/// Toe distance ahead of the ankle along the foot (m; the applet's 0.12).
pub const FOOT_TOE: f64 = 0.12;

/// The planar biped on its terrain.
#[derive(Debug, Clone, PartialEq)]
pub struct Biped {
    /// The body: its force points are the four contact points (left heel, left toe, right
    /// heel, right toe), driven by [`Contact::force`], never by the user.
    pub tree: PlanarTree,
    /// The ground.
    pub terrain: Terrain,
    /// Contact constants.
    pub contact: Contact,
}

/// Generalized coordinates of the biped (pelvis x, y, torso angle, six joints).
pub const DOF: usize = 9;
/// Joint torques.
pub const TORQUES: usize = 6;

impl Default for Biped {
    fn default() -> Self {
        Self::new(Terrain::Flat, Contact::default())
    }
}

impl Biped {
    /// SIMBICON's body on `terrain` with `contact`.
    pub fn new(terrain: Terrain, contact: Contact) -> Self {
        let p = |link: usize, offset: f64| ForcePoint { link, offset };
        Self {
            tree: PlanarTree {
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
            },
            terrain,
            contact,
        }
    }

    /// The contact points' positions (m): left heel, left toe, right heel, right toe.
    pub fn contact_points(&self, q: &[f64]) -> [[f64; 2]; 4] {
        std::array::from_fn(|k| self.contact_point(q, k))
    }

    /// Contact point `k` (0-3, in [`Biped::contact_points`]' order) at configuration `q` (m).
    pub fn contact_point(&self, q: &[f64], k: usize) -> [f64; 2] {
        let f = &self.tree.forces[k];
        self.tree.point(q, f.link, f.offset)
    }

    /// The ground's forces on the four contact points (N), in the order of
    /// [`Biped::contact_points`].
    pub fn contact_forces(&self, x: &[f64]) -> [[f64; 2]; 4] {
        let mut out = [[0.0; 2]; 4];
        for (o, f) in out.iter_mut().zip(&self.tree.forces) {
            let (p, v) = self.tree.point_state(x, f.link, f.offset);
            *o = self.contact.force(&self.terrain, p, v);
        }
        out
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

impl Model for Biped {
    fn name(&self) -> &str {
        "biped"
    }
    fn state_names(&self) -> Vec<String> {
        self.tree.state_names()
    }
    fn control_names(&self) -> Vec<String> {
        self.tree.control_names()[..TORQUES].to_vec()
    }
    fn parameters(&self) -> Vec<Parameter> {
        let mut p = self.tree.parameters();
        p.extend(self.contact.parameters());
        p.extend(sole_parameters(FOOT_HEEL, FOOT_TOE));
        p
    }
    /// 0.1 ms: the stiff contact (6000 N·s/m on a 1 kg foot) needs it for RK4 (the applet
    /// stepped 0.05 ms with its explicit scheme).
    fn default_dt(&self) -> f64 {
        0.0001
    }
}

impl Ode for Biped {
    fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        driven_by_ground(&self.tree, &u[..TORQUES], &self.contact_forces(x), x, dx);
    }

    fn position_dim(&self) -> Option<usize> {
        Some(DOF)
    }

    /// Kinetic plus gravitational energy of the body (J); the contact springs' energy is not
    /// included.
    fn energy(&self, x: &[f64]) -> Option<f64> {
        self.tree.energy(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{IntegratorKind, Simulator};

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

    /// The contact force's derivatives against central finite differences, in and out of
    /// contact, sliding and sticking, on a slope: the smoothness DDP needs.
    #[test]
    fn contact_force_derivatives_match_finite_differences() {
        let c = Contact::default();
        let terrains = [
            Terrain::Flat,
            Terrain::Slope { degrees: 10.0 },
            Terrain::FlatThenHill {
                start_m: 0.0,
                degrees: 10.0,
                smoothing_m: 0.2,
            },
        ];
        let cases = [
            ([0.01, -0.002], [0.3, -0.1]),
            ([0.0, -0.0004], [0.001, 0.02]),
            ([0.05, 0.001], [-0.2, -0.5]),
            ([-0.03, -0.003], [0.0, 0.0]),
        ];
        for t in &terrains {
            for (p, v) in cases {
                let (h, _) = t.height_slope(p[0]);
                let p = [p[0], p[1] + h];
                let f0 = c.force(t, p, v);
                for k in 0..4 {
                    let step = if k < 2 { 1e-8 } else { 1e-7 };
                    let at = |s: f64| {
                        let (mut pp, mut vv) = (p, v);
                        if k < 2 {
                            pp[k] += s;
                        } else {
                            vv[k - 2] += s;
                        }
                        c.force(t, pp, vv)
                    };
                    let (a, b) = (at(step), at(-step));
                    let (a2, b2) = (at(2.0 * step), at(-2.0 * step));
                    for j in 0..2 {
                        let d1 = (a[j] - b[j]) / (2.0 * step);
                        let d2 = (a2[j] - b2[j]) / (4.0 * step);
                        // Two step sizes agree: the force is smooth there (no kink).
                        let scale = d1.abs().max(d2.abs()).max(1.0);
                        assert!(
                            (d1 - d2).abs() < 1e-3 * scale,
                            "{t:?} p={p:?} v={v:?} d/d{k} f{j}: {d1} vs {d2} (f = {f0:?})"
                        );
                    }
                }
            }
        }
        // Height and slope of the rounded hill agree with each other.
        let hill = terrains[2];
        for x in [-1.0, -0.1, 0.0, 0.05, 0.3, 2.0] {
            let (a, _) = hill.height_slope(x + 1e-6);
            let (b, _) = hill.height_slope(x - 1e-6);
            let (_, s) = hill.height_slope(x);
            assert!(((a - b) / 2e-6 - s).abs() < 1e-6, "x = {x}");
        }
    }
}
