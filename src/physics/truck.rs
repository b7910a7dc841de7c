//! # Truck: a rigid body on the ground plane (NeuroAnimator, Fig. 10 upper right, Fig. 13b)
//!
//! A planar *bicycle model*: one rigid body of mass m and yaw inertia I_z about its centre of
//! mass (CoM); the front axle is `a` ahead of the CoM, the rear axle `b` behind it (wheelbase
//! L = a + b). The rear wheels drive (forward and reverse), the front wheels steer by δ.
//!
//! **State** (6, world frame, as in the paper's Table 1): `[x, y, θ, ẋ, ẏ, θ̇]` — CoM position
//! (m), heading θ of the body's forward axis from the world +x axis (rad, counter-clockwise),
//! and their rates. **Controls** (2): `[accel, steer]` — the drive force per unit mass at the
//! rear axle (m/s², negative = reverse/brake) and the front-wheel steering angle δ (rad).
//!
//! ## Why the steering angle is a control and not a state
//! The paper's truck has 6 state variables and 2 controls ("acceleration/deceleration" and
//! "rate of turning"). A steering-*rate* control would make δ a seventh state variable. To keep
//! Table 1's 6 states we let the control set δ directly (clamped to ±`max_steer`): the steering
//! is an ideal position servo, and δ sets the truck's rate of turning, θ̇ ≈ v tan δ / L when
//! rolling. Over an emulator super-step the control is held constant, so δ is piecewise
//! constant, which is how the paper's controllers (20 values per actuator over 20 s) act anyway.
//!
//! ## Equations
//! With body-frame velocities u = ẋ cos θ + ẏ sin θ (forward), v = −ẋ sin θ + ẏ cos θ
//! (leftward), r = θ̇, the tyre contact velocities are
//!
//! - rear: (u, v − b r); front, in the wheel's own frame:
//!   v_f,long = u cos δ + (v + a r) sin δ, v_f,lat = −u sin δ + (v + a r) cos δ.
//!
//! Each axle's lateral force opposes sideways sliding, linear in the slip angle with cornering
//! stiffness C and saturating at the friction limit μ N (N the static axle load,
//! N_f = m g b / L, N_r = m g a / L):
//!
//! - α = atan(v_lat / √(v_long² + v₀²)), F_lat = −μ N tanh(C α / (μ N)).
//!
//! The slip speed v₀ (`slip_speed`) regularises the slip angle at standstill: below it the tyre
//! acts like a stiff viscous damper on sideways motion instead of a discontinuous Coulomb
//! friction, which keeps the ODE smooth and non-stiff at the 0.01 s step. Free-rolling wheels
//! carry no longitudinal force, except the drive force F_d = m·accel along the body axis at the
//! rear axle, rolling resistance −c_r u along the body axis and aerodynamic drag −c_d |ẋ| ẋ
//! (both zero by default). In the body frame,
//!
//! - F_x = F_d − c_r u − F_f,lat sin δ − c_d |ẋ| u, F_y = F_r,lat + F_f,lat cos δ − c_d |ẋ| v,
//! - M_z = a F_f,lat cos δ − b F_r,lat,
//!
//! and the world-frame equations are m ẍ = R(θ) (F_x, F_y), I_z θ̈ = M_z. Every force is
//! computed in the body frame, so the dynamics are exactly invariant to rotating and
//! translating the world frame, which NeuroAnimator's local-frame transform (§3.3) relies on.
//! Lateral tyre forces only ever dissipate energy: F_lat · v_lat ≤ 0.
//!
//! ## References
//! - R. Rajamani, *Vehicle Dynamics and Control*, 2nd ed., §2.3 (kinematic bicycle) and §2.5
//!   (dynamic bicycle model with linear tyres).
//! - H. B. Pacejka, *Tire and Vehicle Dynamics*, 3rd ed., §1.3 (slip angle, saturation).

use super::{Model, Ode, Parameter};
use serde::{Deserialize, Serialize};

