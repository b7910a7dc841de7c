//! The rows of the dive families' result tables, and the names of the dives they compare: one
//! declaration per table, written by the jobs and read back by the figures and the report.
//! Angles are in rad from vertical unless a field says otherwise.

use crate::bellman::combine::BlendMode;
use crate::families::lbc::film::DIVER_COORDS;

crate::result_rows! {
    /// One row of `dives.csv` (every dive family): one DDP dive and how its optimization ended.
    pub struct DiveRow {
        /// The dive's number, from 1, in the order of the family's cases.
        dive: i64 = "dive",
        /// Take-off angular velocity (rad/s).
        initial_omega: f64 = "initial_omega",
        /// The target's rotation from the straight head-down pose (rad).
        target_offset: f64 = "target_offset",
        /// DDP iterations run.
        iterations: i64 = "iterations",
        /// DDP's final cost.
        cost: f64 = "cost",
        /// Entry angle of the optimized dive's final state.
        entry_angle: f64 = "entry_angle",
        /// How DDP stopped (its `Termination`, debug-printed).
        termination: String = "termination",
        /// Largest |u_j| / limit_j over the control tape.
        max_torque_fraction: f64 = "max_torque_fraction",
    }
}

/// A dive the interpolation compares, by what drives it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Linear Bellman combination of the two component trackers.
    Lbc,
    /// The trackers' controls averaged with the fixed (projected) weights.
    Naive,
    /// A DDP dive optimized directly for the reconstructed cost (the ground truth).
    Direct,
    /// One of the component dives themselves (`average_term.csv` only).
    Component,
}

impl Method {
    /// The blends executed at every desired entry, in the tables' order, and how each mixes
    /// the component trackers.
    pub const BLENDS: [(Method, BlendMode); 2] = [
        (Method::Lbc, BlendMode::Lbc),
        (Method::Naive, BlendMode::Naive),
    ];

    /// The methods of `interpolation.csv`, in its order per desired entry.
    pub const COMPARED: [Method; 3] = [Method::Lbc, Method::Naive, Method::Direct];

    /// Its name in the tables.
    pub fn name(self) -> &'static str {
        match self {
            Method::Lbc => "lbc",
            Method::Naive => "naive",
            Method::Direct => "direct",
            Method::Component => "component",
        }
    }
}

crate::result_rows! {
    /// One row of `interpolation.csv`: one method's dive for one desired entry angle.
    pub struct InterpolationRow {
        /// The desired entry angle.
        desired_angle: f64 = "desired_angle",
        /// The method ([`Method::name`]: lbc, naive, direct).
        method: String = "method",
        /// The entry angle reached (NaN: the closed loop diverged).
        reached_angle: f64 = "reached_angle",
        /// Projected weight of the under-rotating component.
        weight1: f64 = "weight1",
        /// Projected weight of the over-rotating component.
        weight2: f64 = "weight2",
        /// Objective with the reconstructed terminal cost (infinite for a diverged dive).
        objective: f64 = "objective",
        /// (objective − direct's) / |direct's|.
        excess_objective: f64 = "excess_objective",
        /// Mean normalized entropy of α (NaN for the direct dive).
        mean_entropy: f64 = "mean_entropy",
        /// Largest |u_j| / limit_j over the dive.
        max_torque_fraction: f64 = "max_torque_fraction",
    }
}

crate::result_rows! {
    /// One row of the interpolation's `projection.csv`: the projection for one desired entry
    /// and the direct dive's optimization.
    pub struct ProjectionRow {
        /// The desired entry angle.
        desired_angle: f64 = "desired_angle",
        /// Projected weight of the under-rotating component.
        weight1: f64 = "weight1",
        /// Projected weight of the over-rotating component.
        weight2: f64 = "weight2",
        /// weight1 + weight2.
        weight_sum: f64 = "weight_sum",
        /// Relative residual of the projection.
        relative_residual: f64 = "relative_residual",
        /// Where the reconstructed torso cost is smallest, from the head-down pose.
        reconstructed_minimum: f64 = "reconstructed_minimum",
        /// Outer iterations of the best direct dive.
        direct_outer_iterations: i64 = "direct_outer_iterations",
        /// The best direct dive's initial control tape, in words.
        direct_start: String = "direct_start",
    }
}

