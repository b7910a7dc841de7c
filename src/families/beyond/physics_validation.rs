//! `physics_validation`: can the simulators be trusted? Energy drift of the frictionless
//! 3-link pendulum and the acrobot vs time step for each integrator (measured convergence order
//! beside the theoretical one), drift of the adaptive RK45 vs tolerance, and passive motion from
//! a few start states.
//!
//! Tables: `energy_drift` (model, integrator, dt, drift), `orders` (model, integrator,
//! theoretical_order, measured_order, points_used), `adaptive` (model, rtol, atol, drift,
//! accepted_steps, rejected_steps, evaluations), `passive_<model>` (start, t, state…, energy).

use crate::experiment::output::{unique, Table, Tables};
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::report::{sig, Findings};
use crate::experiment::resolve::{all_positive, distinct, ensure, positive, ParamError, Validate};
use crate::experiment::rows::{read_rows, table_of, TableRow};
use crate::experiment::rule::{
    rule_settings, rule_table, shown, Check, Cmp, Null, Outcome, Partly, Rule,
};
use crate::experiment::{Error, Family, Job, RunContext};
use crate::physics::acrobot::Acrobot;
use crate::physics::pendulum::{Pendulum3, PendulumVariant};
use crate::physics::{Integrator, IntegratorKind, Model, Ode, Simulator};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The family.
pub struct PhysicsValidation;

/// Parameters of `physics_validation`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Models: `pendulum3` (run frictionless and passive) and/or `acrobot` (no torque).
    pub models: Vec<String>,
    /// Fixed-step integrators for the order study.
    pub integrators: Vec<String>,
    /// Time steps of the order study (s).
    pub dts: Vec<f64>,
    /// Simulated time of each drift measurement (s).
    pub duration: f64,
    /// Relative tolerances of the adaptive RK45 study (atol = rtol · atol_ratio).
    pub tolerances: Vec<f64>,
    /// atol / rtol of the adaptive study.
    #[serde(default = "default_atol_ratio")]
    pub atol_ratio: f64,
    /// Outer interval at which the adaptive integrator is sampled (s).
    #[serde(default = "default_interval")]
    pub adaptive_interval: f64,
    /// Start state of the drift study, per model.
    pub drift_start: BTreeMap<String, Vec<f64>>,
    /// Start states of the passive-motion plots, per model.
    pub passive_starts: BTreeMap<String, Vec<Vec<f64>>>,
    /// Duration of the passive-motion runs (s).
    pub passive_duration: f64,
    /// Time step of the passive-motion runs (s, RK4).
    pub passive_dt: f64,
    /// Drifts below this are round-off and left out of the order fit (J).
    #[serde(default = "default_floor")]
    pub fit_floor: f64,
    /// The verdict's bar (ours): a measured order within this of theory.
    pub rule: OrderRule,
}

/// The verdict's bar (ours).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OrderRule {
    /// A measured energy-drift order passes within this of the theoretical order; below 1, so
    /// an integrator one order off fails.
    pub order_tolerance: f64,
}

/// An integrator one order off: the null of every order check.
const ONE_ORDER_OFF: f64 = 1.0;

fn default_atol_ratio() -> f64 {
    1e-3
}
fn default_interval() -> f64 {
    0.1
}
fn default_floor() -> f64 {
    1e-12
}

