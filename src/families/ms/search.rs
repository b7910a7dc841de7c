//! # The search jobs of `ms_motion` and `ms_learning`
//!
//! Mass-spring motion synthesis experiments (MS §2.3, §3, Fig. 6–9): parallel hill climbing
//! of time-based reflex controllers for one objective, on one lattice.
//!
//! Two families share the parameters [`Params`]:
//!
//! - `ms_motion` (`ms_spider_leap`, `ms_poodle_somersault`, `ms_table_pirouette`): one hill
//!   climb; tables `controller` (regime, time, reflex, reflex_name, alpha, period), `best`
//!   (term, value, weighted; one row per objective term and `total`), `measures` (measure,
//!   value: a fixed set of Table 1 quantities of the best motion, whatever the objective),
//!   `summary` (one row: motion, lattice, evaluations, search_seconds, …), `search`
//!   (iteration, objective, best), `trajectory` (t, regime, mass, x, y, z) and `springs`.
//!   Figures: `<id>_filmstrip.png/svg`, `<id>_motion.gif`, `<id>_search.png/svg`.
//! - `ms_learning` (`ms_fig6_learning_plot`): the hill climb and simulated annealing with the
//!   same evaluation budget on the same problem, run side by side; tables `learning` (method,
//!   iteration, objective, best) and `summary` (method, evaluations, seconds, best_objective).
//!   Figure: `<id>_learning.png/svg`, the scatter of every evaluation with best-so-far lines.
//!
//! The families' figures and report sections are in [`super::motion`] (`ms_motion`) and
//! [`super::fig6_learning_plot`] (`ms_learning`), files named after the experiment ids.

use super::lattices::lattice_by_name;
use super::rows::{
    BestTermRow, ControllerRow, LearningRow, LearningSummaryRow, MeasureRow, MotionSummaryRow,
    SearchRow, SpringRow, TrajectoryRow,
};
use crate::control::search::SearchResult;
use crate::experiment::output::Tables;
use crate::experiment::plot::{Mark, Panel, Series};
use crate::experiment::resolve::{ensure, positive, ParamError, Validate};
use crate::experiment::rows::table_of;
use crate::experiment::{Error, Job, RunContext};
use crate::physics::lattice::{Floor, LatticeModel};
use crate::physics::reflex::Reflex;
use crate::synthesis::controller::{Controller, SimSetup};
use crate::synthesis::objective::{Objective, Orientation, Term, Weighted};
use crate::synthesis::perturb::{MixSpec, PerturbationMix};
use crate::synthesis::search::{anneal, hill_climb, learning_curve, AnnealConfig, HillClimbConfig};
use crate::synthesis::Problem;
use crate::synthesis::BLOWUP_OBJECTIVE;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Which of the paper's motions an experiment reproduces (decides what its report checks).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Motion {
    /// Fig. 7: the spider leans back, then leaps forward, staying upright.
    Leap,
    /// Fig. 8: the poodle's backward somersault while jumping forward.
    Somersault,
    /// Fig. 9: the table's twist–twist–jump pirouette.
    Pirouette,
}

impl Motion {
    /// Every motion.
    pub const ALL: [Motion; 3] = [Motion::Leap, Motion::Somersault, Motion::Pirouette];

    /// Its name in the spec and in `summary.csv`'s `motion` column.
    pub fn name(self) -> &'static str {
        match self {
            Motion::Leap => "leap",
            Motion::Somersault => "somersault",
            Motion::Pirouette => "pirouette",
        }
    }

    /// The motion named `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }
}

/// Simulated annealing settings of `ms_learning` (see [`AnnealConfig`]).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AnnealParams {
    /// Initial temperature as a multiple of the initial objectives' standard deviation.
    pub start_temperature: f64,
    /// Final temperature, same unit.
    pub end_temperature: f64,
}