/// The truck: a planar rigid body with rear-wheel drive and steerable front wheels.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Truck {
    /// Total mass (kg).
    pub mass: f64,
    /// Moment of inertia about the vertical axis through the centre of mass (kg·m²).
    pub yaw_inertia: f64,
    /// Distance from the centre of mass forward to the front axle (m).
    pub front_axle: f64,
    /// Distance from the centre of mass back to the rear axle (m).
    pub rear_axle: f64,
    /// Cornering stiffness of the front axle, both tyres together (N/rad).
    pub front_cornering_stiffness: f64,
    /// Cornering stiffness of the rear axle, both tyres together (N/rad).
    pub rear_cornering_stiffness: f64,
    /// Tyre–ground friction coefficient μ; the lateral force saturates at μ times the axle load
    /// (dimensionless).
    pub friction: f64,
    /// Speed regularising the slip angle at standstill (m/s).
    pub slip_speed: f64,
    /// Rolling-resistance coefficient: force −c_r u along the body axis (N·s/m).
    pub rolling_resistance: f64,
    /// Aerodynamic drag coefficient: force −c_d |v| v (N·s²/m²).
    pub drag: f64,
    /// Largest steering angle magnitude; the steering control is clamped to it (rad).
    pub max_steer: f64,
    /// Largest drive acceleration magnitude; the accel control is clamped to it (m/s²).
    pub max_accel: f64,
    /// Gravitational acceleration, for the axle loads (m/s²).
    pub gravity: f64,
}

impl Default for Truck {
    /// A light truck: 2 t, 3.4 m wheelbase, CoM slightly forward of mid-wheelbase.
    fn default() -> Self {
        Self {
            mass: 2000.0,
            yaw_inertia: 4000.0,
            front_axle: 1.6,
            rear_axle: 1.8,
            front_cornering_stiffness: 80_000.0,
            rear_cornering_stiffness: 80_000.0,
            friction: 0.8,
            slip_speed: 1.0,
            rolling_resistance: 0.0,
            drag: 0.0,
            max_steer: 0.6,
            max_accel: 4.0,
            gravity: 9.81,
        }
    }
}

/// Contact quantities of one evaluation, in the body frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TyreForces {
    /// Front axle lateral force along the front wheels' left axis (N).
    pub front_lateral: f64,
    /// Rear axle lateral force along the body's left axis (N).
    pub rear_lateral: f64,
    /// Sideways sliding velocity of the front contact, in the wheel frame (m/s).
    pub front_slip_velocity: f64,
    /// Sideways sliding velocity of the rear contact (m/s).
    pub rear_slip_velocity: f64,
}

impl Truck {
    /// Wheelbase L = front_axle + rear_axle (m).
    pub fn wheelbase(&self) -> f64 {
        self.front_axle + self.rear_axle
    }

    /// Static axle loads (front, rear) in newtons.
    pub fn axle_loads(&self) -> (f64, f64) {
        let w = self.mass * self.gravity / self.wheelbase();
        (w * self.rear_axle, w * self.front_axle)
    }

    /// Body-frame velocities (forward u, leftward v) of the centre of mass (m/s).
    pub fn body_velocity(x: &[f64]) -> (f64, f64) {
        let (s, c) = crate::portable::sin_cos(x[2]);
        (c * x[3] + s * x[4], -s * x[3] + c * x[4])
    }

    /// The steering angle actually applied for control `steer` (clamped, rad).
    pub fn steer_angle(&self, steer: f64) -> f64 {
        steer.clamp(-self.max_steer, self.max_steer)
    }

    /// Rear-axle position (m): the point that follows the kinematic circle of radius
    /// L / tan δ when rolling slowly.
    pub fn rear_axle_position(&self, x: &[f64]) -> [f64; 2] {
        let (s, c) = crate::portable::sin_cos(x[2]);
        [x[0] - self.rear_axle * c, x[1] - self.rear_axle * s]
    }

    fn lateral_force(&self, stiffness: f64, load: f64, v_long: f64, v_lat: f64) -> f64 {
        let alpha = crate::portable::atan(
            v_lat / (v_long * v_long + self.slip_speed * self.slip_speed).sqrt(),
        );
        let limit = self.friction * load;
        if limit > 0.0 {
            -limit * crate::portable::tanh(stiffness * alpha / limit)
        } else {
            0.0
        }
    }