/// The frictionless, torque-free version of a registry model used here.
pub fn conservative_model(name: &str) -> Option<Box<dyn Ode>> {
    match name {
        "pendulum3" | "pendulum3_passive" | "pendulum3_ext" => Some(Box::new(
            Pendulum3::new(PendulumVariant::Passive).frictionless(),
        )),
        "acrobot" => Some(Box::new(Acrobot::default())),
        _ => None,
    }
}

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        ensure(!self.models.is_empty(), "models", "must not be empty")?;
        let t = self.rule.order_tolerance;
        ensure(
            t > 0.0 && t < ONE_ORDER_OFF,
            "rule.order_tolerance",
            "must be in (0, 1): an integrator one order off must fail",
        )?;
        for (i, m) in self.models.iter().enumerate() {
            let model = conservative_model(m).ok_or_else(|| {
                ParamError::new(
                    format!("models[{i}]"),
                    format!("unknown model `{m}` (this experiment knows pendulum3, acrobot)"),
                )
            })?;
            let n = model.state_dim();
            let start = self.drift_start.get(m).ok_or_else(|| {
                ParamError::new("drift_start", format!("no start state for `{m}`"))
            })?;
            ensure(
                start.len() == n,
                &format!("drift_start.{m}"),
                format!("needs {n} values, got {}", start.len()),
            )?;
            let starts = self.passive_starts.get(m).ok_or_else(|| {
                ParamError::new("passive_starts", format!("no start states for `{m}`"))
            })?;
            for (j, s) in starts.iter().enumerate() {
                ensure(
                    s.len() == n,
                    &format!("passive_starts.{m}[{j}]"),
                    format!("needs {n} values, got {}", s.len()),
                )?;
            }
        }
        ensure(
            !self.integrators.is_empty(),
            "integrators",
            "must not be empty",
        )?;
        for (i, name) in self.integrators.iter().enumerate() {
            let k = IntegratorKind::from_name(name);
            ensure(
                k.is_some(),
                &format!("integrators[{i}]"),
                format!(
                    "unknown integrator `{name}` (known: euler, semi_implicit_euler, rk4, dopri5)"
                ),
            )?;
            ensure(
                k != Some(IntegratorKind::Rk45),
                &format!("integrators[{i}]"),
                "the adaptive rk45 is studied against `tolerances`, not time steps",
            )?;
        }
        distinct("models", &self.models)?;
        distinct("integrators", &self.integrators)?;
        all_positive("dts", &self.dts)?;
        distinct("dts", &self.dts)?;
        positive("duration", self.duration)?;
        all_positive("tolerances", &self.tolerances)?;
        distinct("tolerances", &self.tolerances)?;
        positive("atol_ratio", self.atol_ratio)?;
        positive("adaptive_interval", self.adaptive_interval)?;
        positive("passive_duration", self.passive_duration)?;
        positive("passive_dt", self.passive_dt)?;
        positive("fit_floor", self.fit_floor)?;
        for (i, &dt) in self.dts.iter().enumerate() {
            ensure(
                dt <= self.duration,
                &format!("dts[{i}]"),
                format!(
                    "time step {dt} s is longer than duration {} s",
                    self.duration
                ),
            )?;
        }
        Ok(())
    }
}

/// Max |E(t) − E(0)| over `duration` from `x0` with a fixed step; `inf` if it blew up.
pub fn energy_drift(
    model: &dyn Ode,
    kind: IntegratorKind,
    x0: &[f64],
    dt: f64,
    duration: f64,
) -> f64 {
    let e0 = model.energy(x0).expect("conservative model defines energy");
    let steps = (duration / dt).round().max(1.0) as usize;
    let mut integ = Integrator::new(kind, x0.len());
    let mut x = x0.to_vec();
    let u = vec![0.0; model.control_dim()];
    let mut drift: f64 = 0.0;
    for _ in 0..steps {
        integ.step(model, &mut x, &u, dt);
        if x.iter().any(|v| !v.is_finite()) {
            return f64::INFINITY;
        }
        drift = drift.max((model.energy(&x).unwrap_or(f64::NAN) - e0).abs());
    }
    drift
}

/// Least-squares slope of log(drift) against log(dt), over points above `floor`.
pub fn fitted_order(dts: &[f64], drifts: &[f64], floor: f64) -> (f64, usize) {
    let pts: Vec<(f64, f64)> = dts
        .iter()
        .zip(drifts)
        .filter(|(_, &d)| d.is_finite() && d > floor)
        .map(|(&h, &d)| (crate::portable::ln(h), crate::portable::ln(d)))
        .collect();
    let n = pts.len();
    if n < 2 {
        return (f64::NAN, n);
    }
    let mx = pts.iter().map(|p| p.0).sum::<f64>() / n as f64;
    let my = pts.iter().map(|p| p.1).sum::<f64>() / n as f64;
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    (sxy / sxx, n)
}

crate::result_rows! {
    /// One row of `energy_drift.csv`: one integrator at one step on one model.
    pub struct DriftRow {
        /// The model's name.
        model: String = "model",
        /// The integrator's name ([`IntegratorKind::name`]).
        integrator: String = "integrator",
        /// The time step (s).
        dt: f64 = "dt",
        /// max |E(t) − E(0)| over the run (J).
        drift: f64 = "drift",
    }
}

