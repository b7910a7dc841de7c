//! # A value function for a SIMBICON walker: periodic TV-LQR around its gait
//!
//! SIMBICON ([`super::simbicon`]) is a state machine of PD targets, not an optimal controller:
//! it has no value function of its own, and linear Bellman combination needs one per component
//! (z = exp(−v/λ)). We give each walker the quadratic cost-to-go of the time-varying LQR that
//! tracks its own periodic gait (the LBC paper builds its trackers' value functions the same
//! way, §5.2 eq. 12): v(x) is small on the walker's limit cycle and grows with the distance from
//! it in the metric the gait's own linearized dynamics give, so a state the walker's motion
//! would not visit (a body pitched onto a hill, for the flat walker) costs it more.
//!
//! - **Coordinates** ([`reduced`]): the state without the pelvis' position along the ground,
//!   which the dynamics do not depend on (on level ground and on a constant incline, a shift
//!   along the ground is a symmetry): z = (pelvis height above the ground under it, torso
//!   angle, stance hip/knee/ankle, swing hip/knee/ankle, pelvis velocity x/y, their 7 rates,
//!   the ground's slope under the pelvis), 18 numbers ([`Z`]), the legs named by the stance
//!   side so that the left- and right-stance halves of a stride are one half stride. The slope
//!   is a state that does not move (the terrain's); it is what lets a walker's value tell the
//!   ground it was tuned for from another: its Jacobian column is the same flow map on the
//!   ground tilted by ± the difference step, and it carries no cost of its own (Q's entry 0),
//!   only through what the tilt does to the gait.
//! - **The gait** ([`GaitCycle::record`]): the walker from the SIMBICON applet's start on its
//!   terrain, after a warm-up, from a left heel strike to the right one, sampled every
//!   `knot_dt` (states, and the mean torques over each interval).
//! - **Linearization**: central differences of the `knot_dt` flow map (RK4 steps of the
//!   model's own dt, torques held) in z and in the torques, around each knot; the last knot's
//!   map ends across the heel strike, in the new stance side's coordinates (the mirror).
//! - **Riccati**: P_k = Q + A_kᵀP_{k+1}A_k − A_kᵀP_{k+1}B_k (R + B_kᵀP_{k+1}B_k)⁻¹ B_kᵀP_{k+1}A_k
//!   with Q, R cost rates times `knot_dt`, from each knot over a finite horizon of the gait
//!   repeated (P = 0 at its end): the tracking cost of the next `horizon` seconds. A finite
//!   horizon, because a slope other than the gait's is an offset tracking never removes, whose
//!   cost over an infinite horizon is unbounded (and LBC's components share one horizon).
//! - **Value** ([`GaitCycle::value`]): v(x) = min_k (z − z̄_k)ᵀ P_k (z − z̄_k), the knot with the
//!   lowest cost standing in for the gait's phase.
//!
//! ## References
//! - K. Yin, K. Loken, M. van de Panne, *SIMBICON: Simple Biped Locomotion Control*, SIGGRAPH
//!   2007.
//! - M. da Silva, F. Durand, J. Popović, *Linear Bellman Combination for Control of Character
//!   Animation*, SIGGRAPH 2009, §5.2 (tracking value functions), §6.2 (two SIMBICON walkers).

use super::simbicon::{applet_start, Gait, Simbicon};
use crate::physics::biped::{Biped, Side, DOF, TORQUES};
use crate::physics::ground::Terrain;
use crate::physics::{Dynamics, IntegratorKind, Model, Simulator};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Reduced coordinates per state ([`reduced`]).
pub const Z: usize = 18;

/// The joint coordinates (hip, knee, ankle) of the left and the right leg in q.
const LEFT: [usize; 3] = Biped::leg(Side::Left).joints();
const RIGHT: [usize; 3] = Biped::leg(Side::Right).joints();

/// The reduced coordinates of state `x` with the stance side `left_stance` (module docs).
pub fn reduced(b: &Biped, x: &[f64], left_stance: bool) -> [f64; Z] {
    let (st, sw) = if left_stance {
        (LEFT, RIGHT)
    } else {
        (RIGHT, LEFT)
    };
    let mut z = [0.0; Z];
    z[0] = x[1] - b.terrain.height_slope(x[0]).0;
    z[1] = x[2];
    for i in 0..3 {
        z[2 + i] = x[st[i]];
        z[5 + i] = x[sw[i]];
        z[11 + i] = x[DOF + st[i]];
        z[14 + i] = x[DOF + sw[i]];
    }
    z[8] = x[DOF];
    z[9] = x[DOF + 1];
    z[10] = x[DOF + 2];
    z[SLOPE] = crate::portable::atan(b.terrain.height_slope(x[0]).1);
    z
}

