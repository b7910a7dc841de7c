//! # A 3-D tree on the ground: [`OnGround3d`]
//!
//! A [`Tree3d`] touching the ground of [`crate::physics::ground`] at named points of its
//! bodies ([`BodyPoint`]), through the penalty law every body shares
//! ([`Contact::force3d`]); the law, its parameters and the rule that picks them and the step
//! ([`resting_contact`], [`resting_step`]) are in the [module docs](super). [`solid_box`] is
//! the test body: a box and its eight corners.

use super::tree::{Body3d, BodyPoint, Joint3d, Tree3d};
use crate::physics::ground::{Contact, Terrain};
use crate::physics::{Model, Ode, Parameter};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Penalty constants for a body of `mass` (kg) under `gravity` (m/s²) resting on `support` of
/// its contact points with static penetration about `penetration` (m) (the rule in the
/// [module docs](super)): k = m g / (n δ), c = 2 √(k m / n) (critical damping of one point's
/// share of the mass), contact switching on over ε = δ / 4, friction coefficient `friction`
/// and slip speed `slip_speed` (m/s).
pub fn resting_contact(
    mass: f64,
    gravity: f64,
    support: usize,
    penetration: f64,
    friction: f64,
    slip_speed: f64,
) -> Contact {
    let n = support as f64;
    let stiffness = mass * gravity / (n * penetration);
    Contact {
        stiffness,
        damping: 2.0 * (stiffness * mass / n).sqrt(),
        friction,
        slip_speed,
        smoothing: penetration / 4.0,
        enabled: true,
    }
}

/// The RK4 step (s) for contact of static penetration `penetration` (m) under `gravity`
/// (m/s²): dt = 0.07 / ω with ω = √(g / δ), the natural frequency of the body on its contact
/// springs ([module docs](super)).
pub fn resting_step(gravity: f64, penetration: f64) -> f64 {
    0.07 / (gravity / penetration).sqrt()
}

/// A [`Tree3d`] on the ground, touching it at `points` through the penalty contact of
/// [`crate::physics::ground`] ([`Contact::force3d`]); the controls are the tree's motors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OnGround3d {
    /// The body.
    pub tree: Tree3d,
    /// Its contact points.
    pub points: Vec<BodyPoint>,
    /// The ground's shape (its height varies along world x).
    pub terrain: Terrain,
    /// The penalty constants.
    pub contact: Contact,
}

impl OnGround3d {
    /// Checks the tree, the points, the terrain and the constants.
    pub fn validate(&self) -> Result<(), String> {
        self.tree.validate().map_err(|e| e.to_string())?;
        if let Some((k, p)) = self.points.iter().enumerate().find(|(_, p)| {
            p.body >= self.tree.bodies.len() || !p.offset.iter().all(|c| c.is_finite())
        }) {
            return Err(format!(
                "contact point {k}: {p:?} names no body or is not finite"
            ));
        }
        self.terrain.validate()?;
        self.contact.validate()
    }

    /// The contact points' world positions (m) and velocities (m/s) at state `x`.
    pub fn point_states(&self, x: &[f64]) -> Vec<(Vector3<f64>, Vector3<f64>)> {
        self.tree.point_states(x, &self.points)
    }

    /// The ground's forces (N, world) on the contact points at state `x`.
    pub fn contact_forces(&self, x: &[f64]) -> Vec<Vector3<f64>> {
        self.point_states(x)
            .into_iter()
            .map(|(p, v)| self.force(p, v))
            .collect()
    }

    /// The deepest penetration (m) of a contact point below the terrain at state `x` (the
    /// vertical distance; negative when every point is above it).
    pub fn penetration(&self, x: &[f64]) -> f64 {
        self.point_states(x)
            .iter()
            .map(|(p, _)| self.terrain.height_slope(p.x).0 - p.z)
            .fold(f64::NEG_INFINITY, f64::max)
    }

    fn force(&self, p: Vector3<f64>, v: Vector3<f64>) -> Vector3<f64> {
        Vector3::from(self.contact.force3d(&self.terrain, p.into(), v.into()))
    }
}

