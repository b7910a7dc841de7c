//! `lbc_diver_interpolation`: its parameters, the projected weights and reconstructed cost of a
//! desired entry, and the job (LBC, naive and direct dives per desired entry, the λ sweep, the
//! dives' motion).

use super::rows::{
    AverageRow, DiveRow, InterpolationRow, InterpolationSweepRow, Method, MotionDive, MotionRow,
    OffsetRow, ProjectionRow,
};
use super::{angle_deviation, entry, mean_trajectory, DiveSettings, ReconstructedCost};
use crate::bellman::combine::{BlendMode, TrackerBlend};
use crate::bellman::projection::{project, GaussianReward};
use crate::control::ddp::DdpSolution;
use crate::control::lqr::TrackingController;
use crate::experiment::output::{Table, Tables};
use crate::experiment::plot::FigureSink;
use crate::experiment::report::Findings;
use crate::experiment::resolve::{distinct, ensure, positive, ParamError, Validate};
use crate::experiment::rows::table_of;
use crate::experiment::{other, Error, Family, Job, RunContext};
use crate::families::lbc::{push_entropy, rule_table, ENTROPY_COLUMNS};
use nalgebra::DVector;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The interpolation family.
pub struct LbcDiverInterpolation;

/// Parameters of `lbc_diver_interpolation`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InterpolationParams {
    /// Dive settings.
    pub dive: DiveSettings,
    /// Take-off angular velocity of both dives (rad/s).
    pub omega: f64,
    /// Target offset δ: the dives aim at −δ (under-rotating) and +δ (over-rotating) (rad).
    /// Used when `offsets` is empty (then it must be given); with `offsets` it must be left
    /// out (0): the run sets it to the offset the search chooses.
    #[serde(default)]
    pub offset: f64,
    /// The offset search: offsets δ tried in ascending order, each building
    /// the components exactly as a run at that offset does (average-term scale chosen by its
    /// own rule); the run judges LBC at the first offset where the premise holds
    /// ([`choose_offset`]), and stops searching there. Empty: only `offset`, as before.
    #[serde(default)]
    pub offsets: Vec<f64>,
    /// LBC §4.1: "the quadratic cost functions should share the same scale factor which is
    /// inversely proportional to the square of the distance between each minimum point". On:
    /// at offset δ the dives' torso terminal weight (and the projection's and reconstructed
    /// cost's scale) is `dive.torso_weight` × (δ₀/δ)², δ₀ the first offset tried, so
    /// `dive.torso_weight` is the weight at δ₀. Off (the default, the first offset search's
    /// rule): the same weight at every offset.
    #[serde(default)]
    pub scale_torso_weight: bool,
    /// Desired entry angles (rad), strictly between −δ and δ (at ±δ the weights are (1, 0):
    /// a component, not an interpolation); 0 (vertical, the paper's claim) must be among them.
    pub desired: Vec<f64>,
    /// Outer iterations of the direct DDP dive for the reconstructed cost.
    pub direct_outer_iterations: usize,
    /// A dive reaches the desired entry when |reached − desired| is at most this (rad).
    pub entry_tolerance: f64,
    /// LBC beats the naive average on the objective when its mean excess over the direct DDP
    /// optimum (relative to that optimum) is lower by more than this.
    pub objective_tolerance: f64,
    /// Temperatures λ of the λ sweep (the noise model's λ is the one judged).
    pub lambda_sweep: Vec<f64>,
    /// Scales of the §6.1 average term tried (`DiveSettings::average_scale`): 0 (off) and each
    /// of these are in `average_term.csv`; every other table uses the largest of them at which
    /// both component dives still enter within `entry_tolerance` of their own targets (0 when
    /// none does). Empty: the term stays off.
    #[serde(default)]
    pub average_scales: Vec<f64>,
}