/// Index of the ground's slope under the pelvis in z (rad; constant on an incline).
pub const SLOPE: usize = 17;

/// The full state of reduced coordinates `z` (stance side `left_stance`) with the pelvis at
/// x = `px`: the inverse of [`reduced`] (the slope is the terrain's, not set by `z`).
pub fn full(b: &Biped, z: &[f64; Z], px: f64, left_stance: bool) -> Vec<f64> {
    let (st, sw) = if left_stance {
        (LEFT, RIGHT)
    } else {
        (RIGHT, LEFT)
    };
    let mut x = vec![0.0; 2 * DOF];
    x[0] = px;
    x[1] = z[0] + b.terrain.height_slope(px).0;
    x[2] = z[1];
    for i in 0..3 {
        x[st[i]] = z[2 + i];
        x[sw[i]] = z[5 + i];
        x[DOF + st[i]] = z[11 + i];
        x[DOF + sw[i]] = z[14 + i];
    }
    x[DOF] = z[8];
    x[DOF + 1] = z[9];
    x[DOF + 2] = z[10];
    x
}

/// Torques in the biped's order (left hip, knee, ankle, right …) from stance-first order.
fn torques_of(stance_first: &[f64; TORQUES], left_stance: bool) -> [f64; TORQUES] {
    if left_stance {
        *stance_first
    } else {
        let mut u = [0.0; TORQUES];
        u[..3].copy_from_slice(&stance_first[3..]);
        u[3..].copy_from_slice(&stance_first[..3]);
        u
    }
}

/// Cost rates of the tracking LQR (ours): Q = diag(1/s²) per second with a scale s per kind of
/// coordinate, R = (1/τ²) I per second.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GaitCost {
    /// Scale of the pelvis height (m).
    pub height_m: f64,
    /// Scale of every angle (rad).
    pub angle_rad: f64,
    /// Scale of the pelvis velocity (m/s).
    pub speed_m_s: f64,
    /// Scale of every angular rate (rad/s).
    pub rate_rad_s: f64,
    /// Torque scale τ (N·m).
    pub torque_n_m: f64,
}

impl GaitCost {
    /// Checks the scales.
    pub fn validate(&self) -> Result<(), String> {
        let v = [
            self.height_m,
            self.angle_rad,
            self.speed_m_s,
            self.rate_rad_s,
            self.torque_n_m,
        ];
        if v.iter().all(|s| s.is_finite() && *s > 0.0) {
            Ok(())
        } else {
            Err(format!("every scale must be finite and positive: {v:?}"))
        }
    }

    /// The diagonal of Q (per second).
    fn q(&self) -> [f64; Z] {
        let mut q = [0.0; Z];
        q[0] = self.height_m;
        for i in 1..8 {
            q[i] = self.angle_rad;
        }
        q[8] = self.speed_m_s;
        q[9] = self.speed_m_s;
        for i in 10..SLOPE {
            q[i] = self.rate_rad_s;
        }
        let mut w = q.map(|s| 1.0 / (s * s));
        // The slope carries no cost of its own (module docs).
        w[SLOPE] = 0.0;
        w
    }
}

/// Why a gait could not be given a value function.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GaitError {
    /// The walker fell before its gait could be recorded.
    #[error("the walker fell at t = {0:.3} s before its gait was recorded")]
    Fell(f64),
    /// No full half stride within the time allowed.
    #[error("no half stride (left heel strike to right) within {0:.1} s")]
    NoStride(f64),
    /// The state blew up.
    #[error("{0}")]
    BlowUp(String),
    /// The Riccati recursion from a knot failed (an indefinite or non-finite step).
    #[error("the Riccati recursion from knot {0} failed")]
    Riccati(usize),
    /// The gait's terrain is not level ground or a constant incline.
    #[error("a gait is recorded on level ground or a constant incline, not {0}")]
    Terrain(String),
}

/// A walker's half stride with its periodic LQR value Hessians (module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct GaitCycle {
    /// Seconds between knots.
    pub knot_dt: f64,
    /// Reference coordinates z̄_0..z̄_{K−1} (left stance).
    pub z: Vec<[f64; Z]>,
    /// Mean torques over each knot interval, stance leg first.
    pub u: Vec<[f64; TORQUES]>,
    /// The pelvis' x at each knot (where the linearization put the body).
    pub px: Vec<f64>,
    /// Value Hessians P_0..P_{K−1}.
    pub p: Vec<DMatrix<f64>>,
    /// Knots of the value's horizon.
    pub horizon: usize,
    /// Duration of the recorded half stride (s).
    pub half_period: f64,
    /// Mean forward speed over it (m/s).
    pub speed: f64,
}

