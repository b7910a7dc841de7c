//! # Lunar lander: a 3-D rigid body in gravity (NeuroAnimator, Fig. 10 lower left, Fig. 13c)
//!
//! One rigid body of mass m with a diagonal inertia tensor I = diag(I_x, I_y, I_z) in its body
//! frame, a main rocket thruster along the body +z axis (through the centre of mass) and three
//! attitude jets modelled as pure torques about the three body axes.
//!
//! **State** (13, as in the paper's Table 1): `[p (3), q (4), v (3), ω (3)]` — centre-of-mass
//! position p in the world frame (m, z up), the unit attitude quaternion q = (w, x, y, z)
//! rotating body vectors into the world frame, the linear velocity v in the world frame (m/s)
//! and the angular velocity ω in the body frame (rad/s). **Controls** (4):
//! `[thrust, torque_x, torque_y, torque_z]` in N and N·m, clamped to [0, `max_thrust`] and
//! ±`max_torque`.
//!
//! ## Equations
//! - ṗ = v,
//! - q̇ = ½ q ⊗ (0, ω) (Hamilton product),
//! - m v̇ = T R(q) e_z − m g e_z,
//! - I ω̇ = τ − ω × I ω (Euler's equations in the body frame),
//!
//! where R(q) is the rotation by q / |q|. The right-hand side is homogeneous of degree one in q
//! (q̇ scales with q, R only sees q / |q|), so a drift of |q| away from 1 never feeds back into
//! p, v or ω, neither in the ODE nor through any Runge–Kutta step (whose stages are linear
//! combinations); it only changes the stored norm.
//!
//! ## Quaternion normalisation
//! The exact flow keeps |q| = 1, but integrators step the raw ODE and let |q| drift by
//! O(dt^p) over a fixed time (order p of the method: linearly with dt for Euler, faster than
//! dt⁴ for RK4). [`Lander::normalize_state`] projects q back to the unit sphere. It is applied
//! after every step by [`NormalizedLander`], the [`Dynamics`] to use for long rollouts and for
//! generating emulator training data (NeuroAnimator's local-frame transform needs a unit q).
//! The generic [`Simulator`] paths (`motionlab simulate`) step the raw ODE and do not normalise;
//! with RK4 at 0.01 s the drift over the paper's 20 s rollouts is far below 1e-9.
//!
//! ## Ground
//! Contact is not simulated. [`Lander::touched_down`] reports when the landing-gear reference
//! point, `leg_length` below the centre of mass along the body −z axis, is at or below
//! `ground_height`; a landing objective reads it together with the descent velocity.
//!
//! ## Energy and invariances
//! E = ½ m |v|² + ½ ωᵀ I ω + m g p_z. With no thrust and no torque E and the world-frame angular
//! momentum R(q) I ω are conserved. The dynamics are invariant to translating the world and to
//! rotating it about the vertical (gravity) axis: under p → R_z p + t, q → q_z ⊗ q, v → R_z v,
//! ω stays (body frame).
//!
//! ## References
//! - H. Goldstein, C. Poole, J. Safko, *Classical Mechanics*, 3rd ed., §5.5 (Euler's equations).
//! - J. Diebel, *Representing Attitude: Euler Angles, Unit Quaternions, and Rotation Vectors*,
//!   Stanford (2006), §6 (quaternion kinematics).

use super::{Dynamics, IntegratorKind, Model, Ode, Parameter, Simulator};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// The lunar lander.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Lander {
    /// Total mass (kg).
    pub mass: f64,
    /// Principal moments of inertia about the body x, y, z axes through the centre of mass
    /// (kg·m²).
    pub inertia: [f64; 3],
    /// Gravitational acceleration, along the world −z axis (m/s²).
    pub gravity: f64,
    /// Largest main-engine thrust; the thrust control is clamped to [0, max_thrust] (N).
    pub max_thrust: f64,
    /// Largest attitude-jet torque magnitude about each body axis (N·m).
    pub max_torque: f64,
    /// Height of the ground plane (m).
    pub ground_height: f64,
    /// Distance from the centre of mass down the body −z axis to the landing-gear reference
    /// point (m).
    pub leg_length: f64,
}