impl Validate for InterpolationParams {
    fn validate(&self) -> Result<(), ParamError> {
        self.dive
            .validate()
            .map_err(|e| ParamError::new(format!("dive.{}", e.key), e.message))?;
        if self.offsets.is_empty() {
            positive("offset", self.offset)?;
        } else {
            ensure(
                self.offset == 0.0,
                "offset",
                "must be left out when offsets is given (the search sets it)",
            )?;
            for (i, o) in self.offsets.iter().enumerate() {
                positive(&format!("offsets[{i}]"), *o)?;
                ensure(
                    i == 0 || *o > self.offsets[i - 1],
                    &format!("offsets[{i}]"),
                    "must be larger than the offset before it (ascending, distinct)",
                )?;
            }
        }
        let smallest = self.tried_offsets()[0];
        ensure(self.omega.is_finite(), "omega", "must be finite")?;
        ensure(!self.desired.is_empty(), "desired", "must not be empty")?;
        for (i, g) in self.desired.iter().enumerate() {
            ensure(
                g.abs() < smallest,
                &format!("desired[{i}]"),
                "must lie strictly between -offset and offset, for the smallest offset tried (at ±offset the weights are (1, 0))",
            )?;
        }
        ensure(
            self.desired.contains(&0.0),
            "desired",
            "must contain 0 (the vertical entry of the paper's claim)",
        )?;
        ensure(
            self.direct_outer_iterations >= 1,
            "direct_outer_iterations",
            "must be at least 1",
        )?;
        positive("entry_tolerance", self.entry_tolerance)?;
        positive("objective_tolerance", self.objective_tolerance)?;
        for (i, l) in self.lambda_sweep.iter().enumerate() {
            positive(&format!("lambda_sweep[{i}]"), *l)?;
        }
        distinct("lambda_sweep", &self.lambda_sweep)?;
        for (i, a) in self.average_scales.iter().enumerate() {
            ensure(
                a.is_finite() && *a > 0.0,
                &format!("average_scales[{i}]"),
                "must be finite and > 0 (scale 0, the term off, is always run)",
            )?;
        }
        distinct("average_scales", &self.average_scales)?;
        ensure(
            self.dive.average_scale == 0.0,
            "dive.average_scale",
            "must be 0 here: this experiment chooses its scale from average_scales",
        )?;
        Ok(())
    }
}

/// One interpolation row before it becomes a table row.
struct InterpRow {
    method: Method,
    reached: f64,
    objective: f64,
    entropy: f64,
    torque: f64,
    /// Normalized entropy of α and its deviation from the fixed weights at each step (empty
    /// for the direct dive).
    steps: (Vec<f64>, Vec<f64>),
}

impl InterpolationParams {
    /// Projected weights for desired entry `g` at temperature `lambda`, and the projection.
    pub(super) fn weights(&self, g: f64, lambda: f64) -> Result<(Vec<f64>, f64), Error> {
        let q = self.dive.torso_weight / lambda;
        let comps: Vec<GaussianReward> = [-self.offset, self.offset]
            .iter()
            .map(|&o| GaussianReward::isotropic(&[o], q))
            .collect();
        let p = project(&comps, &GaussianReward::isotropic(&[g], q)).map_err(other)?;
        Ok((p.weights, p.relative_residual))
    }

    fn reconstructed(&self, w: &[f64], lambda: f64) -> ReconstructedCost {
        ReconstructedCost {
            q: self.dive.torso_weight,
            centers: [-self.offset, self.offset]
                .iter()
                .map(|&o| DiveSettings::target_torso(o))
                .collect(),
            weights: w.to_vec(),
            lambda,
        }
    }
}

