//! # `leaper3d`: a human-like 3-D biped on the ground
//!
//! The parameters of Laszlo, van de Panne and Fiume's 3-D model (*Limit Cycle Control and its
//! application to the animation of balancing and walking*, SIGGRAPH 1996) were not found, so
//! this is **our stand-in**: a human-like biped whose segment masses, centres of mass and radii
//! of gyration are those of
//!
//! > P. de Leva, *Adjustments to Zatsiorsky–Seluyanov's segment inertia parameters*,
//! > J. Biomechanics 29(9):1223–1230, 1996, Table 4 (males),
//!
//! for de Leva's reference male (Zatsiorsky's subjects: stature 1.741 m, mass 73.0 kg), not
//! rescaled. Numbers used (mass as a fraction of the body's, centre of mass from the first
//! endpoint as a fraction of the length, radii of gyration about the sagittal (x), transverse
//! (y) and longitudinal (z) axes as fractions of the length; length in mm):
//!
//! | segment | endpoints | length | mass | CM | r_sag | r_trans | r_long |
//! | --- | --- | --- | --- | --- | --- | --- | --- |
//! | head | VERT–MIDG | 203.3 | 0.0694 | 0.5976 | 0.362 | 0.376 | 0.312 |
//! | upper trunk | SUPR–XYPH | 170.7 | 0.1596 | 0.2999 | 0.716 | 0.454 | 0.659 |
//! | middle trunk | XYPH–OMPH | 215.5 | 0.1633 | 0.4502 | 0.482 | 0.383 | 0.468 |
//! | lower trunk | OMPH–MIDH | 145.7 | 0.1117 | 0.6115 | 0.615 | 0.551 | 0.587 |
//! | upper arm | SJC–EJC | 281.7 | 0.0271 | 0.5772 | 0.285 | 0.269 | 0.158 |
//! | forearm | EJC–WJC | 268.9 | 0.0162 | 0.4574 | 0.276 | 0.265 | 0.121 |
//! | hand | WJC–MET3 | 86.2 | 0.0061 | 0.7900 | 0.628 | 0.513 | 0.401 |
//! | thigh | HJC–KJC | 422.2 | 0.1416 | 0.4095 | 0.329 | 0.329 | 0.149 |
//! | shank | KJC–AJC | 434.0 | 0.0433 | 0.4395 | 0.251 | 0.246 | 0.102 |
//! | foot | HEEL–TTIP | 258.1 | 0.0137 | 0.4415 | 0.257 | 0.245 | 0.124 |
//!
//! The fractions sum to 1 (two arms, two legs), so the body's mass is 73.0 kg. The foot lies
//! along x: its longitudinal radius is about x, the transverse about y, the sagittal one taken
//! about z. Each segment's inertia about its centre of mass is diagonal in these axes,
//! I = m (r L)².
//!
//! ## Bodies (z up, x forward, y to the left; every joint frame the parent's, unrotated)
//!
//! ```text
//! pelvis (free) ─┬─ trunk (ball) ─┬─ l_arm (ball)
//!                │                └─ r_arm (ball)
//!                ├─ l_thigh (ball) ── l_shank (revolute y) ── l_foot (revolute y)
//!                └─ r_thigh (ball) ── r_shank (revolute y) ── r_foot (revolute y)
//! ```
//!
//! - `pelvis`: the lower trunk, origin at the mid-hip (MIDH), OMPH 145.7 mm above it.
//! - `trunk`: upper and middle trunk and the head as one rigid body on a ball joint at OMPH;
//!   the head placed with its vertex at the stature, 1.741 m (MIDG 79.6 mm above SUPR).
//! - `l_arm`, `r_arm`: upper arm, forearm and hand as one straight hanging segment on a ball
//!   shoulder.
//! - legs: ball hip, revolute knee and ankle about y (pitch; no second ankle axis).
//!
//! Dimensions de Leva's table does not give are **our choices**: hip joint centres 0.09 m
//! either side of MIDH; shoulder joint centres 0.17 m either side of the trunk's axis at the
//! height of SUPR; the ankle joint 0.07 m above the sole (Winter's 0.039 × stature would be
//! 0.068 m), the heel 0.06 m behind it, the toe tip 0.1981 m in front (foot length 258.1 mm),
//! the foot 0.09 m wide; the foot's centre of mass 0.035 m below the ankle. Joint damping
//! 0.5 N·m·s/rad at every joint; no joint limits.
//!
//! Standing (the default state, [`standing`]): every joint at zero, the pelvis's origin at
//! z = 0.926 m, the soles on the ground; the centre of mass 1.5 mm in front of the ankles,
//! inside the support rectangle (x from −0.06 to 0.198 m, y ±0.135 m). Contact: four points
//! per foot (heel and toe, inner and outer, at the sole's corners) on [`OnGround3d`], with
//! the constants of the rule in the [module docs](super) ([`resting_contact`]: the whole mass
//! on all eight points, μ = 0.9, slip speed 0.05 m/s), but a static penetration δ = 1 mm
//! instead of the tests' 2 mm: standing upright the heels carry about three quarters of the
//! weight, and at δ = 2 mm they rested 3.9 mm deep, at 1 mm 1.7 mm (the drop test).
//!
//! Step 0.1 ms (`DT`), a tenth of the rule's [`super::contact::resting_step`] at δ = 1 mm
//! (0.7 ms): the rule is for the whole mass on its points, but a foot pitching about its ankle
//! (about 0.01 kg·m²) meets the points' damping through the toe's 0.2 m lever, a far faster
//! mode. Measured on the drop test (dropped 5 cm, PD hold): it settles the same at 0.1, 0.2
//! and 0.4 ms; larger steps were not tried.

