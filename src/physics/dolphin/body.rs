//! # Building the dolphin's body: stations, springs, faces and muscle arms
//!
//! [`Dolphin::new`] validates the parameters and lays out the body described in the parent
//! module: 7 stations along x (the nose, five 4-mass rings, the fluke tips), the 91 springs
//! (ring, diameter, longitudinal, shear diagonals, fluke), the 26 outward faces and, for each
//! muscle spring, its lever arm. A muscle bends its segment by θ = c θ_max about y; a spring
//! a–b whose moving end p rotates about the pivot centroid p̄ changes length by
//!
//! ```text
//! ∂L/∂θ = e · (ŷ × (p − p̄)),      e = (p − p_fixed) / |p − p_fixed|,
//! ```
//!
//! to first order, so its rest length becomes L₀ ∓ c θ_max |∂L/∂θ| (dorsal −, ventral +).
//!
//! ## References
//! - X. Tu, D. Terzopoulos, *Artificial Fishes*, SIGGRAPH 1994, §3.
//! - R. Grzeszczuk, D. Terzopoulos, *Automated Learning of Muscle-Actuated Locomotion Through
//!   Control Abstraction*, SIGGRAPH 1995.

use super::*;

/// |∂L/∂θ| of spring a–b of `segment` when the segment bends by θ about the y axis: the
/// station behind ring 1 (segments 1–5), or the nose (segment 0), rotates about the centroid
/// of the segment's ring station (ring 1 for segment 0, ring s for segment s ≥ 1).
fn bend_arm(rest: &[f64], masses: &[f64], segment: usize, a: usize, b: usize) -> f64 {
    let pivot_station = segment.max(1);
    let (mut pivot, mut m) = (Vector3::zeros(), 0.0);
    for i in (0..N_MASSES).filter(|&i| station_of_mass(i) == pivot_station) {
        pivot += masses[i] * point(rest, i);
        m += masses[i];
    }
    pivot /= m;
    let (fixed, moving) = if station_of_mass(a) == pivot_station {
        (a, b)
    } else {
        (b, a)
    };
    let r = point(rest, moving) - pivot;
    let e = (point(rest, moving) - point(rest, fixed)).normalize();
    e.dot(&Vector3::y().cross(&r)).abs()
}

impl Dolphin {
    /// Validates `params` and builds the body.
    pub fn new(params: DolphinParams) -> Result<Self, DolphinError> {
        validate(&params)?;
        let (masses, rest) = rest_shape(&params);
        let springs = springs(&params, &rest, &masses)?;
        let faces = faces();
        Ok(Self {
            params,
            masses,
            rest,
            springs,
            faces,
        })
    }
}

/// Checks the parameters: stations ordered nose to tail, sizes, masses and stiffnesses
/// positive, damping and drag not negative, gravity finite, the largest bend not negative.
fn validate(p: &DolphinParams) -> Result<(), DolphinError> {
    let positive = |name, value: f64| {
        if value.is_finite() && value > 0.0 {
            Ok(())
        } else {
            Err(DolphinError::NotPositive { name, value })
        }
    };
    let non_negative = |name, value: f64| {
        if value.is_finite() && value >= 0.0 {
            Ok(())
        } else {
            Err(DolphinError::Negative { name, value })
        }
    };
    if !(p.station_x.iter().all(|x| x.is_finite()) && p.station_x.windows(2).all(|w| w[0] > w[1])) {
        return Err(DolphinError::StationOrder(p.station_x));
    }
    for &h in &p.ring_half_height {
        positive("ring_half_height", h)?;
    }
    for &w in &p.ring_half_width {
        positive("ring_half_width", w)?;
    }
    positive("fluke_half_span", p.fluke_half_span)?;
    for &m in &p.station_mass {
        positive("station_mass", m)?;
    }
    positive("stiffness", p.stiffness)?;
    positive("muscle_stiffness", p.muscle_stiffness)?;
    non_negative("damping", p.damping)?;
    non_negative("drag", p.drag)?;
    if !p.gravity.is_finite() {
        return Err(DolphinError::NotPositive {
            name: "gravity",
            value: p.gravity,
        });
    }
    if !(p.max_bend.is_finite() && p.max_bend >= 0.0) {
        return Err(DolphinError::Bend(p.max_bend));
    }
    Ok(())
}

