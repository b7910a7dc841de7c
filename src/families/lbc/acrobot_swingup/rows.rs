//! The rows of the tables the report and the figures read back: each declared once, the job
//! writing them through [`table_of`](crate::experiment::rows::table_of) and the readers
//! picking fields by name. Distances to the handstand are state-space norms with angles
//! wrapped ([`distance_to_handstand`](super::distance_to_handstand)); angles in rad unless the
//! field says degrees.

crate::result_rows! {
    /// One row of `final.csv`: one policy from the test start.
    pub struct FinalRow {
        /// The policy (`tracker1`, `tracker2`, `naive`, `lbc`, `naive_sum`).
        policy: String = "policy",
        /// Final distance to the handstand (infinite when the closed loop diverged).
        final_distance: f64 = "final_distance",
        /// Control cost ½∫Ru² (N²·m²·s).
        control_cost: f64 = "control_cost",
        /// Final shoulder angle θ1 (rad).
        final_theta1_rad: f64 = "final_theta1",
        /// Final elbow angle θ2 (rad).
        final_theta2_rad: f64 = "final_theta2",
        /// Largest |hip torque| (N·m).
        max_abs_torque_n_m: f64 = "max_abs_torque",
        /// Mean normalized entropy of α over the steps.
        mean_entropy: f64 = "mean_entropy",
    }
}

crate::result_rows! {
    /// One row of `trajectories.csv`: one policy from the test start at one control step.
    pub struct TrajectoryRow {
        /// The policy.
        policy: String = "policy",
        /// Time (s).
        t_s: f64 = "t",
        /// Shoulder angle θ1 (rad).
        theta1_rad: f64 = "theta1",
        /// Elbow angle θ2 (rad).
        theta2_rad: f64 = "theta2",
        /// Shoulder rate (rad/s).
        omega1_rad_s: f64 = "omega1",
        /// Elbow rate (rad/s).
        omega2_rad_s: f64 = "omega2",
        /// Hip torque (N·m; NaN at the final state).
        u_n_m: f64 = "u",
        /// LBC's weight of tracker 1 (NaN at the final state).
        alpha1: f64 = "alpha1",
        /// Normalized entropy of α (NaN at the final state).
        alpha_entropy: f64 = "alpha_entropy",
    }
}

crate::result_rows! {
    /// One row of `swingups.csv`: the kept DDP swing-up of one start, with its family markers.
    pub struct SwingupRow {
        /// The start's number (1, 2).
        start: i64 = "start",
        /// Start shoulder angle (degrees).
        theta1_deg: f64 = "theta1_deg",
        /// Start elbow angle (degrees).
        theta2_deg: f64 = "theta2_deg",
        /// DDP iterations.
        iterations: i64 = "iterations",
        /// DDP's cost.
        cost: f64 = "cost",
        /// Final distance to the handstand.
        final_distance: f64 = "final_distance",
        /// Why DDP stopped.
        termination: String = "termination",
        /// The initial guess of the kept run.
        guess: String = "guess",
        /// Direction (±1, 0: none) of the shoulder's first swing.
        first_swing_sign: i64 = "first_swing_sign",
        /// Sign (±1, 0: none) of the first hip-torque lobe.
        first_torque_sign: i64 = "first_torque_sign",
        /// Cost over the cheaper swing-up's.
        cost_ratio: f64 = "cost_ratio",
        /// Correlation of its torque tape with swing-up 1's.
        tape_correlation: f64 = "tape_correlation",
        /// 1 when the kept swing-ups are of one family, else 0 (the same in every row).
        same_family: i64 = "same_family",
        /// Largest |hip torque| of the tape (N·m).
        max_abs_torque_n_m: f64 = "max_abs_torque",
        /// The cheapest run of this start in any family.
        lowest_cost_any_family: f64 = "lowest_cost_any_family",
    }
}

