//! # `chain3d`: a small floating tree to check the engine against MuJoCo
//!
//! Four bodies, no contact, z up, gravity 9.81 m/s² along −z:
//!
//! ```text
//! torso (free) ─┬─ upper (ball) ── lower (revolute, axis (0.36, 0.48, 0.8))
//!               └─ arm (revolute, axis (0.8, 0, 0.6))
//! ```
//!
//! | body | parent | joint | offset in parent (m) | joint-frame quaternion (w, x, y, z) | mass (kg) | centre of mass (m) | inertia about the centre of mass `[ixx, iyy, izz, ixy, ixz, iyz]` (kg·m²) | damping (N·m·s/rad) |
//! | --- | --- | --- | --- | --- | --- | --- | --- | --- |
//! | torso | world | free | — | — | 4.0 | (0.02, −0.01, 0.05) | [0.06, 0.05, 0.03, 0.004, −0.003, 0.002] | — |
//! | upper | torso | ball | (0, 0.1, −0.25) | (0.9887710779360422, 0.14943813247359922, 0, 0), 0.3 rad about x | 1.5 | (0, 0.01, −0.18) | [0.02, 0.021, 0.004, 0.001, 0.0005, −0.001] | 0.05 |
//! | lower | upper | revolute, axis (0.36, 0.48, 0.8) | (0, 0, −0.36) | identity | 1.0 | (0.01, 0, −0.16) | [0.012, 0.011, 0.002, −0.0008, 0.0006, 0.0004] | 0.02 |
//! | arm | torso | revolute, axis (0.8, 0, 0.6) | (0.05, −0.15, 0.2) | (0.9950041652780258, 0, 0, 0.09983341664682815), 0.2 rad about z | 0.8 | (0, −0.12, 0) | [0.006, 0.001, 0.006, 0.0003, 0, 0.0002] | 0.03 |
//!
//! The revolute axes are along no principal axis of their bodies and the inertia tensors are
//! not diagonal, so every coupling term of the equations is exercised. Every joint but the
//! root's has motors (controls `upper_tx, upper_ty, upper_tz, lower_torque, arm_torque`, N·m).
//! State (24): `[torso x, y, z, qw, qx, qy, qz, upper qw…qz, lower angle, arm angle]`
//! (13 positions) then `[torso vx, vy, vz (world), wx, wy, wz (body), upper wx, wy, wz
//! (body), lower rate, arm rate]` (11 velocities), MuJoCo's `qpos` and `qvel` exactly.
//!
//! `scripts/mujoco/chain3d.py` builds the same model in MuJoCo from `motionlab describe
//! chain3d` and writes reference trajectories to `tests/data/chain3d/`; the tests below replay
//! them.

use super::tree::{Body3d, Joint3d, Tree3d};

