//! # `ground`: terrain, penalty contact, and a planar body standing on them
//!
//! The ground of LBC's contact examples (§6.3): the SIMBICON biped walks on it and the jumping
//! diver takes off from and lands on it. A body touches it at a few points of its links (a
//! foot's heel and toe) through **penalty forces**, as the LBC paper simulates contact (§6.3:
//! "penalty-based", chosen because it keeps the dynamics smooth enough for DDP). For a contact
//! point p with velocity v over terrain of height h(x):
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
//! equations of motion through the points' Jacobians ([`PlanarTree`]'s force points), and a
//! body's controls are its joint torques only.
//!
//! The normal law is one function, [`Contact::normal_force`], shared with the 3-D bodies:
//! [`Contact::force3d`] lifts the ground to 3-D (z up, the height varying along world x) with
//! friction in the tangent plane, f_t = −μ f_n tanh(|v_t| / v_s) v_t / |v_t|.
//!
//! Terrain ([`Terrain`]): flat, a constant incline, or flat then a hill starting at a given x
//! (the corner rounded over `smoothing_m`, so the height is smooth too).
//!
//! [`OnGround`] is a body on this ground: a floating [`PlanarTree`] whose force points are its
//! contact points, described by a [`BodyPlan`] (the biped of [`super::biped`], the jumper of
//! [`super::jumper`]); it implements [`Model`] and [`Ode`] for every such body.

use super::planar::PlanarTree;
use super::{Model, Ode, Parameter};
use crate::portable::{exp, ln, tanh};
use serde::{Deserialize, Serialize};
use std::f64::consts::FRAC_PI_2;

/// Ground shape under a body.
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

/// tanh(s) / s as a function of s² (1 at 0): an even analytic function, so friction
/// μ f_n (tanh(s)/s) v_t / v_s with s = |v_t| / v_s is infinitely differentiable in v_t, also
/// at v_t = 0. Below s = 0.01 the series 1 − s²/3 + 2s⁴/15 − 17s⁶/315 (next term under
/// 3e-18).
pub fn slip_factor(s2: f64) -> f64 {
    if s2 < 1e-4 {
        1.0 - s2 * (1.0 / 3.0 - s2 * (2.0 / 15.0 - s2 * (17.0 / 315.0)))
    } else {
        let s = s2.sqrt();
        tanh(s) / s
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
        let vn = v[0] * n[0] + v[1] * n[1];
        let vt = v[0] * t[0] + v[1] * t[1];
        let f_n = self.normal_force(d, vn);
        let f_t = -self.friction * f_n * tanh(vt / self.slip_speed);
        [f_n * n[0] + f_t * t[0], f_n * n[1] + f_t * t[1]]
    }

    /// The normal force f_n ≥ 0 (N) on a point at signed distance `d` (m) from the terrain
    /// along its normal, moving at `vn` (m/s) along it: F softplus((k pen − c gate vn) / F)
    /// with pen = ε softplus(−d / ε) and gate = σ(−d / ε) (module docs). The one normal law of
    /// every body on the ground, planar ([`Contact::force`]) and 3-D ([`Contact::force3d`]).
    pub fn normal_force(&self, d: f64, vn: f64) -> f64 {
        let pen = softplus(-d, self.smoothing);
        let gate = sigmoid(-d / self.smoothing);
        let fn_raw = self.stiffness * pen - self.damping * gate * vn;
        softplus(fn_raw, 1.0)
    }

    /// The ground's force (N, world x, y, z; z up) on a point at `p` moving at `v`, the
    /// terrain's height h(x) varying along world x alone (the planar terrain extruded along
    /// y): the normal force of [`Contact::normal_force`] along the unit normal
    /// n = (−h′, 0, 1) / √(1 + h′²), and friction in the tangent plane,
    /// f_t = −μ f_n tanh(|v_t| / v_s) v_t / |v_t|, the planar law turned toward the slip
    /// direction (|f_t| ≤ μ f_n; smooth at v_t = 0, see [`slip_factor`]).
    pub fn force3d(&self, terrain: &Terrain, p: [f64; 3], v: [f64; 3]) -> [f64; 3] {
        if !self.enabled {
            return [0.0; 3];
        }
        let (h, slope) = terrain.height_slope(p[0]);
        let norm = (1.0 + slope * slope).sqrt();
        let n = [-slope / norm, 0.0, 1.0 / norm];
        let d = (p[2] - h) / norm;
        let vn = v[0] * n[0] + v[2] * n[2];
        let vt = [v[0] - vn * n[0], v[1], v[2] - vn * n[2]];
        let f_n = self.normal_force(d, vn);
        let s2 =
            (vt[0] * vt[0] + vt[1] * vt[1] + vt[2] * vt[2]) / (self.slip_speed * self.slip_speed);
        let w = self.friction * f_n * slip_factor(s2) / self.slip_speed;
        [f_n * n[0] - w * vt[0], -w * vt[1], f_n * n[2] - w * vt[2]]
    }
}