crate::result_rows! {
    /// One row of `sweep.csv`: one policy from one start of the start-state sweep.
    pub struct SweepRow {
        /// Start shoulder angle (degrees).
        theta1_deg: f64 = "theta1_deg",
        /// Start elbow angle (degrees).
        theta2_deg: f64 = "theta2_deg",
        /// The policy.
        policy: String = "policy",
        /// Final distance to the handstand.
        final_distance: f64 = "final_distance",
        /// Control cost ½∫Ru².
        control_cost: f64 = "control_cost",
        /// 1 when it ends within the success distance, else 0.
        success: i64 = "success",
        /// Largest |hip torque| (N·m).
        max_abs_torque_n_m: f64 = "max_abs_torque",
        /// Mean normalized entropy of α.
        mean_entropy: f64 = "mean_entropy",
    }
}

crate::result_rows! {
    /// One row of `lambda_sweep.csv`: LBC at one temperature, from the test start and over the
    /// start-state sweep.
    pub struct LambdaRow {
        /// The temperature λ.
        lambda: f64 = "lambda",
        /// Final distance to the handstand from the test start.
        test_final_distance: f64 = "test_final_distance",
        /// Mean normalized entropy of α from the test start.
        test_mean_entropy: f64 = "test_mean_entropy",
        /// Sweep starts LBC swings up from.
        sweep_successes: i64 = "sweep_successes",
        /// Of them, starts where both trackers fail.
        both_fail_successes: i64 = "both_fail_successes",
        /// Sweep starts where both trackers fail.
        both_fail_starts: i64 = "both_fail_starts",
        /// Mean normalized entropy of α over the sweep's runs.
        sweep_mean_entropy: f64 = "sweep_mean_entropy",
    }
}

crate::result_rows! {
    /// One row of `value_model.csv`: one policy from one sweep start with the trackers of one
    /// value model.
    pub struct ValueModelRow {
        /// The value model (`lqr`, `ddp`).
        value_model: String = "value_model",
        /// Start shoulder angle (degrees).
        theta1_deg: f64 = "theta1_deg",
        /// Start elbow angle (degrees).
        theta2_deg: f64 = "theta2_deg",
        /// The policy.
        policy: String = "policy",
        /// Final distance to the handstand.
        final_distance: f64 = "final_distance",
        /// 1 when it ends within the success distance, else 0.
        success: i64 = "success",
    }
}

crate::result_rows! {
    /// One row of `showcase.csv` (the GIF): one policy's pose at one step from the showcased
    /// start.
    pub struct ShowcaseRow {
        /// The policy (`tracker1`, `tracker2`, `lbc`).
        policy: String = "policy",
        /// Start shoulder angle (degrees).
        theta1_deg: f64 = "theta1_deg",
        /// Start elbow angle (degrees).
        theta2_deg: f64 = "theta2_deg",
        /// 1 when the start is a sweep start LBC rescues, 0 for the test start.
        rescued: i64 = "rescued",
        /// Time (s).
        t_s: f64 = "t",
        /// Shoulder angle θ1 (rad).
        theta1_rad: f64 = "theta1",
        /// Elbow angle θ2 (rad).
        theta2_rad: f64 = "theta2",
    }
}

crate::result_rows! {
    /// One row of `tracker_scales.csv`: one policy from the test start with the trackers' LQR
    /// terminal weights × one scale; the flags repeat over the scale's rows.
    pub struct ScaleRow {
        /// The scale of the trackers' terminal weights.
        tracker_weight_scale: f64 = "tracker_weight_scale",
        /// The policy.
        policy: String = "policy",
        /// Final distance to the handstand from the test start.
        final_distance: f64 = "final_distance",
        /// 1 when both trackers' distances are not below the success distance, else 0.
        each_tracker_fails: i64 = "each_tracker_fails",
        /// 1 for the scale the run uses, else 0.
        chosen: i64 = "chosen",
    }
}