/// Walks `gait` on `b`'s terrain from the applet's start at x = 0 for `warmup` seconds, then
/// records one half stride (left heel strike to right heel strike) every `knot_dt`: the states
/// and the mean stance-first torques of each interval; at most `warmup + 5` s.
fn record_half_stride(
    b: &Biped,
    gait: &Gait,
    warmup: f64,
    knot_dt: f64,
) -> Result<(Vec<Vec<f64>>, Vec<[f64; TORQUES]>, f64), GaitError> {
    let dt = b.default_dt();
    let per = (knot_dt / dt).round().max(1.0) as usize;
    let mut sim = Simulator::new(b.clone(), IntegratorKind::Rk4);
    let mut c = Simbicon::new(gait.clone(), 0);
    let mut x = applet_start(b, 0.0);
    let mut u = vec![0.0; TORQUES];
    let limit = warmup + 5.0;
    let (mut t, mut k) = (0.0, 0usize);
    let mut recording = false;
    let (mut states, mut torques) = (Vec::new(), Vec::new());
    let mut acc = [0.0; TORQUES];
    let mut t0 = 0.0;
    loop {
        let before = c.state;
        c.control(b, &x, dt, &mut u);
        // The machine entered state 0 (left heel strike) or state 2 (right heel strike).
        if c.state != before && t >= warmup {
            if c.state == 0 && !recording {
                recording = true;
                t0 = t;
                k = 0;
                states.push(x.clone());
            } else if c.state == 2 && recording {
                // Drop a partial last interval: the half stride is whole knots.
                return Ok((states, torques, t - t0));
            }
        }
        sim.step(&mut x, &u, dt);
        t += dt;
        crate::physics::check_finite("biped", (t / dt) as usize, t, &x)
            .map_err(|e| GaitError::BlowUp(e.to_string()))?;
        if b.fallen(&x) {
            return Err(GaitError::Fell(t));
        }
        if recording {
            for (a, v) in acc.iter_mut().zip(&u) {
                *a += v / per as f64;
            }
            k += 1;
            if k == per {
                torques.push(acc);
                acc = [0.0; TORQUES];
                states.push(x.clone());
                k = 0;
            }
        }
        if t > limit {
            return Err(GaitError::NoStride(limit));
        }
    }
}

impl GaitCycle {
    /// The gait of `gait` on `b`'s terrain (level or a constant incline) and its value
    /// Hessians under `cost` over `horizon_s` seconds (module docs): `warmup` seconds of walking
    /// first, knots every `knot_dt`.
    pub fn record(
        b: &Biped,
        gait: &Gait,
        cost: &GaitCost,
        warmup: f64,
        knot_dt: f64,
        horizon_s: f64,
    ) -> Result<Self, GaitError> {
        if matches!(b.terrain, Terrain::FlatThenHill { .. }) {
            return Err(GaitError::Terrain(format!("{:?}", b.terrain)));
        }
        let (states, torques, half) = record_half_stride(b, gait, warmup, knot_dt)?;
        // Whole knots: K intervals, states 0..K (the last one only closes the last interval).
        let kk = torques.len();
        if kk < 2 {
            return Err(GaitError::NoStride(warmup + 5.0));
        }
        let z: Vec<[f64; Z]> = states[..kk].iter().map(|x| reduced(b, x, true)).collect();
        let px: Vec<f64> = states[..kk].iter().map(|x| x[0]).collect();
        let u: Vec<[f64; TORQUES]> = torques;
        let (a, bm) = linearize(b, &z, &u, &px, knot_dt, STATE_STEP);
        let horizon = (horizon_s / knot_dt).round().max(1.0) as usize;
        let p = horizon_riccati(&a, &bm, cost, knot_dt, horizon)?;
        let speed = (states[kk][0] - states[0][0]) / (kk as f64 * knot_dt);
        Ok(Self {
            knot_dt,
            z,
            u,
            px,
            p,
            horizon,
            half_period: half,
            speed,
        })
    }

