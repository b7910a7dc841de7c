//! `lbc_stepping`'s result tables as typed rows: the job writes them through
//! [`table_of`](crate::experiment::rows::table_of), the figures read the job's tables and the
//! report the CSV files back through the same structs.

use crate::physics::biped::DOF;

crate::result_rows! {
    /// One row of `targets.csv`: one controller's step toward one desired length, on the
    /// simulator.
    pub struct StepRow {
        /// The desired step length (m).
        desired_length_m: f64 = "desired_length_m",
        /// The controller (`lbc`, `naive`, `short`, `long`, `direct`).
        method: String = "method",
        /// The step length reached (m).
        reached_length_m: f64 = "reached_length_m",
        /// 1 when the body fell, else 0.
        fell: f64 = "fell",
        /// The step's control effort.
        effort: f64 = "effort",
        /// Wall time of the run (s).
        seconds: f64 = "seconds",
        /// 1 when the swing heel landed and the body stood, else 0.
        landed: f64 = "landed",
        /// Reached minus desired length (m).
        length_error_m: f64 = "length_error_m",
        /// The projected weight of the short example.
        weight_short: f64 = "weight_short",
        /// The projected weight of the long example.
        weight_long: f64 = "weight_long",
    }
}

crate::result_rows! {
    /// One row of `components.csv`: one DDP example step at one scale of the average term.
    pub struct ComponentRow {
        /// The example (`short` or `long`).
        component: String = "component",
        /// Its target step length (m).
        target_length_m: f64 = "target_length_m",
        /// The length DDP's own map reaches (m; as `targets.csv` measures it).
        reached_length_m: f64 = "reached_length_m",
        /// DDP's iterations.
        iterations: i64 = "iterations",
        /// DDP's final cost.
        cost: f64 = "cost",
        /// Why DDP stopped.
        termination: String = "termination",
        /// Wall time of the solve and its tracker (s).
        seconds: f64 = "seconds",
        /// The scale of the average-trajectory term it was optimized with.
        average_scale: f64 = "average_scale",
    }
}

crate::result_rows! {
    /// One row of `average_effect.csv`: LBC or the naive blend at one desired length, with
    /// the examples optimized at one scale of the average-trajectory term.
    pub struct AverageRow {
        /// The scale of the average-trajectory term.
        average_scale: f64 = "average_scale",
        /// The desired step length (m).
        desired_length_m: f64 = "desired_length_m",
        /// The controller (`lbc` or `naive`).
        method: String = "method",
        /// The step length reached (m).
        reached_length_m: f64 = "reached_length_m",
        /// 1 when the body fell, else 0.
        fell: f64 = "fell",
        /// The step's control effort.
        effort: f64 = "effort",
        /// 1 when the swing heel landed and the body stood, else 0.
        landed: f64 = "landed",
    }
}

crate::result_rows! {
    /// One row of `weights.csv`: LBC's weight of the short example at one knot of one step.
    pub struct WeightRow {
        /// The desired step length (m).
        desired_length_m: f64 = "desired_length_m",
        /// Time in the step (s).
        t_s: f64 = "t",
        /// α_short.
        alpha_short: f64 = "alpha_short",
    }
}

crate::result_rows! {
    /// One row of `walk.csv`: one step of the walk over gaps.
    pub struct WalkStepRow {
        /// The step's number (from 1).
        step: i64 = "step",
        /// The stance heel at the step's start (m).
        stance_heel_m: f64 = "stance_heel_m",
        /// The foothold the step aims at (m).
        foothold_m: f64 = "foothold_m",
        /// The desired length, from the stance heel to the foothold (m).
        desired_length_m: f64 = "desired_length_m",
        /// The length reached (m).
        reached_length_m: f64 = "reached_length_m",
        /// Where the swing heel landed (m).
        landing_heel_m: f64 = "landing_heel_m",
        /// Where the swing toe landed (m).
        landing_toe_m: f64 = "landing_toe_m",
        /// The start of the gap before the foothold (m).
        gap_start_m: f64 = "gap_start_m",
        /// Its end (m).
        gap_end_m: f64 = "gap_end_m",
        /// 1 when the landing sole overlaps a gap, else 0.
        in_gap: f64 = "in_gap",
        /// 1 when the body fell, else 0.
        fell: f64 = "fell",
        /// LBC's projected weight of the short example, normalized.
        weight_short: f64 = "weight_short",
    }
}

crate::result_rows! {
    /// One row of `motion.csv`: the walk's body at one knot, in the world frame.
    pub struct MotionRow {
        /// The step's number (from 1).
        step: i64 = "step",
        /// Time since the walk's start (s).
        t_s: f64 = "t",
        /// α_short (NaN after the step's last knot).
        alpha_short: f64 = "alpha_short",
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
    /// Step `step` at time `t_s` with weight `alpha_short` in the biped's coordinates `q` (the
    /// first [`DOF`] of a state).
    pub fn at(step: i64, t_s: f64, alpha_short: f64, q: &[f64]) -> Self {
        Self {
            step,
            t_s,
            alpha_short,
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