crate::result_rows! {
    /// One row of the interpolation's `lambda_sweep.csv`: LBC at one temperature for one
    /// desired entry (weights re-projected at that temperature).
    pub struct InterpolationSweepRow {
        /// The temperature λ.
        lambda: f64 = "lambda",
        /// The desired entry angle.
        desired_angle: f64 = "desired_angle",
        /// The entry angle reached.
        reached_angle: f64 = "reached_angle",
        /// Mean normalized entropy of α.
        mean_entropy: f64 = "mean_entropy",
        /// Projected weight of the under-rotating component.
        weight1: f64 = "weight1",
        /// Projected weight of the over-rotating component.
        weight2: f64 = "weight2",
    }
}

crate::result_rows! {
    /// One row of `average_term.csv`: at one scale of the §6.1 term (0: off), a component dive
    /// (`desired_angle` its target, `mean_entropy` NaN) or LBC or the naive blend at one
    /// desired entry.
    pub struct AverageRow {
        /// The §6.1 term's scale.
        average_scale: f64 = "average_scale",
        /// The desired entry angle (a component's: its target).
        desired_angle: f64 = "desired_angle",
        /// The method ([`Method::name`]: component, lbc, naive).
        method: String = "method",
        /// The entry angle reached.
        reached_angle: f64 = "reached_angle",
        /// |reached − desired|.
        entry_error: f64 = "entry_error",
        /// Mean normalized entropy of α (NaN for a component).
        mean_entropy: f64 = "mean_entropy",
        /// RMS over the steps and the torso and joint angles of the dive minus the
        /// components' average trajectory (rad): how far it strays from the examples' average.
        angle_deviation: f64 = "angle_deviation",
    }
}

crate::result_rows! {
    /// One row of `offsets.csv`: one offset of the offset search, in the order tried.
    pub struct OffsetRow {
        /// The offset δ (rad).
        offset: f64 = "offset",
        /// The §6.1 average-term scale chosen at this offset (0: off).
        average_scale: f64 = "average_scale",
        /// Entry angle of the under-rotating component.
        under_entry: f64 = "under_entry",
        /// Entry angle of the over-rotating component.
        over_entry: f64 = "over_entry",
        /// Entry angle of the naive blend with the weights projected for vertical.
        naive_vertical_entry: f64 = "naive_vertical_entry",
        /// Entry angle of LBC with the same weights.
        lbc_vertical_entry: f64 = "lbc_vertical_entry",
        /// 1 when the premise holds at this offset, else 0.
        premise_holds: i64 = "premise_holds",
        /// The torso terminal weight at this offset (1/rad²).
        torso_weight: f64 = "torso_weight",
    }
}

/// The dives of the interpolation's `motion` table, in its order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MotionDive {
    /// The under-rotating component.
    Under,
    /// The over-rotating component.
    Over,
    /// The naive blend with the weights projected for vertical.
    Naive,
    /// LBC with the same weights.
    Lbc,
}

impl MotionDive {
    /// Every dive, in the table's order.
    pub const ALL: [MotionDive; 4] = [
        MotionDive::Under,
        MotionDive::Over,
        MotionDive::Naive,
        MotionDive::Lbc,
    ];

    /// Its name in the table.
    pub fn name(self) -> &'static str {
        match self {
            MotionDive::Under => "under-rotating",
            MotionDive::Over => "over-rotating",
            MotionDive::Naive => "naive",
            MotionDive::Lbc => "lbc",
        }
    }

    /// How it drives the component trackers.
    pub fn mode(self) -> BlendMode {
        match self {
            MotionDive::Under => BlendMode::Single(0),
            MotionDive::Over => BlendMode::Single(1),
            MotionDive::Naive => BlendMode::Naive,
            MotionDive::Lbc => BlendMode::Lbc,
        }
    }

    /// Its label in the filmstrip and the GIF.
    pub fn label(self) -> String {
        match self {
            MotionDive::Naive | MotionDive::Lbc => {
                format!("{}, weights for vertical", self.name())
            }
            MotionDive::Under | MotionDive::Over => format!("{} component", self.name()),
        }
    }
}