    /// v(x) with stance side `left_stance`, and the knot it was measured at (module docs).
    pub fn value(&self, b: &Biped, x: &[f64], left_stance: bool) -> (f64, usize) {
        let z = reduced(b, x, left_stance);
        let mut best = (f64::INFINITY, 0);
        let mut d = [0.0; Z];
        for (k, (zk, pk)) in self.z.iter().zip(&self.p).enumerate() {
            for i in 0..Z {
                d[i] = z[i] - zk[i];
            }
            let mut v = 0.0;
            for i in 0..Z {
                let mut row = 0.0;
                for j in 0..Z {
                    row += pk[(i, j)] * d[j];
                }
                v += d[i] * row;
            }
            if v < best.0 {
                best = (v, k);
            }
        }
        best
    }
}

/// Central-difference step in the reduced coordinates (the torques' is 1e-3 N·m per this).
const STATE_STEP: f64 = 1e-5;

/// The biped on a constant incline of `angle` rad (level ground at 0).
fn on_incline(b: &Biped, angle: f64) -> Biped {
    let terrain = if angle == 0.0 {
        Terrain::Flat
    } else {
        Terrain::Slope {
            degrees: angle.to_degrees(),
        }
    };
    Biped::new(terrain, b.contact)
}

/// Central-difference Jacobians (A_k, B_k) of the `knot_dt` flow map in reduced coordinates
/// around each knot (module docs); the last knot's map ends in the right-stance coordinates.
/// The slope's column comes from the same map on the ground tilted by ±`eps_z` rad.
fn linearize(
    b: &Biped,
    z: &[[f64; Z]],
    u: &[[f64; TORQUES]],
    px: &[f64],
    knot_dt: f64,
    eps_z: f64,
) -> (Vec<DMatrix<f64>>, Vec<DMatrix<f64>>) {
    use rayon::prelude::*;
    let kk = z.len();
    let dt = b.default_dt();
    let per = (knot_dt / dt).round().max(1.0) as usize;
    let flow = |body: &Biped, zk: &[f64; Z], uk: &[f64; TORQUES], p: f64, last: bool| {
        let mut sim = Simulator::new(body.clone(), IntegratorKind::Rk4);
        let mut x = full(body, zk, p, true);
        let tq = torques_of(uk, true);
        for _ in 0..per {
            sim.step(&mut x, &tq, dt);
        }
        reduced(body, &x, !last)
    };
    let eps_u = 1e-3 * eps_z / STATE_STEP;
    (0..kk)
        .into_par_iter()
        .map(|k| {
            let last = k + 1 == kk;
            let mut a = DMatrix::zeros(Z, Z);
            let mut bm = DMatrix::zeros(Z, TORQUES);
            for j in 0..Z {
                let (fp, fm) = if j == SLOPE {
                    let angle = z[k][SLOPE];
                    let (bp, bn) = (on_incline(b, angle + eps_z), on_incline(b, angle - eps_z));
                    (
                        flow(&bp, &z[k], &u[k], px[k], last),
                        flow(&bn, &z[k], &u[k], px[k], last),
                    )
                } else {
                    let (mut zp, mut zm) = (z[k], z[k]);
                    zp[j] += eps_z;
                    zm[j] -= eps_z;
                    (
                        flow(b, &zp, &u[k], px[k], last),
                        flow(b, &zm, &u[k], px[k], last),
                    )
                };
                for i in 0..Z {
                    a[(i, j)] = (fp[i] - fm[i]) / (2.0 * eps_z);
                }
            }
            for j in 0..TORQUES {
                let (mut up, mut um) = (u[k], u[k]);
                up[j] += eps_u;
                um[j] -= eps_u;
                let (fp, fm) = (
                    flow(b, &z[k], &up, px[k], last),
                    flow(b, &z[k], &um, px[k], last),
                );
                for i in 0..Z {
                    bm[(i, j)] = (fp[i] - fm[i]) / (2.0 * eps_u);
                }
            }
            (a, bm)
        })
        .unzip()
}