use super::contact::{resting_contact, OnGround3d};
use super::tree::{Body3d, BodyPoint, Joint3d, Tree3d};
use crate::physics::ground::Terrain;

/// Total mass (kg): de Leva's reference male.
pub const MASS: f64 = 73.0;
/// Stature (m): de Leva's reference male.
pub const STATURE: f64 = 1.741;
/// Static penetration of the contact rule (m); see the module docs for why 1 mm.
pub const PENETRATION: f64 = 0.001;
/// Joint damping at every joint (N·m·s/rad).
pub const DAMPING: f64 = 0.5;
/// The model's time step (s).
pub const DT: f64 = 1e-4;

/// de Leva's segment lengths (m).
const HEAD: f64 = 0.2033;
const UPPER_TRUNK: f64 = 0.1707;
const MIDDLE_TRUNK: f64 = 0.2155;
const LOWER_TRUNK: f64 = 0.1457;
const UPPER_ARM: f64 = 0.2817;
const FOREARM: f64 = 0.2689;
const HAND: f64 = 0.0862;
const THIGH: f64 = 0.4222;
const SHANK: f64 = 0.4340;
const FOOT: f64 = 0.2581;

/// Our choices (m), see the module docs.
const HIP_HALF_WIDTH: f64 = 0.09;
const SHOULDER_HALF_WIDTH: f64 = 0.17;
const ANKLE_HEIGHT: f64 = 0.07;
const HEEL_BEHIND: f64 = 0.06;
const FOOT_HALF_WIDTH: f64 = 0.045;
const FOOT_COM_DEPTH: f64 = 0.035;

/// Height of the pelvis's origin (the mid-hip) when standing (m).
pub const HIP_HEIGHT: f64 = ANKLE_HEIGHT + SHANK + THIGH;

/// Body indices, in tree order.
pub const PELVIS: usize = 0;
/// The trunk with the head.
pub const TRUNK: usize = 1;
/// Left thigh, shank, foot; right ones at +3.
pub const L_THIGH: usize = 2;
/// Left shank.
pub const L_SHANK: usize = 3;
/// Left foot.
pub const L_FOOT: usize = 4;
/// Right thigh.
pub const R_THIGH: usize = 5;
/// Right shank.
pub const R_SHANK: usize = 6;
/// Right foot.
pub const R_FOOT: usize = 7;
/// Left arm.
pub const L_ARM: usize = 8;
/// Right arm.
pub const R_ARM: usize = 9;

/// Each body's mirror image through the sagittal plane.
const MIRROR_BODY: [usize; 10] = [0, 1, 5, 6, 7, 2, 3, 4, 9, 8];

/// One segment of de Leva's table placed in a body: mass (kg), centre of mass (m, body
/// coordinates) and principal moments about it (kg·m², body axes).
struct Segment {
    mass: f64,
    com: [f64; 3],
    moments: [f64; 3],
}

