//! # SIMBICON: a state machine of PD targets for the planar biped (Yin, Loken, van de Panne 2007)
//!
//! The controller of SIMBICON's 2-D walker, on [`crate::physics::biped::Biped`]:
//!
//! - a four-state machine per stride: state 0 (left stance) holds for `duration` seconds, state 1
//!   (left stance) until the swing (right) heel strikes, states 2 and 3 the mirror (right
//!   stance);
//! - in each state PD targets for the swing hip, swing knee and ankle, stance knee and ankle and
//!   the torso; knees and ankles are tracked in their joints, the **torso and the swing hip in
//!   the world frame** (the swing thigh's absolute angle), and the stance hip takes the torque
//!   that makes the torso's: τ_stance_hip = −τ_torso − τ_swing_hip;
//! - **balance feedback** on the swing hip's target: θ_d = θ_d0 + c_d·d + c_v·v, d the pelvis'
//!   horizontal distance ahead of the stance heel and v its horizontal velocity.
//!
//! Angles are SIMBICON's: the torso's from upright (positive leaning back), a hip's from the leg
//! straight down along the torso (positive forward), a knee's negative when bent, an ankle's
//! from the foot at right angles to the shin (positive toe up). [`Gait::walk`] is the applet's
//! flat-ground walk (its published controller source: kp = 300, kd = 30 for every joint, torques
//! within ±1000 N·m, swing-hip targets within [−0.4, 1.6] rad, and the targets below).

use crate::physics::biped::{point, Biped, Side, DOF, TORQUES};
use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_PI_2, PI};

/// The PD targets and feedback gains of one state (the stance side's mirror uses the same).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StateTargets {
    /// Seconds in the state; `None`: until the swing heel strikes.
    pub duration: Option<f64>,
    /// Balance gain on the pelvis' distance ahead of the stance heel (rad/m).
    pub c_d: f64,
    /// Balance gain on the pelvis' horizontal velocity (rad·s/m).
    pub c_v: f64,
    /// Torso angle from upright, world frame (rad; positive leaning back).
    pub torso: f64,
    /// Swing thigh's angle from straight down, world frame (rad; positive forward).
    pub swing_hip: f64,
    /// Swing knee (rad; negative bent).
    pub swing_knee: f64,
    /// Swing ankle (rad; positive toe up).
    pub swing_ankle: f64,
    /// Stance knee (rad).
    pub stance_knee: f64,
    /// Stance ankle (rad).
    pub stance_ankle: f64,
}

/// A SIMBICON gait: the two states of a half stride (mirrored for the other) and the PD law.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Gait {
    /// States 0 and 1 (left stance); 2 and 3 are their mirror.
    pub states: [StateTargets; 2],
    /// Proportional gain of every joint (N·m/rad).
    pub kp: f64,
    /// Derivative gain of every joint (N·m·s/rad).
    pub kd: f64,
    /// Torque bound of every joint (N·m).
    pub torque_limit: f64,
    /// Bounds of the swing hip's target (rad).
    pub hip_target: (f64, f64),
}

impl Gait {
    /// The SIMBICON applet's flat-ground walk (its controller source, "Table 1" of the paper
    /// per its comments): state 0 for 0.3 s with c_v = 0.2, swing hip 0.4, swing knee −1.1,
    /// stance knee −0.05; state 1 until heel strike with c_d = 2.2, swing hip −0.7, swing knee
    /// −0.05, stance knee −0.1; ankles 0.2 and torso 0 throughout.
    pub fn walk() -> Self {
        Self {
            states: [
                StateTargets {
                    duration: Some(0.3),
                    c_d: 0.0,
                    c_v: 0.2,
                    torso: 0.0,
                    swing_hip: 0.4,
                    swing_knee: -1.1,
                    swing_ankle: 0.2,
                    stance_knee: -0.05,
                    stance_ankle: 0.2,
                },
                StateTargets {
                    duration: None,
                    c_d: 2.2,
                    c_v: 0.0,
                    torso: 0.0,
                    swing_hip: -0.7,
                    swing_knee: -0.05,
                    swing_ankle: 0.2,
                    stance_knee: -0.1,
                    stance_ankle: 0.2,
                },
            ],
            kp: 300.0,
            kd: 30.0,
            torque_limit: 1000.0,
            hip_target: (-0.4, 1.6),
        }
    }
}

