//! # Planar articulated trees (fixed or floating base)
//!
//! Rigid links in the vertical plane joined by revolute joints into a tree. Link i points along
//! e(φ_i) = (cos φ_i, sin φ_i) with φ_i its absolute angle from the +x axis (counter-clockwise);
//! its joint sits on its parent at distance `attach` along the parent, its centre of mass at
//! distance `com` along itself. Generalized coordinates q: for a floating base the root joint
//! position (x, y) and the root angle, then one relative angle per non-root link; for a fixed
//! base the root angle (about a pivot) and the relative angles.
//!
//! Equations of motion by virtual work over the links' Newton–Euler equations. With J_i the
//! Jacobian of link i's centre of mass, j_i the (constant, 0/1) Jacobian of its angle, and
//! a_i = −Σ_k d_k φ̇_k² e(φ_k) the velocity-product acceleration of its centre of mass (sum over
//! the links k on its path, lever d_k the attachment of the next link on the path, or `com`
//! for the link itself):
//!
//! M(q) q̈ = Q − Σ_i m_i J_iᵀ (a_i − g),  M = Σ_i (m_i J_iᵀ J_i + I_i j_iᵀ j_i),
//!
//! where Q holds joint torques, joint damping and external forces mapped through their point
//! Jacobians. Planar rotation has no gyroscopic term, so this is exact. Up to
//! [`MAX_DOF`] coordinates; `derivative` never allocates.

use super::{Model, Ode, Parameter};
use serde::{Deserialize, Serialize};

/// Largest number of generalized coordinates.
pub const MAX_DOF: usize = 12;

/// One rigid link.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanarLink {
    /// Name (used in state and control names).
    pub name: String,
    /// Parent link index (`None` for the root, which must be link 0).
    pub parent: Option<usize>,
    /// Distance along the parent from the parent's joint to this link's joint (m).
    pub attach: f64,
    /// Mass (kg).
    pub mass: f64,
    /// Length from its joint to its tip (m).
    pub length: f64,
    /// Distance of the centre of mass from its joint (m).
    pub com: f64,
    /// Moment of inertia about the centre of mass (kg·m²).
    pub inertia: f64,
    /// Viscous friction at its joint (N·m·s/rad).
    pub damping: f64,
    /// Whether its joint has a motor (a control torque).
    pub actuated: bool,
}

/// A point where an external force (fx, fy) acts, as two extra controls.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForcePoint {
    /// Link the force acts on.
    pub link: usize,
    /// Distance along the link from its joint (m).
    pub offset: f64,
}

/// A planar articulated tree.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanarTree {
    /// Registry name.
    pub name: String,
    /// Links; link 0 is the root and parents come before children.
    pub links: Vec<PlanarLink>,
    /// Free-flying root (adds x, y of the root joint).
    pub floating: bool,
    /// Gravitational acceleration along −y (m/s²).
    pub gravity: f64,
    /// External force points (each adds controls `<link>_fx`, `<link>_fy`).
    pub forces: Vec<ForcePoint>,
}

/// Kinematic quantities of one configuration.
#[derive(Debug, Clone, Copy)]
struct Kin {
    phi: [f64; MAX_DOF],
    joint: [[f64; 2]; MAX_DOF],
}

impl PlanarTree {
    /// Number of generalized coordinates.
    pub fn dof(&self) -> usize {
        self.links.len() + if self.floating { 2 } else { 0 }
    }

    fn offset(&self) -> usize {
        if self.floating {
            2
        } else {
            0
        }
    }

    /// Index of link `i`'s angle coordinate in q.
    pub fn coord(&self, i: usize) -> usize {
        self.offset() + i
    }