impl Default for Lander {
    /// A 2 t lander in lunar gravity, thrust-to-weight ratio ≈ 3 at full throttle.
    fn default() -> Self {
        Self {
            mass: 2000.0,
            inertia: [3000.0, 3500.0, 2500.0],
            gravity: 1.62,
            max_thrust: 10_000.0,
            max_torque: 2000.0,
            ground_height: 0.0,
            leg_length: 1.5,
        }
    }
}

/// Index of the first quaternion component (w) in the state.
pub const QUAT: usize = 3;
/// Index of the first linear-velocity component in the state.
pub const VEL: usize = 7;
/// Index of the first angular-velocity component in the state.
pub const OMEGA: usize = 10;

impl Lander {
    /// A state at rest, upright (identity attitude), with the centre of mass at `p` (m).
    pub fn upright_at_rest(p: [f64; 3]) -> [f64; 13] {
        let mut x = [0.0; 13];
        x[..3].copy_from_slice(&p);
        x[QUAT] = 1.0;
        x
    }

    /// The attitude quaternion of `x`, normalised.
    pub fn attitude(x: &[f64]) -> UnitQuaternion<f64> {
        UnitQuaternion::from_quaternion(Quaternion::new(x[QUAT], x[4], x[5], x[6]))
    }

    /// The body +z axis (main-thrust direction) in the world frame.
    pub fn thrust_axis(x: &[f64]) -> Vector3<f64> {
        Self::attitude(x) * Vector3::z()
    }

    /// Angular momentum R(q) I ω about the centre of mass, in the world frame (kg·m²/s).
    pub fn angular_momentum(&self, x: &[f64]) -> Vector3<f64> {
        let w = Vector3::new(x[OMEGA], x[OMEGA + 1], x[OMEGA + 2]);
        let iw = Vector3::from(self.inertia).component_mul(&w);
        Self::attitude(x) * iw
    }

    /// Rescales the quaternion of `x` to unit norm (no-op for a zero quaternion).
    pub fn normalize_state(&self, x: &mut [f64]) {
        let q = &mut x[QUAT..QUAT + 4];
        let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
        if n > 0.0 {
            q.iter_mut().for_each(|c| *c /= n);
        }
    }

    /// Height of the landing-gear reference point above the ground (m); ≤ 0 means contact.
    pub fn gear_height(&self, x: &[f64]) -> f64 {
        x[2] - self.leg_length * Self::thrust_axis(x).z - self.ground_height
    }

    /// Whether the landing gear touches (or is below) the ground.
    pub fn touched_down(&self, x: &[f64]) -> bool {
        self.gear_height(x) <= 0.0
    }
}

impl Model for Lander {
    fn name(&self) -> &str {
        "lander"
    }
    fn state_names(&self) -> Vec<String> {
        [
            "x", "y", "z", "qw", "qx", "qy", "qz", "vx", "vy", "vz", "wx", "wy", "wz",
        ]
        .map(String::from)
        .to_vec()
    }
    fn control_names(&self) -> Vec<String> {
        ["thrust", "torque_x", "torque_y", "torque_z"]
            .map(String::from)
            .to_vec()
    }
    fn parameters(&self) -> Vec<Parameter> {
        let axes = ["x", "y", "z"];
        let mut p = vec![Parameter::new("mass", self.mass, "kg", "total mass")];
        for (a, i) in axes.iter().zip(self.inertia) {
            p.push(Parameter::new(
                format!("inertia.{a}"),
                i,
                "kg*m^2",
                "principal moment of inertia about the body axis",
            ));
        }
        p.extend([
            Parameter::gravity(
                self.gravity,
                "gravitational acceleration along world -z (Moon: 1.62)",
            ),
            Parameter::new(
                "max_thrust",
                self.max_thrust,
                "N",
                "main-engine thrust clamp, along body +z",
            ),
            Parameter::new(
                "max_torque",
                self.max_torque,
                "N*m",
                "attitude-jet torque clamp about each body axis",
            ),
            Parameter::new(
                "ground_height",
                self.ground_height,
                "m",
                "height of the ground plane (touchdown report only)",
            ),
            Parameter::new(
                "leg_length",
                self.leg_length,
                "m",
                "centre of mass to landing-gear point along body -z",
            ),
        ]);
        p
    }
    fn default_dt(&self) -> f64 {
        0.01
    }
}