impl InterpolationParams {
    /// `average_term.csv`: per (settings, their component dives and trackers) of `runs`, the
    /// components and LBC and the naive blend with the projected weights at every desired
    /// entry, from the same take-off.
    fn average_effect(
        &self,
        runs: &[(&DiveSettings, &[DdpSolution], &[TrackingController])],
        x_bar: &[DVector<f64>],
    ) -> Result<Vec<AverageRow>, Error> {
        let mut table = Vec::new();
        for (d, sols, trackers) in runs {
            for (s, target) in sols.iter().zip([-self.offset, self.offset]) {
                let reached = component_entry(s);
                table.push(AverageRow {
                    average_scale: d.average_scale,
                    desired_angle: target,
                    method: Method::Component.name().to_string(),
                    reached_angle: reached,
                    entry_error: (reached - target).abs(),
                    mean_entropy: f64::NAN,
                    angle_deviation: angle_deviation(&s.x, x_bar),
                });
            }
            let (lambda, x0) = (d.lambda(), d.takeoff(self.omega));
            for &g in &self.desired {
                let (w, _) = self.weights(g, lambda)?;
                for (method, mode) in Method::BLENDS {
                    let blend = TrackerBlend {
                        trackers,
                        weights: w.clone(),
                        lambda,
                        limits: Some(&d.torque_limits),
                        mode,
                    };
                    let r = d.execute(&blend, &x0)?;
                    let reached = entry(&r.final_state);
                    table.push(AverageRow {
                        average_scale: d.average_scale,
                        desired_angle: g,
                        method: method.name().to_string(),
                        reached_angle: reached,
                        entry_error: (reached - g).abs(),
                        mean_entropy: r.mean_entropy,
                        angle_deviation: angle_deviation(&r.states, x_bar),
                    });
                }
            }
        }
        Ok(table)
    }
}

/// The component dives at one offset, built as the run builds them: without the §6.1 term,
/// with it at every scale of `average_scales`, and the chosen scale's dives and trackers.
struct Components {
    /// The dive settings at the chosen average-term scale.
    d: DiveSettings,
    /// The component dives (under-rotating, over-rotating).
    sols: Vec<DdpSolution>,
    /// Their trackers.
    trackers: Vec<TrackingController>,
    /// The `dives` table's rows.
    examples: Vec<DiveRow>,
    /// The `average_term` table's rows.
    average_t: Vec<AverageRow>,
}

/// One offset of the offset search: the components' entry angles and, with the weights
/// projected for the vertical entry, where the naive blend and LBC enter (rad from vertical).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OffsetTrial {
    /// The offset δ (rad).
    pub offset: f64,
    /// The §6.1 average-term scale chosen at this offset (0: off).
    pub average_scale: f64,
    /// The torso terminal weight at this offset (1/rad²).
    pub torso_weight: f64,
    /// Entry angle of the under-rotating component.
    pub under_entry: f64,
    /// Entry angle of the over-rotating component.
    pub over_entry: f64,
    /// Entry angle of the naive blend with the weights projected for vertical.
    pub naive_entry: f64,
    /// Entry angle of LBC with the same weights.
    pub lbc_entry: f64,
}

impl OffsetTrial {
    /// The figure's premise at this offset (ours, written in the spec): the under-rotating
    /// component enters short of vertical and the over-rotating one past it, each by more than
    /// `tol`, and the naive blend with the projected weights misses vertical by more than `tol`
    /// (a diverged naive dive, NaN, misses).
    pub fn premise_holds(&self, tol: f64) -> bool {
        self.under_entry < -tol && self.over_entry > tol && !(self.naive_entry.abs() <= tol)
    }
}

/// The offset search's rule: the index of the trial with the smallest offset whose premise
/// holds ([`OffsetTrial::premise_holds`]); `None` when no trial's does (premise not
/// reproduced).
pub fn choose_offset(trials: &[OffsetTrial], tol: f64) -> Option<usize> {
    trials
        .iter()
        .enumerate()
        .filter(|(_, t)| t.premise_holds(tol))
        .min_by(|a, b| a.1.offset.total_cmp(&b.1.offset))
        .map(|(i, _)| i)
}

impl InterpolationParams {
    /// The offsets the search tries: `offsets`, or `offset` alone when it is empty.
    pub fn tried_offsets(&self) -> Vec<f64> {
        if self.offsets.is_empty() {
            vec![self.offset]
        } else {
            self.offsets.clone()
        }
    }