impl Model for OnGround3d {
    fn name(&self) -> &str {
        &self.tree.name
    }
    fn state_names(&self) -> Vec<String> {
        self.tree.state_names()
    }
    fn control_names(&self) -> Vec<String> {
        self.tree.control_names()
    }
    fn parameters(&self) -> Vec<Parameter> {
        let mut p = self.tree.parameters();
        p.extend(self.contact.parameters());
        for (k, pt) in self.points.iter().enumerate() {
            p.push(Parameter::new(
                format!("contact_point{k}.body"),
                pt.body as f64,
                "1",
                "index of the body carrying the contact point",
            ));
            for (c, v) in ["x", "y", "z"].iter().zip(pt.offset) {
                p.push(Parameter::new(
                    format!("contact_point{k}.offset.{c}"),
                    v,
                    "m",
                    "contact point in its body's coordinates",
                ));
            }
        }
        p
    }
    fn default_dt(&self) -> f64 {
        self.tree.dt
    }
}

impl Ode for OnGround3d {
    fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        self.tree
            .derivative_with_point_forces(x, u, &self.points, |_, p, v| self.force(p, v), dx);
    }

    /// Kinetic plus gravitational energy of the tree (J); the contact springs' energy is not
    /// included.
    fn energy(&self, x: &[f64]) -> Option<f64> {
        self.tree.energy(x)
    }
}