impl Ode for Lander {
    fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let thrust = u[0].clamp(0.0, self.max_thrust);
        let tau =
            Vector3::new(u[1], u[2], u[3]).map(|t| t.clamp(-self.max_torque, self.max_torque));
        let q = Quaternion::new(x[QUAT], x[4], x[5], x[6]);
        let w = Vector3::new(x[OMEGA], x[OMEGA + 1], x[OMEGA + 2]);
        // ṗ = v
        dx[..3].copy_from_slice(&x[VEL..VEL + 3]);
        // q̇ = ½ q ⊗ (0, ω)
        let qd = q * Quaternion::from_imag(w) * 0.5;
        dx[QUAT] = qd.w;
        dx[4] = qd.i;
        dx[5] = qd.j;
        dx[6] = qd.k;
        // m v̇ = T R(q) e_z − m g e_z
        let n2 = q.norm_squared();
        let axis = if n2 > 0.0 {
            // Third column of R(q / |q|).
            Vector3::new(
                2.0 * (q.i * q.k + q.w * q.j),
                2.0 * (q.j * q.k - q.w * q.i),
                q.w * q.w - q.i * q.i - q.j * q.j + q.k * q.k,
            ) / n2
        } else {
            Vector3::z()
        };
        let a = axis * (thrust / self.mass);
        dx[VEL] = a.x;
        dx[VEL + 1] = a.y;
        dx[VEL + 2] = a.z - self.gravity;
        // I ω̇ = τ − ω × I ω
        let inertia = Vector3::from(self.inertia);
        let wd = (tau - w.cross(&inertia.component_mul(&w))).component_div(&inertia);
        dx[OMEGA..OMEGA + 3].copy_from_slice(wd.as_slice());
    }

    fn energy(&self, x: &[f64]) -> Option<f64> {
        let v2: f64 = x[VEL..VEL + 3].iter().map(|v| v * v).sum();
        let rot: f64 = (0..3)
            .map(|i| self.inertia[i] * x[OMEGA + i] * x[OMEGA + i])
            .sum();
        Some(0.5 * self.mass * v2 + 0.5 * rot + self.mass * self.gravity * x[2])
    }
}

/// The lander integrated by an [`IntegratorKind`], with the quaternion renormalised after
/// every step ([`Lander::normalize_state`]).
#[derive(Debug, Clone)]
pub struct NormalizedLander {
    /// The underlying raw-ODE simulator.
    pub sim: Simulator<Lander>,
}

impl NormalizedLander {
    /// Wraps `lander` with an integrator of the given kind.
    pub fn new(lander: Lander, kind: IntegratorKind) -> Self {
        Self {
            sim: Simulator::new(lander, kind),
        }
    }
}

