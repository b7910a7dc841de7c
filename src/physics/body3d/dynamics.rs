//! Forward dynamics of a [`Tree3d`]: joint transforms and velocities, the composite-rigid-body
//! algorithm for H(q), the recursive Newton–Euler algorithm for the bias forces, a Cholesky
//! solve, and the quaternion rates (the equations are in the [module docs](super)).

use super::spatial::{
    axis_angle, bottom, cross_force, cross_motion, join, quat_rate, quat_to_matrix, top, Spatial,
    Xform,
};
use super::tree::{BodyPoint, Joint3d, Tree3d, MAX_BODIES, MAX_DOF};
use crate::physics::Ode;
use nalgebra::{DMatrix, Matrix3, Matrix6, Vector3};

fn unit(v: [f64; 3]) -> Vector3<f64> {
    let v = Vector3::from(v);
    v / v.norm()
}

/// Per-configuration quantities of a forward pass, on the stack.
struct Pass {
    /// ⁱX_λ(i): parent (world, for the root) to body coordinates.
    x: [Xform; MAX_BODIES],
    /// Motion-subspace columns, one per degree of freedom, in their body's coordinates.
    s: [Spatial; MAX_DOF],
    /// Body velocities in body coordinates.
    v: [Spatial; MAX_BODIES],
    /// Velocity-product accelerations cᵢ = vᵢ ×ₘ Sᵢ q̇ᵢ + S̊ᵢ q̇ᵢ.
    c: [Spatial; MAX_BODIES],
}

impl Tree3d {
    /// Joint transform ⁱX_λ(i) of body `i` at its coordinates `q` (of length `nq`), and its
    /// motion-subspace columns written into `s`.
    fn joint(&self, i: usize, q: &[f64], s: &mut [Spatial]) -> Xform {
        let b = &self.bodies[i];
        match b.joint {
            Joint3d::Free => {
                let r = quat_to_matrix([q[3], q[4], q[5], q[6]]);
                for k in 0..3 {
                    // ṗ_k moves the origin along world axis k: Rᵀ e_k in body coordinates.
                    let col = Vector3::new(r[(k, 0)], r[(k, 1)], r[(k, 2)]);
                    s[k] = join(Vector3::zeros(), col);
                    let mut w = Vector3::zeros();
                    w[k] = 1.0;
                    s[3 + k] = join(w, Vector3::zeros());
                }
                Xform {
                    e: r.transpose(),
                    r: Vector3::new(q[0], q[1], q[2]),
                }
            }
            Joint3d::Ball => {
                for (k, col) in s[..3].iter_mut().enumerate() {
                    let mut w = Vector3::zeros();
                    w[k] = 1.0;
                    *col = join(w, Vector3::zeros());
                }
                let rel = quat_to_matrix(b.orientation) * quat_to_matrix([q[0], q[1], q[2], q[3]]);
                Xform {
                    e: rel.transpose(),
                    r: Vector3::from(b.offset),
                }
            }
            Joint3d::Revolute { axis } => {
                let a = unit(axis);
                s[0] = join(a, Vector3::zeros());
                let rel = quat_to_matrix(b.orientation) * axis_angle(&a, q[0]);
                Xform {
                    e: rel.transpose(),
                    r: Vector3::from(b.offset),
                }
            }
        }
    }

    /// Transforms, motion subspaces, velocities and velocity-product accelerations at `x`.
    fn pass(&self, x: &[f64]) -> Pass {
        let nq = self.nq();
        let (q, qd) = (&x[..nq], &x[nq..]);
        let mut p = Pass {
            x: [Xform::identity(); MAX_BODIES],
            s: [Spatial::zeros(); MAX_DOF],
            v: [Spatial::zeros(); MAX_BODIES],
            c: [Spatial::zeros(); MAX_BODIES],
        };
        let (mut iq, mut iv) = (0, 0);
        for (i, b) in self.bodies.iter().enumerate() {
            let (nqi, nvi) = (b.joint.nq(), b.joint.nv());
            p.x[i] = self.joint(i, &q[iq..iq + nqi], &mut p.s[iv..iv + nvi]);
            let mut vj = Spatial::zeros();
            for k in iv..iv + nvi {
                vj += p.s[k] * qd[k];
            }
            let vp = b
                .parent
                .map_or(Spatial::zeros(), |j| p.x[i].motion(&p.v[j]));
            p.v[i] = vp + vj;
            p.c[i] = cross_motion(&p.v[i], &vj);
            if b.joint == Joint3d::Free {
                // The free joint's linear columns Rᵀ e_k turn with the body:
                // S̊ q̇ = [0; −ω × Rᵀ ṗ].
                let (w, v) = (top(&vj), bottom(&vj));
                p.c[i] += join(Vector3::zeros(), -w.cross(&v));
            }
            iq += nqi;
            iv += nvi;
        }
        p
    }