/// Parameters shared by `ms_motion` and `ms_learning`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// The motion whose claim the report checks.
    pub motion: Motion,
    /// `cube`, `pyramid` or `chair`.
    pub lattice: String,
    /// Gravity (m/s²); the paper's low gravity is [`crate::physics::lattice::LOW_GRAVITY`].
    pub gravity: f64,
    /// Coulomb friction against or across the preferred direction.
    pub friction: f64,
    /// Coulomb friction along the preferred direction.
    pub preferred_friction: f64,
    /// Preferred horizontal direction of friction (x, y).
    pub preferred_direction: [f64; 2],
    /// Regimes C per controller.
    pub regimes: usize,
    /// Period t_per (s); t_per ≥ horizon means aperiodic.
    pub period: f64,
    /// Horizon T (s).
    pub horizon: f64,
    /// Trajectory sample interval (s), also the objective's time resolution.
    pub sample_dt: f64,
    /// RK45 relative tolerance of the evaluations.
    pub rtol: f64,
    /// RK45 absolute tolerance of the evaluations.
    pub atol: f64,
    /// Search set size N (the paper: 100).
    pub set_size: usize,
    /// Hill-climbing iterations (the paper: 25,000 for Fig. 6, 15,000 recommended).
    pub iterations: usize,
    /// Iterations evaluated in parallel per batch (1 = the paper's sequential loop).
    pub batch: usize,
    /// Panels of the filmstrip.
    pub filmstrip_frames: usize,
    /// The objective (Table 1 terms with weights).
    pub objective: Objective,
    /// Simulated annealing settings (`ms_learning` only).
    #[serde(default)]
    pub anneal: Option<AnnealParams>,
    /// The perturbation probabilities: a named mix (`"table2"`, the paper's and the default;
    /// `"new_values_only"`; `"one_regime_only"`) or a table of the ten probabilities
    /// ([`PerturbationMix`]).
    #[serde(default)]
    pub perturbations: MixSpec,
}

impl Params {
    /// Checks every parameter (the lattice exists, ranges, the objective, the mix).
    // A settings check (a length > 0), no data path.
    #[allow(clippy::disallowed_methods)]
    pub fn check(&self) -> Result<(), ParamError> {
        let lattice = lattice_by_name(&self.lattice).ok_or_else(|| {
            ParamError::new(
                "lattice",
                format!("unknown lattice `{}` (cube, pyramid, chair)", self.lattice),
            )
        })?;
        positive("gravity", self.gravity)?;
        ensure(
            self.friction >= 0.0 && self.preferred_friction >= 0.0,
            "friction",
            "friction coefficients must be >= 0",
        )?;
        ensure(
            self.preferred_direction[0].hypot(self.preferred_direction[1]) > 0.0,
            "preferred_direction",
            "must be non-zero",
        )?;
        ensure(self.regimes >= 1, "regimes", "must be at least 1")?;
        positive("period", self.period)?;
        positive("horizon", self.horizon)?;
        positive("sample_dt", self.sample_dt)?;
        ensure(
            self.sample_dt <= self.horizon,
            "sample_dt",
            "must not exceed the horizon",
        )?;
        positive("rtol", self.rtol)?;
        positive("atol", self.atol)?;
        ensure(self.set_size >= 1, "set_size", "must be at least 1")?;
        ensure(self.batch >= 1, "batch", "must be at least 1")?;
        ensure(
            self.filmstrip_frames >= 1,
            "filmstrip_frames",
            "must be at least 1",
        )?;
        ensure(
            !self.objective.terms.is_empty(),
            "objective.terms",
            "need at least one term",
        )?;
        self.objective
            .validate(&lattice.rest_positions())
            .map_err(|e| ParamError::new("objective", e))?;
        self.perturbations
            .mix()
            .map_err(|e| ParamError::new("perturbations", e))?;
        if let Some(a) = &self.anneal {
            positive("anneal.start_temperature", a.start_temperature)?;
            positive("anneal.end_temperature", a.end_temperature)?;
        }
        Ok(())
    }

    /// The synthesis problem these parameters describe.
    pub fn problem(&self) -> Result<Problem, Error> {
        let lattice = lattice_by_name(&self.lattice).ok_or_else(|| super::other("lattice"))?;
        let floor = Floor {
            friction: self.friction,
            preferred_friction: self.preferred_friction,
            preferred_direction: self.preferred_direction,
            ..Floor::default()
        };
        let model = LatticeModel::new(lattice)
            .map_err(super::other)?
            .with_gravity(self.gravity)
            .with_floor(floor)
            .map_err(super::other)?;
        Ok(Problem {
            setup: SimSetup::new(model, self.horizon, self.sample_dt)
                .with_tolerances(self.rtol, self.atol),
            objective: self.objective.clone(),
        })
    }

    /// The period t_per, at most the horizon.
    pub fn period(&self) -> f64 {
        self.period.min(self.horizon)
    }