/// Every mass and the rest positions (x, y, z per mass): the nose, each ring's top, left,
/// bottom and right, the fluke tips.
fn rest_shape(p: &DolphinParams) -> ([f64; N_MASSES], [f64; N_POS]) {
    let mut masses = [0.0; N_MASSES];
    let mut rest = [0.0; N_POS];
    for (i, m) in masses.iter_mut().enumerate() {
        let st = station_of_mass(i);
        *m = p.station_mass[st];
        let x = p.station_x[st];
        let (y, z) = match i {
            NOSE => (0.0, 0.0),
            FLUKE_LEFT => (p.fluke_half_span, 0.0),
            FLUKE_RIGHT => (-p.fluke_half_span, 0.0),
            _ => {
                let (h, w) = (p.ring_half_height[st - 1], p.ring_half_width[st - 1]);
                [(0.0, h), (w, 0.0), (0.0, -h), (-w, 0.0)][(i - 1) % 4]
            }
        };
        rest[3 * i..3 * i + 3].copy_from_slice(&[x, y, z]);
    }
    (masses, rest)
}

/// The 91 springs at their rest lengths, muscles with their lever arms; a largest bend that
/// would shorten a muscle spring to nothing is an error.
fn springs(
    p: &DolphinParams,
    rest: &[f64; N_POS],
    masses: &[f64; N_MASSES],
) -> Result<Vec<Spring>, DolphinError> {
    let mut springs = Vec::with_capacity(91);
    let mut spring = |a: usize, b: usize, kind, muscle: Option<(usize, Side)>| {
        let rest_length = (point(rest, b) - point(rest, a)).norm();
        let muscle = muscle.map(|(segment, side)| Muscle {
            segment,
            side,
            arm: bend_arm(rest, masses, segment, a, b),
        });
        springs.push(Spring {
            a,
            b,
            rest_length,
            stiffness: if muscle.is_some() {
                p.muscle_stiffness
            } else {
                p.stiffness
            },
            kind,
            muscle,
        })
    };
    let side = |k: usize, seg: usize| match k {
        TOP => Some((seg, Side::Dorsal)),
        BOTTOM => Some((seg, Side::Ventral)),
        _ => None,
    };
    for r in 0..N_RINGS {
        for k in 0..4 {
            spring(
                ring_mass(r, k),
                ring_mass(r, (k + 1) % 4),
                SpringKind::Ring,
                None,
            );
        }
        spring(
            ring_mass(r, TOP),
            ring_mass(r, BOTTOM),
            SpringKind::Cross,
            None,
        );
        spring(
            ring_mass(r, LEFT),
            ring_mass(r, RIGHT),
            SpringKind::Cross,
            None,
        );
    }
    for k in 0..4 {
        spring(NOSE, ring_mass(0, k), SpringKind::Longitudinal, side(k, 0));
    }
    for r in 0..N_RINGS - 1 {
        for k in 0..4 {
            let k1 = (k + 1) % 4;
            spring(
                ring_mass(r, k),
                ring_mass(r + 1, k),
                SpringKind::Longitudinal,
                side(k, r + 1),
            );
            spring(
                ring_mass(r, k),
                ring_mass(r + 1, k1),
                SpringKind::Diagonal,
                None,
            );
            spring(
                ring_mass(r, k1),
                ring_mass(r + 1, k),
                SpringKind::Diagonal,
                None,
            );
        }
    }
    for k in 0..4 {
        for tip in [FLUKE_LEFT, FLUKE_RIGHT] {
            spring(ring_mass(4, k), tip, SpringKind::Longitudinal, side(k, 5));
        }
    }
    spring(FLUKE_LEFT, FLUKE_RIGHT, SpringKind::Fluke, None);
    for s in &springs {
        if let Some(m) = s.muscle {
            if p.max_bend * m.arm >= s.rest_length {
                return Err(DolphinError::Bend(p.max_bend));
            }
        }
    }
    Ok(springs)
}