    /// These parameters at offset `o` (no search).
    pub(super) fn at(&self, o: f64) -> InterpolationParams {
        let mut dive = self.dive.clone();
        if self.scale_torso_weight {
            let d0 = self.tried_offsets()[0];
            dive.torso_weight *= (d0 / o).powi(2);
        }
        InterpolationParams {
            offset: o,
            offsets: Vec::new(),
            dive,
            ..self.clone()
        }
    }

    /// The components at `self.offset`: the dives without the §6.1 term, their average
    /// trajectory x̄, the dives re-optimized with the term at every scale of
    /// `average_scales`, and the largest scale at which both still reach their own targets
    /// (the paper's examples do).
    fn components(&self, ctx: &RunContext) -> Result<Components, Error> {
        let cases = [(self.omega, -self.offset), (self.omega, self.offset)];
        let base = self.dive.clone();
        let plain = base.optimize_all(ctx, &cases)?;
        let x_bar = std::sync::Arc::new(mean_trajectory(&plain.0, base.steps()));
        let mut scaled = Vec::new();
        for &a in &self.average_scales {
            let mut on = self.dive.clone();
            on.average_scale = a;
            on.average = Some(x_bar.clone());
            let out = on.optimize_all(ctx, &cases)?;
            scaled.push((on, out));
        }
        let mut runs = vec![(&base, plain.0.as_slice(), plain.1.as_slice())];
        runs.extend(
            scaled
                .iter()
                .map(|(d, o)| (d, o.0.as_slice(), o.1.as_slice())),
        );
        let average_t = self.average_effect(&runs, &x_bar)?;
        let reaches = |sols: &[DdpSolution]| {
            sols.iter()
                .zip([-self.offset, self.offset])
                .all(|(s, t)| (component_entry(s) - t).abs() <= self.entry_tolerance)
        };
        let chosen = scaled
            .iter()
            .enumerate()
            .filter(|(_, (d, o))| d.average_scale > 0.0 && reaches(&o.0))
            .max_by(|a, b| a.1 .0.average_scale.total_cmp(&b.1 .0.average_scale))
            .map(|(i, _)| i);
        let (d, (sols, trackers, examples)) = match chosen {
            Some(i) => scaled.swap_remove(i),
            None => (base, plain),
        };
        Ok(Components {
            d,
            sols,
            trackers,
            examples,
            average_t,
        })
    }

    /// The offset trial of components `c` built at `self.offset`.
    fn trial(&self, c: &Components) -> Result<OffsetTrial, Error> {
        let (d, lambda) = (&c.d, c.d.lambda());
        let (w, _) = self.weights(0.0, lambda)?;
        let x0 = d.takeoff(self.omega);
        let mut vertical = [f64::NAN; 2];
        for (v, mode) in vertical.iter_mut().zip([BlendMode::Naive, BlendMode::Lbc]) {
            let blend = TrackerBlend {
                trackers: &c.trackers,
                weights: w.clone(),
                lambda,
                limits: Some(&d.torque_limits),
                mode,
            };
            *v = entry(&d.execute(&blend, &x0)?.final_state);
        }
        Ok(OffsetTrial {
            offset: self.offset,
            average_scale: d.average_scale,
            torso_weight: d.torso_weight,
            under_entry: component_entry(&c.sols[0]),
            over_entry: component_entry(&c.sols[1]),
            naive_entry: vertical[0],
            lbc_entry: vertical[1],
        })
    }
}

/// Entry angle of an optimized dive's final state (rad).
fn component_entry(s: &DdpSolution) -> f64 {
    entry(&s.x.last().cloned())
}