    /// Joint-space inertia matrix H(q) by the composite-rigid-body algorithm, into the
    /// leading nv × nv block of `h`.
    fn crba(&self, p: &Pass, h: &mut [[f64; MAX_DOF]; MAX_DOF]) {
        let n = self.bodies.len();
        let mut ic = [Matrix6::zeros(); MAX_BODIES];
        for (i, b) in self.bodies.iter().enumerate() {
            ic[i] = b.spatial_inertia();
        }
        for i in (1..n).rev() {
            let j = self.bodies[i].parent.expect("only the root has no parent");
            let add = p.x[i].inertia_to_parent(&ic[i]);
            ic[j] += add;
        }
        let mut iv = 0;
        for (i, b) in self.bodies.iter().enumerate() {
            for k in iv..iv + b.joint.nv() {
                let mut f = ic[i] * p.s[k];
                for l in iv..iv + b.joint.nv() {
                    h[l][k] = p.s[l].dot(&f);
                }
                let mut j = i;
                while let Some(par) = self.bodies[j].parent {
                    f = p.x[j].force_to_parent(&f);
                    j = par;
                    let jv = self.v_index(j);
                    for l in jv..jv + self.bodies[j].joint.nv() {
                        h[l][k] = p.s[l].dot(&f);
                        h[k][l] = h[l][k];
                    }
                }
            }
            iv += b.joint.nv();
        }
    }

    /// Generalized bias forces C(q, q̇) q̇ + g(q) by the recursive Newton–Euler algorithm
    /// with q̈ = 0, into `bias[..nv]`.
    fn rnea_bias(&self, p: &Pass, bias: &mut [f64; MAX_DOF]) {
        let n = self.bodies.len();
        let a_world = Spatial::new(0.0, 0.0, 0.0, 0.0, 0.0, self.gravity);
        let mut a = [Spatial::zeros(); MAX_BODIES];
        let mut f = [Spatial::zeros(); MAX_BODIES];
        for (i, b) in self.bodies.iter().enumerate() {
            let ap = b.parent.map_or(a_world, |j| a[j]);
            a[i] = p.x[i].motion(&ap) + p.c[i];
            let inertia = b.spatial_inertia();
            f[i] = inertia * a[i] + cross_force(&p.v[i], &(inertia * p.v[i]));
        }
        for i in (0..n).rev() {
            let iv = self.v_index(i);
            for k in iv..iv + self.bodies[i].joint.nv() {
                bias[k] = p.s[k].dot(&f[i]);
            }
            if let Some(j) = self.bodies[i].parent {
                let fp = p.x[i].force_to_parent(&f[i]);
                f[j] += fp;
            }
        }
    }

    /// Joint-space inertia matrix H(q) (nv × nv, kg·m² / kg blocks).
    pub fn mass_matrix(&self, x: &[f64]) -> DMatrix<f64> {
        let p = self.pass(x);
        let mut h = [[0.0; MAX_DOF]; MAX_DOF];
        self.crba(&p, &mut h);
        let n = self.nv();
        DMatrix::from_fn(n, n, |r, c| h[r][c])
    }

    /// World rotation (body to world coordinates) and origin (m) of every body.
    pub fn poses(&self, q: &[f64]) -> Vec<(Matrix3<f64>, Vector3<f64>)> {
        let mut s = [Spatial::zeros(); 6];
        let mut out: Vec<(Matrix3<f64>, Vector3<f64>)> = Vec::with_capacity(self.bodies.len());
        let mut iq = 0;
        for (i, b) in self.bodies.iter().enumerate() {
            let x = self.joint(i, &q[iq..iq + b.joint.nq()], &mut s);
            iq += b.joint.nq();
            out.push(match b.parent {
                None => (x.e.transpose(), x.r),
                Some(j) => {
                    let (r, o) = out[j];
                    (r * x.e.transpose(), o + r * x.r)
                }
            });
        }
        out
    }