    /// The perturbation probabilities (Table 2 unless the spec says otherwise; checked by
    /// validation).
    pub fn mix(&self) -> PerturbationMix {
        self.perturbations.mix().unwrap_or_default()
    }

    /// The hill-climbing settings of these parameters.
    pub fn hill_config(&self) -> HillClimbConfig {
        HillClimbConfig {
            set_size: self.set_size,
            iterations: self.iterations,
            batch: self.batch,
            regimes: self.regimes,
            period: self.period(),
            mix: self.mix(),
        }
    }
}

/// The fixed measures reported for every motion (unit weights; see [`Term`]).
pub fn measures() -> Vec<(&'static str, Term)> {
    let loss = |o, deg| Term::OrientationLoss {
        orientation: o,
        max_angle_deg: deg,
        at_end_only: false,
    };
    let rot = |axis| Term::Rotation {
        axis,
        absolute: false,
    };
    vec![
        (
            "displacement_x",
            Term::Displacement {
                direction: [1.0, 0.0],
            },
        ),
        (
            "displacement_y",
            Term::Displacement {
                direction: [0.0, 1.0],
            },
        ),
        ("horizontal_distance", Term::HorizontalDistance),
        ("max_height", Term::MaxHeight),
        ("min_contacts", Term::MinContacts),
        ("contact_time", Term::ContactTime),
        ("rotation_x", rot([1.0, 0.0, 0.0])),
        ("rotation_back_y", rot([0.0, -1.0, 0.0])),
        ("rotation_z", rot([0.0, 0.0, 1.0])),
        ("uprightness_loss_60", loss(Orientation::Upright, 60.0)),
        ("left_right_loss_45", loss(Orientation::LeftRight, 45.0)),
        ("hops", Term::Hops),
        ("on_ground", Term::OnGround),
    ]
}

/// The [`measures`] of trajectory `tr` (unit weights; contact height and body frame of
/// `objective`), by name.
pub fn measure_values(
    objective: &Objective,
    tr: &crate::synthesis::controller::Trajectory,
) -> Vec<(&'static str, f64)> {
    let m = measures();
    let mobj = Objective {
        terms: m
            .iter()
            .map(|(_, term)| Weighted {
                weight: 1.0,
                term: term.clone(),
            })
            .collect(),
        ..objective.clone()
    };
    m.iter().map(|(n, _)| *n).zip(mobj.values(tr)).collect()
}

/// `ms_motion` parameters (no annealing).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(transparent)]
pub struct MotionJob(pub Params);
/// `ms_learning` parameters (annealing required).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(transparent)]
pub struct LearningJob(pub Params);

impl Validate for MotionJob {
    fn validate(&self) -> Result<(), ParamError> {
        self.0.check()?;
        ensure(
            self.0.anneal.is_none(),
            "anneal",
            "only the learning-plot experiment runs simulated annealing",
        )
    }
}

impl Validate for LearningJob {
    fn validate(&self) -> Result<(), ParamError> {
        self.0.check()?;
        ensure(
            self.0.anneal.is_some(),
            "anneal",
            "the learning plot needs [params.anneal]",
        )
    }
}

fn progress_fn(pb: &indicatif::ProgressBar) -> impl Fn(usize) + Sync + '_ {
    move |done| pb.set_position(done as u64)
}

/// The searches of the learning plot, as `learning.csv` names them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Search {
    /// Parallel hill climbing (the paper's).
    HillClimbing,
    /// Simulated annealing with the same budget.
    SimulatedAnnealing,
}

impl Search {
    /// Both, in table order.
    pub const ALL: [Search; 2] = [Search::HillClimbing, Search::SimulatedAnnealing];

    /// The name the tables write (`method`).
    pub fn name(self) -> &'static str {
        match self {
            Search::HillClimbing => "hill_climbing",
            Search::SimulatedAnnealing => "simulated_annealing",
        }
    }
}

/// Every evaluation of search `r`, as `search.csv` writes it.
fn search_rows(r: &SearchResult<Controller>) -> Vec<SearchRow> {
    learning_curve(r)
        .into_iter()
        .map(|e| SearchRow {
            iteration: e.iteration as i64,
            objective: e.value,
            best: e.best,
        })
        .collect()
}