/// The SIMBICON angles of a state `x` of the biped: (torso from upright, [left hip, knee,
/// ankle], [right hip, knee, ankle]) and their rates, in the same layout.
pub fn simbicon_angles(x: &[f64]) -> ([f64; 7], [f64; 7]) {
    let q = |i: usize| x[i];
    let r = |i: usize| x[DOF + i];
    let [lh, lk, la] = Biped::leg(Side::Left).joints();
    let [rh, rk, ra] = Biped::leg(Side::Right).joints();
    let angles = [
        q(2) - FRAC_PI_2,
        q(lh) + PI,
        q(lk),
        q(la) - FRAC_PI_2,
        q(rh) + PI,
        q(rk),
        q(ra) - FRAC_PI_2,
    ];
    let rates = [r(2), r(lh), r(lk), r(la), r(rh), r(rk), r(ra)];
    (angles, rates)
}

/// The controller's state: the machine's state (0-3), the time in it, the strides counted.
#[derive(Debug, Clone, PartialEq)]
pub struct Simbicon {
    /// The gait.
    pub gait: Gait,
    /// State of the machine, 0-3 (0, 1: left stance).
    pub state: usize,
    /// Seconds spent in it.
    pub time_in_state: f64,
    /// Heel strikes so far (steps taken).
    pub steps: usize,
}

impl Simbicon {
    /// A controller starting in `state` (0-3).
    pub fn new(gait: Gait, state: usize) -> Self {
        Self {
            gait,
            state: state % 4,
            time_in_state: 0.0,
            steps: 0,
        }
    }

    /// Whether the left leg is the stance leg now.
    pub fn left_stance(&self) -> bool {
        self.state < 2
    }

    /// Advances the machine by `dt` seconds at state `x` (time-outs and heel strikes) and writes
    /// the six joint torques into `u`.
    pub fn control(&mut self, biped: &Biped, x: &[f64], dt: f64, u: &mut [f64]) {
        self.advance(biped, x, dt);
        self.torques(biped, x, u);
    }

    fn advance(&mut self, biped: &Biped, x: &[f64], dt: f64) {
        self.time_in_state += dt;
        let targets = self.gait.states[self.state % 2];
        let next = match targets.duration {
            Some(d) => self.time_in_state >= d,
            None => {
                // The swing heel strikes when it reaches the ground.
                let heel = if self.left_stance() { 2 } else { 0 };
                let p = biped.contact_point(&x[..DOF], heel);
                p[1] <= biped.terrain.height_slope(p[0]).0
            }
        };
        if next {
            if targets.duration.is_none() {
                self.steps += 1;
            }
            self.state = (self.state + 1) % 4;
            self.time_in_state = 0.0;
        }
    }

    fn torques(&self, biped: &Biped, x: &[f64], u: &mut [f64]) {
        let g = &self.gait;
        let t = g.states[self.state % 2];
        let (a, r) = simbicon_angles(x);
        let left = self.left_stance();
        // Indices into the SIMBICON angle arrays: 1-3 left, 4-6 right.
        let (st, sw) = if left { (1, 4) } else { (4, 1) };
        let pd = |target: f64, angle: f64, rate: f64| g.kp * (target - angle) - g.kd * rate;
        let heel = if left {
            point::LEFT_HEEL
        } else {
            point::RIGHT_HEEL
        };
        let heel_x = biped.contact_point(&x[..DOF], heel)[0];
        let (d, v) = (x[0] - heel_x, x[DOF]);
        let hip_target =
            (t.swing_hip + t.c_d * d + t.c_v * v).clamp(g.hip_target.0, g.hip_target.1);
        let torso = pd(t.torso, a[0], r[0]);
        // The swing thigh in the world frame: its hip angle plus the torso's.
        let swing_hip = pd(hip_target, a[sw] + a[0], r[sw] + r[0]);
        let swing_knee = pd(t.swing_knee, a[sw + 1], r[sw + 1]);
        let swing_ankle = pd(t.swing_ankle, a[sw + 2], r[sw + 2]);
        let stance_knee = pd(t.stance_knee, a[st + 1], r[st + 1]);
        let stance_ankle = pd(t.stance_ankle, a[st + 2], r[st + 2]);
        let stance_hip = -torso - swing_hip;
        // Torques in the biped's order: left hip, knee, ankle, right hip, knee, ankle.
        let (stance, swing) = (
            [stance_hip, stance_knee, stance_ankle],
            [swing_hip, swing_knee, swing_ankle],
        );
        let (l, rr) = if left {
            (stance, swing)
        } else {
            (swing, stance)
        };
        let lim = g.torque_limit;
        for (k, v) in l.iter().chain(&rr).enumerate().take(TORQUES) {
            u[k] = v.clamp(-lim, lim);
        }
    }
}