crate::result_rows! {
    /// One row of `orders.csv`: one integrator's drift order on one model.
    pub struct OrderRow {
        /// The model's name.
        model: String = "model",
        /// The integrator's name.
        integrator: String = "integrator",
        /// Its order in theory.
        theoretical_order: i64 = "theoretical_order",
        /// The slope of log drift against log dt.
        measured_order: f64 = "measured_order",
        /// The points above the fit's floor.
        points_used: i64 = "points_used",
    }
}

crate::result_rows! {
    /// One row of `adaptive.csv`: adaptive RK45 at one tolerance on one model.
    pub struct AdaptiveRow {
        /// The model's name.
        model: String = "model",
        /// The relative tolerance.
        rtol: f64 = "rtol",
        /// The absolute tolerance.
        atol: f64 = "atol",
        /// max |E(t) − E(0)| over the run (J).
        drift: f64 = "drift",
        /// Steps accepted.
        accepted_steps: i64 = "accepted_steps",
        /// Steps rejected.
        rejected_steps: i64 = "rejected_steps",
        /// Right-hand side evaluations.
        evaluations: i64 = "evaluations",
    }
}

crate::result_rows! {
    /// The leading columns of a row of `passive_<model>.csv`: one start's passive motion at
    /// one time; the state follows in one column per state variable (named as `describe`
    /// names them), then the energy.
    pub struct PassiveRow {
        /// The start's index among the spec's `passive_starts`.
        start: i64 = "start",
        /// Time (s).
        t_s: f64 = "t",
    }
}