impl Job for MotionJob {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(&self.0).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let p = &self.0;
        let problem = p.problem()?;
        let eval = |c: &Controller| problem.evaluate(c);
        let pb = ctx.progress(
            p.iterations as u64,
            &format!("hill climbing ({})", p.motion.name()),
        );
        let t0 = Instant::now();
        let res = ctx
            .stage("hill climbing", || {
                hill_climb(&eval, &p.hill_config(), ctx.seed, &progress_fn(&pb))
            })
            .map_err(super::other)?;
        let seconds = t0.elapsed().as_secs_f64();
        pb.finish_and_clear();
        let tr = problem.trajectory(&res.best).map_err(super::other)?;
        let mut ctl = Vec::new();
        for (i, r) in res.best.regimes.iter().enumerate() {
            ctl.push(ControllerRow {
                regime: i as i64,
                time: r.time,
                reflex: r.reflex as i64,
                reflex_name: Reflex::from_number(r.reflex).map_err(super::other)?.name(),
                alpha: r.alpha,
                period: res.best.period,
            });
        }
        let values = problem.objective.values(&tr);
        let mut best = Vec::new();
        let mut total = 0.0;
        for (w, v) in problem.objective.terms.iter().zip(&values) {
            best.push(BestTermRow {
                term: w.term.name(),
                value: *v,
                weighted: w.weight * v,
            });
            total += w.weight * v;
        }
        best.push(BestTermRow {
            term: "total".into(),
            value: total,
            weighted: total,
        });
        let meas: Vec<MeasureRow> = measure_values(&problem.objective, &tr)
            .into_iter()
            .map(|(name, value)| MeasureRow {
                measure: name.to_string(),
                value,
            })
            .collect();
        let init_best = learning_curve(&res)
            .iter()
            .filter(|e| e.iteration == 0)
            .map(|e| e.value)
            .fold(f64::NEG_INFINITY, f64::max);
        let evals = res.evaluations.len();
        let summary = MotionSummaryRow {
            motion: p.motion.name().to_string(),
            lattice: p.lattice.clone(),
            regimes: p.regimes as i64,
            period: p.period(),
            horizon: p.horizon,
            gravity: p.gravity,
            iterations: p.iterations as i64,
            evaluations: evals as i64,
            search_seconds: seconds,
            evals_per_s: evals as f64 / seconds.max(1e-9),
            initial_best: init_best,
            best_objective: -res.best_value,
            filmstrip_frames: p.filmstrip_frames as i64,
        };
        let mut traj = Vec::new();
        for f in &tr.frames {
            for (i, q) in f.positions.iter().enumerate() {
                traj.push(TrajectoryRow {
                    t: f.t,
                    regime: f.regime as i64,
                    mass: i as i64,
                    x: q[0],
                    y: q[1],
                    z: q[2],
                });
            }
        }
        let springs = &problem.setup.model.lattice.springs;
        let spr: Vec<SpringRow> = springs
            .iter()
            .enumerate()
            .map(|(j, s)| SpringRow {
                spring: j as i64,
                a: s.a as i64,
                b: s.b as i64,
            })
            .collect();
        Ok(Tables::from([
            ("controller", table_of(&ctl)),
            ("best", table_of(&best)),
            ("measures", table_of(&meas)),
            ("summary", table_of(&[summary])),
            ("search", table_of(&search_rows(&res))),
            ("trajectory", table_of(&traj)),
            ("springs", table_of(&spr)),
        ]))
    }
}