    /// World position (m) and velocity (m/s) of the point at `point` (body coordinates, m) on
    /// body `i`, at state `x = [q, v]`.
    pub fn point_state(
        &self,
        x: &[f64],
        i: usize,
        point: [f64; 3],
    ) -> (Vector3<f64>, Vector3<f64>) {
        let (r, o) = self.poses(&x[..self.nq()])[i];
        let v = self.pass(x).v[i];
        let pt = Vector3::from(point);
        (o + r * pt, r * (bottom(&v) + top(&v).cross(&pt)))
    }

    /// Whole-body centre of mass (m).
    pub fn center_of_mass(&self, q: &[f64]) -> Vector3<f64> {
        let poses = self.poses(q);
        let mut acc = Vector3::zeros();
        let mut m = 0.0;
        for (b, (r, o)) in self.bodies.iter().zip(&poses) {
            acc += (o + r * Vector3::from(b.com)) * b.mass;
            m += b.mass;
        }
        acc / m
    }

    /// Linear momentum (kg·m/s) and angular momentum about the world origin (kg·m²/s), both
    /// in world coordinates.
    pub fn momentum(&self, x: &[f64]) -> (Vector3<f64>, Vector3<f64>) {
        let poses = self.poses(&x[..self.nq()]);
        let p = self.pass(x);
        let (mut lin, mut ang) = (Vector3::zeros(), Vector3::zeros());
        for (i, b) in self.bodies.iter().enumerate() {
            let h = b.spatial_inertia() * p.v[i];
            let (r, o) = poses[i];
            let l = r * bottom(&h);
            lin += l;
            ang += r * top(&h) + o.cross(&l);
        }
        (lin, ang)
    }

    /// Kinetic energy ½ Σ vᵢᵀ Iᵢ vᵢ (J).
    pub fn kinetic_energy(&self, x: &[f64]) -> f64 {
        let p = self.pass(x);
        self.bodies
            .iter()
            .enumerate()
            .map(|(i, b)| 0.5 * p.v[i].dot(&(b.spatial_inertia() * p.v[i])))
            .sum()
    }

    /// World rotation (body to world coordinates) and origin (m) of every body, from a pass's
    /// transforms, in fixed arrays ([`Tree3d::poses`] without allocation).
    fn world_poses(&self, p: &Pass) -> [(Matrix3<f64>, Vector3<f64>); MAX_BODIES] {
        let mut out = [(Matrix3::identity(), Vector3::zeros()); MAX_BODIES];
        for (i, b) in self.bodies.iter().enumerate() {
            let x = &p.x[i];
            out[i] = match b.parent {
                None => (x.e.transpose(), x.r),
                Some(j) => {
                    let (r, o) = out[j];
                    (r * x.e.transpose(), o + r * x.r)
                }
            };
        }
        out
    }

    /// Spatial forces (body coordinates) of world `forces` on `points`, one per body, and the
    /// points' world positions and velocities: the force on point k is `force(k, position,
    /// velocity)`.
    fn point_forces(
        &self,
        p: &Pass,
        points: &[BodyPoint],
        mut force: impl FnMut(usize, Vector3<f64>, Vector3<f64>) -> Vector3<f64>,
    ) -> [Spatial; MAX_BODIES] {
        let world = self.world_poses(p);
        let mut fext = [Spatial::zeros(); MAX_BODIES];
        for (k, pt) in points.iter().enumerate() {
            let (r, o) = world[pt.body];
            let off = Vector3::from(pt.offset);
            let v = p.v[pt.body];
            let vel = r * (bottom(&v) + top(&v).cross(&off));
            let fb = r.transpose() * force(k, o + r * off, vel);
            fext[pt.body] += join(off.cross(&fb), fb);
        }
        fext
    }

