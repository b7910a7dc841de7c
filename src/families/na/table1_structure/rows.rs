//! The typed rows of the tables the job writes and the figures and the report read back.

crate::result_rows! {
    /// One row of `structure.csv`: one Table 1 net (the dolphin's global and local nets too).
    pub struct StructureRow {
        /// The net's name (the model's; `dolphin_global`, `dolphin_local_*` for the hierarchy).
        net: String = "net",
        /// Net inputs.
        inputs: i64 = "inputs",
        /// Hidden units.
        hidden: i64 = "hidden",
        /// Net outputs.
        outputs: i64 = "outputs",
        /// Training examples.
        examples: i64 = "examples",
        /// One-step training MSE (normalized).
        train_error: f64 = "train_error",
        /// One-step held-out MSE (normalized).
        heldout_error: f64 = "heldout_error",
        /// Training seconds.
        train_s: f64 = "train_s",
        /// Weights.
        weights: i64 = "weights",
        /// examples / weights.
        examples_per_weight: f64 = "examples_per_weight",
        /// Why training stopped.
        stop: String = "stop",
        /// 1 when the net came from the cache.
        cached: i64 = "cached",
        /// 40-step rollout error, mean over the steps (units of the state variance).
        rollout40_error_mean: f64 = "rollout40_error_mean",
        /// 40-step rollout error at the last step.
        rollout40_error_final: f64 = "rollout40_error_final",
        /// 1 when the net is anchored at its equilibrium (`anchor = true`).
        anchored: i64 = "anchored",
        /// The share of its training examples in the tasks' regime (NaN for the dolphin's).
        regime_share: f64 = "regime_share",
        /// The data regime's name.
        data: String = "data",
    }
}

crate::result_rows! {
    /// One row of `training.csv`: a net's errors after one iteration of its first training
    /// stage.
    pub struct TrainingRow {
        /// The net's name.
        net: String = "net",
        /// The iteration (CG, L-BFGS) or epoch (momentum).
        iteration: i64 = "iteration",
        /// Training MSE per output (normalized).
        train_error: f64 = "train_error",
        /// Held-out MSE per output (normalized).
        heldout_error: f64 = "heldout_error",
    }
}

crate::result_rows! {
    /// One row of `rollout_training.csv`: the k-step rollout fine-tuning's loss (one-step loss
    /// + rollout_weight x k-step rollout loss) after one iteration.
    pub struct RolloutTrainingRow {
        /// The net's name.
        net: String = "net",
        /// The iteration.
        iteration: i64 = "iteration",
        /// Loss on the training examples and windows.
        train_loss: f64 = "train_loss",
        /// Loss on the held-out examples and windows.
        heldout_loss: f64 = "heldout_loss",
    }
}

crate::result_rows! {
    /// One row of `rollout.csv`: a net's rollout error against the simulator at one super-step.
    pub struct RolloutRow {
        /// The net's name (`dolphin` for the composed hierarchy).
        net: String = "net",
        /// The super-step (from 1).
        step: i64 = "step",
        /// Mean squared error over the state variance.
        error: f64 = "error",
    }
}

crate::result_rows! {
    /// One row of `drift.csv`: one neutral-control drift task of one net.
    pub struct DriftRow {
        /// The net's name.
        net: String = "net",
        /// The drift task's name.
        task: String = "task",
        /// The horizon (s).
        horizon_s: f64 = "horizon_s",
        /// How far the emulator's position part moved from the start.
        emulator_drift: f64 = "emulator_drift",
        /// How far the simulator's moved.
        simulator_drift: f64 = "simulator_drift",
        /// The emulator's and the simulator's ends apart.
        gap: f64 = "gap",
        /// The task's tolerance (ours).
        tolerance: f64 = "tolerance",
        /// 1 when the start and control are the anchored net's equilibrium.
        at_anchor: i64 = "at_anchor",
    }
}

crate::result_rows! {
    /// One row of `global_error.csv`: the dolphin's global net's held-out error on one output.
    pub struct GlobalErrorRow {
        /// The segment (0 nose … 5 fluke).
        segment: i64 = "segment",
        /// The quantity (`centroid`, `orientation`, `velocity`, `angular_velocity`).
        quantity: String = "quantity",
        /// The component (`x`, `y`, `z`, `w`).
        component: String = "component",
        /// Held-out one-step MSE, in the units the net trains in.
        heldout_mse: f64 = "heldout_mse",
        /// The output's own variance.
        target_variance: f64 = "target_variance",
    }
}

crate::result_rows! {
    /// One row of `normalization.csv`: a catalog net built under one normalization.
    pub struct NormalizationRow {
        /// The net's name.
        net: String = "net",
        /// The normalization's name ([`crate::emulator::catalog::Normalization::name`]).
        normalization: String = "normalization",
        /// 1 when it is the net's own (the spec's).
        in_spec: i64 = "in_spec",
        /// One-step rollout error.
        rollout1_error: f64 = "rollout1_error",
        /// 40-step rollout error, mean.
        rollout40_error_mean: f64 = "rollout40_error_mean",
        /// 40-step rollout error, last step.
        rollout40_error_final: f64 = "rollout40_error_final",
        /// Training seconds.
        train_s: f64 = "train_s",
        /// 1 when the net came from the cache.
        cached: i64 = "cached",
    }
}

crate::result_rows! {
    /// One row of `regime_fidelity.csv`: one task quantity of a catalog net (or a variant of
    /// it) on the control tasks' inputs, in tolerance units.
    pub struct RegimeFidelityRow {
        /// The net's name.
        net: String = "net",
        /// The state quantity.
        quantity: String = "quantity",
        /// One-step bias over the tolerance.
        bias_tol: f64 = "bias_tol",
        /// One-step RMS error over the tolerance.
        rms_tol: f64 = "rms_tol",
        /// Median 40-step error over the tolerance.
        rollout40_tol: f64 = "rollout40_tol",
        /// `paper` (the net of the table) or the variant's name.
        variant: String = "variant",
        /// The data regime's name.
        data: String = "data",
        /// The training's input noise.
        input_noise: f64 = "input_noise",
        /// The quantity's tolerance.
        tolerance: f64 = "tolerance",
        /// The share of the training examples in the tasks' regime.
        regime_share: f64 = "regime_share",
        /// Why training stopped.
        stop: String = "stop",
    }
}