impl Job for LearningJob {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(&self.0).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let p = &self.0;
        let a = p
            .anneal
            .as_ref()
            .ok_or_else(|| super::other("missing anneal settings"))?;
        let problem = p.problem()?;
        let eval = |c: &Controller| problem.evaluate(c);
        let hc_cfg = p.hill_config();
        let sa_cfg = AnnealConfig {
            initial: p.set_size,
            iterations: p.iterations,
            start_temperature: a.start_temperature,
            end_temperature: a.end_temperature,
            regimes: p.regimes,
            period: p.period(),
            mix: p.mix(),
        };
        let pb_h = ctx.progress(p.iterations as u64, "hill climbing");
        let pb_a = ctx.progress(p.iterations as u64, "simulated annealing");
        let t0 = Instant::now();
        // Both searches run side by side on the pool (annealing is sequential; hill climbing
        // evaluates its batches in parallel on the remaining threads).
        let ((hc, hc_s), (sa, sa_s)) = ctx.stage("hill climbing + annealing", || {
            rayon::join(
                || {
                    let t = Instant::now();
                    let r = hill_climb(&eval, &hc_cfg, ctx.seed, &progress_fn(&pb_h));
                    (r, t.elapsed().as_secs_f64())
                },
                || {
                    let t = Instant::now();
                    let r = anneal(&eval, &sa_cfg, ctx.seed, &progress_fn(&pb_a));
                    (r, t.elapsed().as_secs_f64())
                },
            )
        });
        let wall = t0.elapsed().as_secs_f64();
        pb_h.finish_and_clear();
        pb_a.finish_and_clear();
        let (mut learning, mut summary) = (Vec::new(), Vec::new());
        for (search, r, s) in [
            (Search::HillClimbing, &hc, hc_s),
            (Search::SimulatedAnnealing, &sa, sa_s),
        ] {
            let r = r.as_ref().map_err(super::other)?;
            for e in learning_curve(r) {
                learning.push(LearningRow {
                    method: search.name().to_string(),
                    iteration: e.iteration as i64,
                    objective: e.value,
                    best: e.best,
                });
            }
            summary.push(LearningSummaryRow {
                method: search.name().to_string(),
                evaluations: r.evaluations.len() as i64,
                seconds: s,
                wall_seconds_both: wall,
                best_objective: -r.best_value,
            });
        }
        Ok(Tables::from([
            ("learning", table_of(&learning)),
            ("summary", table_of(&summary)),
        ]))
    }
}

/// The search-trace panel: every evaluation's objective and the best so far, per method.
/// Blow-ups (a diverged simulation scores [`BLOWUP_OBJECTIVE`]) are left out and counted in
/// the axis label; the y axis starts at the 2nd percentile of the other evaluations, so the
/// rare very poor ones do not flatten the curves, and the label says how many lie below it.
pub(super) fn learning_panel(title: &str, tables: &[(&str, &[SearchRow])], x_label: &str) -> Panel {
    learning_panel_on(title, tables, x_label, tables)
}

/// [`learning_panel`] with the y axis fitted to the evaluations of `axis_from` (panels side by
/// side on one scale).
pub(super) fn learning_panel_on(
    title: &str,
    tables: &[(&str, &[SearchRow])],
    x_label: &str,
    axis_from: &[(&str, &[SearchRow])],
) -> Panel {
    let drawn = |v: &f64| v.is_finite() && *v != BLOWUP_OBJECTIVE;
    let objectives = |ts: &[(&str, &[SearchRow])]| -> Vec<f64> {
        ts.iter()
            .flat_map(|(_, rows)| rows.iter().map(|r| r.objective))
            .collect()
    };
    let mut axis: Vec<f64> = objectives(axis_from).into_iter().filter(drawn).collect();
    axis.sort_by(f64::total_cmp);
    let lo = axis.get(axis.len() / 50).copied().unwrap_or(0.0);
    let hi = axis.last().copied().unwrap_or(1.0);
    let pad = 0.05 * (hi - lo).max(1e-9);
    let own = objectives(tables);
    let blowups = own.iter().filter(|&&v| v == BLOWUP_OBJECTIVE).count();
    let all: Vec<f64> = own.into_iter().filter(drawn).collect();
    let below = all.iter().filter(|&&v| v < lo - pad).count();
    let total = all.len() + blowups;
    let mut notes = Vec::new();
    if blowups > 0 {
        notes.push(format!(
            "{blowups} of {total} evaluations blew up, not drawn"
        ));
    }
    if below > 0 {
        notes.push(format!("{below} more lie below the axis"));
    }
    let y_label = if notes.is_empty() {
        "objective (larger is better)".to_string()
    } else {
        format!("objective (larger is better; {})", notes.join("; "))
    };
    let mut series = Vec::new();
    for (k, (name, rows)) in tables.iter().enumerate() {
        // Rows with iteration 0 are the initial random controllers: drawn at x = 0.
        series.push(
            Series::line(
                format!("{name}: every evaluation"),
                rows.iter()
                    .filter(|r| drawn(&r.objective))
                    .map(|r| (r.iteration as f64, r.objective))
                    .collect(),
                2 * k + 1,
            )
            .mark(Mark::Points),
        );
        series.push(Series::line(
            format!("{name}: best so far"),
            rows.iter()
                .filter(|r| drawn(&r.best))
                .map(|r| (r.iteration as f64, r.best))
                .collect(),
            2 * k,
        ));
    }
    Panel {
        title: title.into(),
        x_label: x_label.into(),
        y_label,
        series,
        y_range: Some((lo - pad, hi + pad)),
        ..Panel::default()
    }
}