/// A foot's contact points as model parameters: the heel `heel` m behind the ankle and the toe
/// `toe` m ahead of it.
fn sole_parameters(heel: f64, toe: f64) -> [Parameter; 2] {
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
fn driven_by_ground(
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

/// When a body standing on the ground has fallen: its root joint (the pelvis or hip) lower than
/// `min_height` above the ground under it, or its root link more than `max_tilt` from upright.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FallLimits {
    /// Lowest height of the root joint above the ground (m).
    pub min_height: f64,
    /// Largest angle of the root link from upright (rad).
    pub max_tilt: f64,
}

/// What makes a planar tree a body on the ground: its links and contact points, and when it has
/// fallen. Implemented by the biped's and the jumper's descriptions.
pub trait BodyPlan: std::fmt::Debug + Clone + PartialEq + Send + Sync + 'static {
    /// Generalized coordinates (root x, y, root angle, the joints).
    const DOF: usize;
    /// Joint torques (the body's controls).
    const TORQUES: usize;
    /// Heel distance behind the ankle along the sole (m).
    const HEEL: f64;
    /// Toe distance ahead of the ankle along the sole (m).
    const TOE: f64;
    /// When the body has fallen.
    const FALL: FallLimits;
    /// The body: a floating tree whose force points are its contact points.
    fn tree() -> PlanarTree;
}

/// A planar body described by `P` on the ground, touching it at its `N` contact points.
#[derive(Debug, Clone, PartialEq)]
pub struct OnGround<P: BodyPlan, const N: usize> {
    /// The body: its force points are the `N` contact points, driven by [`Contact::force`],
    /// never by the user.
    pub tree: PlanarTree,
    /// The ground.
    pub terrain: Terrain,
    /// Contact constants.
    pub contact: Contact,
    plan: std::marker::PhantomData<P>,
}

impl<P: BodyPlan, const N: usize> Default for OnGround<P, N> {
    fn default() -> Self {
        Self::new(Terrain::Flat, Contact::default())
    }
}

impl<P: BodyPlan, const N: usize> OnGround<P, N> {
    /// The body of `P` on `terrain` with `contact`.
    pub fn new(terrain: Terrain, contact: Contact) -> Self {
        let tree = P::tree();
        assert_eq!(tree.forces.len(), N, "{}: contact points", tree.name);
        Self {
            tree,
            terrain,
            contact,
            plan: std::marker::PhantomData,
        }
    }

    /// The contact points' positions (m) at configuration `q`, in the tree's force-point order.
    pub fn contact_points(&self, q: &[f64]) -> [[f64; 2]; N] {
        std::array::from_fn(|k| self.contact_point(q, k))
    }

    /// Contact point `k` (in [`OnGround::contact_points`]' order) at configuration `q` (m).
    pub fn contact_point(&self, q: &[f64], k: usize) -> [f64; 2] {
        let f = &self.tree.forces[k];
        self.tree.point(q, f.link, f.offset)
    }

    /// The ground's forces on the contact points (N), in the order of
    /// [`OnGround::contact_points`].
    pub fn contact_forces(&self, x: &[f64]) -> [[f64; 2]; N] {
        std::array::from_fn(|k| {
            let f = &self.tree.forces[k];
            let (p, v) = self.tree.point_state(x, f.link, f.offset);
            self.contact.force(&self.terrain, p, v)
        })
    }

    /// Whether state `x` has fallen, by the body's [`BodyPlan::FALL`] limits.
    pub fn fallen(&self, x: &[f64]) -> bool {
        let FallLimits {
            min_height,
            max_tilt,
        } = P::FALL;
        x[1] - self.terrain.height_slope(x[0]).0 < min_height || (x[2] - FRAC_PI_2).abs() > max_tilt
    }

    /// The centre of mass's velocity (m/s) at state `x`.
    pub fn com_velocity(&self, x: &[f64]) -> [f64; 2] {
        let (p, _) = self.tree.momentum(x);
        let m: f64 = self.tree.links.iter().map(|l| l.mass).sum();
        [p[0] / m, p[1] / m]
    }
}

impl<P: BodyPlan, const N: usize> Model for OnGround<P, N> {
    fn name(&self) -> &str {
        &self.tree.name
    }
    fn state_names(&self) -> Vec<String> {
        self.tree.state_names()
    }
    fn control_names(&self) -> Vec<String> {
        self.tree.control_names()[..P::TORQUES].to_vec()
    }
    fn parameters(&self) -> Vec<Parameter> {
        let mut p = self.tree.parameters();
        p.extend(self.contact.parameters());
        p.extend(sole_parameters(P::HEEL, P::TOE));
        p
    }
    /// 0.1 ms: the stiff contact (6000 N·s/m on a 1-2 kg foot) needs it for RK4 (SIMBICON's
    /// applet stepped 0.05 ms with its explicit scheme).
    fn default_dt(&self) -> f64 {
        0.0001
    }
}