impl Dynamics for NormalizedLander {
    fn state_dim(&self) -> usize {
        13
    }
    fn control_dim(&self) -> usize {
        4
    }
    fn step(&mut self, x: &mut [f64], u: &[f64], dt: f64) {
        self.sim.step(x, u, dt);
        self.sim.model.normalize_state(x);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tumbling state near the unstable intermediate axis (x), off-centre attitude.
    fn tumbling() -> [f64; 13] {
        let q = UnitQuaternion::from_euler_angles(0.3, -0.5, 1.2);
        let q = q.quaternion();
        [
            10.0, -4.0, 50.0, q.w, q.i, q.j, q.k, 1.5, -0.5, -2.0, 3.0, 0.2, 0.3,
        ]
    }

    fn quat_norm(x: &[f64]) -> f64 {
        x[QUAT..QUAT + 4].iter().map(|c| c * c).sum::<f64>().sqrt()
    }

    fn run(kind: IntegratorKind, x0: &[f64], u: &[f64], dt: f64, t: f64) -> Vec<f64> {
        let mut sim = Simulator::new(Lander::default(), kind);
        let mut x = x0.to_vec();
        for _ in 0..(t / dt).round() as usize {
            sim.step(&mut x, u, dt);
        }
        x
    }

    #[test]
    fn angular_momentum_conserved_without_torque() {
        let lander = Lander::default();
        let x0 = tumbling();
        let l0 = lander.angular_momentum(&x0);
        let mut sim = NormalizedLander::new(lander.clone(), IntegratorKind::Rk4);
        let mut x = x0;
        let mut max_dev: f64 = 0.0;
        let mut min_wx: f64 = f64::INFINITY;
        for _ in 0..10_000 {
            sim.step(&mut x, &[0.0; 4], 1e-3);
            max_dev = max_dev.max((lander.angular_momentum(&x) - l0).norm());
            min_wx = min_wx.min(x[OMEGA]);
        }
        // It really tumbles: the intermediate-axis spin flips over.
        assert!(min_wx < 0.0, "no flip: min wx {min_wx}");
        assert!(max_dev < 1e-8 * l0.norm(), "momentum drift {max_dev}");
    }

    #[test]
    fn energy_conserved_without_thrust() {
        let lander = Lander::default();
        let x0 = tumbling();
        let e0 = lander.energy(&x0).unwrap();
        let mut sim = NormalizedLander::new(lander.clone(), IntegratorKind::Rk4);
        let mut x = x0;
        let mut max_dev: f64 = 0.0;
        for _ in 0..10_000 {
            sim.step(&mut x, &[0.0; 4], 1e-3);
            max_dev = max_dev.max((lander.energy(&x).unwrap() - e0).abs());
        }
        assert!(max_dev < 1e-8 * e0.abs(), "energy drift {max_dev} of {e0}");
    }

    #[test]
    fn quaternion_norm_drift_has_the_integrator_order() {
        let x0 = tumbling();
        for (kind, order) in [(IntegratorKind::Euler, 1.0), (IntegratorKind::Rk4, 4.0)] {
            let drift = |dt: f64| (quat_norm(&run(kind, &x0, &[0.0; 4], dt, 4.0)) - 1.0).abs();
            let (d1, d2) = (drift(0.04), drift(0.02));
            let measured = (d1 / d2).log2();
            assert!(
                d1 > 0.0 && measured > order - 0.3,
                "{kind:?}: {d1} {d2} {measured}"
            );
        }
        // With renormalisation after each step, the norm stays 1 to round-off.
        let mut sim = NormalizedLander::new(Lander::default(), IntegratorKind::Euler);
        let mut x = x0;
        for _ in 0..1000 {
            sim.step(&mut x, &[3000.0, 100.0, -50.0, 20.0], 0.01);
            assert!((quat_norm(&x) - 1.0).abs() < 1e-14);
        }
    }

    #[test]
    fn norm_drift_does_not_feed_back() {
        let lander = Lander::default();
        let x0 = tumbling();
        let u = [4000.0, 300.0, -200.0, 100.0];
        let mut scaled = x0;
        scaled[QUAT..QUAT + 4].iter_mut().for_each(|c| *c *= 1.3);
        let a = run(IntegratorKind::Rk4, &x0, &u, 0.01, 1.0);
        let b = run(IntegratorKind::Rk4, &scaled, &u, 0.01, 1.0);
        for i in 0..13 {
            let expect = if (QUAT..QUAT + 4).contains(&i) {
                1.3 * a[i]
            } else {
                a[i]
            };
            assert!((b[i] - expect).abs() < 1e-12 * (1.0 + expect.abs()), "{i}");
        }
        let mut dx = [0.0; 13];
        lander.derivative(&x0, &u, &mut dx);
        assert!(dx[OMEGA].is_finite());
    }

    #[test]
    fn upright_thrust_gives_thrust_over_mass_minus_g() {
        let lander = Lander::default();
        let x = Lander::upright_at_rest([0.0, 0.0, 100.0]);
        let mut dx = [0.0; 13];
        let thrust = 5000.0;
        lander.derivative(&x, &[thrust, 0.0, 0.0, 0.0], &mut dx);
        assert_eq!(&dx[VEL..VEL + 2], &[0.0, 0.0]);
        assert!((dx[VEL + 2] - (thrust / lander.mass - lander.gravity)).abs() < 1e-15);
        assert!(dx[..7].iter().chain(&dx[OMEGA..]).all(|d| *d == 0.0));
        // Hovering thrust holds it still over a whole rollout.
        let hover = lander.mass * lander.gravity;
        let y = run(IntegratorKind::Rk4, &x, &[hover, 0.0, 0.0, 0.0], 0.01, 5.0);
        assert!((y[2] - 100.0).abs() < 1e-10 && y[VEL + 2].abs() < 1e-10);
        // Controls are clamped: no negative thrust.
        lander.derivative(&x, &[-1e6, 0.0, 0.0, 0.0], &mut dx);
        assert_eq!(dx[VEL + 2], -lander.gravity);
    }

    #[test]
    fn tilted_thrust_and_attitude_jets_act_along_body_axes() {
        let lander = Lander::default();
        let mut x = tumbling();
        x[OMEGA..].fill(0.0);
        let mut dx = [0.0; 13];
        let (thrust, tau) = (6000.0, [400.0, -300.0, 200.0]);
        lander.derivative(&x, &[thrust, tau[0], tau[1], tau[2]], &mut dx);
        let expect = Lander::thrust_axis(&x) * (thrust / lander.mass) - Vector3::z() * 1.62;
        for i in 0..3 {
            assert!((dx[VEL + i] - expect[i]).abs() < 1e-14);
            assert!((dx[OMEGA + i] - tau[i] / lander.inertia[i]).abs() < 1e-15);
        }
    }

    #[test]
    fn invariant_to_vertical_rotation_and_horizontal_translation() {
        let x0 = tumbling();
        let u = [7000.0, 500.0, -800.0, 300.0];
        let (phi, t) = (2.3_f64, Vector3::new(-120.0, 45.0, 0.0));
        let rz = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), phi);
        let transform = |x: &[f64], r: &UnitQuaternion<f64>, shift: Vector3<f64>| {
            let p = r * Vector3::new(x[0], x[1], x[2]) + shift;
            let q = r.quaternion() * Quaternion::new(x[QUAT], x[4], x[5], x[6]);
            let v = r * Vector3::new(x[VEL], x[VEL + 1], x[VEL + 2]);
            let mut y = x.to_vec();
            y[..3].copy_from_slice(p.as_slice());
            y[QUAT..QUAT + 4].copy_from_slice(&[q.w, q.i, q.j, q.k]);
            y[VEL..VEL + 3].copy_from_slice(v.as_slice());
            y
        };
        for kind in [IntegratorKind::Rk4, IntegratorKind::Euler] {
            let mut sim = NormalizedLander::new(Lander::default(), kind);
            let mut a = x0.to_vec();
            let mut b = transform(&x0, &rz, t);
            for _ in 0..10 {
                sim.step(&mut a, &u, 0.01);
                sim.step(&mut b, &u, 0.01);
            }
            let back = transform(&b, &rz.inverse(), Vector3::zeros());
            let back = transform(&back, &UnitQuaternion::identity(), -(rz.inverse() * t));
            for i in 0..13 {
                assert!(
                    (a[i] - back[i]).abs() < 1e-12,
                    "{kind:?} {i}: {} {}",
                    a[i],
                    back[i]
                );
            }
        }
    }

    #[test]
    fn touchdown_is_reported_at_the_gear_point() {
        let lander = Lander::default();
        let x = Lander::upright_at_rest([5.0, 5.0, 1.6]);
        assert!(!lander.touched_down(&x));
        assert!((lander.gear_height(&x) - 0.1).abs() < 1e-12);
        // Free fall from rest: touches down after √(2·0.1/g).
        let mut sim = NormalizedLander::new(lander.clone(), IntegratorKind::Rk4);
        let mut y = x;
        let mut t = 0.0;
        while !lander.touched_down(&y) {
            sim.step(&mut y, &[0.0; 4], 0.01);
            t += 0.01;
        }
        let expect = (2.0 * 0.1 / lander.gravity).sqrt();
        assert!(t >= expect && t < expect + 0.0100001, "{t} vs {expect}");
    }
}