crate::result_rows! {
    /// One row of the interpolation's `motion.csv`: a filmstrip dive's state at one step.
    pub struct MotionRow {
        /// The dive ([`MotionDive::name`]).
        dive: String = "dive",
        /// Time since take-off (s).
        t_s: f64 = "t",
        /// Hip position, horizontal (m).
        hip_x_m: f64 = "x",
        /// Hip position, vertical (m).
        hip_y_m: f64 = "y",
        /// Torso angle (rad).
        torso_rad: f64 = "torso",
        /// Neck joint angle (rad).
        neck_rad: f64 = "neck",
        /// Shoulder joint angle (rad).
        shoulder_rad: f64 = "shoulder",
        /// Elbow joint angle (rad).
        elbow_rad: f64 = "elbow",
        /// Hip joint angle (rad).
        hip_rad: f64 = "hip",
        /// Knee joint angle (rad).
        knee_rad: f64 = "knee",
        /// Ankle joint angle (rad).
        ankle_rad: f64 = "ankle",
    }
}

impl MotionRow {
    /// Dive `dive` at time `t_s` in the diver's generalized coordinates `q` (the first
    /// [`DIVER_COORDS`] of a state).
    pub fn at(dive: MotionDive, t_s: f64, q: &[f64]) -> Self {
        Self {
            dive: dive.name().to_string(),
            t_s,
            hip_x_m: q[0],
            hip_y_m: q[1],
            torso_rad: q[2],
            neck_rad: q[3],
            shoulder_rad: q[4],
            elbow_rad: q[5],
            hip_rad: q[6],
            knee_rad: q[7],
            ankle_rad: q[8],
        }
    }

    /// The diver's generalized coordinates, in the state's order.
    pub fn coords(&self) -> [f64; DIVER_COORDS] {
        [
            self.hip_x_m,
            self.hip_y_m,
            self.torso_rad,
            self.neck_rad,
            self.shoulder_rad,
            self.elbow_rad,
            self.hip_rad,
            self.knee_rad,
            self.ankle_rad,
        ]
    }
}

/// A dive of the coordination: LBC of every component tracker, or the single one compared.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tracking {
    /// LBC of the component trackers with w = 1.
    Lbc,
    /// The one tracker of the spec's `single` component.
    Single,
}

impl Tracking {
    /// Both, in the tables' order.
    pub const ALL: [Tracking; 2] = [Tracking::Lbc, Tracking::Single];

    /// Its name in the tables.
    pub fn name(self) -> &'static str {
        match self {
            Tracking::Lbc => "lbc",
            Tracking::Single => "single",
        }
    }

    /// How it drives the trackers, `single` the single tracker's index.
    pub fn mode(self, single: usize) -> BlendMode {
        match self {
            Tracking::Lbc => BlendMode::Lbc,
            Tracking::Single => BlendMode::Single(single),
        }
    }
}

crate::result_rows! {
    /// One row of `coordination.csv`: LBC or the single tracker from one take-off rate.
    pub struct CoordinationRow {
        /// Take-off angular velocity (rad/s).
        initial_omega: f64 = "initial_omega",
        /// The dive ([`Tracking::name`]).
        method: String = "method",
        /// |entry angle| (NaN: the closed loop diverged).
        entry_error: f64 = "entry_error",
        /// Running plus terminal cost (infinite for a diverged dive).
        objective: f64 = "objective",
        /// Mean normalized entropy of α.
        mean_entropy: f64 = "mean_entropy",
        /// Largest |u_j| / limit_j over the dive.
        max_torque_fraction: f64 = "max_torque_fraction",
        /// Its objective against the other dive's from the same rate (`compare_objectives`:
        /// better, worse, tie).
        objective_outcome: String = "objective_outcome",
    }
}