/// A segment of `length` (m) and mass fraction `fraction` whose first endpoint is at `top`
/// and which runs along −z, its centre of mass at `cm` of the length,
/// radii of gyration `r = [sagittal, transverse, longitudinal]` (fractions of the length).
fn segment(length: f64, fraction: f64, cm: f64, r: [f64; 3], top: [f64; 3]) -> Segment {
    let mass = fraction * MASS;
    let i = r.map(|k| mass * (k * length) * (k * length));
    Segment {
        mass,
        com: [top[0], top[1], top[2] - cm * length],
        moments: i,
    }
}

/// Mass, centre of mass and inertia tensor about it (`[ixx, iyy, izz, ixy, ixz, iyz]`) of
/// rigidly joined segments (the parallel-axis theorem).
fn composite(parts: &[Segment]) -> (f64, [f64; 3], [f64; 6]) {
    let mass: f64 = parts.iter().map(|s| s.mass).sum();
    let mut com = [0.0; 3];
    for s in parts {
        for k in 0..3 {
            com[k] += s.mass * s.com[k] / mass;
        }
    }
    let mut i = [0.0; 6];
    for s in parts {
        let d = [s.com[0] - com[0], s.com[1] - com[1], s.com[2] - com[2]];
        let d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        i[0] += s.moments[0] + s.mass * (d2 - d[0] * d[0]);
        i[1] += s.moments[1] + s.mass * (d2 - d[1] * d[1]);
        i[2] += s.moments[2] + s.mass * (d2 - d[2] * d[2]);
        i[3] -= s.mass * d[0] * d[1];
        i[4] -= s.mass * d[0] * d[2];
        i[5] -= s.mass * d[1] * d[2];
    }
    (mass, com, i)
}

fn body(
    name: &str,
    parent: Option<usize>,
    joint: Joint3d,
    offset: [f64; 3],
    (mass, com, inertia): (f64, [f64; 3], [f64; 6]),
) -> Body3d {
    Body3d {
        name: name.into(),
        parent,
        joint,
        offset,
        orientation: [1.0, 0.0, 0.0, 0.0],
        mass,
        com,
        inertia,
        damping: if parent.is_some() { DAMPING } else { 0.0 },
        actuated: parent.is_some(),
    }
}

/// The articulated body alone (no contact), 10 bodies, 25 degrees of freedom.
pub fn leaper3d_tree() -> Tree3d {
    let pitch = Joint3d::Revolute {
        axis: [0.0, 1.0, 0.0],
    };
    // Pelvis: lower trunk, OMPH at the top, MIDH (the origin) at the bottom.
    let pelvis = composite(&[segment(
        LOWER_TRUNK,
        0.1117,
        0.6115,
        [0.615, 0.551, 0.587],
        [0.0, 0.0, LOWER_TRUNK],
    )]);
    // Trunk: origin at OMPH; XYPH and SUPR above it, the head's vertex at the stature.
    let supr = MIDDLE_TRUNK + UPPER_TRUNK;
    let vertex = STATURE - HIP_HEIGHT - LOWER_TRUNK;
    let trunk = composite(&[
        segment(
            MIDDLE_TRUNK,
            0.1633,
            0.4502,
            [0.482, 0.383, 0.468],
            [0.0, 0.0, MIDDLE_TRUNK],
        ),
        segment(
            UPPER_TRUNK,
            0.1596,
            0.2999,
            [0.716, 0.454, 0.659],
            [0.0, 0.0, supr],
        ),
        segment(
            HEAD,
            0.0694,
            0.5976,
            [0.362, 0.376, 0.312],
            [0.0, 0.0, vertex],
        ),
    ]);
    let arm = composite(&[
        segment(UPPER_ARM, 0.0271, 0.5772, [0.285, 0.269, 0.158], [0.0; 3]),
        segment(
            FOREARM,
            0.0162,
            0.4574,
            [0.276, 0.265, 0.121],
            [0.0, 0.0, -UPPER_ARM],
        ),
        segment(
            HAND,
            0.0061,
            0.79,
            [0.628, 0.513, 0.401],
            [0.0, 0.0, -UPPER_ARM - FOREARM],
        ),
    ]);
    let thigh = composite(&[segment(
        THIGH,
        0.1416,
        0.4095,
        [0.329, 0.329, 0.149],
        [0.0; 3],
    )]);
    let shank = composite(&[segment(
        SHANK,
        0.0433,
        0.4395,
        [0.251, 0.246, 0.102],
        [0.0; 3],
    )]);
    let foot = {
        // Along +x from the heel: longitudinal about x, transverse about y, sagittal about z.
        let mass = 0.0137 * MASS;
        let r = |k: f64| mass * (k * FOOT) * (k * FOOT);
        (
            mass,
            [-HEEL_BEHIND + 0.4415 * FOOT, 0.0, -FOOT_COM_DEPTH],
            [r(0.124), r(0.245), r(0.257), 0.0, 0.0, 0.0],
        )
    };
    let mut bodies = vec![
        body("pelvis", None, Joint3d::Free, [0.0; 3], pelvis),
        body(
            "trunk",
            Some(PELVIS),
            Joint3d::Ball,
            [0.0, 0.0, LOWER_TRUNK],
            trunk,
        ),
    ];
    for (side, s) in [("l", 1.0), ("r", -1.0)] {
        let t = bodies.len();
        bodies.push(body(
            &format!("{side}_thigh"),
            Some(PELVIS),
            Joint3d::Ball,
            [0.0, s * HIP_HALF_WIDTH, 0.0],
            thigh,
        ));
        bodies.push(body(
            &format!("{side}_shank"),
            Some(t),
            pitch,
            [0.0, 0.0, -THIGH],
            shank,
        ));
        bodies.push(body(
            &format!("{side}_foot"),
            Some(t + 1),
            pitch,
            [0.0, 0.0, -SHANK],
            foot,
        ));
    }
    for (side, s) in [("l", 1.0), ("r", -1.0)] {
        bodies.push(body(
            &format!("{side}_arm"),
            Some(TRUNK),
            Joint3d::Ball,
            [0.0, s * SHOULDER_HALF_WIDTH, supr],
            arm,
        ));
    }
    Tree3d {
        name: "leaper3d".into(),
        bodies,
        gravity: 9.81,
        dt: DT,
    }
}