    /// Checks the structure: root first, parents before children, dof within [`MAX_DOF`].
    pub fn validate(&self) -> Result<(), String> {
        if self.links.is_empty() {
            return Err("no links".into());
        }
        if self.dof() > MAX_DOF {
            return Err(format!("{} coordinates, at most {MAX_DOF}", self.dof()));
        }
        for (i, l) in self.links.iter().enumerate() {
            match (i, l.parent) {
                (0, None) => {}
                (0, Some(_)) => return Err("link 0 must be the root".into()),
                (_, Some(p)) if p < i => {}
                _ => return Err(format!("link {i} must have a parent before it")),
            }
            if !(l.mass > 0.0 && l.inertia >= 0.0 && l.length >= 0.0) {
                return Err(format!(
                    "link {i}: mass must be > 0, inertia and length >= 0"
                ));
            }
        }
        for f in &self.forces {
            if f.link >= self.links.len() {
                return Err(format!("force on unknown link {}", f.link));
            }
        }
        Ok(())
    }

    fn kinematics(&self, q: &[f64]) -> Kin {
        let mut k = Kin {
            phi: [0.0; MAX_DOF],
            joint: [[0.0; 2]; MAX_DOF],
        };
        let root = if self.floating {
            [q[0], q[1]]
        } else {
            [0.0, 0.0]
        };
        for (i, l) in self.links.iter().enumerate() {
            let c = self.coord(i);
            match l.parent {
                None => {
                    k.phi[i] = q[c];
                    k.joint[i] = root;
                }
                Some(p) => {
                    k.phi[i] = k.phi[p] + q[c];
                    let (s, co) = crate::portable::sin_cos(k.phi[p]);
                    k.joint[i] = [k.joint[p][0] + l.attach * co, k.joint[p][1] + l.attach * s];
                }
            }
        }
        k
    }

    /// Absolute angles of every link at configuration `q`.
    pub fn angles(&self, q: &[f64]) -> Vec<f64> {
        let k = self.kinematics(q);
        k.phi[..self.links.len()].to_vec()
    }

    /// Joint positions of every link at configuration `q` (m).
    pub fn joints(&self, q: &[f64]) -> Vec<[f64; 2]> {
        let k = self.kinematics(q);
        k.joint[..self.links.len()].to_vec()
    }

    /// Position of the point at distance `r` along link `i` (m).
    pub fn point(&self, q: &[f64], i: usize, r: f64) -> [f64; 2] {
        let k = self.kinematics(q);
        let (s, c) = crate::portable::sin_cos(k.phi[i]);
        [k.joint[i][0] + r * c, k.joint[i][1] + r * s]
    }

    /// Position (m) and velocity (m/s) of the point at distance `r` along link `i`, for the
    /// state `x = [q, q̇]`: v = J(q) q̇ with J the point's Jacobian. Never allocates.
    pub fn point_state(&self, x: &[f64], i: usize, r: f64) -> ([f64; 2], [f64; 2]) {
        let n = self.dof();
        let (q, qd) = (&x[..n], &x[n..2 * n]);
        let kin = self.kinematics(q);
        let mut jac = [[0.0; MAX_DOF]; 2];
        self.point_jacobian(&kin, qd, i, r, &mut jac);
        let (s, c) = crate::portable::sin_cos(kin.phi[i]);
        let p = [kin.joint[i][0] + r * c, kin.joint[i][1] + r * s];
        let v = [
            jac[0][..n].iter().zip(qd).map(|(a, b)| a * b).sum(),
            jac[1][..n].iter().zip(qd).map(|(a, b)| a * b).sum(),
        ];
        (p, v)
    }

    /// Whole-body centre of mass (m).
    pub fn center_of_mass(&self, q: &[f64]) -> [f64; 2] {
        let mut acc = [0.0; 2];
        let mut m = 0.0;
        for (i, l) in self.links.iter().enumerate() {
            let p = self.point(q, i, l.com);
            acc[0] += l.mass * p[0];
            acc[1] += l.mass * p[1];
            m += l.mass;
        }
        [acc[0] / m, acc[1] / m]
    }

    /// Walks the path from the root to link `i` (or to a point at `r` on it), calling
    /// `f(k, lever)` for each link k on the path with the lever of its contribution.
    fn path(&self, i: usize, r: f64, mut f: impl FnMut(usize, f64)) {
        f(i, r);
        let mut child = i;
        while let Some(p) = self.links[child].parent {
            f(p, self.links[child].attach);
            child = p;
        }
    }