impl Job for InterpolationParams {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        // The offset search: ascending offsets, each built as a run at that offset builds its
        // components; stop at the first whose premise holds. With none, the tables use the
        // largest offset tried and the verdict is "premise not reproduced".
        let mut trials = Vec::new();
        let mut built = None;
        for o in self.tried_offsets() {
            let p = self.at(o);
            let c = p.components(ctx)?;
            let t = p.trial(&c)?;
            trials.push(t);
            built = Some((p, c));
            if t.premise_holds(self.entry_tolerance) {
                break;
            }
        }
        let (p, c) = built.expect("validation: at least one offset");
        let offsets_t: Vec<OffsetRow> = trials
            .iter()
            .map(|t| OffsetRow {
                offset: t.offset,
                average_scale: t.average_scale,
                under_entry: t.under_entry,
                over_entry: t.over_entry,
                naive_vertical_entry: t.naive_entry,
                lbc_vertical_entry: t.lbc_entry,
                premise_holds: i64::from(t.premise_holds(self.entry_tolerance)),
                torso_weight: t.torso_weight,
            })
            .collect();
        let found = choose_offset(&trials, self.entry_tolerance).is_some();
        let mut tables = p.judge(ctx, c, found)?;
        tables.insert("offsets", table_of(&offsets_t));
        Ok(tables)
    }
}

impl InterpolationParams {
    /// Everything the run judges at `self.offset`, from the components `c` built there;
    /// `found`: whether the offset search found an offset whose premise holds.
    fn judge(&self, ctx: &RunContext, c: Components, found: bool) -> Result<Tables, Error> {
        let Components {
            d,
            sols,
            trackers,
            examples,
            average_t,
        } = c;
        let d = &d;
        let lambda = d.lambda();
        let x0 = d.takeoff(self.omega);
        let bl = Blender {
            trackers: &trackers,
            limits: d.torque_limits,
        };
        let rows = self.interpolate(ctx, d, &bl, &sols, &x0);
        let InterpTables {
            table,
            proj,
            entropy: entropy_t,
        } = self.interpolation_tables(d, rows)?;
        let lam = self.lambda_table(d, &bl, &x0)?;
        let motion = self.motion_table(d, &bl, &x0)?;
        let spacing = 2.0 * self.offset;
        let rule = rule_table(&[
            ("lambda", lambda),
            ("torque_noise", d.torque_noise),
            ("entry_tolerance", self.entry_tolerance),
            ("objective_tolerance", self.objective_tolerance),
            ("average_scale", d.average_scale),
            ("offset", self.offset),
            ("offset_premise_found", found as u8 as f64),
            (
                "q_spacing2_over_lambda",
                d.torso_weight * spacing * spacing / lambda,
            ),
        ]);
        Ok(Tables::from([
            ("interpolation", table_of(&table)),
            ("dives", table_of(&examples)),
            ("projection", table_of(&proj)),
            ("lambda_sweep", table_of(&lam)),
            ("motion", table_of(&motion)),
            ("average_term", table_of(&average_t)),
            ("entropy", entropy_t),
            ("rule", rule),
        ]))
    }
}

/// The component trackers and the torque limits every blend of them shares.
struct Blender<'a> {
    trackers: &'a [TrackingController],
    limits: [f64; 6],
}

impl Blender<'_> {
    /// The blend of the trackers with weights `w` in mode `mode` at temperature `lambda`.
    fn blend(&self, w: &[f64], mode: BlendMode, lambda: f64) -> TrackerBlend<'_> {
        TrackerBlend {
            trackers: self.trackers,
            weights: w.to_vec(),
            lambda,
            limits: Some(&self.limits),
            mode,
        }
    }
}

/// One desired entry angle's interpolation: LBC's, the naive blend's and the direct dive's
/// rows, the projected weights, the projection's residual, the reconstructed minimum and
/// the direct dive's outer iterations and initial guess.
struct InterpOut {
    rows: Vec<InterpRow>,
    w: Vec<f64>,
    residual: f64,
    minimum: f64,
    iterations: usize,
    start: String,
}