/// The 26 outward faces: triangles at the nose and the fluke, quads between the rings.
fn faces() -> Vec<Face> {
    let mut faces = Vec::with_capacity(26);
    let tri = |a, b, c| Face {
        corners: [a, b, c, c],
        n: 3,
    };
    for k in 0..4 {
        faces.push(tri(NOSE, ring_mass(0, (k + 1) % 4), ring_mass(0, k)));
    }
    for r in 0..N_RINGS - 1 {
        for k in 0..4 {
            let k1 = (k + 1) % 4;
            faces.push(Face {
                corners: [
                    ring_mass(r, k1),
                    ring_mass(r + 1, k1),
                    ring_mass(r + 1, k),
                    ring_mass(r, k),
                ],
                n: 4,
            });
        }
    }
    let m5 = |k| ring_mass(4, k);
    let (fl, fr) = (FLUKE_LEFT, FLUKE_RIGHT);
    faces.extend([
        tri(m5(LEFT), fl, m5(TOP)),
        tri(m5(TOP), fl, fr),
        tri(m5(TOP), fr, m5(RIGHT)),
        tri(m5(BOTTOM), fl, m5(LEFT)),
        tri(m5(BOTTOM), fr, fl),
        tri(m5(RIGHT), fr, m5(BOTTOM)),
    ]);
    faces
}

#[cfg(test)]
mod tests {
    use super::super::tests::perturbed;
    use super::*;
    use crate::physics::{model_by_name, Model, Ode};

    #[test]
    fn layout_has_23_masses_91_springs_26_faces_6_segments() {
        let d = Dolphin::default();
        assert_eq!(d.springs().len(), 91);
        assert_eq!(d.faces().len(), 26);
        assert_eq!(d.state_dim(), 138);
        assert_eq!(d.position_dim(), Some(69));
        assert_eq!(d.control_names()[5], "muscle6");
        assert_eq!(d.state_names()[69], "nose.vx");
        let mut per_segment = [0; N_SEGMENTS];
        for i in 0..N_MASSES {
            let s = segment_of_mass(i);
            per_segment[s] += 1;
            assert!(segment_frame_masses(s).contains(&i), "mass {i}");
        }
        assert_eq!(per_segment, [5, 4, 4, 4, 4, 2]);
        // Each muscle has one dorsal and one ventral group.
        for seg in 0..N_SEGMENTS {
            let count = |side| {
                d.springs()
                    .iter()
                    .filter(|s| s.muscle.is_some_and(|m| m.segment == seg && m.side == side))
                    .count()
            };
            let expect = if seg == 5 { 2 } else { 1 };
            assert_eq!(
                (count(Side::Dorsal), count(Side::Ventral)),
                (expect, expect)
            );
        }
        let m = model_by_name("dolphin").unwrap();
        assert_eq!(m.state_dim(), 138);
        assert!(crate::physics::MODEL_NAMES.contains(&"dolphin"));
    }

    #[test]
    fn surface_is_closed_and_outward() {
        let d = Dolphin::default();
        for x in [d.rest_state(), perturbed(&d, 0.05)] {
            let total: Vector3<f64> = d.faces().iter().map(|f| f.vector_area(&x)).sum();
            assert!(total.norm() < 1e-14, "open surface: {total}");
        }
        let q = d.rest_positions();
        for f in d.faces() {
            let c = f.mean(q);
            let radial = Vector3::new(0.0, c.y, c.z);
            assert!(f.vector_area(q).dot(&radial) > 0.0, "{f:?} points inwards");
        }
        let v = d.volume(&d.rest_state());
        assert!(v > 0.05 && v < 0.2, "volume {v}");
    }
}