    /// Generalized forces Sᵢᵀ Σ_{subtree of i} fⱼ of spatial forces `fext` (each body's
    /// coordinates), accumulated from the leaves as in the second sweep of the RNEA.
    fn external(&self, p: &Pass, fext: &mut [Spatial; MAX_BODIES], out: &mut [f64; MAX_DOF]) {
        for i in (0..self.bodies.len()).rev() {
            let iv = self.v_index(i);
            for k in iv..iv + self.bodies[i].joint.nv() {
                out[k] = p.s[k].dot(&fext[i]);
            }
            if let Some(j) = self.bodies[i].parent {
                let fp = p.x[i].force_to_parent(&fext[i]);
                fext[j] += fp;
            }
        }
    }

    /// ẋ at `x` under motor torques `u` and world forces on `points`: the force on point k
    /// (N, world) is `force(k, position, velocity)` of the point's world position (m) and
    /// velocity (m/s) at `x`; they enter as Σₖ Jₖᵀ fₖ. Never allocates; without points this
    /// is [`Ode::derivative`] (up to the sign of a zero).
    pub fn derivative_with_point_forces(
        &self,
        x: &[f64],
        u: &[f64],
        points: &[BodyPoint],
        force: impl FnMut(usize, Vector3<f64>, Vector3<f64>) -> Vector3<f64>,
        dx: &mut [f64],
    ) {
        let p = self.pass(x);
        let mut fext = self.point_forces(&p, points, force);
        let mut q = [0.0; MAX_DOF];
        self.external(&p, &mut fext, &mut q);
        self.forward(x, u, &p, Some(&q), dx);
    }

    /// The generalized force Σₖ Jₖᵀ fₖ (nv entries, N or N·m per velocity coordinate) of world
    /// forces `forces[k]` (N) on `points[k]` at the configuration of state `x`: its dot
    /// product with any q̇ is the forces' power Σₖ fₖ · vₖ.
    pub fn generalized_force(
        &self,
        x: &[f64],
        points: &[BodyPoint],
        forces: &[Vector3<f64>],
    ) -> Vec<f64> {
        let p = self.pass(x);
        let mut fext = self.point_forces(&p, points, |k, _, _| forces[k]);
        let mut q = [0.0; MAX_DOF];
        self.external(&p, &mut fext, &mut q);
        q[..self.nv()].to_vec()
    }

    /// World positions (m) and velocities (m/s) of `points` at state `x`.
    pub fn point_states(
        &self,
        x: &[f64],
        points: &[BodyPoint],
    ) -> Vec<(Vector3<f64>, Vector3<f64>)> {
        let p = self.pass(x);
        let mut out = Vec::with_capacity(points.len());
        self.point_forces(&p, points, |_, pos, vel| {
            out.push((pos, vel));
            Vector3::zeros()
        });
        out
    }
}

impl Tree3d {
    /// ẋ at `x` under motor torques `u` and, when given, the generalized forces `ext` of
    /// external forces (added to the right-hand side after damping and motors).
    fn forward(
        &self,
        x: &[f64],
        u: &[f64],
        p: &Pass,
        ext: Option<&[f64; MAX_DOF]>,
        dx: &mut [f64],
    ) {
        let (nq, nv) = (self.nq(), self.nv());
        let qd = &x[nq..nq + nv];
        let mut h = [[0.0; MAX_DOF]; MAX_DOF];
        let mut rhs = [0.0; MAX_DOF];
        self.crba(p, &mut h);
        self.rnea_bias(p, &mut rhs);
        for r in rhs[..nv].iter_mut() {
            *r = -*r;
        }
        // Damping and motors.
        let (mut iv, mut ku) = (0, 0);
        for b in &self.bodies {
            let nvi = b.joint.nv();
            if b.parent.is_some() {
                for k in iv..iv + nvi {
                    rhs[k] -= b.damping * qd[k];
                    if b.actuated {
                        rhs[k] += u[ku];
                        ku += 1;
                    }
                }
            }
            iv += nvi;
        }
        if let Some(q) = ext {
            for (r, e) in rhs[..nv].iter_mut().zip(q) {
                *r += e;
            }
        }
        crate::linalg::cholesky_solve_fixed(&mut h, &mut rhs, nv);
        // Position rates.
        let (mut iq, mut iv) = (0, 0);
        for b in &self.bodies {
            match b.joint {
                Joint3d::Free => {
                    dx[iq..iq + 3].copy_from_slice(&qd[iv..iv + 3]);
                    let q = [x[iq + 3], x[iq + 4], x[iq + 5], x[iq + 6]];
                    let w = [qd[iv + 3], qd[iv + 4], qd[iv + 5]];
                    dx[iq + 3..iq + 7].copy_from_slice(&quat_rate(q, w));
                }
                Joint3d::Ball => {
                    let q = [x[iq], x[iq + 1], x[iq + 2], x[iq + 3]];
                    let w = [qd[iv], qd[iv + 1], qd[iv + 2]];
                    dx[iq..iq + 4].copy_from_slice(&quat_rate(q, w));
                }
                Joint3d::Revolute { .. } => dx[iq] = qd[iv],
            }
            iq += b.joint.nq();
            iv += b.joint.nv();
        }
        dx[nq..nq + nv].copy_from_slice(&rhs[..nv]);
    }
}