/// The `interpolation` and `projection` tables' rows and the `entropy` table.
struct InterpTables {
    table: Vec<InterpolationRow>,
    proj: Vec<ProjectionRow>,
    entropy: Table,
}

impl InterpolationParams {
    /// Every desired entry angle: LBC and the naive blend executed with the projected weights,
    /// and the best direct DDP dive for the reconstructed objective as ground truth.
    fn interpolate(
        &self,
        ctx: &RunContext,
        d: &DiveSettings,
        bl: &Blender,
        sols: &[DdpSolution],
        x0: &DVector<f64>,
    ) -> Vec<Result<InterpOut, Error>> {
        let lambda = d.lambda();
        // Initial guesses of the direct dive: the average tape and a component's tape.
        let average: Vec<DVector<f64>> = sols[0]
            .u
            .iter()
            .zip(&sols[1].u)
            .map(|(a, b)| (a + b) * 0.5)
            .collect();
        let tapes: [(&str, &[DVector<f64>]); 2] = [
            ("under-rotating tape", &sols[0].u),
            ("over-rotating tape", &sols[1].u),
        ];
        let pb = ctx.progress(self.desired.len() as u64, "interpolations");
        let rows: Vec<Result<InterpOut, Error>> = ctx.stage("interpolate", || {
            self.desired
                .par_iter()
                .map(|&g| {
                    let (w, residual) = self.weights(g, lambda)?;
                    let rec = self.reconstructed(&w, lambda);
                    let mut out = Vec::new();
                    for (method, mode) in Method::BLENDS {
                        let r = d.execute(&bl.blend(&w, mode, lambda), x0)?;
                        out.push(InterpRow {
                            method,
                            reached: entry(&r.final_state),
                            objective: d.reconstructed_objective(&rec, r.running, &r.final_state),
                            entropy: r.mean_entropy,
                            torque: r.max_torque_fraction,
                            steps: (r.entropy, r.alpha_deviation),
                        });
                    }
                    // Ground truth: the best direct DDP dive from the average tape and from
                    // the tape of the more heavily weighted component.
                    let heavier = tapes[(w[1] > w[0]) as usize];
                    let mut best: Option<(f64, DdpSolution, usize, &str)> = None;
                    for (label, u0) in [("average tape", average.as_slice()), heavier] {
                        let (s, it) = d.direct(x0, &rec, u0, self.direct_outer_iterations)?;
                        let run =
                            s.u.iter()
                                .enumerate()
                                .map(|(k, u)| d.cost(0.0).running(k, &s.x[k], u))
                                .sum::<f64>();
                        let j = d.reconstructed_objective(&rec, run, &Some(s.x[s.u.len()].clone()));
                        if best.as_ref().is_none_or(|b| j < b.0) {
                            best = Some((j, s, it, label));
                        }
                    }
                    let (j, s, it, label) = best.expect("two guesses");
                    out.push(InterpRow {
                        method: Method::Direct,
                        reached: entry(&Some(s.x[s.u.len()].clone())),
                        objective: j,
                        entropy: f64::NAN,
                        torque: d.torque_fraction(&s.u),
                        steps: (Vec::new(), Vec::new()),
                    });
                    let minimum = rec.minimum() - DiveSettings::target_torso(0.0);
                    pb.inc(1);
                    Ok(InterpOut {
                        rows: out,
                        w,
                        residual,
                        minimum,
                        iterations: it,
                        start: label.to_string(),
                    })
                })
                .collect()
        });
        pb.finish_and_clear();
        rows
    }