/// The states of a `passive_<model>` table's rows, their variables named `names`.
fn states_of(t: &Table, names: &[String]) -> Vec<Vec<f64>> {
    let columns: Vec<Vec<f64>> = names.iter().map(|c| t.f64s(c)).collect();
    (0..t.len())
        .map(|r| columns.iter().map(|c| c[r]).collect())
        .collect()
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let kinds: Vec<IntegratorKind> = self
            .integrators
            .iter()
            .filter_map(|n| IntegratorKind::from_name(n))
            .collect();
        // Order study: every (model, integrator, dt) is independent.
        let items: Vec<(usize, IntegratorKind, f64)> = (0..self.models.len())
            .flat_map(|m| {
                kinds
                    .iter()
                    .flat_map(move |&k| self.dts.iter().map(move |&dt| (m, k, dt)))
            })
            .collect();
        let pb = ctx.progress(items.len() as u64, "energy drift vs dt");
        let drifts: Vec<f64> = ctx.stage("energy drift", || {
            items
                .par_iter()
                .map(|&(m, k, dt)| {
                    let name = &self.models[m];
                    let model = conservative_model(name).expect("validated");
                    let d = energy_drift(&*model, k, &self.drift_start[name], dt, self.duration);
                    pb.inc(1);
                    d
                })
                .collect()
        });
        pb.finish_and_clear();
        let drift_t: Vec<DriftRow> = items
            .iter()
            .zip(&drifts)
            .map(|(&(m, k, dt), &drift)| DriftRow {
                model: self.models[m].clone(),
                integrator: k.name().to_string(),
                dt,
                drift,
            })
            .collect();
        let mut orders = Vec::new();
        for (m, name) in self.models.iter().enumerate() {
            for &k in &kinds {
                let d: Vec<f64> = items
                    .iter()
                    .zip(&drifts)
                    .filter(|((mm, kk, _), _)| *mm == m && *kk == k)
                    .map(|(_, &d)| d)
                    .collect();
                let (order, used) = fitted_order(&self.dts, &d, self.fit_floor);
                orders.push(OrderRow {
                    model: name.clone(),
                    integrator: k.name().to_string(),
                    theoretical_order: i64::from(k.order()),
                    measured_order: order,
                    points_used: used as i64,
                });
            }
        }
        // Adaptive RK45 vs tolerance.
        let ad_items: Vec<(usize, f64)> = (0..self.models.len())
            .flat_map(|m| self.tolerances.iter().map(move |&t| (m, t)))
            .collect();
        let adaptive: Vec<(f64, crate::physics::Rk45Stats)> = ctx.stage("adaptive rk45", || {
            ad_items
                .par_iter()
                .map(|&(m, rtol)| {
                    let name = &self.models[m];
                    let model = conservative_model(name).expect("validated");
                    let x0 = &self.drift_start[name];
                    let e0 = model.energy(x0).expect("energy");
                    let mut integ = Integrator::new(IntegratorKind::Rk45, x0.len())
                        .with_tolerances(rtol, rtol * self.atol_ratio);
                    let mut x = x0.clone();
                    let steps = (self.duration / self.adaptive_interval).round().max(1.0) as usize;
                    let mut drift: f64 = 0.0;
                    let u = vec![0.0; model.control_dim()];
                    for _ in 0..steps {
                        integ.step(&*model, &mut x, &u, self.adaptive_interval);
                        drift = drift.max((model.energy(&x).unwrap_or(f64::NAN) - e0).abs());
                    }
                    (drift, integ.stats())
                })
                .collect()
        });
        let ad_t: Vec<AdaptiveRow> = ad_items
            .iter()
            .zip(&adaptive)
            .map(|(&(m, rtol), (d, s))| AdaptiveRow {
                model: self.models[m].clone(),
                rtol,
                atol: rtol * self.atol_ratio,
                drift: *d,
                accepted_steps: s.accepted as i64,
                rejected_steps: s.rejected as i64,
                evaluations: s.evaluations as i64,
            })
            .collect();
        let mut tables = Tables::default();
        tables.insert("energy_drift", table_of(&drift_t));
        tables.insert("orders", table_of(&orders));
        tables.insert(
            "rule",
            rule_table(&[("order_tolerance", self.rule.order_tolerance)]),
        );
        tables.insert("adaptive", table_of(&ad_t));
        // Passive motion.
        ctx.stage("passive motion", || -> Result<(), Error> {
            for name in &self.models {
                let model = conservative_model(name).expect("validated");
                let names = model.state_names();
                let mut cols: Vec<&str> = PassiveRow::COLUMNS.to_vec();
                cols.extend(names.iter().map(String::as_str));
                cols.push("energy");
                let mut t = Table::new(&cols);
                let steps = (self.passive_duration / self.passive_dt).round() as usize;
                let runs: Vec<Result<Vec<(f64, Vec<f64>)>, Error>> = self.passive_starts[name]
                    .par_iter()
                    .map(|x0| {
                        let model = conservative_model(name).expect("validated");
                        let mut sim = Simulator::new(model, IntegratorKind::Rk4);
                        let mut traj = Vec::with_capacity(steps + 1);
                        sim.rollout(
                            x0,
                            self.passive_dt,
                            steps,
                            |_, _, _, _| {},
                            |_, t, x| traj.push((t, x.to_vec())),
                        )?;
                        Ok(traj)
                    })
                    .collect();
                for (j, run) in runs.into_iter().enumerate() {
                    for (time, x) in run? {
                        let lead = PassiveRow {
                            start: j as i64,
                            t_s: time,
                        };
                        let mut r = lead.cells();
                        r.extend(x.iter().map(|&v| v.into()));
                        r.push(model.energy(&x).unwrap_or(f64::NAN).into());
                        t.push(r);
                    }
                }
                tables.insert(&format!("passive_{name}"), t);
            }
            Ok(())
        })?;
        Ok(tables)
    }
}

