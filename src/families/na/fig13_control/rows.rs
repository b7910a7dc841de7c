//! The rows of `na_fig13_control`'s tables that its figures and report read back.

use crate::experiment::output::Table;
use crate::experiment::rows::TableRow;

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

    /// A control task of the paper's formulation (the dolphin's swim aside): the run learns it
    /// over the net seeds (`net_seeds.csv`) and records its descent (`path.csv`).
    pub fn is_paper_control(&self) -> bool {
        self.is_paper() && self.task != "dolphin"
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

crate::result_rows! {
    /// One run of a step-size sweep: a row of `sweep.csv` (through the emulator),
    /// `physics_sweep.csv` (through the physical model's RK4 step), `best_weights_sweep.csv`
    /// (the physics under the best-conditioned weights) and `best_weights_emulator_sweep.csv`
    /// (the Table 1 net under them). The errors are at the run's best-so-far iterate.
    pub struct SweepRow {
        /// The task.
        task: String = "task",
        /// The step rule (`fixed`, ..., `levenberg_marquardt`).
        rule: String = "rule",
        /// The step size η (NaN for Levenberg-Marquardt).
        eta: f64 = "eta",
        /// The momentum α (NaN for Levenberg-Marquardt).
        alpha: f64 = "alpha",
        /// The iterations run (the budget, or fewer when the goal stopped it).
        iterations: i64 = "iterations",
        /// The objective evaluations run.
        evaluations: i64 = "evaluations",
        /// The first iteration within tolerance on the substrate learned through (NaN: none).
        iterations_to_goal: f64 = "iterations_to_goal",
        /// The evaluations up to it (NaN: none).
        evaluations_to_goal: f64 = "evaluations_to_goal",
        /// The best-so-far iterate.
        best_iteration: i64 = "best_iteration",
        /// Its objective J.
        best_objective: f64 = "best_objective",
        /// Its final error on the substrate learned through (1 = tolerance).
        rollout_error: f64 = "rollout_error",
        /// The same controls' final error replayed on the simulator.
        simulator_error: f64 = "simulator_error",
    }
}

impl SweepRow {
    /// The run reached its goal on the substrate it learned through.
    pub fn reached(&self) -> bool {
        self.iterations_to_goal.is_finite()
    }
}

crate::result_rows! {
    /// One task's terminal Gauss-Newton matrix at its start knots on one substrate: a row of
    /// `conditioning.csv` (columns: [`super::CONDITIONING_COLUMNS`]).
    pub struct ConditioningRow {
        /// The task.
        task: String = "task",
        /// `emulator` or `physics`.
        substrate: String = "substrate",
        /// The eigenvalues computed (the knots' count).
        knots: i64 = "knots",
        /// The independent weighted final-state variables r.
        dof: i64 = "dof",
        /// The step scale λ at the start.
        step_scale: f64 = "step_scale",
        /// The largest eigenvalue μ_1.
        eigen_largest: f64 = "eigen_largest",
        /// The r-th eigenvalue μ_r.
        eigen_slowest: f64 = "eigen_slowest",
        /// μ_1/μ_r.
        condition: f64 = "condition",
        /// The headline's η.
        eta: f64 = "eta",
        /// Iterations per tenfold reduction along the slowest direction.
        iterations_per_decade: f64 = "iterations_per_decade",
        /// The condition of the equilibrated K.
        condition_equilibrated: f64 = "condition_equilibrated",
        /// The lowest condition any diagonal weighting can have (at least).
        condition_any_weighting: f64 = "condition_any_weighting",
        /// The iterations per tenfold reduction there (at least).
        iterations_per_decade_any_weighting: f64 = "iterations_per_decade_any_weighting",
        /// The paper's iteration count for the task.
        paper_iterations: i64 = "paper_iterations",
    }
}

impl ConditioningRow {
    /// Through the physical model (the spec's reading is on these rows).
    pub fn is_physics(&self) -> bool {
        self.substrate == "physics"
    }
}

crate::result_rows! {
    /// One independent weighted final-state variable of a task run under the best-conditioned
    /// weights: a row of `best_weights.csv` (columns: [`super::BEST_WEIGHTS_COLUMNS`]).
    pub struct BestWeightsRow {
        /// The task.
        task: String = "task",
        /// The state variable's index.
        variable: i64 = "variable",
        /// The task's tolerance on it.
        tolerance: f64 = "tolerance",
        /// The tolerance the best weights amount to.
        tolerance_best: f64 = "tolerance_best",
        /// The condition under the task's weights.
        condition: f64 = "condition",
        /// The condition under the best weights.
        condition_best: f64 = "condition_best",
        /// The iterations per tenfold reduction at the latter.
        iterations_per_decade_best: f64 = "iterations_per_decade_best",
    }
}

crate::result_rows! {
    /// One rung of a task's conditioning ladder: a row of `conditioning_ladder.csv` (ours). Per
    /// task of the paper's formulation that has a formulation of ours on the same net, the
    /// terminal Gauss-Newton condition through that net at the initial knots as the paper's
    /// changes are applied to ours one at a time: rung 0 is ours, the last rung the paper's
    /// task; `iterations_per_decade` is the headline's pace along the slowest direction at
    /// that condition (the task's eta and alpha, lambda at the largest eigenvalue).
    pub struct LadderRow {
        /// The task.
        task: String = "task",
        /// The rung (0: ours).
        rung: i64 = "rung",
        /// What the rung changed.
        change: String = "change",
        /// The independent weighted final-state variables r.
        dof: i64 = "dof",
        /// The condition of G at the task's initial knots.
        condition: f64 = "condition",
        /// The task's η.
        eta: f64 = "eta",
        /// Iterations per tenfold reduction along the slowest direction.
        iterations_per_decade: f64 = "iterations_per_decade",
    }
}

crate::result_rows! {
    /// One eigenvalue of a task's terminal Gauss-Newton matrix at its start knots: a row of
    /// `spectrum.csv`.
    pub struct SpectrumRow {
        /// The task.
        task: String = "task",
        /// `emulator` or `physics`.
        substrate: String = "substrate",
        /// The eigenvalue's rank (1: the largest).
        index: i64 = "index",
        /// The eigenvalue.
        eigenvalue: f64 = "eigenvalue",
    }
}

crate::result_rows! {
    /// One state variable of a task with its final-state tolerance: a row of `states.csv`.
    pub struct StateRow {
        /// The task.
        task: String = "task",
        /// Its column in `trajectory.csv` and `goal.csv` (`s0`, `s1`, ...).
        column: String = "column",
        /// The variable's name.
        name: String = "name",
        /// Its final-state tolerance (0: not part of the goal).
        tolerance: f64 = "tolerance",
    }
}

crate::result_rows! {
    /// One task's headline through one Table 1 net seed: a row of `net_seeds.csv` (columns:
    /// [`super::seeds::SEEDS_COLUMNS`]).
    pub struct NetSeedRow {
        /// The task.
        task: String = "task",
        /// The net seed.
        net_seed: i64 = "net_seed",
        /// The best iterate's final error on the net.
        emulator_error: f64 = "emulator_error",
        /// The same controls' on the simulator.
        simulator_error: f64 = "simulator_error",
        /// The best iterate.
        best_iteration: i64 = "best_iteration",
        /// 1 when both final errors are at most 1.
        at_goal: i64 = "at_goal",
        /// `paper` (counted by the verdict) or `ours`.
        formulation: String = "formulation",
        /// The first iteration of the descent continued at the goal on both (NaN: none).
        iterations_to_goal: f64 = "iterations_to_goal",
        /// The same for the descent through the physics (NaN: none).
        physics_iterations_to_goal: f64 = "physics_iterations_to_goal",
    }
}

crate::result_rows! {
    /// One paper task's headline through one second line's net of one seed: a row of
    /// `net_lines.csv` (columns: [`super::seeds::LINES_COLUMNS`]).
    pub struct NetLineRow {
        /// The task.
        task: String = "task",
        /// The net's change (`box`, `noise`, `typical`).
        line: String = "line",
        /// The net seed.
        net_seed: i64 = "net_seed",
        /// The best iterate's final error on the net.
        emulator_error: f64 = "emulator_error",
        /// The same controls' on the simulator.
        simulator_error: f64 = "simulator_error",
        /// The best iterate.
        best_iteration: i64 = "best_iteration",
        /// 1 when both final errors are at most 1.
        at_goal: i64 = "at_goal",
        /// The first iteration of the descent continued at the goal on both (NaN: none).
        iterations_to_goal: f64 = "iterations_to_goal",
    }
}

crate::result_rows! {
    /// One iterate of a paper task's headline descent through one net seed's net: a row of
    /// `path.csv` (columns: [`super::PATH_COLUMNS`]).
    pub struct PathRow {
        /// The task.
        task: String = "task",
        /// The net seed.
        net_seed: i64 = "net_seed",
        /// The iteration (0: the start).
        iteration: i64 = "iteration",
        /// J on the net.
        objective: f64 = "objective",
        /// The iterate's final error on the net.
        emulator_error: f64 = "emulator_error",
        /// Its controls' final error replayed on the simulator.
        simulator_error: f64 = "simulator_error",
        /// The largest Hessian eigenvalue of J there over the one at the start.
        curvature_ratio: f64 = "curvature_ratio",
        /// Momentum's stable limit of that ratio, 2(1 + α)/η.
        stable_ratio: f64 = "stable_ratio",
    }
}

crate::result_rows! {
    /// One round of the dolphin's DAgger: a row of `dolphin_dagger.csv` (columns:
    /// [`super::dolphin_dagger::COLUMNS`]).
    pub struct DolphinDaggerRow {
        /// The round (0: the Table 1 global net).
        round: i64 = "round",
        /// The examples the round's net was trained on.
        examples: i64 = "examples",
        /// Of them, gathered by DAgger.
        dagger_examples: i64 = "dagger_examples",
        /// The rollout windows gathered.
        dagger_windows: i64 = "dagger_windows",
        /// The fine-tuning's iterations.
        fine_tune_iterations: i64 = "fine_tune_iterations",
        /// The learned swim's best iterate.
        best_iteration: i64 = "best_iteration",
        /// Its objective.
        best_objective: f64 = "best_objective",
        /// The distance swum on the round's net (m).
        distance_emulator_m: f64 = "distance_emulator_m",
        /// The same knots' distance on the simulator (m).
        distance_simulator_m: f64 = "distance_simulator_m",
        /// The hand-made wave's distance on the simulator (m).
        reference_distance_m: f64 = "reference_distance_m",
        /// The simulator's distance over the wave's.
        fraction_of_reference: f64 = "fraction_of_reference",
        /// The muscle pattern's periodicity.
        periodicity: f64 = "periodicity",
        /// Its period (s).
        period_s: f64 = "period_s",
        /// The zero-control drift of the mean centroid on the net (m).
        drift_emulator_m: f64 = "drift_emulator_m",
        /// The same on the simulator (m).
        drift_simulator_m: f64 = "drift_simulator_m",
        /// The distance between the two drifts' ends (m).
        drift_gap_m: f64 = "drift_gap_m",
    }
}

// Tables that hold tasks of models of different sizes have lead columns and then numbered
// columns `s0`, `s1`, ... (NaN past a model's own): the lead columns are declared as rows, the
// numbered ones read by `numbered`, so each column name is written once here.

/// The numbered columns `prefix`0, `prefix`1, ... of `t`, as one vector per row.
fn numbered(t: &Table, prefix: &str) -> Vec<Vec<f64>> {
    let columns: Vec<Vec<f64>> = (0..)
        .map(|k| format!("{prefix}{k}"))
        .take_while(|name| t.column(name).is_some())
        .map(|name| t.f64s(&name))
        .collect();
    (0..t.len())
        .map(|r| columns.iter().map(|c| c[r]).collect())
        .collect()
}

crate::result_rows! {
    /// The lead columns of `trajectory.csv`.
    struct TrajectoryLead {
        task: String = "task",
        step: i64 = "step",
        t: f64 = "t",
        source: String = "source",
    }
}

/// One state of a task's motion: a row of `trajectory.csv` (columns `task`, `step`, `t`,
/// `source`, then the state `s0`, `s1`, ...).
#[derive(Debug, Clone, PartialEq)]
pub struct TrajectoryRow {
    /// The task.
    pub task: String,
    /// The emulator step.
    pub step: i64,
    /// Its time (s).
    pub t: f64,
    /// `emulator` (the learned controls driving the net) or `simulator` (their replay).
    pub source: String,
    /// The state (NaN past the model's own dimension).
    pub state: Vec<f64>,
}

impl TrajectoryRow {
    /// Every row of the job's `trajectory` table.
    pub fn from_table(t: &Table) -> Vec<Self> {
        TrajectoryLead::from_table(t)
            .into_iter()
            .zip(numbered(t, "s"))
            .map(|(l, state)| Self {
                task: l.task,
                step: l.step,
                t: l.t,
                source: l.source,
                state,
            })
            .collect()
    }
}

crate::result_rows! {
    /// The lead columns of `goal.csv`.
    struct GoalLead {
        task: String = "task",
        model: String = "model",
    }
}

/// One task's goal state: a row of `goal.csv` (columns `task`, `model`, then `s0`, `s1`, ...).
#[derive(Debug, Clone, PartialEq)]
pub struct GoalRow {
    /// The task.
    pub task: String,
    /// Its model ([`crate::emulator::catalog::NetModel::name`]).
    pub model: String,
    /// The target state (NaN past the model's own dimension).
    pub target: Vec<f64>,
}

impl GoalRow {
    /// Every row of the job's `goal` table.
    pub fn from_table(t: &Table) -> Vec<Self> {
        GoalLead::from_table(t)
            .into_iter()
            .zip(numbered(t, "s"))
            .map(|(l, target)| Self {
                task: l.task,
                model: l.model,
                target,
            })
            .collect()
    }
}

crate::result_rows! {
    /// The lead columns of `dolphin_motion.csv`.
    struct DolphinMotionLead {
        source: String = "source",
        step: i64 = "step",
        t: f64 = "t",
    }
}

/// One step of the dolphin's motion: a row of `dolphin_motion.csv` (columns `source`, `step`,
/// `t`, then the mass positions `p0`, `p1`, ...).
#[derive(Debug, Clone, PartialEq)]
pub struct DolphinMotionRow {
    /// `emulator` (global and local nets) or `simulator`.
    pub source: String,
    /// The emulator step.
    pub step: i64,
    /// Its time (s).
    pub t: f64,
    /// The mass positions.
    pub positions: Vec<f64>,
}

impl DolphinMotionRow {
    /// Every row of the job's `dolphin_motion` table.
    pub fn from_table(t: &Table) -> Vec<Self> {
        DolphinMotionLead::from_table(t)
            .into_iter()
            .zip(numbered(t, "p"))
            .map(|(l, positions)| Self {
                source: l.source,
                step: l.step,
                t: l.t,
                positions,
            })
            .collect()
    }
}