/// The eight contact points: per foot (left, then right) heel outer, heel inner, toe outer,
/// toe inner, on the sole.
pub fn foot_points() -> Vec<BodyPoint> {
    let mut p = Vec::with_capacity(8);
    for (foot, s) in [(L_FOOT, 1.0), (R_FOOT, -1.0)] {
        for x in [-HEEL_BEHIND, FOOT - HEEL_BEHIND] {
            for y in [s * FOOT_HALF_WIDTH, -s * FOOT_HALF_WIDTH] {
                p.push(BodyPoint {
                    body: foot,
                    offset: [x, y, -ANKLE_HEIGHT],
                });
            }
        }
    }
    p
}

/// The `leaper3d` model: [`leaper3d_tree`] on flat ground at [`foot_points`] (see the
/// [module docs](self)).
pub fn leaper3d() -> OnGround3d {
    leaper3d_on(PENETRATION)
}

/// [`leaper3d`] with the contact rule's static penetration `penetration` (m).
pub fn leaper3d_on(penetration: f64) -> OnGround3d {
    let tree = leaper3d_tree();
    OnGround3d {
        contact: resting_contact(MASS, tree.gravity, 8, penetration, 0.9, 0.05),
        tree,
        points: foot_points(),
        terrain: Terrain::Flat,
    }
}

/// The standing state: every joint at zero, at rest, the soles at z = 0 (the pelvis's
/// origin at [`HIP_HEIGHT`]).
pub fn standing(tree: &Tree3d) -> Vec<f64> {
    let mut x = Vec::with_capacity(tree.nq() + tree.nv());
    for b in &tree.bodies {
        match b.joint {
            Joint3d::Free => x.extend([0.0, 0.0, HIP_HEIGHT, 1.0, 0.0, 0.0, 0.0]),
            Joint3d::Ball => x.extend([1.0, 0.0, 0.0, 0.0]),
            Joint3d::Revolute { .. } => x.push(0.0),
        }
    }
    x.resize(tree.nq() + tree.nv(), 0.0);
    x
}

