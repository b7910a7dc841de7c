//! # Planar diver (linear Bellman combination, Fig. 6 and 8)
//!
//! A seven-link planar character in flight, built on [`PlanarTree`]: torso (root, its joint at
//! the hip), head, upper arms, forearms with hands, thighs, shanks and feet (left and right
//! limbs lumped, as in a symmetric dive). Six joint motors (neck, shoulder, elbow, hip, knee,
//! ankle); gravity only, no water or air forces. State: hip position, torso angle, the six
//! joint angles, and their rates (18 variables).
//!
//! Parameters (ours; the paper takes Sok et al. 2007's, which we do not have): a 70 kg, 1.75 m
//! body with segment masses and lengths after Winter's anthropometric tables, centre-of-mass
//! fractions of about 0.45 of segment length and radii of gyration of 0.3 segment lengths.
//!
//! The *entry angle* is the angle of the body line from the feet to the hands measured from
//! straight down (0 = a vertical, head-first entry), positive counter-clockwise.

use super::planar::{PlanarLink, PlanarTree};

/// Builds the diver.
pub fn diver() -> PlanarTree {
    let link =
        |name: &str, parent: Option<usize>, attach: f64, mass: f64, length: f64, com: f64| {
            PlanarLink {
                name: name.into(),
                parent,
                attach,
                mass,
                length,
                com,
                inertia: mass * (0.3 * length).powi(2),
                damping: 0.5,
                actuated: parent.is_some(),
            }
        };
    PlanarTree {
        name: "diver".into(),
        links: vec![
            link("torso", None, 0.0, 34.8, 0.52, 0.27),
            link("head", Some(0), 0.52, 5.7, 0.25, 0.12),
            link("upper_arm", Some(0), 0.50, 3.9, 0.30, 0.13),
            link("forearm", Some(2), 0.30, 3.1, 0.42, 0.18),
            link("thigh", Some(0), 0.0, 14.0, 0.43, 0.19),
            link("shank", Some(4), 0.43, 6.5, 0.43, 0.19),
            link("foot", Some(5), 0.43, 2.0, 0.20, 0.08),
        ],
        floating: true,
        gravity: 9.81,
        forces: vec![],
    }
}

/// Index of the forearm (hands at its tip) and of the foot (toes at its tip).
const FOREARM: usize = 3;
const FOOT: usize = 6;

/// Angle of the feet-to-hands line from straight down (rad), in (−π, π].
pub fn entry_angle(tree: &PlanarTree, q: &[f64]) -> f64 {
    let hands = tree.point(q, FOREARM, tree.links[FOREARM].length);
    let feet = tree.point(q, FOOT, tree.links[FOOT].length);
    let (dx, dy) = (hands[0] - feet[0], hands[1] - feet[1]);
    // Straight down is (0, −1); angle of (dx, dy) relative to it, counter-clockwise.
    crate::portable::atan2(dx, -dy)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::Model;
    use std::f64::consts::PI;

    #[test]
    fn structure_and_names() {
        let d = diver();
        d.validate().unwrap();
        assert_eq!(d.state_dim(), 18);
        assert_eq!(d.control_dim(), 6);
        let mass: f64 = d.links.iter().map(|l| l.mass).sum();
        assert!((mass - 70.0).abs() < 0.5, "{mass}");
    }

    #[test]
    fn entry_angle_of_straight_poses() {
        let d = diver();
        // Torso pointing straight down (−π/2), arms overhead (shoulder joint π relative: arm
        // continues the torso line), legs straight up (hip joint π from torso): vertical entry.
        let mut q = [0.0; 9];
        q[2] = -PI / 2.0;
        q[4] = 0.0; // upper arm along the torso, beyond the shoulder
        q[6] = PI; // thigh opposite the torso
        assert!(entry_angle(&d, &q).abs() < 1e-12, "{}", entry_angle(&d, &q));
        // Rotating the whole body by 0.3 rad rotates the entry angle by 0.3 rad.
        q[2] += 0.3;
        assert!((entry_angle(&d, &q) - 0.3).abs() < 1e-12);
    }
}