crate::result_rows! {
    /// One row of the coordination's `lambda_sweep.csv`: LBC at one temperature from one
    /// take-off rate, against the single tracker.
    pub struct CoordinationSweepRow {
        /// The temperature λ.
        lambda: f64 = "lambda",
        /// Take-off angular velocity (rad/s).
        initial_omega: f64 = "initial_omega",
        /// |entry angle|.
        entry_error: f64 = "entry_error",
        /// Running plus terminal cost.
        objective: f64 = "objective",
        /// Mean normalized entropy of α.
        mean_entropy: f64 = "mean_entropy",
        /// Its objective against the single tracker's (better, worse, tie).
        objective_outcome: String = "objective_outcome",
    }
}

/// The value function the coordination's trackers are built with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValueFunction {
    /// The LQR tracker's (eq. 12).
    Lqr,
    /// DDP's, with the second-order dynamics terms (LBC §5.2).
    Ddp,
}

impl ValueFunction {
    /// Its name in `value_comparison.csv`.
    pub fn name(self) -> &'static str {
        match self {
            ValueFunction::Lqr => "lqr",
            ValueFunction::Ddp => "ddp",
        }
    }
}

crate::result_rows! {
    /// One row of `value_comparison.csv`: one dive from one take-off rate with the trackers of
    /// one value function.
    pub struct ValueRow {
        /// Take-off angular velocity (rad/s).
        initial_omega: f64 = "initial_omega",
        /// The value function ([`ValueFunction::name`]).
        value_function: String = "value_function",
        /// The dive ([`Tracking::name`]).
        method: String = "method",
        /// |entry angle|.
        entry_error: f64 = "entry_error",
        /// Running plus terminal cost.
        objective: f64 = "objective",
        /// Mean normalized entropy of α.
        mean_entropy: f64 = "mean_entropy",
    }
}

crate::result_rows! {
    /// One row of `poses.csv`: one dive's last pose from one take-off rate (NaN coordinates:
    /// the closed loop diverged).
    pub struct PoseRow {
        /// Take-off angular velocity (rad/s).
        initial_omega: f64 = "initial_omega",
        /// The dive ([`Tracking::name`]).
        method: String = "method",
        /// |entry angle|.
        entry_error: f64 = "entry_error",
        /// Hip position, horizontal (m).
        hip_x_m: f64 = "x",
        /// Hip position, vertical (m).
        hip_y_m: f64 = "y",
        /// Torso angle (rad).
        torso_rad: f64 = "torso",
        /// Neck joint angle (rad).
        neck_rad: f64 = "neck",
        /// Shoulder joint angle (rad).
        shoulder_rad: f64 = "shoulder",
        /// Elbow joint angle (rad).
        elbow_rad: f64 = "elbow",
        /// Hip joint angle (rad).
        hip_rad: f64 = "hip",
        /// Knee joint angle (rad).
        knee_rad: f64 = "knee",
        /// Ankle joint angle (rad).
        ankle_rad: f64 = "ankle",
    }
}

impl PoseRow {
    /// The pose `q` (the diver's generalized coordinates) of `method` from `initial_omega`.
    pub fn at(initial_omega: f64, method: Tracking, entry_error: f64, q: &[f64]) -> Self {
        Self {
            initial_omega,
            method: method.name().to_string(),
            entry_error,
            hip_x_m: q[0],
            hip_y_m: q[1],
            torso_rad: q[2],
            neck_rad: q[3],
            shoulder_rad: q[4],
            elbow_rad: q[5],
            hip_rad: q[6],
            knee_rad: q[7],
            ankle_rad: q[8],
        }
    }