impl Ode for Tree3d {
    fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        self.forward(x, u, &self.pass(x), None, dx);
    }

    fn energy(&self, x: &[f64]) -> Option<f64> {
        let com = self.center_of_mass(&x[..self.nq()]);
        let mass: f64 = self.bodies.iter().map(|b| b.mass).sum();
        Some(self.kinetic_energy(x) + mass * self.gravity * com.z)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::body3d::chain3d;
    use crate::physics::{IntegratorKind, Model, Simulator};

    fn unit_quat(v: [f64; 4]) -> [f64; 4] {
        let n = v.iter().map(|c| c * c).sum::<f64>().sqrt();
        v.map(|c| c / n)
    }

    /// A generic state of `chain3d`: unit quaternions, every velocity non-zero.
    fn state() -> Vec<f64> {
        let mut x = vec![0.3, -0.2, 1.1];
        x.extend(unit_quat([0.8, 0.3, -0.4, 0.2]));
        x.extend(unit_quat([0.9, -0.2, 0.35, 0.1]));
        x.extend([0.7, -0.5]);
        x.extend([0.4, -0.3, 0.9, 1.3, -0.7, 0.6, -1.1, 0.8, 0.5, 1.7, -2.2]);
        x
    }

    fn derivative(t: &Tree3d, x: &[f64], u: &[f64]) -> Vec<f64> {
        let mut dx = vec![0.0; x.len()];
        t.derivative(x, u, &mut dx);
        dx
    }

    /// x + s ẋ, the state a short time s along the flow to first order.
    fn along(x: &[f64], dx: &[f64], s: f64) -> Vec<f64> {
        x.iter().zip(dx).map(|(a, b)| a + s * b).collect()
    }

    #[test]
    fn mass_matrix_is_symmetric_positive_definite_and_gives_the_kinetic_energy() {
        let t = chain3d();
        let x = state();
        let h = t.mass_matrix(&x);
        assert!((&h - h.transpose()).abs().max() < 1e-14);
        assert!(h.clone().symmetric_eigenvalues().iter().all(|&e| e > 0.0));
        let v = nalgebra::DVector::from_column_slice(&x[t.nq()..]);
        let ke = 0.5 * v.dot(&(&h * &v));
        assert!((ke - t.kinetic_energy(&x)).abs() < 1e-13 * ke, "{ke}");
    }

    #[test]
    fn point_velocity_is_the_time_derivative_of_the_point() {
        // Checks the quaternion rates (free and ball), the joint transforms and the velocity
        // recursion against central differences of world positions along ẋ.
        let t = chain3d();
        let x = state();
        let dx = derivative(&t, &x, &[0.0; 5]);
        let h = 1e-6;
        for (i, pt) in [
            (0, [0.1, -0.2, 0.3]),
            (1, [0.0, 0.05, -0.3]),
            (2, [0.02, 0.0, -0.3]),
            (3, [0.0, -0.2, 0.05]),
        ] {
            let (_, v) = t.point_state(&x, i, pt);
            let pos = |s: f64| t.point_state(&along(&x, &dx, s), i, pt).0;
            let fd = (pos(h) - pos(-h)) / (2.0 * h);
            assert!(
                (fd - v).norm() < 1e-8 * (1.0 + v.norm()),
                "body {i}: {fd} vs {v}"
            );
        }
    }

    #[test]
    fn energy_rate_is_the_power_of_torques_and_damping() {
        // dE/dt along ẋ (central differences) = τ · q̇ − Σ b q̇²: checks H, the bias forces,
        // gravity, damping and the motors together.
        let t = chain3d();
        let x = state();
        let u = [0.4, -0.3, 0.2, 0.5, -0.6];
        let dx = derivative(&t, &x, &u);
        let h = 1e-6;
        let e = |s: f64| t.energy(&along(&x, &dx, s)).unwrap();
        let rate = (e(h) - e(-h)) / (2.0 * h);
        let v = &x[t.nq()..];
        let mut power = 0.0;
        for (k, &vk) in v.iter().enumerate().skip(6) {
            let b = t.bodies[(1..4)
                .find(|&i| k < t.v_index(i) + t.bodies[i].joint.nv())
                .unwrap()]
            .damping;
            power += u[k - 6] * vk - b * vk * vk;
        }
        assert!(
            (rate - power).abs() < 1e-7 * (1.0 + power.abs()),
            "{rate} vs {power}"
        );
    }

    fn passive(gravity: f64) -> Tree3d {
        let mut t = chain3d();
        t.gravity = gravity;
        t.bodies.iter_mut().for_each(|b| b.damping = 0.0);
        t
    }

    fn run(t: &Tree3d, x0: &[f64], u: &[f64], dt: f64, duration: f64) -> Vec<f64> {
        let steps = (duration / dt).round() as usize;
        let mut sim = Simulator::new(t.clone(), IntegratorKind::Rk4);
        sim.rollout(
            x0,
            dt,
            steps,
            |_, _, _, c| c.copy_from_slice(u),
            |_, _, _| {},
        )
        .unwrap()
    }

    #[test]
    fn energy_is_conserved_and_its_drift_has_rk4_order() {
        let t = passive(9.81);
        let x0 = state();
        let e0 = t.energy(&x0).unwrap();
        let drift = |dt: f64| (t.energy(&run(&t, &x0, &[0.0; 5], dt, 1.0)).unwrap() - e0).abs();
        let (d1, d2) = (drift(0.01), drift(0.005));
        let order = (d1 / d2).log2();
        assert!(
            (3.5..4.6).contains(&order),
            "drifts {d1:e}, {d2:e}: order {order}"
        );
        assert!(drift(t.dt) < 1e-9 * e0.abs(), "{}", drift(t.dt));
    }

    #[test]
    fn momentum_is_conserved_without_gravity() {
        // Motors and joint damping are internal: neither linear nor angular momentum changes.
        let t = {
            let mut t = chain3d();
            t.gravity = 0.0;
            t
        };
        let x0 = state();
        let u = [0.4, -0.3, 0.2, 0.5, -0.6];
        // Exactly, along the flow: central differences of both momenta along ẋ vanish.
        let dx = derivative(&t, &x0, &u);
        let h = 1e-5;
        let (pa, la) = t.momentum(&along(&x0, &dx, h));
        let (pb, lb) = t.momentum(&along(&x0, &dx, -h));
        let (rp, rl) = ((pa - pb) / (2.0 * h), (la - lb) / (2.0 * h));
        assert!(rp.norm() < 1e-8 && rl.norm() < 1e-8, "{rp} {rl}");
        // Over a rollout, up to RK4's truncation error, which shrinks at its order.
        let (p0, l0) = t.momentum(&x0);
        let drift = |dt: f64| {
            let (p, l) = t.momentum(&run(&t, &x0, &u, dt, 1.0));
            ((p - p0).norm(), (l - l0).norm())
        };
        let ((p1, l1), (p2, l2)) = (drift(0.004), drift(0.002));
        for (a, b) in [(p1, p2), (l1, l2)] {
            let order = (a / b).log2();
            assert!(
                (3.5..4.6).contains(&order),
                "drifts {a:e}, {b:e}: order {order}"
            );
        }
        let (p, l) = drift(t.dt);
        assert!(p < 2e-8 && l < 2e-8, "{p:e} {l:e}");
        // With gravity only the vertical momentum changes, by −m g t.
        let t = chain3d();
        let (p0, _) = t.momentum(&x0);
        let (p, _) = t.momentum(&run(&t, &x0, &[0.0; 5], 0.002, 0.5));
        let m: f64 = t.bodies.iter().map(|b| b.mass).sum();
        let want = p0 - Vector3::new(0.0, 0.0, m * 9.81 * 0.5);
        assert!((p - want).norm() < 1e-10, "{p} vs {want}");
    }

    #[test]
    fn quaternion_rates_are_tangent_and_the_norm_holds() {
        let t = chain3d();
        let x0 = state();
        let dx = derivative(&t, &x0, &[0.0; 5]);
        for a in [3, 7] {
            let dot: f64 = (0..4).map(|k| x0[a + k] * dx[a + k]).sum();
            assert!(dot.abs() < 1e-15, "{dot}");
        }
        // The dynamics see q / |q| only: a scaled quaternion leaves the accelerations alone.
        let mut y = x0.clone();
        y[3..7].iter_mut().for_each(|c| *c *= 1.5);
        y[7..11].iter_mut().for_each(|c| *c *= 0.5);
        let dy = derivative(&t, &y, &[0.0; 5]);
        for k in t.nq()..x0.len() {
            assert!((dx[k] - dy[k]).abs() < 1e-12 * (1.0 + dx[k].abs()), "{k}");
        }
        // RK4 keeps |q| = 1 to far below the test tolerance over 2 s; normalize_state restores it.
        let mut x = run(&t, &x0, &[0.0; 5], t.dt, 2.0);
        let norm = |x: &[f64], a: usize| x[a..a + 4].iter().map(|c| c * c).sum::<f64>().sqrt();
        for a in [3, 7] {
            assert!((norm(&x, a) - 1.0).abs() < 1e-12, "{}", norm(&x, a));
        }
        x[3] *= 1.01;
        t.normalize_state(&mut x);
        assert!((norm(&x, 3) - 1.0).abs() < 1e-15 && (norm(&x, 7) - 1.0).abs() < 1e-15);
    }

    #[test]
    fn a_single_free_body_obeys_newton_and_euler() {
        // The tree solves for the acceleration of the body's origin, off the centre of mass
        // c; written back at the centre of mass it must be free fall, and ω̇ must follow
        // Euler's equations I_c ω̇ = −ω × I_c ω.
        let mut t = chain3d();
        t.bodies.truncate(1);
        let b = t.bodies[0].clone();
        let q = unit_quat([0.7, 0.2, -0.5, 0.4]);
        let w = Vector3::new(1.2, -0.7, 2.1);
        let c = Vector3::from(b.com);
        let r = quat_to_matrix(q);
        let vc = Vector3::new(0.3, 0.1, -0.4);
        // The origin's world velocity from the centre of mass's.
        let vo = vc - r * w.cross(&c);
        let mut x = vec![0.0, 0.0, 1.0];
        x.extend(q);
        x.extend(vo.iter());
        x.extend(w.iter());
        let dx = derivative(&t, &x, &[]);
        let wd = Vector3::new(dx[10], dx[11], dx[12]);
        let ic = b.inertia_matrix();
        // Euler's equations about the centre of mass, body axes.
        let want = ic.try_inverse().unwrap() * (-w.cross(&(ic * w)));
        assert!((wd - want).norm() < 1e-12, "{wd} vs {want}");
        // The centre of mass falls freely: p̈_o + R(ω̇ × c + ω × (ω × c)) = −g e_z.
        let po = Vector3::new(dx[7], dx[8], dx[9]);
        let ac = po + r * (wd.cross(&c) + w.cross(&w.cross(&c)));
        assert!((ac - Vector3::new(0.0, 0.0, -9.81)).norm() < 1e-12, "{ac}");
    }

    #[test]
    fn an_all_zero_state_stays_finite() {
        // `motionlab simulate chain3d` from zeros: a zero quaternion reads as the identity.
        let t = chain3d();
        let x = vec![0.0; t.state_dim()];
        let dx = derivative(&t, &x, &[0.0; 5]);
        assert!(dx.iter().all(|v| v.is_finite()));
    }
}
