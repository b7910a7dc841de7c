//! `lbc_walking`'s result tables as typed rows: the job writes them through
//! [`table_of`](crate::experiment::rows::table_of), the figures read the job's tables and the
//! report the CSV files back through the same structs.

use crate::physics::biped::DOF;

crate::result_rows! {
    /// One row of `walks.csv`: one controller's walk on one terrain.
    pub struct WalkRow {
        /// The terrain's name (`flat`, `incline`, `flat_then_hill`).
        terrain: String = "terrain",
        /// The controller (`flat`, `hill`, `naive`, `lbc`).
        controller: String = "controller",
        /// Pelvis x advance (m) up to the end or the fall.
        distance_m: f64 = "distance_m",
        /// 1 when it fell, else 0.
        fell: i64 = "fell",
        /// Distance over the seconds walked (m/s).
        mean_speed_m_s: f64 = "mean_speed_m_s",
        /// Heel strikes of the (first) state machine.
        steps: i64 = "steps",
        /// When it fell (s; NaN when it did not).
        fell_at_s: f64 = "fell_at_s",
        /// LBC's temperature (NaN for the other controllers).
        lambda: f64 = "lambda",
    }
}

crate::result_rows! {
    /// One row of `lambda_sweep.csv`: LBC at one temperature on one terrain.
    pub struct SweepRow {
        /// LBC's temperature λ.
        lambda: f64 = "lambda",
        /// The terrain's name.
        terrain: String = "terrain",
        /// Pelvis x advance (m) up to the end or the fall.
        distance_m: f64 = "distance_m",
        /// 1 when it fell, else 0.
        fell: i64 = "fell",
        /// α_hill's mean on the track's flat part (NaN off the flat-then-hill track).
        alpha_hill_flat_part: f64 = "alpha_hill_flat_part",
        /// α_hill's mean on the track's hill part (likewise).
        alpha_hill_hill_part: f64 = "alpha_hill_hill_part",
    }
}

crate::result_rows! {
    /// One row of `search.csv`: one hill walker of the search grid on the incline.
    pub struct SearchRow {
        /// Its torso target's offset from the flat walker's (rad).
        torso_offset: f64 = "torso_offset",
        /// Its swing hip target's offset from the flat walker's (rad).
        hip_offset: f64 = "hip_offset",
        /// Distance up the incline (m).
        distance_m: f64 = "distance_m",
        /// 1 when it fell, else 0.
        fell: i64 = "fell",
        /// 1 for the walker chosen as the hill walker, else 0.
        chosen: i64 = "chosen",
    }
}

crate::result_rows! {
    /// One row of `weights.csv`: LBC's weights and values at one sample of one terrain's walk.
    pub struct WeightRow {
        /// The terrain's name.
        terrain: String = "terrain",
        /// Time (s).
        t_s: f64 = "t",
        /// Pelvis x (m).
        x_m: f64 = "x",
        /// The ground's slope under the pelvis (degrees).
        slope_deg: f64 = "slope_deg",
        /// α_flat = 1 − α_hill.
        alpha_flat: f64 = "alpha_flat",
        /// α_hill.
        alpha_hill: f64 = "alpha_hill",
        /// The flat walker's value.
        v_flat: f64 = "v_flat",
        /// The hill walker's value.
        v_hill: f64 = "v_hill",
    }
}

crate::result_rows! {
    /// One row of `motion.csv`: LBC's or the flat walker's body at one sample of the
    /// flat-then-hill walk.
    pub struct MotionRow {
        /// The controller (`lbc` or `flat`).
        controller: String = "controller",
        /// Time (s).
        t_s: f64 = "t",
        /// α_hill.
        alpha_hill: f64 = "alpha_hill",
        /// Pelvis x (m).
        q0: f64 = "q0",
        /// Pelvis y (m).
        q1: f64 = "q1",
        /// Torso angle (rad).
        q2: f64 = "q2",
        /// Left hip (rad).
        q3: f64 = "q3",
        /// Left knee (rad).
        q4: f64 = "q4",
        /// Left ankle (rad).
        q5: f64 = "q5",
        /// Right hip (rad).
        q6: f64 = "q6",
        /// Right knee (rad).
        q7: f64 = "q7",
        /// Right ankle (rad).
        q8: f64 = "q8",
    }
}

impl MotionRow {
    /// `controller` at time `t_s` with weight `alpha_hill` in the biped's coordinates `q`
    /// (the first [`DOF`] of a state).
    pub fn at(controller: &str, t_s: f64, alpha_hill: f64, q: &[f64]) -> Self {
        Self {
            controller: controller.to_string(),
            t_s,
            alpha_hill,
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

    /// The biped's coordinates, in the state's order.
    pub fn q(&self) -> [f64; DOF] {
        [
            self.q0, self.q1, self.q2, self.q3, self.q4, self.q5, self.q6, self.q7, self.q8,
        ]
    }
}