/// The `chain3d` model (see the [module docs](self) for every value).
pub fn chain3d() -> Tree3d {
    let body = |name: &str,
                parent: Option<usize>,
                joint: Joint3d,
                offset: [f64; 3],
                orientation: [f64; 4],
                mass: f64,
                com: [f64; 3],
                inertia: [f64; 6],
                damping: f64| Body3d {
        name: name.into(),
        parent,
        joint,
        offset,
        orientation,
        mass,
        com,
        inertia,
        damping,
        actuated: parent.is_some(),
    };
    let identity = [1.0, 0.0, 0.0, 0.0];
    Tree3d {
        name: "chain3d".into(),
        bodies: vec![
            body(
                "torso",
                None,
                Joint3d::Free,
                [0.0; 3],
                identity,
                4.0,
                [0.02, -0.01, 0.05],
                [0.06, 0.05, 0.03, 0.004, -0.003, 0.002],
                0.0,
            ),
            body(
                "upper",
                Some(0),
                Joint3d::Ball,
                [0.0, 0.1, -0.25],
                [0.9887710779360422, 0.14943813247359922, 0.0, 0.0],
                1.5,
                [0.0, 0.01, -0.18],
                [0.02, 0.021, 0.004, 0.001, 0.0005, -0.001],
                0.05,
            ),
            body(
                "lower",
                Some(1),
                Joint3d::Revolute {
                    axis: [0.36, 0.48, 0.8],
                },
                [0.0, 0.0, -0.36],
                identity,
                1.0,
                [0.01, 0.0, -0.16],
                [0.012, 0.011, 0.002, -0.0008, 0.0006, 0.0004],
                0.02,
            ),
            body(
                "arm",
                Some(0),
                Joint3d::Revolute {
                    axis: [0.8, 0.0, 0.6],
                },
                [0.05, -0.15, 0.2],
                [0.9950041652780258, 0.0, 0.0, 0.09983341664682815],
                0.8,
                [0.0, -0.12, 0.0],
                [0.006, 0.001, 0.006, 0.0003, 0.0, 0.0002],
                0.03,
            ),
        ],
        gravity: 9.81,
        dt: 0.001,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::body3d::spatial::quat_angle;
    use crate::physics::{IntegratorKind, Model, Ode, Simulator};

    /// MuJoCo's rows: `t`, the state in describe's order, MuJoCo's energy, the controls.
    fn reference(csv: &str) -> Vec<Vec<f64>> {
        let mut lines = csv.lines().filter(|l| !l.starts_with('#'));
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let names = chain3d().state_names();
        assert_eq!(
            header[1..=names.len()],
            names.iter().map(|s| s.as_str()).collect::<Vec<_>>()[..]
        );
        lines
            .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
            .collect()
    }

    /// Largest joint-angle difference (rad) between our RK4 rollout and MuJoCo's over 2 s,
    /// and the largest energy difference (J).
    fn against_mujoco(csv: &str) -> (f64, f64) {
        let model = chain3d();
        model.validate().unwrap();
        let (nx, nu) = (model.state_dim(), model.control_dim());
        let rows = reference(csv);
        let u: Vec<f64> = rows[0][rows[0].len() - nu..].to_vec();
        let dt = model.default_dt();
        let stride = ((rows[1][0] - rows[0][0]) / dt).round() as usize;
        let steps = stride * (rows.len() - 1);
        let mut sim = Simulator::new(model.clone(), IntegratorKind::Rk4);
        let (mut angle, mut energy) = (0.0f64, 0.0f64);
        sim.rollout(
            &rows[0][1..=nx],
            dt,
            steps,
            |_, _, _, c| c.copy_from_slice(&u),
            |k, _, x| {
                if k % stride != 0 {
                    return;
                }
                let r = &rows[k / stride];
                let y = &r[1..=nx];
                for (i, b) in model.bodies.iter().enumerate() {
                    let iq = model.q_index(i);
                    let e = match b.joint {
                        Joint3d::Free => quat_angle(&x[iq + 3..iq + 7], &y[iq + 3..iq + 7]),
                        Joint3d::Ball => quat_angle(&x[iq..iq + 4], &y[iq..iq + 4]),
                        Joint3d::Revolute { .. } => (x[iq] - y[iq]).abs(),
                    };
                    angle = angle.max(e);
                }
                energy = energy.max((model.energy(x).unwrap() - r[nx + 1]).abs());
            },
        )
        .unwrap();
        (angle, energy)
    }

    fn check(name: &str, csv: &str) {
        let (angle, energy) = against_mujoco(csv);
        eprintln!("{name}: largest angle error {angle:.3e} rad, energy error {energy:.3e} J");
        assert!(
            angle < 1e-6 && energy < 1e-6,
            "{name}: {angle} rad, {energy} J"
        );
    }

    #[test]
    fn tumble_matches_mujoco() {
        check(
            "tumble",
            include_str!("../../../tests/data/chain3d/tumble.csv"),
        );
    }

    #[test]
    fn spin_matches_mujoco() {
        check("spin", include_str!("../../../tests/data/chain3d/spin.csv"));
    }

    #[test]
    fn driven_matches_mujoco() {
        check(
            "driven",
            include_str!("../../../tests/data/chain3d/driven.csv"),
        );
    }
}