    /// The diver's generalized coordinates, in the state's order.
    pub fn coords(&self) -> [f64; DIVER_COORDS] {
        [
            self.hip_x_m,
            self.hip_y_m,
            self.torso_rad,
            self.neck_rad,
            self.shoulder_rad,
            self.elbow_rad,
            self.hip_rad,
            self.knee_rad,
            self.ankle_rad,
        ]
    }
}

crate::result_rows! {
    /// One row of `disturbance.csv`: a controller's dive at a force scale under one trial's
    /// pushes (force scale 0: its unpushed dive, trial 0).
    pub struct DisturbanceRow {
        /// The controller (lbc, pd).
        controller: String = "controller",
        /// The pushes' scale (0: unpushed).
        force_scale: f64 = "force_scale",
        /// ∫ ½ uᵀRu dt.
        effort: f64 = "effort",
        /// RMS over the flight of the torso and joint angles minus the same controller's
        /// unpushed dive's (rad).
        deviation: f64 = "deviation",
        /// |entry angle| (rad).
        final_error: f64 = "final_error",
        /// The trial (push set) number, from 0.
        trial: i64 = "trial",
        /// |entry angle − the unpushed dive's| (rad).
        entry_change: f64 = "entry_change",
        /// Largest |u_j| / limit_j over the dive.
        max_torque_fraction: f64 = "max_torque_fraction",
    }
}

crate::result_rows! {
    /// One row of the disturbance's `motion.csv`: a controller's dive, unpushed or under trial
    /// 0's pushes at one scale, at one dive step; `q0`…`q8` are the diver's generalized
    /// coordinates.
    pub struct FlightRow {
        /// The controller (lbc, pd).
        controller: String = "controller",
        /// The pushes' scale (0: unpushed).
        force_scale: f64 = "force_scale",
        /// Time since take-off (s).
        t_s: f64 = "t",
        /// Hip position, horizontal (m).
        hip_x_m: f64 = "q0",
        /// Hip position, vertical (m).
        hip_y_m: f64 = "q1",
        /// Torso angle (rad).
        torso_rad: f64 = "q2",
        /// Neck joint angle (rad).
        neck_rad: f64 = "q3",
        /// Shoulder joint angle (rad).
        shoulder_rad: f64 = "q4",
        /// Elbow joint angle (rad).
        elbow_rad: f64 = "q5",
        /// Hip joint angle (rad).
        hip_rad: f64 = "q6",
        /// Knee joint angle (rad).
        knee_rad: f64 = "q7",
        /// Ankle joint angle (rad).
        ankle_rad: f64 = "q8",
    }
}

impl FlightRow {
    /// `controller`'s dive at `force_scale` at time `t_s` in the state `x` (its first
    /// [`DIVER_COORDS`] values).
    pub fn at(controller: &str, force_scale: f64, t_s: f64, x: &[f64]) -> Self {
        Self {
            controller: controller.to_string(),
            force_scale,
            t_s,
            hip_x_m: x[0],
            hip_y_m: x[1],
            torso_rad: x[2],
            neck_rad: x[3],
            shoulder_rad: x[4],
            elbow_rad: x[5],
            hip_rad: x[6],
            knee_rad: x[7],
            ankle_rad: x[8],
        }
    }

    /// The diver's generalized coordinates, in the state's order.
    pub fn coords(&self) -> [f64; DIVER_COORDS] {
        [
            self.hip_x_m,
            self.hip_y_m,
            self.torso_rad,
            self.neck_rad,
            self.shoulder_rad,
            self.elbow_rad,
            self.hip_rad,
            self.knee_rad,
            self.ankle_rad,
        ]
    }
}

crate::result_rows! {
    /// One row of `pushes.csv`: one push of one trial, at scale 1.
    pub struct PushRow {
        /// The trial (push set) number, from 0.
        trial: i64 = "trial",
        /// When the push starts (s).
        start_s: f64 = "start_s",
        /// How long it lasts (s).
        duration_s: f64 = "duration_s",
        /// Its horizontal force (N).
        force_x_n: f64 = "force_x_n",
        /// Its vertical force (N).
        force_y_n: f64 = "force_y_n",
    }
}