/// The state reflected through the sagittal plane (y → −y): left and right bodies swap;
/// positions and linear velocities flip y; quaternions (w, x, y, z) become (w, −x, y, −z)
/// and angular velocities (x, y, z) become (−x, y, −z) (rotations about y, the knees' and
/// ankles', are unchanged).
pub fn mirror(tree: &Tree3d, x: &[f64]) -> Vec<f64> {
    let nq = tree.nq();
    let mut y = x.to_vec();
    for (i, b) in tree.bodies.iter().enumerate() {
        let j = MIRROR_BODY[i];
        let (qi, qj) = (tree.q_index(i), tree.q_index(j));
        let (vi, vj) = (nq + tree.v_index(i), nq + tree.v_index(j));
        let (q, v) = (&x[qj..qj + b.joint.nq()], &x[vj..vj + b.joint.nv()]);
        let (oq, ov) = match b.joint {
            Joint3d::Free => (
                vec![q[0], -q[1], q[2], q[3], -q[4], q[5], -q[6]],
                vec![v[0], -v[1], v[2], -v[3], v[4], -v[5]],
            ),
            Joint3d::Ball => (vec![q[0], -q[1], q[2], -q[3]], vec![-v[0], v[1], -v[2]]),
            Joint3d::Revolute { .. } => (q.to_vec(), v.to_vec()),
        };
        y[qi..qi + b.joint.nq()].copy_from_slice(&oq);
        y[vi..vi + b.joint.nv()].copy_from_slice(&ov);
    }
    y
}