    /// Whether link `m` is on the path from the root to link `k`.
    fn on_path(&self, m: usize, k: usize) -> bool {
        let mut c = Some(k);
        while let Some(x) = c {
            if x == m {
                return true;
            }
            c = self.links[x].parent;
        }
        false
    }

    /// Jacobian (2 × dof, into `jac`) of the point at `r` on link `i`, and its velocity-product
    /// acceleration.
    fn point_jacobian(
        &self,
        kin: &Kin,
        qd: &[f64],
        i: usize,
        r: f64,
        jac: &mut [[f64; MAX_DOF]; 2],
    ) -> [f64; 2] {
        let n = self.dof();
        for row in jac.iter_mut() {
            row[..n].iter_mut().for_each(|v| *v = 0.0);
        }
        if self.floating {
            jac[0][0] = 1.0;
            jac[1][1] = 1.0;
        }
        // Absolute angular rates.
        let mut w = [0.0; MAX_DOF];
        for (k, l) in self.links.iter().enumerate() {
            w[k] = qd[self.coord(k)] + l.parent.map_or(0.0, |p| w[p]);
        }
        let mut bias = [0.0; 2];
        self.path(i, r, |k, lever| {
            let (s, c) = crate::portable::sin_cos(kin.phi[k]);
            // d/dφ_k of lever·e(φ_k) is lever·(−sin, cos); φ_k depends on every link on its path.
            for m in 0..self.links.len() {
                if self.on_path(m, k) {
                    let col = self.coord(m);
                    jac[0][col] += -lever * s;
                    jac[1][col] += lever * c;
                }
            }
            bias[0] -= lever * w[k] * w[k] * c;
            bias[1] -= lever * w[k] * w[k] * s;
        });
        bias
    }

    /// Joint-space mass matrix M(q) (row-major, dof × dof).
    pub fn mass_matrix(&self, q: &[f64]) -> Vec<Vec<f64>> {
        let n = self.dof();
        let kin = self.kinematics(q);
        let zeros = [0.0; MAX_DOF];
        let mut m = [[0.0; MAX_DOF]; MAX_DOF];
        let mut jac = [[0.0; MAX_DOF]; 2];
        for (i, l) in self.links.iter().enumerate() {
            self.point_jacobian(&kin, &zeros, i, l.com, &mut jac);
            self.accumulate_mass(&mut m, &jac, i);
        }
        (0..n).map(|r| m[r][..n].to_vec()).collect()
    }

    fn accumulate_mass(
        &self,
        m: &mut [[f64; MAX_DOF]; MAX_DOF],
        jac: &[[f64; MAX_DOF]; 2],
        i: usize,
    ) {
        let n = self.dof();
        let l = &self.links[i];
        for a in 0..n {
            for b in 0..n {
                m[a][b] += l.mass * (jac[0][a] * jac[0][b] + jac[1][a] * jac[1][b]);
            }
        }
        for a in 0..self.links.len() {
            if !self.on_path(a, i) {
                continue;
            }
            for b in 0..self.links.len() {
                if self.on_path(b, i) {
                    m[self.coord(a)][self.coord(b)] += l.inertia;
                }
            }
        }
    }

    /// Links with motors, in control order.
    pub fn actuated(&self) -> Vec<usize> {
        (0..self.links.len())
            .filter(|&i| self.links[i].actuated)
            .collect()
    }

    /// Total linear momentum (kg·m/s) and angular momentum about the origin (kg·m²/s).
    pub fn momentum(&self, x: &[f64]) -> ([f64; 2], f64) {
        let n = self.dof();
        let (q, qd) = (&x[..n], &x[n..2 * n]);
        let kin = self.kinematics(q);
        let mut jac = [[0.0; MAX_DOF]; 2];
        let (mut p, mut h) = ([0.0; 2], 0.0);
        for (i, l) in self.links.iter().enumerate() {
            self.point_jacobian(&kin, qd, i, l.com, &mut jac);
            let v = [
                (0..n).map(|c| jac[0][c] * qd[c]).sum::<f64>(),
                (0..n).map(|c| jac[1][c] * qd[c]).sum::<f64>(),
            ];
            let pos = self.point(q, i, l.com);
            let w: f64 = (0..self.links.len())
                .filter(|&m| self.on_path(m, i))
                .map(|m| qd[self.coord(m)])
                .sum();
            p[0] += l.mass * v[0];
            p[1] += l.mass * v[1];
            h += l.mass * (pos[0] * v[1] - pos[1] * v[0]) + l.inertia * w;
        }
        (p, h)
    }
}