/// The SIMBICON applet's start, mid-stride just after a left heel strike (its published initial
/// state, in this model's coordinates: the pelvis at x = `x`, its height lowered so that the left
/// foot's lowest point touches the ground).
pub fn applet_start(biped: &Biped, x: f64) -> Vec<f64> {
    let mut s = vec![0.0; 2 * DOF];
    let [lh, lk, la] = Biped::leg(Side::Left).joints();
    let [rh, rk, ra] = Biped::leg(Side::Right).joints();
    s[0] = x;
    s[2] = FRAC_PI_2 + 0.051;
    s[lh] = -PI + 0.298;
    s[lk] = -0.601;
    s[la] = FRAC_PI_2 + 0.241;
    s[rh] = -PI - 0.221;
    s[rk] = -0.217;
    s[ra] = FRAC_PI_2 + 0.360;
    let rates = [
        (0, 0.98),
        (1, -0.229),
        (2, 0.276),
        (lh, -3.268),
        (lk, 3.167),
        (la, 3.532),
        (rh, -1.430),
        (rk, 0.086),
        (ra, 0.697),
    ];
    for (i, v) in rates {
        s[DOF + i] = v;
    }
    let pts = biped.contact_points(&s[..DOF]);
    let gap = pts[..2]
        .iter()
        .map(|p| p[1] - biped.terrain.height_slope(p[0]).0)
        .fold(f64::INFINITY, f64::min);
    s[1] = -gap;
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{IntegratorKind, Model, Simulator};

    /// The published flat-ground walk from the applet's start: at least 20 steps in 20 s
    /// without falling, moving forward.
    #[test]
    fn the_simbicon_walk_takes_twenty_steps_without_falling() {
        let b = Biped::default();
        let x0 = applet_start(&b, 0.0);
        let dt = b.default_dt();
        let mut c = Simbicon::new(Gait::walk(), 0);
        let mut sim = Simulator::new(b.clone(), IntegratorKind::Rk4);
        let mut fell_at = None;
        let mut last = x0.clone();
        let steps = (20.0 / dt) as usize;
        sim.rollout(
            &x0,
            dt,
            steps,
            |_, _, x, u| c.control(&b, x, dt, u),
            |k, _, x| {
                if fell_at.is_none() && b.fallen(x) {
                    fell_at = Some(k as f64 * dt);
                }
                last.copy_from_slice(x);
            },
        )
        .expect("finite");
        assert_eq!(fell_at, None, "fell; {} steps", c.steps);
        assert!(c.steps >= 20, "{} steps", c.steps);
        assert!(last[0] > 5.0, "walked {} m", last[0]);
    }

    /// The SIMBICON angles of a standing pose: torso and knees 0, hips leaning back and ankles
    /// forward by the stance lean (feet flat), no motion.
    #[test]
    fn standing_in_simbicon_angles() {
        let b = Biped::default();
        let lean = b.stance_lean();
        let (a, r) = simbicon_angles(&b.standing(0.0, 0.0));
        let want = [0.0, -lean, 0.0, lean, -lean, 0.0, lean];
        for (v, w) in a.iter().zip(want) {
            assert!((v - w).abs() < 1e-12, "{a:?}");
        }
        assert!(r.iter().all(|v| *v == 0.0));
    }
}