impl<P: BodyPlan, const N: usize> Ode for OnGround<P, N> {
    fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        driven_by_ground(&self.tree, &u[..P::TORQUES], &self.contact_forces(x), x, dx);
    }

    fn position_dim(&self) -> Option<usize> {
        Some(P::DOF)
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

    use crate::physics::biped::{Biped, Side, SimbiconBody};
    use crate::physics::jumper::{DiverBody, Jumper};

    /// The centre of mass's velocity is the time derivative of its position along the state's
    /// velocity (central differences), for both bodies on the ground.
    #[test]
    fn com_velocity_is_the_rate_of_the_centre_of_mass() {
        fn check<P: BodyPlan, const N: usize>(body: &OnGround<P, N>, x: &[f64]) {
            let dof = P::DOF;
            let h = 1e-6;
            let at = |s: f64| {
                let q: Vec<f64> = (0..dof).map(|i| x[i] + s * x[dof + i]).collect();
                body.tree.center_of_mass(&q)
            };
            let (a, b) = (at(h), at(-h));
            let v = body.com_velocity(x);
            for k in 0..2 {
                let fd = (a[k] - b[k]) / (2.0 * h);
                assert!(
                    (fd - v[k]).abs() < 1e-6,
                    "{}: {fd} vs {}",
                    body.tree.name,
                    v[k]
                );
            }
        }
        let rates = |x: &mut Vec<f64>, dof: usize| {
            for (i, v) in x[dof..].iter_mut().enumerate() {
                *v = 0.4 * ((i as f64) * 1.3).sin() - 0.1;
            }
        };
        let b = Biped::default();
        let mut x = b.standing(0.0, 0.0);
        rates(&mut x, SimbiconBody::DOF);
        check(&b, &x);
        let j = Jumper::default();
        let mut x = j.crouch(0.0, 0.3, 0.3, 0.2);
        rates(&mut x, DiverBody::DOF);
        check(&j, &x);
    }

    /// Each body falls by its own limits: standing (crouching) it has not fallen; its root
    /// lowered just under the limit's height above the ground, or tipped just past the limit's
    /// angle, it has; just within either, it has not.
    #[test]
    fn each_body_falls_by_its_own_limits() {
        fn check<P: BodyPlan, const N: usize>(body: &OnGround<P, N>, x: &[f64]) {
            let FallLimits {
                min_height,
                max_tilt,
            } = P::FALL;
            assert!(!body.fallen(x), "{}: fallen at the start", body.tree.name);
            let h = body.terrain.height_slope(x[0]).0;
            for (dy, fell) in [(-1e-9, true), (1e-9, false)] {
                let mut y = x.to_vec();
                y[1] = h + min_height + dy;
                assert_eq!(
                    body.fallen(&y),
                    fell,
                    "{} at height {}",
                    body.tree.name,
                    y[1]
                );
            }
            for (da, fell) in [(1e-9, true), (-1e-9, false)] {
                for sign in [1.0, -1.0] {
                    let mut y = x.to_vec();
                    y[2] = FRAC_PI_2 + sign * (max_tilt + da);
                    assert_eq!(body.fallen(&y), fell, "{} tilted {}", body.tree.name, y[2]);
                }
            }
        }
        let slope = Terrain::Slope { degrees: 5.0 };
        for terrain in [Terrain::Flat, slope] {
            let b = Biped::new(terrain, Contact::default());
            check(&b, &b.standing(0.3, 0.0));
            let j = Jumper::new(terrain, Contact::default());
            check(&j, &j.crouch(0.3, 0.3, 0.3, 0.2));
        }
    }

    /// The biped's legs name the links they move, and mirroring swaps exactly them.
    #[test]
    fn the_bipeds_legs_are_its_thigh_shin_and_foot_joints() {
        let names = Biped::default().state_names();
        for (side, word) in [(Side::Left, "left"), (Side::Right, "right")] {
            let leg = Biped::leg(side);
            for (i, part) in leg.joints().into_iter().zip(["thigh", "shin", "foot"]) {
                assert_eq!(names[i], format!("{word}_{part}_joint"));
            }
            assert_ne!(side.other(), side);
            assert_eq!(side.other().other(), side);
            assert_ne!(Biped::leg(side), Biped::leg(side.other()));
        }
        let x: Vec<f64> = (0..2 * crate::physics::biped::DOF)
            .map(|i| i as f64)
            .collect();
        let m = Biped::mirror(&x);
        let (l, r) = (
            Biped::leg(Side::Left).joints(),
            Biped::leg(Side::Right).joints(),
        );
        for i in 0..x.len() {
            let q = i % crate::physics::biped::DOF;
            let base = i - q;
            let want = if let Some(k) = l.iter().position(|&j| j == q) {
                x[base + r[k]]
            } else if let Some(k) = r.iter().position(|&j| j == q) {
                x[base + l[k]]
            } else {
                x[i]
            };
            assert_eq!(m[i], want, "coordinate {i}");
        }
    }
}