    /// Lateral tyre forces and slip velocities at state `x` with steering angle `delta` (rad,
    /// already clamped).
    pub fn tyre_forces(&self, x: &[f64], delta: f64) -> TyreForces {
        let (u, v) = Self::body_velocity(x);
        let r = x[5];
        let (sd, cd) = crate::portable::sin_cos(delta);
        let vf = v + self.front_axle * r;
        let f_long = u * cd + vf * sd;
        let f_lat = -u * sd + vf * cd;
        let r_lat = v - self.rear_axle * r;
        let (nf, nr) = self.axle_loads();
        TyreForces {
            front_lateral: self.lateral_force(self.front_cornering_stiffness, nf, f_long, f_lat),
            rear_lateral: self.lateral_force(self.rear_cornering_stiffness, nr, u, r_lat),
            front_slip_velocity: f_lat,
            rear_slip_velocity: r_lat,
        }
    }
}

impl Model for Truck {
    fn name(&self) -> &str {
        "truck"
    }
    fn state_names(&self) -> Vec<String> {
        ["x", "y", "theta", "x_dot", "y_dot", "theta_dot"]
            .map(String::from)
            .to_vec()
    }
    fn control_names(&self) -> Vec<String> {
        vec!["accel".into(), "steer".into()]
    }
    fn parameters(&self) -> Vec<Parameter> {
        vec![
            Parameter::new("mass", self.mass, "kg", "total mass"),
            Parameter::new(
                "yaw_inertia",
                self.yaw_inertia,
                "kg*m^2",
                "moment of inertia about the vertical axis through the centre of mass",
            ),
            Parameter::new(
                "front_axle",
                self.front_axle,
                "m",
                "centre of mass to front axle (forward)",
            ),
            Parameter::new(
                "rear_axle",
                self.rear_axle,
                "m",
                "centre of mass to rear (driven) axle (backward)",
            ),
            Parameter::new(
                "front_cornering_stiffness",
                self.front_cornering_stiffness,
                "N/rad",
                "front axle lateral force per unit slip angle (both tyres)",
            ),
            Parameter::new(
                "rear_cornering_stiffness",
                self.rear_cornering_stiffness,
                "N/rad",
                "rear axle lateral force per unit slip angle (both tyres)",
            ),
            Parameter::new(
                "friction",
                self.friction,
                "1",
                "tyre friction coefficient: lateral force saturates at friction * axle load",
            ),
            Parameter::new(
                "slip_speed",
                self.slip_speed,
                "m/s",
                "regularises the slip angle at standstill (viscous below it)",
            ),
            Parameter::new(
                "rolling_resistance",
                self.rolling_resistance,
                "N*s/m",
                "longitudinal resistance -c_r * forward speed",
            ),
            Parameter::new(
                "drag",
                self.drag,
                "N*s^2/m^2",
                "aerodynamic drag -c_d * |v| * v",
            ),
            Parameter::new("max_steer", self.max_steer, "rad", "steering control clamp"),
            Parameter::new(
                "max_accel",
                self.max_accel,
                "m/s^2",
                "drive acceleration control clamp (forward and reverse)",
            ),
            Parameter::gravity(self.gravity, "gravitational acceleration (axle loads)"),
        ]
    }
    fn default_dt(&self) -> f64 {
        0.01
    }
}