impl Model for PlanarTree {
    fn name(&self) -> &str {
        &self.name
    }
    fn state_names(&self) -> Vec<String> {
        let mut q: Vec<String> = Vec::new();
        if self.floating {
            q.push(format!("{}_x", self.links[0].name));
            q.push(format!("{}_y", self.links[0].name));
        }
        for (i, l) in self.links.iter().enumerate() {
            q.push(if i == 0 {
                format!("{}_angle", l.name)
            } else {
                format!("{}_joint", l.name)
            });
        }
        let qd: Vec<String> = q.iter().map(|s| format!("{s}_rate")).collect();
        q.into_iter().chain(qd).collect()
    }
    fn control_names(&self) -> Vec<String> {
        let mut c: Vec<String> = self
            .actuated()
            .into_iter()
            .map(|i| format!("{}_torque", self.links[i].name))
            .collect();
        for f in &self.forces {
            let n = &self.links[f.link].name;
            c.push(format!("{n}_fx"));
            c.push(format!("{n}_fy"));
        }
        c
    }
    fn parameters(&self) -> Vec<Parameter> {
        let mut p = Vec::new();
        for l in &self.links {
            let n = &l.name;
            let body = [l.mass, l.length, l.com, l.inertia];
            p.extend(Parameter::rigid_link(n, body, "joint-to-tip length"));
            p.push(Parameter::new(
                format!("{n}.attach"),
                l.attach,
                "m",
                "joint position along the parent link",
            ));
            p.push(Parameter::joint_damping(n, l.damping));
        }
        p.push(Parameter::gravity(
            self.gravity,
            "gravitational acceleration (along -y)",
        ));
        p
    }
    fn default_dt(&self) -> f64 {
        0.005
    }
}