/// A solid box of `mass` (kg) and half extents `half` (m), its origin at its centre, as the
/// single free body of a tree named `name`, stepped at `dt` (s); and its eight corners.
pub fn solid_box(name: &str, mass: f64, half: [f64; 3], dt: f64) -> (Tree3d, Vec<BodyPoint>) {
    let [a, b, c] = half.map(|h| 4.0 * h * h);
    let tree = Tree3d {
        name: name.into(),
        bodies: vec![Body3d {
            name: "box".into(),
            parent: None,
            joint: Joint3d::Free,
            offset: [0.0; 3],
            orientation: [1.0, 0.0, 0.0, 0.0],
            mass,
            com: [0.0; 3],
            inertia: [
                mass * (b + c) / 12.0,
                mass * (a + c) / 12.0,
                mass * (a + b) / 12.0,
                0.0,
                0.0,
                0.0,
            ],
            damping: 0.0,
            actuated: false,
        }],
        gravity: 9.81,
        dt,
    };
    let mut points = Vec::with_capacity(8);
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            for sz in [-1.0, 1.0] {
                points.push(BodyPoint {
                    body: 0,
                    offset: [sx * half[0], sy * half[1], sz * half[2]],
                });
            }
        }
    }
    (tree, points)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::body3d::chain3d;
    use crate::physics::{IntegratorKind, Simulator};

    const DELTA: f64 = 0.002;
    const MASS: f64 = 2.0;
    const HALF: [f64; 3] = [0.15, 0.1, 0.05];
    /// Slip speed of the tests' friction (m/s).
    const SLIP: f64 = 0.05;

    fn unit_quat(v: [f64; 4]) -> [f64; 4] {
        let n = v.iter().map(|c| c * c).sum::<f64>().sqrt();
        v.map(|c| c / n)
    }

    /// The 2 kg box on `terrain`, 2 mm static penetration on four corners.
    fn boxed(terrain: Terrain, friction: f64) -> OnGround3d {
        let (tree, points) = solid_box("box", MASS, HALF, resting_step(9.81, DELTA));
        OnGround3d {
            tree,
            points,
            terrain,
            contact: resting_contact(MASS, 9.81, 4, DELTA, friction, SLIP),
        }
    }

    fn box_state(p: [f64; 3], q: [f64; 4], v: [f64; 3], w: [f64; 3]) -> Vec<f64> {
        let mut x = p.to_vec();
        x.extend(unit_quat(q));
        x.extend(v);
        x.extend(w);
        x
    }

    fn run(
        m: &OnGround3d,
        x0: &[f64],
        dt: f64,
        duration: f64,
        mut each: impl FnMut(f64, &[f64]),
    ) -> Vec<f64> {
        let steps = (duration / dt).round() as usize;
        let u = vec![0.0; m.control_dim()];
        let mut sim = Simulator::new(m.clone(), IntegratorKind::Rk4);
        sim.rollout(
            x0,
            dt,
            steps,
            |_, _, _, c| c.copy_from_slice(&u),
            |_, t, x| each(t, x),
        )
        .unwrap()
    }

    fn speed(m: &OnGround3d, x: &[f64]) -> f64 {
        m.point_states(x)
            .iter()
            .map(|(_, v)| v.norm())
            .fold(0.0, f64::max)
    }

    /// Generic points on every body of `chain3d`.
    fn chain_points() -> Vec<BodyPoint> {
        [
            (0, [0.1, -0.2, 0.3]),
            (0, [-0.1, 0.1, -0.2]),
            (1, [0.0, 0.05, -0.3]),
            (2, [0.02, 0.0, -0.3]),
            (3, [0.0, -0.2, 0.05]),
        ]
        .map(|(body, offset)| BodyPoint { body, offset })
        .to_vec()
    }

    /// A generic state of `chain3d` (the one of the dynamics tests).
    fn chain_state() -> Vec<f64> {
        let mut x = vec![0.3, -0.2, 1.1];
        x.extend(unit_quat([0.8, 0.3, -0.4, 0.2]));
        x.extend(unit_quat([0.9, -0.2, 0.35, 0.1]));
        x.extend([0.7, -0.5]);
        x.extend([0.4, -0.3, 0.9, 1.3, -0.7, 0.6, -1.1, 0.8, 0.5, 1.7, -2.2]);
        x
    }

    /// Σ Jᵀ f does the forces' virtual work: Q · q̇ = Σ f · v for every q̇, the point velocities
    /// from `point_state` (world poses and the velocity recursion); and it enters the dynamics as
    /// H v̇ = … + Q.
    #[test]
    fn point_forces_enter_through_the_transposed_jacobian() {
        let t = chain3d();
        let points = chain_points();
        let forces: Vec<Vector3<f64>> = (0..points.len())
            .map(|k| Vector3::new(1.0 + k as f64, -0.5 * k as f64, 2.0 - 0.7 * k as f64))
            .collect();
        let mut x = chain_state();
        let nq = t.nq();
        let q = t.generalized_force(&x, &points, &forces);
        for trial in 0..4 {
            // Another q̇ each time: the identity is linear in q̇.
            for (i, v) in x[nq..].iter_mut().enumerate() {
                *v = (0.37 * (i + 3 * trial) as f64).sin() * 1.5;
            }
            let power: f64 = q.iter().zip(&x[nq..]).map(|(a, b)| a * b).sum();
            let work: f64 = points
                .iter()
                .zip(&forces)
                .map(|(p, f)| f.dot(&t.point_state(&x, p.body, p.offset).1))
                .sum();
            assert!(
                (power - work).abs() < 1e-12 * (1.0 + work.abs()),
                "{power} vs {work}"
            );
            // The point states agree with point_state.
            for (p, (pos, vel)) in points.iter().zip(t.point_states(&x, &points)) {
                let (a, b) = t.point_state(&x, p.body, p.offset);
                assert!((a - pos).norm() < 1e-14 && (b - vel).norm() < 1e-13);
            }
        }
        let u = [0.4, -0.3, 0.2, 0.5, -0.6];
        let mut free = vec![0.0; x.len()];
        let mut pushed = vec![0.0; x.len()];
        t.derivative(&x, &u, &mut free);
        t.derivative_with_point_forces(&x, &u, &points, |k, _, _| forces[k], &mut pushed);
        assert_eq!(free[..nq], pushed[..nq]);
        let h = t.mass_matrix(&x);
        let dv =
            nalgebra::DVector::from_iterator(t.nv(), (nq..x.len()).map(|k| pushed[k] - free[k]));
        let hq = &h * dv;
        for (a, b) in hq.iter().zip(&q) {
            assert!((a - b).abs() < 1e-10 * (1.0 + b.abs()), "{a} vs {b}");
        }
        // No force: the tree's own derivative.
        t.derivative_with_point_forces(&x, &u, &points, |_, _, _| Vector3::zeros(), &mut pushed);
        assert_eq!(free, pushed);
    }

    /// Central differences at steps h and 2h agree: `f` is smooth at `x` (no kink).
    fn assert_smooth(what: &str, x: &[f64], steps: &[f64], f: &dyn Fn(&[f64]) -> Vec<f64>) {
        for (k, &h) in steps.iter().enumerate() {
            let at = |s: f64| {
                let mut y = x.to_vec();
                y[k] += s;
                f(&y)
            };
            let (a, b, a2, b2) = (at(h), at(-h), at(2.0 * h), at(-2.0 * h));
            for j in 0..a.len() {
                let d1 = (a[j] - b[j]) / (2.0 * h);
                let d2 = (a2[j] - b2[j]) / (4.0 * h);
                let scale = d1.abs().max(d2.abs()).max(1.0);
                assert!(
                    (d1 - d2).abs() < 1e-4 * scale,
                    "{what} at {x:?}: d/dx{k} of output {j}: {d1} vs {d2}"
                );
            }
        }
    }

    /// The 3-D contact force is smooth in the point's position and velocity: in and out of
    /// contact, on the contact boundary and across the switch-on length, sliding, slowly
    /// slipping and at rest tangentially, on flat and sloped ground.
    #[test]
    fn contact_force_is_smooth_in_and_out_of_contact() {
        let c = resting_contact(MASS, 9.81, 4, DELTA, 0.8, SLIP);
        let eps = c.smoothing;
        let terrains = [
            Terrain::Flat,
            Terrain::Slope { degrees: 12.0 },
            Terrain::FlatThenHill {
                start_m: 0.0,
                degrees: 10.0,
                smoothing_m: 0.2,
            },
        ];
        let depths = [
            -8.0 * eps,
            -eps,
            -0.1 * eps,
            0.0,
            0.3 * eps,
            2.0 * eps,
            20.0 * eps,
        ];
        let velocities = [
            [0.3, -0.2, -0.4],
            [1e-4, -2e-4, 0.05],
            [0.0, 0.0, 0.0],
            [-0.01, 0.02, 0.3],
        ];
        for t in &terrains {
            for d in depths {
                for v in velocities {
                    let x = 0.05;
                    let z = t.height_slope(x).0 + d;
                    let s = [x, 0.1, z, v[0], v[1], v[2]];
                    let f = |y: &[f64]| {
                        c.force3d(t, [y[0], y[1], y[2]], [y[3], y[4], y[5]])
                            .to_vec()
                    };
                    assert_smooth(
                        &format!("{t:?}"),
                        &s,
                        &[1e-7, 1e-7, 1e-7, 1e-6, 1e-6, 1e-6],
                        &f,
                    );
                }
            }
        }
        // Off: no force.
        let off = Contact {
            enabled: false,
            ..c
        };
        assert_eq!(
            off.force3d(&Terrain::Flat, [0.0, 0.0, -0.1], [1.0, 0.0, -1.0]),
            [0.0; 3]
        );
    }

    /// The whole dynamics of the box on the ground is smooth in the state: ẋ against central
    /// differences at two steps in every state coordinate, in the air, touching, resting and
    /// sliding, and with a corner just crossing the contact boundary.
    #[test]
    fn dynamics_on_the_ground_are_smooth_in_the_state() {
        let m = boxed(Terrain::Slope { degrees: 5.0 }, 0.8);
        let q = [0.95, 0.1, -0.15, 0.05];
        let mut states = Vec::new();
        for z in [0.3, 0.06, 0.05, 0.048, 0.045] {
            states.push(box_state(
                [0.02, 0.01, z],
                q,
                [0.2, -0.1, -0.3],
                [0.5, -0.4, 0.8],
            ));
            states.push(box_state([0.02, 0.01, z], q, [0.0; 3], [0.0; 3]));
        }
        // A corner exactly on the boundary.
        let mut x = states[2].clone();
        x[2] += m.penetration(&x);
        states.push(x);
        let dx = |y: &[f64]| {
            let mut d = vec![0.0; y.len()];
            m.derivative(y, &[], &mut d);
            d
        };
        let steps: Vec<f64> = (0..13).map(|k| if k < 7 { 1e-7 } else { 1e-6 }).collect();
        for s in &states {
            assert_smooth("box", s, &steps, &dx);
        }
    }

    /// The slip factor tanh(s)/s: its series and its closed form agree where they meet, and
    /// it is the planar law's tanh on a line.
    #[test]
    fn slip_factor_is_tanh_s_over_s_on_both_sides_of_its_switch() {
        use crate::physics::ground::slip_factor;
        for s2 in [1e-4 * (1.0 - 1e-12), 1e-4, 1e-4 * (1.0 + 1e-12)] {
            let s = f64::sqrt(s2);
            assert!((slip_factor(s2) - s.tanh() / s).abs() < 1e-15, "{s2}");
        }
        assert_eq!(slip_factor(0.0), 1.0);
        for s in [1e-3, 0.05, 0.7, 3.0, 40.0] {
            assert!((s * slip_factor(s * s) - s.tanh()).abs() < 1e-15, "{s}");
        }
    }

    /// Friction never exceeds μ f_n, opposes the slip and lies in the tangent plane.
    #[test]
    fn friction_is_bounded_by_coulomb_and_opposes_sliding() {
        let c = resting_contact(MASS, 9.81, 4, DELTA, 0.7, SLIP);
        let mut r = 0.3_f64;
        let mut next = || {
            r = (r * 997.0 + 0.123).fract();
            2.0 * r - 1.0
        };
        for t in [Terrain::Flat, Terrain::Slope { degrees: -15.0 }] {
            for _ in 0..2000 {
                let x = next();
                let p = [x, next(), t.height_slope(x).0 + 0.004 * next()];
                let scale = [1e-4, 1e-2, 1.0][((next() + 1.0) * 1.5) as usize % 3];
                let v = [scale * next(), scale * next(), scale * next()];
                let f = Vector3::from(c.force3d(&t, p, v));
                let slope = t.height_slope(p[0]).1;
                let n = Vector3::new(-slope, 0.0, 1.0).normalize();
                let v = Vector3::from(v);
                let vt = v - n * v.dot(&n);
                let (f_n, ft) = (f.dot(&n), f - n * f.dot(&n));
                assert!(f_n >= 0.0);
                assert!(
                    ft.norm() <= c.friction * f_n * (1.0 + 1e-12),
                    "{ft} vs {f_n}"
                );
                assert!(ft.dot(&vt) <= 0.0);
                assert!(ft.cross(&vt).norm() <= 1e-9 * (ft.norm() * vt.norm() + 1e-300));
            }
        }
    }

    /// The box dropped from 0.3 m, tilted and spinning, lands on its corners and comes to rest
    /// on its face.
    #[test]
    fn a_dropped_box_comes_to_rest_without_sinking() {
        let m = boxed(Terrain::Flat, 0.9);
        let x0 = box_state(
            [0.0, 0.0, 0.3],
            [0.9, 0.2, -0.3, 0.1],
            [0.3, -0.2, 0.0],
            [1.0, -2.0, 3.0],
        );
        let bound = MASS * 9.81 / (4.0 * m.contact.stiffness);
        let mut worst: f64 = f64::NEG_INFINITY;
        let mut qn: f64 = 0.0;
        let x = run(&m, &x0, m.tree.dt, 3.0, |_, x| {
            worst = worst.max(m.penetration(x));
            qn = qn.max((x[3..7].iter().map(|c| c * c).sum::<f64>().sqrt() - 1.0).abs());
        });
        // At rest on four corners, not sunk past the static compression m g / (4 k) = δ.
        let rest = m.penetration(&x);
        assert!(
            rest > 0.5 * bound && rest < bound,
            "resting at {rest:e} m (bound {bound:e})"
        );
        assert!(worst < 12.0 * bound, "impact {worst:e} m");
        assert!(speed(&m, &x) < 1e-9, "{:e}", speed(&m, &x));
        // The quaternion's norm stays 1 within RK4's error through the impacts, which shrinks
        // faster than the step's cube.
        assert!(qn < 1e-6, "{qn:e}");
        let drift = |dt: f64| {
            let mut qn: f64 = 0.0;
            run(&m, &x0, dt, 1.0, |_, x| {
                qn = qn.max((x[3..7].iter().map(|c| c * c).sum::<f64>().sqrt() - 1.0).abs())
            });
            qn
        };
        let (d1, d2, d4) = (
            drift(m.tree.dt),
            drift(m.tree.dt / 2.0),
            drift(m.tree.dt / 4.0),
        );
        assert!(d2 < d1 / 8.0 && d4 < d2 / 8.0, "{d1:e} {d2:e} {d4:e}");
    }

    /// `chain3d` dropped on five points of its bodies settles: by 3 s it lies still but for the
    /// creep of regularized friction (the joints' gravity torques load the points tangentially),
    /// no point deeper than the whole weight on one point would press it, m g / k.
    #[test]
    fn chain3d_dropped_comes_to_rest_without_sinking() {
        let mut tree = chain3d();
        tree.dt = resting_step(9.81, DELTA);
        let mass: f64 = tree.bodies.iter().map(|b| b.mass).sum();
        let points = chain_points();
        let m = OnGround3d {
            tree,
            points,
            terrain: Terrain::Flat,
            contact: resting_contact(mass, 9.81, 3, DELTA, 0.9, SLIP),
        };
        let mut x0 = chain_state();
        x0[2] = 0.8;
        let nq = m.tree.nq();
        x0[nq..].iter_mut().for_each(|v| *v *= 0.3);
        let mut worst: f64 = f64::NEG_INFINITY;
        let x = run(&m, &x0, m.tree.dt, 3.0, |_, x| {
            worst = worst.max(m.penetration(x))
        });
        let bound = mass * 9.81 / m.contact.stiffness;
        let rest = m.penetration(&x);
        assert!(
            rest > 0.0 && rest < 0.5 * bound,
            "{rest:e} (bound {bound:e})"
        );
        assert!(worst < 5.0 * bound, "{worst:e}");
        assert!(
            m.tree.kinetic_energy(&x) < 1e-3,
            "{}",
            m.tree.kinetic_energy(&x)
        );
        assert!(speed(&m, &x) < 0.05, "{}", speed(&m, &x));
    }

    /// Spring energy of the normal law, ∫_d^∞ f_n(s, 0) ds (Simpson), for the energy balance.
    fn spring_energy(c: &Contact, d: f64) -> f64 {
        let top = 40.0 * c.smoothing;
        if d >= top {
            return 0.0;
        }
        let n = 2000;
        let h = (top - d) / n as f64;
        let mut acc = 0.0;
        for i in 0..=n {
            let w = if i == 0 || i == n {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            acc += w * c.normal_force(d + i as f64 * h, 0.0);
        }
        acc * h / 3.0
    }

    /// The box set sliding and spinning on its face: kinetic, gravitational and contact-spring
    /// energy together never rise (within RK4's error) and the box stops.
    #[test]
    fn a_sliding_box_loses_energy_and_stops() {
        let m = boxed(Terrain::Flat, 0.5);
        let rest_z = HALF[2] - 0.0017;
        let x0 = box_state(
            [0.0, 0.0, rest_z],
            [1.0, 0.0, 0.0, 0.0],
            [1.0, 0.5, 0.0],
            [0.0, 0.0, 2.0],
        );
        let total = |x: &[f64]| {
            m.tree.energy(x).unwrap()
                + m.point_states(x)
                    .iter()
                    .map(|(p, _)| spring_energy(&m.contact, p.z))
                    .sum::<f64>()
        };
        let mut prev = total(&x0);
        let mut worst_rise: f64 = 0.0;
        let x = run(&m, &x0, m.tree.dt, 1.0, |_, x| {
            let e = total(x);
            worst_rise = worst_rise.max(e - prev);
            prev = e;
        });
        // The first second loses 1.3 J; no step gains more than RK4's error.
        assert!(worst_rise < 1e-9, "{worst_rise:e}");
        assert!(total(&x) < total(&x0) - 1.0);
        assert!(speed(&m, &x) < 1e-9, "{:e}", speed(&m, &x));
    }

    /// With μ = 0 the ground pushes only along z: the falling, spinning box's horizontal momentum
    /// stays what it was through the bounces.
    #[test]
    fn frictionless_contact_keeps_horizontal_momentum() {
        let m = boxed(Terrain::Flat, 0.0);
        let x0 = box_state(
            [0.0, 0.0, 0.2],
            [0.9, 0.2, -0.3, 0.1],
            [0.7, -0.4, -1.0],
            [1.0, -2.0, 3.0],
        );
        let (p0, _) = m.tree.momentum(&x0);
        let mut worst: f64 = 0.0;
        let mut touched = false;
        let x = run(&m, &x0, m.tree.dt, 1.0, |_, x| {
            let (p, _) = m.tree.momentum(x);
            worst = worst.max(((p.x - p0.x).powi(2) + (p.y - p0.y).powi(2)).sqrt());
            touched |= m.penetration(x) > 0.0;
        });
        let (p, _) = m.tree.momentum(&x);
        assert!(touched);
        assert!(worst < 1e-12, "{worst:e}");
        // The vertical momentum did change: the ground stopped the fall.
        assert!((p.z - p0.z).abs() > 1.0);
    }

    /// On a 10° slope the box stays with μ = 0.9 > tan 10° and slides with μ = 0.1.
    #[test]
    fn a_box_on_a_slope_stays_with_high_friction_and_slides_with_low() {
        let deg: f64 = 10.0;
        let a = -deg.to_radians();
        let q = [(a / 2.0).cos(), 0.0, (a / 2.0).sin(), 0.0];
        for mu in [0.9, 0.1] {
            let m = boxed(Terrain::Slope { degrees: deg }, mu);
            // Centre at the rest height above the surface point (0, 0, 0), along the normal.
            let n = Vector3::new(-(deg.to_radians()).sin(), 0.0, (deg.to_radians()).cos());
            let c = n * (HALF[2] - 0.0017);
            let x0 = box_state([c.x, c.y, c.z], q, [0.0; 3], [0.0; 3]);
            let x = run(&m, &x0, m.tree.dt, 2.0, |_, _| {});
            let moved = Vector3::new(x[0] - x0[0], x[1] - x0[1], x[2] - x0[2]);
            let (s, cth) = (deg.to_radians().sin(), deg.to_radians().cos());
            let expect = 0.5 * 9.81 * (s - mu * cth) * 4.0;
            let creep = SLIP * ((s / cth) / mu).atanh();
            if mu > s / cth {
                // Held: regularized friction lets it creep at v_s atanh(tan θ / μ), no faster.
                assert!(speed(&m, &x) < 1.01 * creep, "{} vs {creep}", speed(&m, &x));
                assert!(moved.norm() < 2.0 * creep, "{}", moved.norm());
            } else {
                // Slides downhill (toward −x) at g (sin θ − μ cos θ).
                let v = 9.81 * (s - mu * cth) * 2.0;
                assert!(
                    moved.x < 0.0 && (speed(&m, &x) - v).abs() < 0.05 * v,
                    "{} vs {v}",
                    speed(&m, &x)
                );
                assert!(
                    (moved.norm() - expect).abs() < 0.05 * expect,
                    "{} vs {expect}",
                    moved.norm()
                );
            }
            assert!(m.penetration(&x) < DELTA / cth, "{}", m.penetration(&x));
        }
    }
}