impl Ode for Truck {
    fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let accel = u[0].clamp(-self.max_accel, self.max_accel);
        let delta = self.steer_angle(u[1]);
        let (s, c) = crate::portable::sin_cos(x[2]);
        let (vu, vv) = Self::body_velocity(x);
        let tyres = self.tyre_forces(x, delta);
        let (sd, cd) = crate::portable::sin_cos(delta);
        let speed = crate::portable::hypot(x[3], x[4]);
        let fx = self.mass * accel
            - self.rolling_resistance * vu
            - tyres.front_lateral * sd
            - self.drag * speed * vu;
        let fy = tyres.rear_lateral + tyres.front_lateral * cd - self.drag * speed * vv;
        let mz = self.front_axle * tyres.front_lateral * cd - self.rear_axle * tyres.rear_lateral;
        dx[0] = x[3];
        dx[1] = x[4];
        dx[2] = x[5];
        dx[3] = (c * fx - s * fy) / self.mass;
        dx[4] = (s * fx + c * fy) / self.mass;
        dx[5] = mz / self.yaw_inertia;
    }

    fn position_dim(&self) -> Option<usize> {
        Some(3)
    }

    fn energy(&self, x: &[f64]) -> Option<f64> {
        Some(0.5 * self.mass * (x[3] * x[3] + x[4] * x[4]) + 0.5 * self.yaw_inertia * x[5] * x[5])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{Dynamics, IntegratorKind, Simulator};

    /// State moving forward at `speed` along heading `theta`.
    fn driving(theta: f64, speed: f64) -> [f64; 6] {
        [
            3.0,
            -2.0,
            theta,
            speed * theta.cos(),
            speed * theta.sin(),
            0.0,
        ]
    }

    #[test]
    fn straight_line_with_zero_controls_stays_straight() {
        let t = Truck::default();
        let theta = 0.7;
        let x0 = driving(theta, 10.0);
        let mut sim = Simulator::new(t, IntegratorKind::Rk4);
        let x = sim
            .rollout(&x0, 0.01, 1000, |_, _, _, _| {}, |_, _, _| {})
            .unwrap();
        // No resistance by default: constant velocity, unchanged heading.
        assert!((x[2] - theta).abs() < 1e-12 && x[5].abs() < 1e-12);
        assert!((x[3] - x0[3]).abs() < 1e-12 && (x[4] - x0[4]).abs() < 1e-12);
        assert!((x[0] - (x0[0] + 10.0 * x0[3])).abs() < 1e-9);
        assert!((x[1] - (x0[1] + 10.0 * x0[4])).abs() < 1e-9);
    }

    #[test]
    fn resistance_slows_but_keeps_the_line() {
        let t = Truck {
            rolling_resistance: 50.0,
            drag: 0.5,
            ..Truck::default()
        };
        let theta = -2.0;
        let x0 = driving(theta, 10.0);
        let mut sim = Simulator::new(t, IntegratorKind::Rk4);
        let mut last = f64::INFINITY;
        let x = sim
            .rollout(
                &x0,
                0.01,
                2000,
                |_, _, _, _| {},
                |_, _, x| {
                    let (u, v) = Truck::body_velocity(x);
                    assert!(u <= last && u > 0.0 && v.abs() < 1e-12);
                    last = u;
                },
            )
            .unwrap();
        assert!((x[2] - theta).abs() < 1e-12 && x[5].abs() < 1e-12);
        assert!(last < 9.0, "speed {last}");
    }

    #[test]
    fn invariant_to_rotating_and_translating_the_world() {
        let t = Truck::default();
        let x0 = [1.5, -0.7, 0.4, 6.0, 2.5, 0.8];
        let u = [1.3, -0.25];
        let (phi, tx, ty) = (2.1_f64, -40.0, 17.0);
        let (s, c) = phi.sin_cos();
        let to_world = |x: &[f64; 6]| -> [f64; 6] {
            [
                c * x[0] - s * x[1] + tx,
                s * x[0] + c * x[1] + ty,
                x[2] + phi,
                c * x[3] - s * x[4],
                s * x[3] + c * x[4],
                x[5],
            ]
        };
        let from_world = |x: &[f64; 6]| -> [f64; 6] {
            let (px, py) = (x[0] - tx, x[1] - ty);
            [
                c * px + s * py,
                -s * px + c * py,
                x[2] - phi,
                c * x[3] + s * x[4],
                -s * x[3] + c * x[4],
                x[5],
            ]
        };
        for kind in [IntegratorKind::Rk4, IntegratorKind::Euler] {
            let mut sim = Simulator::new(t.clone(), kind);
            let mut a = x0;
            let mut b = to_world(&x0);
            for _ in 0..10 {
                sim.step(&mut a, &u, 0.01);
                sim.step(&mut b, &u, 0.01);
            }
            let b = from_world(&b);
            for i in 0..6 {
                assert!(
                    (a[i] - b[i]).abs() < 1e-12,
                    "{kind:?} {i}: {} vs {}",
                    a[i],
                    b[i]
                );
            }
        }
    }

    #[test]
    fn lateral_velocity_decays() {
        let t = Truck::default();
        // Driving forward at 5 m/s and sliding sideways at 2 m/s: the tyres saturate (skid),
        // then grip.
        let theta: f64 = 0.3;
        let (s, c) = theta.sin_cos();
        let x0 = [0.0, 0.0, theta, 5.0 * c - 2.0 * s, 5.0 * s + 2.0 * c, 0.0];
        let mut sim = Simulator::new(t.clone(), IntegratorKind::Rk4);
        let mut energy = t.energy(&x0).unwrap();
        let mut slip_at = Vec::new();
        let x = sim
            .rollout(
                &x0,
                0.01,
                300,
                |_, _, _, _| {},
                |k, _, x| {
                    let e = t.energy(x).unwrap();
                    assert!(e <= energy + 1e-9, "energy rose at step {k}");
                    energy = e;
                    if k % 50 == 0 {
                        slip_at.push(Truck::body_velocity(x).1.abs());
                    }
                },
            )
            .unwrap();
        let (u, v) = Truck::body_velocity(&x);
        assert!(slip_at[1] < 0.5 * slip_at[0], "{slip_at:?}");
        assert!(v.abs() < 1e-3 && x[5].abs() < 1e-3, "v = {v}, r = {}", x[5]);
        assert!(u > 3.0, "still rolling forward: {u}");
    }

    #[test]
    fn constant_steering_follows_kinematic_circle_at_low_speed() {
        let t = Truck::default();
        let speed = 1.0;
        for delta in [0.3_f64, -0.2] {
            let mut sim = Simulator::new(t.clone(), IntegratorKind::Rk4);
            // Speed held by a proportional drive controller; 30 s settles the transient.
            let x = sim
                .rollout(
                    &driving(0.0, speed),
                    0.01,
                    3000,
                    |_, _, x, u| {
                        u[0] = 2.0 * (speed - Truck::body_velocity(x).0);
                        u[1] = delta;
                    },
                    |_, _, _| {},
                )
                .unwrap();
            // Rear-axle speed / yaw rate = rear-axle path radius.
            let (u, v) = Truck::body_velocity(&x);
            let rear_speed = u.hypot(v - t.rear_axle * x[5]);
            let radius = rear_speed / x[5].abs();
            let expected = t.wheelbase() / delta.abs().tan();
            assert!(
                (radius / expected - 1.0).abs() < 0.01,
                "delta {delta}: radius {radius} vs {expected}"
            );
            assert_eq!(x[5].signum(), delta.signum());
        }
    }

    #[test]
    fn power_balance_matches_derivative() {
        // dE/dt = drive power + tyre power (≤ 0) − resistance power.
        let t = Truck {
            rolling_resistance: 30.0,
            drag: 0.4,
            ..Truck::default()
        };
        let x = [0.0, 0.0, 1.1, 3.0, -4.0, 0.6];
        let u = [1.5, 0.2];
        let mut dx = [0.0; 6];
        t.derivative(&x, &u, &mut dx);
        let h = 1e-6;
        let e = |s: f64| {
            let y: Vec<f64> = x.iter().zip(&dx).map(|(p, q)| p + s * q).collect();
            t.energy(&y).unwrap()
        };
        let de = (e(h) - e(-h)) / (2.0 * h);
        let tyres = t.tyre_forces(&x, u[1]);
        let (vu, _) = Truck::body_velocity(&x);
        let speed = crate::portable::hypot(x[3], x[4]);
        let tyre_power = tyres.front_lateral * tyres.front_slip_velocity
            + tyres.rear_lateral * tyres.rear_slip_velocity;
        assert!(tyre_power < 0.0);
        let expected = t.mass * u[0] * vu + tyre_power
            - t.rolling_resistance * vu * vu
            - t.drag * speed.powi(3);
        assert!(
            (de - expected).abs() < 1e-4 * expected.abs(),
            "{de} vs {expected}"
        );
    }

    #[test]
    fn controls_are_clamped_and_drive_works_in_reverse() {
        let t = Truck::default();
        let x = [0.0, 0.0, 0.5, 0.0, 0.0, 0.0];
        let mut dx = [0.0; 6];
        t.derivative(&x, &[-100.0, 0.0], &mut dx);
        let a = dx[3].hypot(dx[4]);
        assert!((a - t.max_accel).abs() < 1e-12);
        // Pointing backwards along the heading.
        assert!((dx[3] + t.max_accel * 0.5f64.cos()).abs() < 1e-12);
        assert_eq!(t.steer_angle(2.0), t.max_steer);
    }
}