impl Ode for PlanarTree {
    fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let n = self.dof();
        let (q, qd) = (&x[..n], &x[n..2 * n]);
        let kin = self.kinematics(q);
        let mut m = [[0.0; MAX_DOF]; MAX_DOF];
        let mut rhs = [0.0; MAX_DOF];
        let mut jac = [[0.0; MAX_DOF]; 2];
        for (i, l) in self.links.iter().enumerate() {
            let a = self.point_jacobian(&kin, qd, i, l.com, &mut jac);
            self.accumulate_mass(&mut m, &jac, i);
            // −J_iᵀ m_i (a_i − g), g = (0, −gravity)
            let f = [-l.mass * a[0], -l.mass * (a[1] + self.gravity)];
            for c in 0..n {
                rhs[c] += jac[0][c] * f[0] + jac[1][c] * f[1];
            }
            rhs[self.coord(i)] -= l.damping * qd[self.coord(i)];
        }
        let mut k = 0;
        for (i, l) in self.links.iter().enumerate() {
            if l.actuated {
                rhs[self.coord(i)] += u[k];
                k += 1;
            }
        }
        for fp in &self.forces {
            let (fx, fy) = (u[k], u[k + 1]);
            k += 2;
            self.point_jacobian(&kin, qd, fp.link, fp.offset, &mut jac);
            for c in 0..n {
                rhs[c] += jac[0][c] * fx + jac[1][c] * fy;
            }
        }
        crate::linalg::cholesky_solve_fixed(&mut m, &mut rhs, n);
        dx[..n].copy_from_slice(qd);
        dx[n..2 * n].copy_from_slice(&rhs[..n]);
    }

    fn position_dim(&self) -> Option<usize> {
        Some(self.dof())
    }

    fn energy(&self, x: &[f64]) -> Option<f64> {
        let n = self.dof();
        let m = self.mass_matrix(&x[..n]);
        let qd = &x[n..2 * n];
        let mut ke = 0.0;
        for a in 0..n {
            for b in 0..n {
                ke += 0.5 * qd[a] * m[a][b] * qd[b];
            }
        }
        let pe: f64 = self
            .links
            .iter()
            .enumerate()
            .map(|(i, l)| l.mass * self.gravity * self.point(&x[..n], i, l.com)[1])
            .sum();
        Some(ke + pe)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::acrobot::Acrobot;
    use crate::physics::{IntegratorKind, Simulator};

    /// The acrobot as a fixed-base tree: point masses at the link tips.
    fn acrobot_tree() -> PlanarTree {
        let link = |name: &str, parent: Option<usize>, actuated| PlanarLink {
            name: name.into(),
            parent,
            attach: 1.0,
            mass: 1.0,
            length: 1.0,
            com: 1.0,
            inertia: 0.0,
            damping: 0.0,
            actuated,
        };
        PlanarTree {
            name: "acrobot_tree".into(),
            links: vec![link("arm", None, false), link("leg", Some(0), true)],
            floating: false,
            gravity: 9.81,
            forces: vec![],
        }
    }

    /// A floating 4-link tree with a branch.
    fn floating_tree() -> PlanarTree {
        let link =
            |name: &str, parent: Option<usize>, attach: f64, mass: f64, length: f64| PlanarLink {
                name: name.into(),
                parent,
                attach,
                mass,
                length,
                com: 0.45 * length,
                inertia: mass * length * length / 12.0,
                damping: 0.0,
                actuated: parent.is_some(),
            };
        PlanarTree {
            name: "tree".into(),
            links: vec![
                link("torso", None, 0.0, 30.0, 0.6),
                link("arm", Some(0), 0.55, 4.0, 0.6),
                link("thigh", Some(0), 0.0, 12.0, 0.45),
                link("shank", Some(2), 0.45, 6.0, 0.45),
            ],
            floating: true,
            gravity: 9.81,
            forces: vec![ForcePoint {
                link: 1,
                offset: 0.6,
            }],
        }
    }

    #[test]
    fn point_velocity_is_the_time_derivative_of_the_point() {
        let t = floating_tree();
        let n = t.dof();
        let x: Vec<f64> = (0..2 * n).map(|k| 0.3 + 0.17 * k as f64).collect();
        for (i, r) in [(0, 0.5), (1, 0.6), (3, 0.2)] {
            let (p, v) = t.point_state(&x, i, r);
            assert_eq!(p, t.point(&x[..n], i, r));
            // Central difference of the position along q(t) = q + t q̇.
            let h = 1e-6;
            let at = |s: f64| {
                let q: Vec<f64> = (0..n).map(|k| x[k] + s * x[n + k]).collect();
                t.point(&q, i, r)
            };
            let (a, b) = (at(h), at(-h));
            for d in 0..2 {
                let fd = (a[d] - b[d]) / (2.0 * h);
                assert!(
                    (fd - v[d]).abs() < 1e-7 * (1.0 + fd.abs()),
                    "{i} {d}: {fd} vs {}",
                    v[d]
                );
            }
        }
    }

    #[test]
    fn reproduces_the_acrobot() {
        let t = acrobot_tree();
        t.validate().unwrap();
        let a = Acrobot::default();
        for x in [
            [0.3, -0.4, 1.2, -0.8],
            [-1.5, 0.2, 0.0, 2.0],
            [2.0, 3.0, -1.0, 0.5],
        ] {
            let (mut d1, mut d2) = ([0.0; 4], [0.0; 4]);
            t.derivative(&x, &[0.7], &mut d1);
            a.derivative(&x, &[0.7], &mut d2);
            for i in 0..4 {
                assert!((d1[i] - d2[i]).abs() < 1e-10, "{d1:?} vs {d2:?}");
            }
        }
    }

    #[test]
    fn mass_matrix_is_symmetric_positive_definite() {
        let t = floating_tree();
        let m = t.mass_matrix(&[0.1, 0.2, 0.3, -0.5, 1.0, 0.4]);
        let n = t.dof();
        let mm = nalgebra::DMatrix::from_fn(n, n, |a, b| m[a][b]);
        assert!((&mm - mm.transpose()).abs().max() < 1e-12);
        assert!(mm.symmetric_eigenvalues().iter().all(|&e| e > 0.0));
    }

    #[test]
    fn in_flight_momentum_and_energy_behave() {
        // Internal torques change neither angular momentum about the centre of mass nor the
        // free fall of the centre of mass; without torques energy is conserved.
        let t = floating_tree();
        let n = t.dof();
        let x0 = [0.0, 2.0, 0.4, 0.3, -0.6, 0.5, 1.0, 3.0, 1.5, -1.0, 2.0, 0.5];
        let torques = [3.0, -5.0, 2.0, 0.0, 0.0];
        let mut sim = Simulator::new(t.clone(), IntegratorKind::Rk4);
        let (p0, h0) = t.momentum(&x0);
        let c0 = t.center_of_mass(&x0[..n]);
        let dt = 0.001;
        let steps = 500;
        let x = sim
            .rollout(
                &x0,
                dt,
                steps,
                |_, _, _, u| u.copy_from_slice(&torques),
                |_, _, _| {},
            )
            .unwrap();
        let tt = steps as f64 * dt;
        let (p, h) = t.momentum(&x);
        let c = t.center_of_mass(&x[..n]);
        let mass: f64 = t.links.iter().map(|l| l.mass).sum();
        // Linear momentum: only gravity acts.
        assert!((p[0] - p0[0]).abs() < 1e-8 && (p[1] - (p0[1] - mass * 9.81 * tt)).abs() < 1e-8);
        // Angular momentum about the moving centre of mass is conserved.
        let h_com = |h: f64, p: [f64; 2], c: [f64; 2]| h - (c[0] * p[1] - c[1] * p[0]);
        assert!(
            (h_com(h, p, c) - h_com(h0, p0, c0)).abs() < 1e-7,
            "{} vs {}",
            h_com(h, p, c),
            h_com(h0, p0, c0)
        );
        // Energy without torques.
        let e0 = t.energy(&x0).unwrap();
        let mut sim = Simulator::new(t.clone(), IntegratorKind::Rk4);
        let x = sim
            .rollout(&x0, dt, steps, |_, _, _, _| {}, |_, _, _| {})
            .unwrap();
        assert!((t.energy(&x).unwrap() - e0).abs() < 1e-7 * e0.abs().max(1.0));
    }

    #[test]
    fn external_force_power_balance() {
        let t = floating_tree();
        let n = t.dof();
        let x = [
            0.1, 1.0, 0.4, 0.3, -0.6, 0.5, 0.5, -0.3, 1.5, -1.0, 2.0, 0.5,
        ];
        let u = [0.0, 0.0, 0.0, 40.0, -25.0];
        let mut dx = [0.0; 12];
        t.derivative(&x, &u, &mut dx);
        let h = 1e-6;
        let e = |s: f64| {
            let y: Vec<f64> = x.iter().zip(&dx).map(|(a, b)| a + s * b).collect();
            t.energy(&y).unwrap()
        };
        let de = (e(h) - e(-h)) / (2.0 * h);
        // Power of the force at the arm tip: F · v_tip, v_tip by finite differences.
        let p1 = t.point(&x[..n], 1, 0.6);
        let y: Vec<f64> = x[..n].iter().zip(&x[n..]).map(|(a, b)| a + h * b).collect();
        let p2 = t.point(&y, 1, 0.6);
        let v = [(p2[0] - p1[0]) / h, (p2[1] - p1[1]) / h];
        let power = 40.0 * v[0] - 25.0 * v[1];
        assert!(
            (de - power).abs() < 1e-3 * power.abs().max(1.0),
            "{de} vs {power}"
        );
    }
}