impl Family for PhysicsValidation {
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "energy_drift",
            "energy drift after a fixed time vs time step (log-log) for each integrator on the frictionless 3-link pendulum and the acrobot, beside lines of the theoretical order.",
        ),
        (
            "adaptive",
            "adaptive RK45: energy drift and step count vs tolerance.",
        ),
        (
            "passive_pendulum3",
            "passive motion of the frictionless 3-link pendulum (RK4 at the spec's passive_dt), joint angles vs time from each of the spec's start states (in each panel's title).",
        ),
        (
            "passive_acrobot",
            "passive motion of the acrobot without torque (RK4 at the spec's passive_dt), joint angles vs time from each of the spec's start states (in each panel's title).",
        ),
    ];
    const CHECK: bool = true;
    const KIND: &'static str = "physics_validation";
    type Params = Params;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        let mut files = Vec::new();
        let drift = DriftRow::from_table(tables.require("energy_drift")?);
        let orders = OrderRow::from_table(tables.require("orders")?);
        let models = unique(&drift.iter().map(|r| r.model.clone()).collect::<Vec<_>>());
        files.extend(fig.draw("energy_drift", &drift_figure(&drift, &orders, &models))?);
        if let Some(ad) = tables.get("adaptive") {
            files.extend(fig.draw("adaptive", &adaptive_figure(&AdaptiveRow::from_table(ad)))?);
        }
        for m in &models {
            let Some(t) = tables.get(&format!("passive_{m}")) else {
                continue;
            };
            let Some(model) = conservative_model(m) else {
                continue;
            };
            let names = model.state_names();
            let nq = model.position_dim().unwrap_or(names.len());
            let lead = PassiveRow::from_table(t);
            let states = states_of(t, &names);
            let n_starts = lead.iter().map(|r| r.start).max().unwrap_or(0) as usize + 1;
            let mut panels = Vec::new();
            for s in 0..n_starts {
                let rows: Vec<usize> = (0..lead.len())
                    .filter(|&r| lead[r].start as usize == s)
                    .collect();
                let series = names[..nq]
                    .iter()
                    .enumerate()
                    .map(|(c, n)| {
                        Series::line(
                            format!("{n} (rad)"),
                            rows.iter().map(|&r| (lead[r].t_s, states[r][c])).collect(),
                            c,
                        )
                    })
                    .collect();
                // The start state, read from the first row of this start (t = 0): its angles,
                // and its rates where any is not zero.
                let x0: Vec<f64> = rows.first().map(|&r| states[r].clone()).unwrap_or_default();
                let list = |v: &[f64]| {
                    v.iter()
                        .map(|x| format!("{x:.2}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                };
                let (q0, v0) = x0.split_at(nq.min(x0.len()));
                let start = if v0.iter().all(|&v| v == 0.0) {
                    format!("q = ({}) rad at rest", list(q0))
                } else {
                    format!("q = ({}) rad, q' = ({}) rad/s", list(q0), list(v0))
                };
                panels.push(Panel {
                    title: format!("{m}: passive motion from {start}"),
                    x_label: "time (s)".into(),
                    y_label: "joint angle (rad)".into(),
                    series,
                    ..Default::default()
                });
            }
            files.extend(fig.draw(&format!("passive_{m}"), &Figure::grid(panels, 3))?);
        }
        Ok(files)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        let orders: Vec<OrderRow> = read_rows(&dir.join("orders.csv"))?;
        let mut md = String::from("| model | integrator | theoretical order | measured order |\n| --- | --- | --- | --- |\n");
        let tolerance = rule_settings(dir)?("order_tolerance");
        let mut held = Vec::new();
        for o in &orders {
            let (t, v) = (o.theoretical_order as f64, o.measured_order);
            held.push(Check::new(
                format!(
                    "{} {}: |measured − theoretical order|",
                    o.model, o.integrator
                ),
                (t - v).abs(),
                Cmp::AtMost,
                tolerance,
                Null::new("an integrator one order off", ONE_ORDER_OFF),
            ));
            md.push_str(&format!(
                "| {} | {} | {} | {} |\n",
                o.model,
                o.integrator,
                t,
                sig(v)
            ));
        }
        // Adaptive: does drift fall as the tolerance tightens?
        let adaptive: Vec<AdaptiveRow> = read_rows(&dir.join("adaptive.csv"))?;
        // Per model (sorted by name): the tightest and loosest tolerance's drift.
        let mut per_model: std::collections::BTreeMap<String, (f64, f64)> = Default::default();
        for a in adaptive {
            let d = a.drift;
            let e = per_model
                .entry(a.model)
                .or_insert((f64::INFINITY, f64::NEG_INFINITY));
            *e = (e.0.min(d), e.1.max(d));
        }
        md.push_str("\nAdaptive RK45 over the tolerance sweep: ");
        let parts: Vec<String> = per_model
            .iter()
            .map(|(m, (best, worst))| {
                format!(
                    "{m} drift from {} J (loosest) to {} J (tightest)",
                    sig(*worst),
                    sig(*best)
                )
            })
            .collect();
        md.push_str(&parts.join("; "));
        md.push('.');
        let rule = Rule::gated(vec![], held, Partly::Any);
        let (ok, total) = rule.as_ref().map_or((0, 0), |r| {
            let pass = r.held.iter().filter(|c| c.outcome() == Outcome::Pass);
            (pass.count(), r.held.len())
        });
        let (verdict, _, text) = shown(
            rule.as_ref(),
            "No rule: the order tolerance is not below one order.",
        );
        Ok(Findings {
            ours: md,
            verdict,
            rule: rule.clone(),
            why: format!(
                "{ok} of {total} measured energy-drift orders are within {} of theory. Rule (bar ours, in the spec's [params.rule]): {text}",
                sig(tolerance)
            ),
        })
    }
}

/// Per model, the energy drift against the time step for every integrator (from
/// `energy_drift`), labelled with its measured order (from `orders`) and the theory's.
fn drift_figure(drift: &[DriftRow], orders: &[OrderRow], models: &[String]) -> Figure {
    let integrators = unique(
        &drift
            .iter()
            .map(|r| r.integrator.clone())
            .collect::<Vec<_>>(),
    );
    let mut panels = Vec::new();
    for m in models {
        let mut series = Vec::new();
        for (c, integ) in integrators.iter().enumerate() {
            let pts: Vec<(f64, f64)> = drift
                .iter()
                .filter(|r| r.model == *m && r.integrator == *integ)
                .map(|r| (r.dt, r.drift))
                .collect();
            let order = orders
                .iter()
                .find(|r| r.model == *m && r.integrator == *integ)
                .map_or(f64::NAN, |r| r.measured_order);
            let theory = IntegratorKind::from_name(integ)
                .map(|k| k.order())
                .unwrap_or(0);
            series.push(
                Series::line(
                    format!("{integ}: slope {order:.2} (theory {theory})"),
                    pts,
                    c,
                )
                .mark(Mark::LinePoints),
            );
        }
        panels.push(Panel {
            title: format!("{m}: energy drift vs time step"),
            x_label: "time step dt (s)".into(),
            y_label: "max |E(t) - E(0)| (J)".into(),
            log_x: true,
            log_y: true,
            series,
            ..Panel::default()
        });
    }
    Figure::grid(panels, 2)
}

/// Adaptive RK45's energy drift and accepted steps against its tolerance (from `adaptive`).
fn adaptive_figure(ad: &[AdaptiveRow]) -> Figure {
    let models = unique(&ad.iter().map(|r| r.model.clone()).collect::<Vec<_>>());
    let mut drift_series = Vec::new();
    let mut step_series = Vec::new();
    for (c, m) in models.iter().enumerate() {
        let rows: Vec<&AdaptiveRow> = ad.iter().filter(|r| r.model == *m).collect();
        drift_series.push(
            Series::line(
                m.clone(),
                rows.iter().map(|r| (r.rtol, r.drift)).collect(),
                c,
            )
            .mark(Mark::LinePoints),
        );
        step_series.push(
            Series::line(
                m.clone(),
                rows.iter()
                    .map(|r| (r.rtol, r.accepted_steps as f64))
                    .collect(),
                c,
            )
            .mark(Mark::LinePoints),
        );
    }
    let panels = vec![
        Panel {
            title: "adaptive RK45: energy drift vs tolerance".into(),
            x_label: "relative tolerance".into(),
            y_label: "max |E(t) - E(0)| (J)".into(),
            log_x: true,
            log_y: true,
            series: drift_series,
            ..Panel::default()
        },
        Panel {
            title: "adaptive RK45: accepted steps vs tolerance".into(),
            x_label: "relative tolerance".into(),
            y_label: "accepted steps".into(),
            log_x: true,
            log_y: true,
            series: step_series,
            ..Panel::default()
        },
    ];
    Figure::grid(panels, 2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_fit_recovers_a_power_law() {
        let dts = [0.1, 0.05, 0.025, 0.0125];
        let d: Vec<f64> = dts.iter().map(|h: &f64| 3.0 * h.powi(4)).collect();
        let (o, n) = fitted_order(&dts, &d, 0.0);
        assert!((o - 4.0).abs() < 1e-9 && n == 4);
        // Points under the floor are left out.
        let (_, n) = fitted_order(&dts, &d, 1e-5);
        assert_eq!(n, 2);
    }

    #[test]
    fn rk4_energy_drift_has_order_four_on_the_pendulum() {
        let m = conservative_model("pendulum3").unwrap();
        let x0 = [1.2, -0.7, 0.9, 0.0, 1.0, -0.5];
        let dts = [0.01, 0.005, 0.0025];
        let d: Vec<f64> = dts
            .iter()
            .map(|&h| energy_drift(&*m, IntegratorKind::Rk4, &x0, h, 1.0))
            .collect();
        let (o, _) = fitted_order(&dts, &d, 1e-12);
        assert!((o - 4.0).abs() < 0.5, "order {o}, drifts {d:?}");
    }
}