    /// The interpolation rows as tables, in the order of the desired angles; the first
    /// failed interpolation is the error.
    fn interpolation_tables(
        &self,
        d: &DiveSettings,
        rows: Vec<Result<InterpOut, Error>>,
    ) -> Result<InterpTables, Error> {
        let mut table = Vec::new();
        let mut proj = Vec::new();
        let mut entropy_t = Table::new(&ENTROPY_COLUMNS);
        for (&g, r) in self.desired.iter().zip(rows) {
            let InterpOut {
                rows: out,
                w,
                residual,
                minimum,
                iterations: it,
                start: label,
            } = r?;
            for r in out.iter().filter(|r| r.method != Method::Direct) {
                let run = format!("desired {g} rad");
                let name = r.method.name();
                push_entropy(&mut entropy_t, &run, name, d.dt, &r.steps.0, &r.steps.1);
            }
            let best = out
                .iter()
                .find(|r| r.method == Method::Direct)
                .map_or(f64::NAN, |r| r.objective);
            for r in &out {
                table.push(InterpolationRow {
                    desired_angle: g,
                    method: r.method.name().to_string(),
                    reached_angle: r.reached,
                    weight1: w[0],
                    weight2: w[1],
                    objective: r.objective,
                    excess_objective: (r.objective - best) / best.abs(),
                    mean_entropy: r.entropy,
                    max_torque_fraction: r.torque,
                });
            }
            proj.push(ProjectionRow {
                desired_angle: g,
                weight1: w[0],
                weight2: w[1],
                weight_sum: w[0] + w[1],
                relative_residual: residual,
                reconstructed_minimum: minimum,
                direct_outer_iterations: it as i64,
                direct_start: label,
            });
        }
        Ok(InterpTables {
            table,
            proj,
            entropy: entropy_t,
        })
    }

    /// λ sweep of LBC (weights re-projected at each λ, as the blend and projection agree).
    fn lambda_table(
        &self,
        d: &DiveSettings,
        bl: &Blender,
        x0: &DVector<f64>,
    ) -> Result<Vec<InterpolationSweepRow>, Error> {
        let mut lam = Vec::new();
        for &l in &self.lambda_sweep {
            for &g in &self.desired {
                let (w, _) = self.weights(g, l)?;
                let r = d.execute(&bl.blend(&w, BlendMode::Lbc, l), x0)?;
                lam.push(InterpolationSweepRow {
                    lambda: l,
                    desired_angle: g,
                    reached_angle: entry(&r.final_state),
                    mean_entropy: r.mean_entropy,
                    weight1: w[0],
                    weight2: w[1],
                });
            }
        }
        Ok(lam)
    }

    /// The filmstrip's dives: the two components and, with the weights projected for the
    /// vertical entry, the naive average and LBC (every executed state).
    fn motion_table(
        &self,
        d: &DiveSettings,
        bl: &Blender,
        x0: &DVector<f64>,
    ) -> Result<Vec<MotionRow>, Error> {
        let lambda = d.lambda();
        let (w0, _) = self.weights(0.0, lambda)?;
        let mut motion = Vec::new();
        for dive in MotionDive::ALL {
            let r = d.execute(&bl.blend(&w0, dive.mode(), lambda), x0)?;
            for (k, x) in r.states.iter().enumerate() {
                motion.push(MotionRow::at(dive, k as f64 * d.dt, x.as_slice()));
            }
        }
        Ok(motion)
    }
}

impl Family for LbcDiverInterpolation {
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        ("entropy", "the normalized entropy of LBC's weights α at every control step (1: uniform, 0: one controller takes over), per run; where α stays at the fixed weights LBC is the naive blend by construction."),
        (
            "entry",
            "the entry angle reached vs the desired one by LBC, the naive blend and a direct DDP dive, and each one's excess objective over the direct optimum of the reconstructed cost.",
        ),
        (
            "filmstrip",
            "the two component dives and, with the weights projected for a vertical entry, the naive blend and LBC: the pose every 0.2 s, the torso in grey, the feet-to-hands line at entry.",
        ),
        (
            "dives",
            "the four dives of the filmstrip side by side in real time.",
        ),
    ];
    const KIND: &'static str = "lbc_diver_interpolation";
    type Params = InterpolationParams;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        super::figures::interpolation(fig, tables)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        super::report::interpolation(dir)
    }
}
