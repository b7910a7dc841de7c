//! The typed rows of the search jobs' tables ([`super::search`]'s `MotionJob`, read by
//! `ms_motion`'s figures and report, and `LearningJob`, read by `ms_learning`'s).

crate::result_rows! {
    /// One row of `controller.csv`: one regime of the best controller.
    pub struct ControllerRow {
        /// The regime's index.
        regime: i64 = "regime",
        /// Its time t_i in the period (s).
        time: f64 = "time",
        /// Its reflex's number.
        reflex: i64 = "reflex",
        /// Its reflex's name.
        reflex_name: String = "reflex_name",
        /// Its reflex coefficient α_i.
        alpha: f64 = "alpha",
        /// The controller's period t_per (s).
        period: f64 = "period",
    }
}

crate::result_rows! {
    /// One row of `best.csv`: one objective term of the best controller (the last, `total`,
    /// their weighted sum).
    pub struct BestTermRow {
        /// The term's name.
        term: String = "term",
        /// Its value.
        value: f64 = "value",
        /// Its value times its weight.
        weighted: f64 = "weighted",
    }
}

crate::result_rows! {
    /// One row of `measures.csv`: one fixed measure of the best motion
    /// ([`super::search::measures`]).
    pub struct MeasureRow {
        /// The measure's name.
        measure: String = "measure",
        /// Its value (unit weight).
        value: f64 = "value",
    }
}

crate::result_rows! {
    /// The row of `summary.csv` of a motion's search.
    pub struct MotionSummaryRow {
        /// The motion's name ([`super::search::Motion::name`]).
        motion: String = "motion",
        /// The lattice's name.
        lattice: String = "lattice",
        /// Regimes per period.
        regimes: i64 = "regimes",
        /// The period t_per (s).
        period: f64 = "period",
        /// The simulated horizon (s).
        horizon: f64 = "horizon",
        /// Gravity (m/s²).
        gravity: f64 = "gravity",
        /// Hill-climbing iterations.
        iterations: i64 = "iterations",
        /// Controllers evaluated.
        evaluations: i64 = "evaluations",
        /// The search's wall time (s).
        search_seconds: f64 = "search_seconds",
        /// Evaluations per second of wall time.
        evals_per_s: f64 = "evals_per_s",
        /// The objective of the best initial random controller.
        initial_best: f64 = "initial_best",
        /// The best objective found.
        best_objective: f64 = "best_objective",
        /// Frames of the filmstrip figure.
        filmstrip_frames: i64 = "filmstrip_frames",
    }
}

crate::result_rows! {
    /// One row of `search.csv`: one evaluation of the search.
    pub struct SearchRow {
        /// Its iteration (0: the initial random controllers).
        iteration: i64 = "iteration",
        /// Its objective.
        objective: f64 = "objective",
        /// The best objective so far.
        best: f64 = "best",
    }
}

crate::result_rows! {
    /// One row of `trajectory.csv`: one mass at one sample of the best motion.
    pub struct TrajectoryRow {
        /// The sample's time (s).
        t: f64 = "t",
        /// The regime that drove the interval ending then.
        regime: i64 = "regime",
        /// The mass's index.
        mass: i64 = "mass",
        /// Its x (m).
        x: f64 = "x",
        /// Its y (m).
        y: f64 = "y",
        /// Its height z (m).
        z: f64 = "z",
    }
}

crate::result_rows! {
    /// One row of a motion's `springs.csv`: one spring of the lattice.
    pub struct SpringRow {
        /// The spring's index.
        spring: i64 = "spring",
        /// Its first mass.
        a: i64 = "a",
        /// Its second mass.
        b: i64 = "b",
    }
}

crate::result_rows! {
    /// One row of `learning.csv`: one evaluation of one search.
    pub struct LearningRow {
        /// The search ([`super::search::Search::name`]).
        method: String = "method",
        /// Its iteration (0: the initial random controllers).
        iteration: i64 = "iteration",
        /// Its objective.
        objective: f64 = "objective",
        /// The search's best objective so far.
        best: f64 = "best",
    }
}

crate::result_rows! {
    /// One row of the learning plot's `summary.csv`: one search.
    pub struct LearningSummaryRow {
        /// The search ([`super::search::Search::name`]).
        method: String = "method",
        /// Controllers evaluated.
        evaluations: i64 = "evaluations",
        /// Its own wall time (s).
        seconds: f64 = "seconds",
        /// The wall time of both searches side by side (s).
        wall_seconds_both: f64 = "wall_seconds_both",
        /// The best objective found.
        best_objective: f64 = "best_objective",
    }
}