/// The value Hessians P_0..P_{K−1}: for each knot k, the Riccati recursion backward over the
/// `horizon` knots that follow it (the half stride repeated, its last knot's map mirrored into
/// the next), from P = 0 (module docs).
fn horizon_riccati(
    a: &[DMatrix<f64>],
    bm: &[DMatrix<f64>],
    cost: &GaitCost,
    knot_dt: f64,
    horizon: usize,
) -> Result<Vec<DMatrix<f64>>, GaitError> {
    let kk = a.len();
    let q = DMatrix::from_diagonal(&DVector::from_iterator(
        Z,
        cost.q().iter().map(|v| v * knot_dt),
    ));
    let r = DMatrix::identity(TORQUES, TORQUES) * (knot_dt / cost.torque_n_m.powi(2));
    (0..kk)
        .map(|k| {
            let mut p = DMatrix::zeros(Z, Z);
            for j in (k..k + horizon).rev() {
                let (aj, bj) = (&a[j % kk], &bm[j % kk]);
                let pa = &p * aj;
                let pb = &p * bj;
                let s = &r + bj.transpose() * &pb;
                let chol = s.cholesky().ok_or(GaitError::Riccati(k))?;
                let gain = chol.solve(&(pb.transpose() * aj));
                let next = &q + aj.transpose() * &pa - pa.transpose() * bj * &gain;
                p = (&next + next.transpose()) * 0.5;
            }
            if p.iter().all(|v| v.is_finite()) {
                Ok(p)
            } else {
                Err(GaitError::Riccati(k))
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::ground::{Contact, Terrain};

    fn cost() -> GaitCost {
        GaitCost {
            height_m: 0.05,
            angle_rad: 0.1,
            speed_m_s: 0.5,
            rate_rad_s: 1.0,
            torque_n_m: 100.0,
        }
    }

    #[test]
    fn reduced_coordinates_round_trip_and_mirror_the_legs() {
        let b = Biped::new(Terrain::Slope { degrees: 10.0 }, Contact::default());
        let x = applet_start(&b, 0.3);
        for left in [true, false] {
            let z = reduced(&b, &x, left);
            let back = full(&b, &z, x[0], left);
            for (p, q) in back.iter().zip(&x) {
                assert!((p - q).abs() < 1e-12, "{back:?} vs {x:?}");
            }
        }
        // Right stance names the right leg first: the mirror of the left-stance coordinates.
        let (l, r) = (reduced(&b, &x, true), reduced(&b, &x, false));
        assert_eq!(&l[2..5], &r[5..8]);
        assert_eq!(&l[11..14], &r[14..17]);
        assert!((l[SLOPE] - 10f64.to_radians()).abs() < 1e-12);
        // Along the incline the coordinates do not change (a symmetry of the dynamics).
        let mut shifted = x.clone();
        let (h0, _) = b.terrain.height_slope(x[0]);
        let (h1, _) = b.terrain.height_slope(x[0] + 0.7);
        shifted[0] += 0.7;
        shifted[1] += h1 - h0;
        let zs = reduced(&b, &shifted, true);
        for (p, q) in zs.iter().zip(&l) {
            assert!((p - q).abs() < 1e-12);
        }
    }

    /// The applet walk's half stride on level ground: periodic (its end, in the next stance's
    /// coordinates, near its start), the value Hessians symmetric and positive semi-definite,
    /// v small on the cycle and larger off it; its Jacobians agree at two step sizes (the
    /// contact is smooth enough to linearize).
    #[test]
    fn the_flat_walk_has_a_periodic_gait_with_a_positive_value() {
        let b = Biped::default();
        let cyc = GaitCycle::record(&b, &Gait::walk(), &cost(), 4.0, 0.01, 1.0).unwrap();
        assert!(cyc.z.len() >= 20, "{} knots", cyc.z.len());
        assert!(cyc.speed > 0.5, "{} m/s", cyc.speed);
        for p in &cyc.p {
            assert!((p - p.transpose()).norm() <= 1e-9 * p.norm());
            let eig = p.clone().symmetric_eigenvalues();
            assert!(eig.min() > -1e-8 * eig.max(), "{eig}");
        }
        // On the cycle (a knot's own state) v is 0; a pitched torso costs more.
        let x = full(&b, &cyc.z[5], cyc.px[5], true);
        let (v0, k0) = cyc.value(&b, &x, true);
        assert_eq!((v0, k0), (0.0, 5));
        let mut pitched = x.clone();
        pitched[2] += 0.2;
        assert!(cyc.value(&b, &pitched, true).0 > 1e-3);
        // Jacobians at two step sizes ten times apart agree to 1% (measured 0.4%): the flow map
        // is smooth where it is linearized (the contact switches on over 0.5 mm).
        let few = 3;
        let (a1, b1) = linearize(&b, &cyc.z[..few], &cyc.u[..few], &cyc.px[..few], 0.01, 1e-5);
        let (a2, b2) = linearize(&b, &cyc.z[..few], &cyc.u[..few], &cyc.px[..few], 0.01, 1e-4);
        for k in 0..few {
            let da = (&a1[k] - &a2[k]).norm() / a1[k].norm();
            let db = (&b1[k] - &b2[k]).norm() / b1[k].norm();
            assert!(da < 1e-2 && db < 1e-2, "knot {k}: {da} {db}");
        }
    }
}
