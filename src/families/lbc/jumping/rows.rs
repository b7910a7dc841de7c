//! `lbc_jumping`'s result tables as typed rows: the job writes them through
//! [`table_of`](crate::experiment::rows::table_of), the figures read the job's tables and the
//! report the CSV files back through the same structs.

use crate::physics::jumper::DOF;

crate::result_rows! {
    /// One row of `jumps.csv`: one take-off controller at one desired jump, run on the
    /// simulator through its take-off and the desired jump's landing tracker.
    pub struct JumpRow {
        /// The desired jump's height (m; its PD push's strength is `desired_strength`).
        desired_height_m: f64 = "desired",
        /// The take-off controller ([`super::job::METHODS`]).
        method: String = "method",
        /// The take-off state's distance from the desired jump's, in the metric's units.
        takeoff_error: f64 = "takeoff_error",
        /// 1 when the body ended standing on its foot, else 0.
        landed: f64 = "landed",
        /// The desired jump's PD push strength (the spec's `desired`).
        desired_strength: f64 = "desired_strength",
        /// The jump's height (m).
        height_m: f64 = "height_m",
        /// 1 when the body fell at any time, else 0.
        fell: f64 = "fell",
        /// ½∫uᵀRu dt over the take-off.
        effort: f64 = "effort",
        /// The projected weight of the low example.
        weight_low: f64 = "weight_low",
        /// The projected weight of the high example.
        weight_high: f64 = "weight_high",
        /// The take-off's centre-of-mass velocity error (m/s).
        speed_error_m_s: f64 = "speed_error_m_s",
        /// Wall time of the run (s).
        seconds: f64 = "seconds",
    }
}

crate::result_rows! {
    /// One row of `components.csv`: one take-off example by DDP.
    pub struct JumpComponentRow {
        /// The example (`low` or `high`).
        component: String = "component",
        /// Its PD push's strength.
        strength: f64 = "strength",
        /// Its jump's height (m).
        height_m: f64 = "height_m",
        /// Its tracker alone on the simulator against its own target.
        takeoff_error: f64 = "takeoff_error",
        /// DDP's iterations.
        iterations: i64 = "iterations",
        /// DDP's final cost.
        cost: f64 = "cost",
        /// Why DDP stopped.
        termination: String = "termination",
        /// Wall time of the solve and its tracker (s).
        seconds: f64 = "seconds",
    }
}

crate::result_rows! {
    /// One row of `weights.csv`: LBC's weight of the low example at one time of one take-off.
    pub struct WeightRow {
        /// The desired jump's height (m).
        desired_height_m: f64 = "desired",
        /// Time from the crouch (s).
        t_s: f64 = "t",
        /// α_low.
        alpha_low: f64 = "alpha_low",
    }
}

crate::result_rows! {
    /// One row of `motion.csv`: one take-off controller's body at one knot.
    pub struct MotionRow {
        /// The take-off controller.
        method: String = "method",
        /// Time from the crouch (s).
        t_s: f64 = "t",
        /// α_low (NaN after the take-off's last knot).
        alpha_low: f64 = "alpha_low",
        /// Hip x (m).
        q0: f64 = "q0",
        /// Hip y (m).
        q1: f64 = "q1",
        /// Torso angle (rad).
        q2: f64 = "q2",
        /// Neck (rad).
        q3: f64 = "q3",
        /// Shoulder (rad).
        q4: f64 = "q4",
        /// Elbow (rad).
        q5: f64 = "q5",
        /// Hip (rad).
        q6: f64 = "q6",
        /// Knee (rad).
        q7: f64 = "q7",
        /// Ankle (rad).
        q8: f64 = "q8",
    }
}

impl MotionRow {
    /// `method` at time `t_s` with weight `alpha_low` in the jumper's coordinates `q` (the
    /// first [`DOF`] of a state).
    pub fn at(method: &str, t_s: f64, alpha_low: f64, q: &[f64]) -> Self {
        Self {
            method: method.to_string(),
            t_s,
            alpha_low,
            q0: q[0],
            q1: q[1],
            q2: q[2],
            q3: q[3],
            q4: q[4],
            q5: q[5],
            q6: q[6],
            q7: q[7],
            q8: q[8],
        }
    }

    /// The jumper's coordinates, in the state's order.
    pub fn q(&self) -> [f64; DOF] {
        [
            self.q0, self.q1, self.q2, self.q3, self.q4, self.q5, self.q6, self.q7, self.q8,
        ]
    }
}
