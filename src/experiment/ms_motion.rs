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

use super::ms_draw::{draw_panels, write_gif, LatticePanel};
use super::ms_lattices::{lattice_by_name, springs_of};
use super::output::{df_f64, df_str, read_csv, Table, Tables};
use super::plot::{Figure, Legend, Mark, Panel, Series};
use super::report::{sig, Findings, Verdict};
use super::resolve::{ensure, positive, typed_job, ParamError, Validate};
use super::{Error, Experiment, Job, RunContext};
use crate::control::search::SearchResult;
use crate::physics::lattice::{Floor, LatticeModel};
use crate::physics::reflex::Reflex;
use crate::row;
use crate::synthesis::controller::{Controller, SimSetup};
use crate::synthesis::objective::{Objective, Orientation, Term, Weighted};
use crate::synthesis::search::{anneal, hill_climb, learning_curve, AnnealConfig, HillClimbConfig};
use crate::synthesis::Problem;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};
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
    fn name(self) -> &'static str {
        match self {
            Motion::Leap => "leap",
            Motion::Somersault => "somersault",
            Motion::Pirouette => "pirouette",
        }
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
}

impl Params {
    fn check(&self) -> Result<(), ParamError> {
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

    fn period(&self) -> f64 {
        self.period.min(self.horizon)
    }

    fn hill_config(&self) -> HillClimbConfig {
        HillClimbConfig {
            set_size: self.set_size,
            iterations: self.iterations,
            batch: self.batch,
            regimes: self.regimes,
            period: self.period(),
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

/// The motion family.
pub struct MsMotion;
/// The learning-plot family.
pub struct MsLearning;

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

fn search_table(r: &SearchResult<Controller>) -> Table {
    let mut t = Table::new(&["iteration", "objective", "best"]);
    for e in learning_curve(r) {
        t.push(row![e.iteration, e.value, e.best]);
    }
    t
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
        let mut ctl = Table::new(&["regime", "time", "reflex", "reflex_name", "alpha", "period"]);
        for (i, r) in res.best.regimes.iter().enumerate() {
            let name = Reflex::from_number(r.reflex).map_err(super::other)?.name();
            ctl.push(row![i, r.time, r.reflex, name, r.alpha, res.best.period]);
        }
        let values = problem.objective.values(&tr);
        let mut best = Table::new(&["term", "value", "weighted"]);
        let mut total = 0.0;
        for (w, v) in problem.objective.terms.iter().zip(&values) {
            best.push(row![w.term.name(), *v, w.weight * v]);
            total += w.weight * v;
        }
        best.push(row!["total", total, total]);
        let mobj = Objective {
            terms: measures()
                .into_iter()
                .map(|(_, term)| Weighted { weight: 1.0, term })
                .collect(),
            ..problem.objective.clone()
        };
        let mut meas = Table::new(&["measure", "value"]);
        for ((name, _), v) in measures().iter().zip(mobj.values(&tr)) {
            meas.push(row![*name, v]);
        }
        let init_best = learning_curve(&res)
            .iter()
            .filter(|e| e.iteration == 0)
            .map(|e| e.value)
            .fold(f64::NEG_INFINITY, f64::max);
        let mut summary = Table::new(&[
            "motion",
            "lattice",
            "regimes",
            "period",
            "horizon",
            "gravity",
            "iterations",
            "evaluations",
            "search_seconds",
            "evals_per_s",
            "initial_best",
            "best_objective",
            "filmstrip_frames",
        ]);
        let evals = res.evaluations.len();
        summary.push(row![
            p.motion.name(),
            p.lattice.as_str(),
            p.regimes,
            p.period(),
            p.horizon,
            p.gravity,
            p.iterations,
            evals,
            seconds,
            evals as f64 / seconds.max(1e-9),
            init_best,
            -res.best_value,
            p.filmstrip_frames
        ]);
        let mut traj = Table::new(&["t", "regime", "mass", "x", "y", "z"]);
        for f in &tr.frames {
            for (i, q) in f.positions.iter().enumerate() {
                traj.push(row![f.t, f.regime, i, q[0], q[1], q[2]]);
            }
        }
        let mut spr = Table::new(&["spring", "a", "b"]);
        for (j, s) in problem.setup.model.lattice.springs.iter().enumerate() {
            spr.push(row![j, s.a, s.b]);
        }
        let mut t = Tables::default();
        t.insert("controller", ctl);
        t.insert("best", best);
        t.insert("measures", meas);
        t.insert("summary", summary);
        t.insert("search", search_table(&res));
        t.insert("trajectory", traj);
        t.insert("springs", spr);
        Ok(t)
    }
}

/// Frames `(t, regime, positions)` of a `trajectory` table.
fn frames_of(t: &Table) -> Vec<(f64, usize, Vec<[f64; 3]>)> {
    let (time, reg, mass) = (t.f64s("t"), t.f64s("regime"), t.f64s("mass"));
    let (x, y, z) = (t.f64s("x"), t.f64s("y"), t.f64s("z"));
    let mut out: Vec<(f64, usize, Vec<[f64; 3]>)> = Vec::new();
    for i in 0..time.len() {
        if mass[i] == 0.0 {
            out.push((time[i], reg[i] as usize, Vec::new()));
        }
        if let Some(f) = out.last_mut() {
            f.2.push([x[i], y[i], z[i]]);
        }
    }
    out
}

fn com(p: &[[f64; 3]]) -> [f64; 3] {
    // Shipped lattices have equal masses.
    let n = p.len().max(1) as f64;
    let mut c = [0.0; 3];
    for q in p {
        for k in 0..3 {
            c[k] += q[k] / n;
        }
    }
    c
}

fn learning_panel(title: &str, tables: &[(&str, &Table)], x_label: &str) -> Panel {
    let mut series = Vec::new();
    for (k, (name, t)) in tables.iter().enumerate() {
        let (it, obj, best) = (t.f64s("iteration"), t.f64s("objective"), t.f64s("best"));
        // Rows with iteration 0 are the initial random controllers: drawn at x = 0.
        series.push(
            Series::line(
                format!("{name}: every evaluation"),
                it.iter().zip(&obj).map(|(&a, &b)| (a, b)).collect(),
                2 * k + 1,
            )
            .mark(Mark::Points),
        );
        series.push(Series::line(
            format!("{name}: best so far"),
            it.iter().zip(&best).map(|(&a, &b)| (a, b)).collect(),
            2 * k,
        ));
    }
    Panel {
        title: title.into(),
        x_label: x_label.into(),
        y_label: "objective".into(),
        series,
        legend: Legend::LowerRight,
        ..Panel::default()
    }
}

impl Experiment for MsMotion {
    fn kind(&self) -> &'static str {
        "ms_motion"
    }

    fn resolve(&self, params: &toml::Value) -> Result<Box<dyn Job>, ParamError> {
        typed_job::<MotionJob>(params)
    }

    fn figures(
        &self,
        fig: &super::plot::FigureSink,
        tables: &Tables,
    ) -> Result<Vec<PathBuf>, Error> {
        let springs = springs_of(tables.require("springs")?, None);
        let frames = frames_of(tables.require("trajectory")?);
        let ctl = tables.require("controller")?;
        let names = ctl.strs("reflex_name");
        let alphas = ctl.f64s("alpha");
        let trail: Vec<[f64; 3]> = frames.iter().map(|f| com(&f.2)).collect();
        let label = |reg: usize| {
            format!(
                "{} {:+.2}",
                names.get(reg).map(String::as_str).unwrap_or("?"),
                alphas.get(reg).copied().unwrap_or(f64::NAN)
            )
        };
        let mut files = Vec::new();
        if frames.is_empty() {
            return Ok(files);
        }
        let strip = (tables
            .require("summary")?
            .f64s("filmstrip_frames")
            .first()
            .copied()
            .unwrap_or(8.0) as usize)
            .clamp(1, frames.len());
        let picks: Vec<usize> = (0..strip)
            .map(|i| {
                if strip == 1 {
                    frames.len() - 1
                } else {
                    i * (frames.len() - 1) / (strip - 1)
                }
            })
            .collect();
        let panels: Vec<LatticePanel> = picks
            .iter()
            .map(|&i| LatticePanel {
                title: format!("t = {:.2} s, {}", frames[i].0, label(frames[i].1)),
                positions: frames[i].2.clone(),
                ghost: None,
                trail: trail[..=i].to_vec(),
            })
            .collect();
        files.extend(draw_panels(
            &fig.dir,
            &format!("{}_filmstrip", fig.id),
            &panels,
            &springs,
            4,
            (360, 300),
            true,
        )?);
        // GIF in real time with at most ~100 frames.
        let dt = if frames.len() > 1 {
            frames[1].0 - frames[0].0
        } else {
            0.04
        };
        let every = frames.len().div_ceil(100).max(1);
        let gif_frames: Vec<(String, Vec<[f64; 3]>)> = frames
            .iter()
            .step_by(every)
            .map(|f| {
                (
                    format!("{}  t = {:.2} s  {}", fig.id, f.0, label(f.1)),
                    f.2.clone(),
                )
            })
            .collect();
        let delay = ((every as f64 * dt * 1000.0).round() as u32).max(20);
        let gif_trail: Vec<[f64; 3]> = trail.iter().step_by(every).copied().collect();
        files.push(write_gif(
            &fig.dir,
            &format!("{}_motion", fig.id),
            &gif_frames,
            &gif_trail,
            &springs,
            (560, 420),
            delay,
        )?);
        let search = tables.require("search")?;
        files.extend(fig.draw(
            "search",
            &Figure::grid(
                vec![learning_panel(
                    "hill climbing: objective of every evaluation",
                    &[("hill climbing", search)],
                    "iteration (0: initial random controllers)",
                )],
                1,
            ),
        )?);
        Ok(files)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        let s = read_csv(&dir.join("summary.csv"))?;
        let motion = df_str(&s, "motion")?.first().cloned().unwrap_or_default();
        let get1 = |c: &str| -> Result<f64, Error> {
            Ok(df_f64(&s, c)?.first().copied().unwrap_or(f64::NAN))
        };
        let (evals, secs, best, init) = (
            get1("evaluations")?,
            get1("search_seconds")?,
            get1("best_objective")?,
            get1("initial_best")?,
        );
        let m = read_csv(&dir.join("measures.csv"))?;
        let names = df_str(&m, "measure")?;
        let vals = df_f64(&m, "value")?;
        let mv = |n: &str| {
            names
                .iter()
                .position(|x| x == n)
                .map(|i| vals[i])
                .unwrap_or(f64::NAN)
        };
        let b = read_csv(&dir.join("best.csv"))?;
        let (bt, bv, bw) = (
            df_str(&b, "term")?,
            df_f64(&b, "value")?,
            df_f64(&b, "weighted")?,
        );
        let mut md = String::from("| objective term | value | weighted |\n| --- | --- | --- |\n");
        for i in 0..bt.len() {
            md.push_str(&format!(
                "| {} | {} | {} |\n",
                bt[i],
                sig(bv[i]),
                sig(bw[i])
            ));
        }
        md.push_str("\n| measure of the best motion | value |\n| --- | --- |\n");
        for (n, v) in names.iter().zip(&vals) {
            md.push_str(&format!("| {n} | {} |\n", sig(*v)));
        }
        md.push_str(&format!(
            "\nSearch: {} evaluations in {} s ({} evaluations/s); best of the initial random set {}, final best {}.\n",
            evals,
            sig(secs),
            sig(evals / secs.max(1e-9)),
            sig(init),
            sig(best)
        ));
        let upright = mv("uprightness_loss_60") == 0.0;
        let airborne = mv("hops") >= 1.0 || mv("min_contacts") == 0.0;
        let (verdict, why) = match motion.as_str() {
            "leap" => {
                let d = mv("displacement_x");
                let v = if d > 1.0 && upright && airborne {
                    Verdict::Held
                } else if d > 0.3 && upright {
                    Verdict::Partly
                } else {
                    Verdict::NotHeld
                };
                (
                    v,
                    format!(
                        "The spider travels {} m along +x (1 m = its base width), stays upright: {}, leaves the ground: {}.",
                        sig(d),
                        upright,
                        airborne
                    ),
                )
            }
            "somersault" => {
                let r = mv("rotation_back_y");
                let d = mv("displacement_x");
                let ground = mv("on_ground") == 1.0;
                let lr = mv("left_right_loss_45") == 0.0;
                let v = if r >= 0.9 * 2.0 * PI && d > 0.0 && ground && lr {
                    Verdict::Held
                } else if r >= PI && d > 0.0 {
                    Verdict::Partly
                } else {
                    Verdict::NotHeld
                };
                (
                    v,
                    format!(
                        "Backward rotation {} turns while moving {} m forward; on the ground at T: {}; no rolling/turning beyond 45°: {}.",
                        sig(r / (2.0 * PI)),
                        sig(d),
                        ground,
                        lr
                    ),
                )
            }
            _ => {
                let r = mv("rotation_z").abs();
                let ground = mv("on_ground") == 1.0;
                let v = if r >= PI && upright && ground && airborne {
                    Verdict::Held
                } else if r >= PI / 4.0 && upright {
                    Verdict::Partly
                } else {
                    Verdict::NotHeld
                };
                (
                    v,
                    format!(
                        "The table turns {}° about the vertical, stays upright: {}, jumps: {}, on the ground at T: {}, drifts {} m.",
                        sig(r.to_degrees()),
                        upright,
                        airborne,
                        ground,
                        sig(mv("horizontal_distance"))
                    ),
                )
            }
        };
        Ok(Findings {
            ours: md,
            verdict,
            why,
        })
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
        let mut learning = Table::new(&["method", "iteration", "objective", "best"]);
        let mut summary = Table::new(&[
            "method",
            "evaluations",
            "seconds",
            "wall_seconds_both",
            "best_objective",
        ]);
        for (name, r, s) in [
            ("hill_climbing", &hc, hc_s),
            ("simulated_annealing", &sa, sa_s),
        ] {
            let r = r.as_ref().map_err(super::other)?;
            for e in learning_curve(r) {
                learning.push(row![name, e.iteration, e.value, e.best]);
            }
            summary.push(row![name, r.evaluations.len(), s, wall, -r.best_value]);
        }
        let mut t = Tables::default();
        t.insert("learning", learning);
        t.insert("summary", summary);
        Ok(t)
    }
}

/// Learning-curve statistics of one method from `learning.csv` columns.
struct Curve {
    init_best: f64,
    at_fifth: f64,
    end_best: f64,
    poor_late: f64,
    iterations: f64,
}

fn curve(method: &str, m: &[String], it: &[f64], obj: &[f64], best: &[f64]) -> Curve {
    let rows: Vec<usize> = (0..m.len()).filter(|&i| m[i] == method).collect();
    let iterations = rows.iter().map(|&i| it[i]).fold(0.0, f64::max);
    let best_at = |limit: f64| {
        rows.iter()
            .filter(|&&i| it[i] <= limit)
            .map(|&i| best[i])
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let init_best = best_at(0.0);
    let late: Vec<usize> = rows
        .iter()
        .copied()
        .filter(|&i| it[i] > 0.8 * iterations)
        .collect();
    let poor = late.iter().filter(|&&i| obj[i] < init_best).count() as f64;
    Curve {
        init_best,
        at_fifth: best_at(iterations / 5.0),
        end_best: best_at(iterations),
        poor_late: poor / late.len().max(1) as f64,
        iterations,
    }
}

impl Experiment for MsLearning {
    fn kind(&self) -> &'static str {
        "ms_learning"
    }

    fn resolve(&self, params: &toml::Value) -> Result<Box<dyn Job>, ParamError> {
        typed_job::<LearningJob>(params)
    }

    fn figures(
        &self,
        fig: &super::plot::FigureSink,
        tables: &Tables,
    ) -> Result<Vec<PathBuf>, Error> {
        let t = tables.require("learning")?;
        let methods = t.strs("method");
        let split = |name: &str| {
            let mut out = Table::new(&["iteration", "objective", "best"]);
            let (it, o, b) = (t.f64s("iteration"), t.f64s("objective"), t.f64s("best"));
            for i in 0..methods.len() {
                if methods[i] == name {
                    out.push(row![it[i], o[i], b[i]]);
                }
            }
            out
        };
        let (h, s) = (split("hill_climbing"), split("simulated_annealing"));
        // The y range: from a low quantile of all evaluations to above the best (blown-up or
        // very poor evaluations would squash the plot otherwise).
        let mut all: Vec<f64> = t
            .f64s("objective")
            .into_iter()
            .filter(|v| v.is_finite())
            .collect();
        all.sort_by(f64::total_cmp);
        let lo = all.get(all.len() / 50).copied().unwrap_or(0.0);
        let hi = all.last().copied().unwrap_or(1.0);
        let pad = 0.05 * (hi - lo).max(1e-9);
        let mut panel = learning_panel(
            "learning plot: poodle somersault (Fig. 6)",
            &[("hill climbing", &h), ("simulated annealing", &s)],
            "iteration (0: initial random controllers)",
        );
        panel.y_range = Some((lo - pad, hi + pad));
        let mut fig6 = Figure::grid(vec![panel], 1);
        fig6.panel_size = (960, 560);
        fig.draw("learning", &fig6)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        let df = read_csv(&dir.join("learning.csv"))?;
        let (m, it, obj, best) = (
            df_str(&df, "method")?,
            df_f64(&df, "iteration")?,
            df_f64(&df, "objective")?,
            df_f64(&df, "best")?,
        );
        let s = read_csv(&dir.join("summary.csv"))?;
        let (sm, secs, evals) = (
            df_str(&s, "method")?,
            df_f64(&s, "seconds")?,
            df_f64(&s, "evaluations")?,
        );
        let wall = df_f64(&s, "wall_seconds_both")?
            .first()
            .copied()
            .unwrap_or(f64::NAN);
        let h = curve("hill_climbing", &m, &it, &obj, &best);
        let a = curve("simulated_annealing", &m, &it, &obj, &best);
        let frac = |c: &Curve| (c.at_fifth - c.init_best) / (c.end_best - c.init_best).max(1e-12);
        let mut md = String::from(
            "| method | evaluations | seconds | best of initial set | best at 1/5 of the iterations | final best | share of the gain by 1/5 | evaluations in the last 1/5 worse than the initial best |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n",
        );
        for (name, c) in [("hill_climbing", &h), ("simulated_annealing", &a)] {
            let k = sm.iter().position(|x| x == name);
            md.push_str(&format!(
                "| {name} | {} | {} | {} | {} | {} | {} | {} |\n",
                k.map(|k| evals[k]).unwrap_or(f64::NAN),
                sig(k.map(|k| secs[k]).unwrap_or(f64::NAN)),
                sig(c.init_best),
                sig(c.at_fifth),
                sig(c.end_best),
                sig(frac(c)),
                sig(c.poor_late)
            ));
        }
        md.push_str(&format!(
            "\nBoth searches ran side by side in {} s of wall time ({} iterations each; the paper: 25,000 iterations in 66 min on a DEC 3000/400 AXP).\n",
            sig(wall),
            h.iterations
        ));
        let fast_then_slow = frac(&h) >= 0.6 && h.end_best > h.init_best;
        let many_poor = h.poor_late >= 0.2;
        let verdict = match (fast_then_slow, many_poor) {
            (true, true) => Verdict::Held,
            (false, false) => Verdict::NotHeld,
            _ => Verdict::Partly,
        };
        Ok(Findings {
            ours: md,
            verdict,
            why: format!(
                "Hill climbing made {}% of its total gain in the first fifth of the iterations (fast, then slow: {}); {}% of its evaluations in the last fifth were worse than the best random controller (many stay poor: {}); simulated annealing with the same budget ended at {} vs {}.",
                sig(100.0 * frac(&h)),
                fast_then_slow,
                sig(100.0 * h.poor_late),
                many_poor,
                sig(a.end_best),
                sig(h.end_best)
            ),
        })
    }
}
