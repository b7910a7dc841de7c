//! The rows of `na_fig13_control`'s headline tables that its figures and report read back.

crate::result_rows! {
    /// One iteration of one task's descent: a row of `objective.csv`.
    pub struct ObjectiveRow {
        /// The task.
        task: String = "task",
        /// The iteration (0: the start).
        iteration: i64 = "iteration",
        /// The objective J there.
        objective: f64 = "objective",
    }
}

crate::result_rows! {
    /// One task's learned controls, scored: a row of `final.csv`.
    pub struct FinalRow {
        /// The task.
        task: String = "task",
        /// RMS of (s_M − s_d)/σ over the weighted state variables when the controls drive the
        /// emulator (≤ 1: within tolerance); for the dolphin, its shortfall (m) from the
        /// hand-made wave's distance.
        emulator_error: f64 = "emulator_error",
        /// The same when they are replayed on the physical simulator.
        simulator_error: f64 = "simulator_error",
        /// The best-so-far iterate scored (the lowest emulator J).
        best_iteration: i64 = "best_iteration",
        /// `paper` or `ours` ([`super::Formulation::name`]).
        formulation: String = "formulation",
        /// The final error of the task's initial controls replayed on the simulator (NaN for
        /// the dolphin).
        start_simulator_error: f64 = "start_simulator_error",
    }
}

impl FinalRow {
    /// The task is of the paper's formulation (counted in the headline).
    pub fn is_paper(&self) -> bool {
        self.formulation == super::Formulation::Paper.name()
    }
}

crate::result_rows! {
    /// One of the dolphin's swims: a row of `swim.csv` (no rows without `[params.dolphin]`).
    pub struct SwimRow {
        /// `emulator`, `simulator` (the learned controls) or `reference_wave_simulator` (the
        /// hand-made travelling wave).
        source: String = "source",
        /// The forward distance swum (m).
        distance_m: f64 = "distance_m",
        /// The controls' effort.
        effort: f64 = "effort",
        /// The muscle pattern's periodicity (mean over muscles of the largest autocorrelation
        /// at lags of 3 steps to half the horizon; 1: a sinusoid, 0: noise or constant).
        periodicity: f64 = "periodicity",
        /// The lag of that autocorrelation (s).
        period_s: f64 = "period_s",
    }
}

crate::result_rows! {
    /// One iterate of a paper task's headline descent through the physics, under the
    /// calibration of one net seed's net, with that net's gradient beside the physics' (ours,
    /// a diagnostic beside the verdict): a row of `physics_path.csv`. While the residual is
    /// large a net can steer the descent as the physics does; near the goal the physics'
    /// gradient shrinks with the residual and a net's open-loop bias becomes the larger part
    /// of its own.
    pub struct PhysicsPathRow {
        /// The task.
        task: String = "task",
        /// The net seed whose calibration the descent uses and whose net is compared.
        net_seed: i64 = "net_seed",
        /// The iteration (0: the start).
        iteration: i64 = "iteration",
        /// The iterate's final error through the physics (1 = tolerance).
        physics_error: f64 = "physics_error",
        /// Cosine between the net's gradient of J and the physics' at the iterate.
        gradient_cosine: f64 = "gradient_cosine",
        /// Norm of the net's gradient minus the physics', over the physics' norm.
        gradient_relative_error: f64 = "gradient_relative_error",
    }
}