/// Controls mirrored like [`mirror`]: ball torques (x, y, z) → (−x, y, −z), swapped left and
/// right; revolute (pitch) torques swapped.
pub fn mirror_controls(tree: &Tree3d, u: &[f64]) -> Vec<f64> {
    let mut at = [0usize; 10];
    let mut k = 0;
    for i in tree.actuated() {
        at[i] = k;
        k += tree.bodies[i].joint.nv();
    }
    let mut out = u.to_vec();
    for i in tree.actuated() {
        let (a, b) = (at[i], at[MIRROR_BODY[i]]);
        match tree.bodies[i].joint {
            Joint3d::Ball => out[a..a + 3].copy_from_slice(&[-u[b], u[b + 1], -u[b + 2]]),
            _ => out[a] = u[b],
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{IntegratorKind, Model, Ode, Simulator};
    use crate::portable::{cos, sin};

    /// PD hold of the standing joint angles: per actuated body (stiffness N·m/rad, damping
    /// N·m·s/rad).
    fn gains(i: usize) -> (f64, f64) {
        match i {
            TRUNK => (1500.0, 60.0),
            L_THIGH | R_THIGH => (1500.0, 60.0),
            L_SHANK | R_SHANK => (1500.0, 40.0),
            L_FOOT | R_FOOT => (800.0, 10.0),
            _ => (200.0, 5.0),
        }
    }

    /// Torques holding every joint at zero angle.
    fn pd(tree: &Tree3d, x: &[f64], u: &mut [f64]) {
        let nq = tree.nq();
        let mut k = 0;
        for i in tree.actuated() {
            let (kp, kd) = gains(i);
            let (iq, iv) = (tree.q_index(i), nq + tree.v_index(i));
            match tree.bodies[i].joint {
                Joint3d::Ball => {
                    let s = if x[iq] < 0.0 { -1.0 } else { 1.0 };
                    for c in 0..3 {
                        u[k + c] = -kp * 2.0 * s * x[iq + 1 + c] - kd * x[iv + c];
                    }
                    k += 3;
                }
                _ => {
                    u[k] = -kp * x[iq] - kd * x[iv];
                    k += 1;
                }
            }
        }
    }

    #[test]
    fn leaper3d_describe_lists_every_body_and_the_mass_adds_up() {
        let m = leaper3d();
        m.validate().unwrap();
        let p = m.parameters();
        let find = |n: &str| p.iter().find(|q| q.name == n);
        for b in &m.tree.bodies {
            let n = &b.name;
            let mass = find(&format!("{n}.mass")).unwrap();
            assert_eq!((mass.unit, mass.value), ("kg", b.mass));
            assert!(b.mass > 0.0);
            for c in ["ixx", "iyy", "izz", "ixy", "ixz", "iyz"] {
                assert_eq!(find(&format!("{n}.inertia.{c}")).unwrap().unit, "kg*m^2");
            }
            assert!(find(&format!("{n}.joint")).is_some());
            if b.parent.is_some() {
                for c in ["x", "y", "z"] {
                    assert_eq!(find(&format!("{n}.offset.{c}")).unwrap().unit, "m");
                }
            }
            if let Joint3d::Revolute { .. } = b.joint {
                assert_eq!(find(&format!("{n}.axis.y")).unwrap().value, 1.0);
            }
        }
        assert!(find("contact_point7.offset.z").is_some());
        let total: f64 = m.tree.bodies.iter().map(|b| b.mass).sum();
        assert!((total - MASS).abs() < 1e-9, "{total}");
        assert_eq!(m.tree.bodies.len(), 10);
        assert_eq!(m.tree.nv(), 25);
        assert_eq!(m.state_names().len(), m.state_dim());
        assert_eq!(m.control_names().len(), 19);
        assert_eq!(m.control_names()[0], "trunk_tx");
    }

    #[test]
    fn leaper3d_stands_on_its_soles_over_its_support() {
        let m = leaper3d();
        let x = standing(&m.tree);
        let pts = m.point_states(&x);
        for (k, (p, _)) in pts.iter().enumerate() {
            assert!(p.z.abs() < 1e-3, "point {k} at z = {}", p.z);
        }
        let com = m.tree.center_of_mass(&x[..m.tree.nq()]);
        let (lo_x, hi_x) = pts.iter().fold((f64::MAX, f64::MIN), |(a, b), (p, _)| {
            (a.min(p.x), b.max(p.x))
        });
        let (lo_y, hi_y) = pts.iter().fold((f64::MAX, f64::MIN), |(a, b), (p, _)| {
            (a.min(p.y), b.max(p.y))
        });
        // The support polygon is the rectangle around both feet (they are parallel).
        assert!(com.x > lo_x && com.x < hi_x && com.y > lo_y && com.y < hi_y);
        assert!(com.z > 0.8 && com.z < 1.2, "{com}");
        // The head's top at the stature.
        let top = m
            .tree
            .point_state(&x, TRUNK, [0.0, 0.0, STATURE - HIP_HEIGHT - LOWER_TRUNK]);
        assert!((top.0.z - STATURE).abs() < 1e-12);
    }

    #[test]
    fn leaper3d_dropped_with_a_pd_hold_comes_to_rest() {
        let m = leaper3d();
        let mut x0 = standing(&m.tree);
        x0[2] += 0.05;
        let steps = (1.5 / DT).round() as usize;
        let mut worst = f64::NEG_INFINITY;
        let mut sim = Simulator::new(m.clone(), IntegratorKind::Rk4);
        let tree = m.tree.clone();
        let x = sim
            .rollout(
                &x0,
                DT,
                steps,
                |_, _, x, u| pd(&tree, x, u),
                |_, _, x| worst = worst.max(m.penetration(x)),
            )
            .unwrap();
        let nq = m.tree.nq();
        let speed = x[nq..nq + 3].iter().map(|v| v * v).sum::<f64>().sqrt();
        let rest = m.penetration(&x);
        eprintln!("root speed {speed:e} m/s, resting {rest:e} m, deepest {worst:e} m");
        assert!(speed < 0.05, "{speed}");
        assert!(rest < 0.002 && rest > 0.0, "{rest}");
        assert!(x[2] > HIP_HEIGHT - 0.02, "pelvis at {}", x[2]);
    }

    /// A survey, not a check (`cargo test --release --lib -- --ignored step_survey
    /// --nocapture`): which RK4 steps the leaper survives, in the air with and without the PD
    /// hold and dropped 2 cm onto contacts of several static penetrations without torques.
    /// It prints the pelvis height after each run or `X` where the run blew up; what it found
    /// is in docs/body3d.md.
    #[test]
    #[ignore]
    fn leaper3d_step_survey() {
        let steps = [1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2];
        let run = |m: &OnGround3d, x0: &[f64], dt: f64, secs: f64, hold: bool| {
            let mut sim = Simulator::new(m.clone(), IntegratorKind::Rk4);
            let tree = m.tree.clone();
            let n = (secs / dt).round() as usize;
            match sim.rollout(
                x0,
                dt,
                n,
                |_, _, x, u| {
                    if hold {
                        pd(&tree, x, u)
                    } else {
                        u.fill(0.0)
                    }
                },
                |_, _, _| {},
            ) {
                Ok(x) => format!("{:.2}", x[2]),
                Err(_) => "X".into(),
            }
        };
        for hold in [false, true] {
            let m = leaper3d();
            let mut x0 = standing(&m.tree);
            x0[2] += 2.0;
            let nq = m.tree.nq();
            for k in 0..m.tree.nv() {
                x0[nq + k] = 0.3 * sin(1.7 * k as f64);
            }
            let cells: Vec<String> = steps
                .iter()
                .map(|&dt| run(&m, &x0, dt, 0.5, hold))
                .collect();
            eprintln!("air, PD hold {hold}: {cells:?} at {steps:?} s");
        }
        for pen in [0.001, 0.005, 0.01, 0.02] {
            let m = leaper3d_on(pen);
            let mut x0 = standing(&m.tree);
            x0[2] += 0.02;
            let cells: Vec<String> = steps
                .iter()
                .map(|&dt| run(&m, &x0, dt, 0.6, false))
                .collect();
            eprintln!("ground, penetration {pen} m, no torques: {cells:?} at {steps:?} s");
        }
    }

    #[test]
    fn leaper3d_mirrored_start_stays_mirrored() {
        let m = leaper3d();
        let t = &m.tree;
        let nq = t.nq();
        let mut x0 = standing(t);
        x0[2] += 0.01;
        // Something asymmetric: a tilted pelvis, a raised left leg, spins.
        let l = t.q_index(L_THIGH);
        x0[3..7].copy_from_slice(&[0.99, 0.05, -0.03, 0.08]);
        x0[l..l + 4].copy_from_slice(&[0.97, 0.1, -0.2, 0.05]);
        t.normalize_state(&mut x0);
        x0[t.q_index(L_SHANK)] = 0.4;
        for (k, v) in x0[nq..].iter_mut().enumerate() {
            *v = 0.3 * sin((k as f64) * 0.7 + 0.2);
        }
        let u: Vec<f64> = (0..m.control_dim())
            .map(|k| 5.0 * cos((k as f64) * 1.3))
            .collect();
        let (x1, u1) = (mirror(t, &x0), mirror_controls(t, &u));
        let run = |x: &[f64], u: &[f64]| {
            let mut out = Vec::new();
            let mut sim = Simulator::new(m.clone(), IntegratorKind::Rk4);
            sim.rollout(
                x,
                DT,
                2000,
                |_, _, _, c| c.copy_from_slice(u),
                |k, _, x| {
                    if k % 100 == 0 {
                        out.push(x.to_vec())
                    }
                },
            )
            .unwrap();
            out
        };
        let (a, b) = (run(&x0, &u), run(&x1, &u1));
        let mut worst: f64 = 0.0;
        for (xa, xb) in a.iter().zip(&b) {
            let ma = mirror(t, xa);
            for (p, q) in ma.iter().zip(xb) {
                worst = worst.max((p - q).abs());
            }
        }
        eprintln!("largest mirror mismatch {worst:e}");
        assert!(worst < 1e-9, "{worst:e}");
        // And the mirror is an involution that does change this state.
        assert_eq!(mirror(t, &x1), x0);
        assert!(x1 != x0);
    }

    #[test]
    fn leaper3d_energy_in_the_air_is_conserved_to_rk4_order() {
        let mut t = leaper3d_tree();
        t.bodies.iter_mut().for_each(|b| b.damping = 0.0);
        let nq = t.nq();
        let mut x0 = standing(&t);
        x0[2] = 100.0;
        let l = t.q_index(L_SHANK);
        x0[l] = 0.5;
        for (k, v) in x0[nq..].iter_mut().enumerate() {
            *v = 1.5 * sin((k as f64) * 0.9 + 0.4);
        }
        let e0 = t.energy(&x0).unwrap();
        let u = vec![0.0; t.control_dim()];
        let drift = |dt: f64| {
            let mut sim = Simulator::new(t.clone(), IntegratorKind::Rk4);
            let steps = (0.5 / dt).round() as usize;
            let x = sim
                .rollout(
                    &x0,
                    dt,
                    steps,
                    |_, _, _, c| c.copy_from_slice(&u),
                    |_, _, _| {},
                )
                .unwrap();
            (t.energy(&x).unwrap() - e0).abs()
        };
        let (d1, d2) = (drift(0.004), drift(0.002));
        let order = (d1 / d2).log2();
        eprintln!("drifts {d1:e}, {d2:e}: order {order}");
        assert!(
            (3.5..4.6).contains(&order),
            "drifts {d1:e}, {d2:e}: order {order}"
        );
        assert!(drift(1e-3) < 1e-8 * e0.abs());
    }
}
