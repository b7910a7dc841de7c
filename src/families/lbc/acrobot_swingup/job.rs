//! The job: swing-ups, trackers, the test start, the start-state and λ sweeps, the value
//! models compared and the showcase, as tables.

use super::rows::{
    FinalRow, LambdaRow, ScaleRow, ShowcaseRow, SweepRow, SwingupRow, TrajectoryRow, ValueModelRow,
};
use super::setup::{
    cheapest, distance_to_handstand, first_swing_sign, first_torque_sign, mode, mode_index,
    radians, tape_correlation, Candidate, Rollout, POLICIES,
};
use super::verdict::{choose_scale, sweep_counts};
use super::Params;
use crate::bellman::combine::{BlendMode, TrackerBlend};
use crate::control::ddp::DdpSolution;
use crate::control::lqr::TrackingController;
use crate::control::Rk4Map;
use crate::experiment::output::{Table, Tables};
use crate::experiment::rows::table_of;
use crate::experiment::{other, Error, Job, RunContext};
use crate::families::lbc::{entropy_rows, rule_table, EntropyRow};
use crate::physics::acrobot::Acrobot;
use crate::row;
use nalgebra::DVector;
use rayon::prelude::*;

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let map = Rk4Map::new(Acrobot::default(), self.dt).map_err(other)?;
        let (cands, best) = ctx.stage("ddp", || self.swing_ups(&map))?;
        let sols: Vec<&DdpSolution> = best.iter().map(|&b| &cands[b].sol).collect();
        // The trackers' setting: the first scale of their LQR terminal weights at
        // which each tracker alone fails from the test start (the paper's premise); every
        // policy from the test start at every scale tried, for the table.
        let lambda = self.lambda();
        let limits = [self.torque_limit];
        let scales = self.scales();
        let search = ctx.stage("lqr", || {
            self.scale_search(&map, &sols, &scales, &limits, lambda)
        })?;
        let scale = scales[search.pick.unwrap_or(0)];
        let scale_t = self.scale_table(&search);
        let candidates = candidates_table(&cands, &best);
        let SwingupTables { swingups, trace } = self.swingup_tables(&cands, &best, &sols);
        let lp = ClosedLoop {
            map: &map,
            trackers: &search.trackers,
            alt: search.alt.as_deref(),
            limits: &limits,
            lambda,
        };
        // The test start.
        let x0 = radians(&self.test_start);
        let TestStartTables {
            fin,
            traj,
            entropy: entropy_t,
        } = ctx.stage("test start", || self.test_start_tables(&lp, &x0))?;
        let grid = self.start_grid();
        let rows = self.sweep_rows(ctx, &lp, &grid)?;
        let SweepTables { sweep, models } = self.sweep_tables(&grid, &rows);
        let showcase = self.showcase_table(&lp, &grid, &rows)?;
        let lam = self.lambda_table(&lp, &x0, &rows)?;
        let rule = rule_table(&[
            ("lambda", lambda),
            ("torque_noise", self.torque_noise),
            ("torque_limit", self.torque_limit),
            ("success_distance", self.success_distance),
            ("held_fraction", self.held_fraction),
            ("partly_fraction", self.partly_fraction),
            ("max_cost_ratio", self.max_cost_ratio),
            ("value_model_ddp", (self.value_model == "ddp") as u8 as f64),
            ("other_value_model_built", search.alt.is_some() as u8 as f64),
            ("tracker_weight_scale", scale),
            ("scale_premise_found", search.pick.is_some() as u8 as f64),
        ]);
        Ok(Tables::from([
            ("final", table_of(&fin)),
            ("trajectories", table_of(&traj)),
            ("swingups", table_of(&swingups)),
            ("swingup_candidates", candidates),
            ("ddp_trace", trace),
            ("sweep", table_of(&sweep)),
            ("lambda_sweep", table_of(&lam)),
            ("value_model", table_of(&models)),
            ("showcase", table_of(&showcase)),
            ("tracker_scales", table_of(&scale_t)),
            ("entropy", table_of(&entropy_t)),
            ("rule", rule),
        ]))
    }
}

/// The trackers' scale search: each policy's final distance from the test start per scale
/// tried, the scale picked, and the trackers (and the other value model's) at that scale.
struct ScaleSearch {
    rows: Vec<(f64, Vec<f64>)>,
    pick: Option<usize>,
    trackers: Vec<TrackingController>,
    alt: Option<Vec<TrackingController>>,
}

/// What every closed-loop rollout after the scale search shares: the map, the trackers (and
/// the other value model's, when built), the torque limits and the spec's λ.
struct ClosedLoop<'a> {
    map: &'a Rk4Map<Acrobot>,
    trackers: &'a [TrackingController],
    alt: Option<&'a [TrackingController]>,
    limits: &'a [f64],
    lambda: f64,
}

/// The kept swing-ups per start and their DDP iterations.
struct SwingupTables {
    swingups: Vec<SwingupRow>,
    trace: Table,
}

/// The policies from the test start: final states, trajectories and α's entropy.
struct TestStartTables {
    fin: Vec<FinalRow>,
    traj: Vec<TrajectoryRow>,
    entropy: Vec<EntropyRow>,
}

/// Final distance, control cost, largest torque and mean entropy of one rollout.
type Outcome = (f64, f64, f64, f64);

/// One start of the sweep: every policy at the spec's λ, LBC at each swept λ, and every
/// policy with the other value model's trackers (empty when those were not built).
struct StartOutcomes {
    policies: Vec<Outcome>,
    lambdas: Vec<Outcome>,
    others: Vec<Outcome>,
}

/// The start-state sweep per policy, and per value model.
struct SweepTables {
    sweep: Vec<SweepRow>,
    models: Vec<ValueModelRow>,
}

/// The rollout's summary for the sweep tables.
fn summary(r: &Rollout) -> Outcome {
    (
        r.final_distance(),
        r.control_cost,
        r.max_abs_torque(),
        r.mean_entropy(),
    )
}

/// Every DDP candidate per start and guess, and whether it was kept.
fn candidates_table(cands: &[Candidate], best: &[usize]) -> Table {
    let mut candidates = Table::new(&[
        "start",
        "guess",
        "iterations",
        "cost",
        "final_distance",
        "first_swing_sign",
        "first_torque_sign",
        "kept",
        "termination",
    ]);
    for (i, c) in cands.iter().enumerate() {
        candidates.push(row![
            c.start + 1,
            c.guess.as_str(),
            c.sol.trace.len(),
            c.sol.cost,
            distance_to_handstand(c.sol.x[c.sol.u.len()].as_slice()),
            first_swing_sign(&c.sol.x),
            first_torque_sign(&c.sol.u),
            best.contains(&i) as i64,
            format!("{:?}", c.sol.termination)
        ]);
    }
    candidates
}

impl Params {
    /// Whether a final distance counts as a swing-up to the handstand.
    fn reaches(&self, d: f64) -> bool {
        d < self.success_distance
    }

    /// The spec's blend of `lp`'s trackers in mode `m` at temperature `lambda`.
    fn loop_blend<'a>(&self, lp: &ClosedLoop<'a>, m: BlendMode, lambda: f64) -> TrackerBlend<'a> {
        self.blend(lp.trackers, lp.limits, m, lambda)
    }

    /// Every policy from the test start at every tracker weight scale tried, and the scale
    /// the run uses with its trackers.
    fn scale_search(
        &self,
        map: &Rk4Map<Acrobot>,
        sols: &[&DdpSolution],
        scales: &[f64],
        limits: &[f64],
        lambda: f64,
    ) -> Result<ScaleSearch, Error> {
        let x0 = radians(&self.test_start);
        let (mut rows, mut sets) = (Vec::new(), Vec::new());
        for &s in scales {
            let ts = self.trackers(map, sols, &self.value_model, s)?;
            let d = (0..POLICIES.len())
                .map(|i| {
                    let b = self.blend(&ts, limits, mode(i), lambda);
                    Ok(self.run_policy(map, &b, &x0)?.final_distance())
                })
                .collect::<Result<Vec<f64>, Error>>()?;
            rows.push((s, d));
            sets.push(ts);
        }
        let trials: Vec<(f64, f64, f64)> = rows.iter().map(|(s, d)| (*s, d[0], d[1])).collect();
        let pick = choose_scale(&trials, self.success_distance);
        let trackers = sets.swap_remove(pick.unwrap_or(0));
        // The other value model at the same scale, for the comparison; DDP's Q_uu need not
        // be positive definite, so it may be missing.
        let alt = self
            .trackers(map, sols, self.other_model(), scales[pick.unwrap_or(0)])
            .ok();
        Ok(ScaleSearch {
            rows,
            pick,
            trackers,
            alt,
        })
    }

    /// `tracker_scales`: the scale search's rows.
    fn scale_table(&self, search: &ScaleSearch) -> Vec<ScaleRow> {
        let mut scale_t = Vec::new();
        for (i, (s, d)) in search.rows.iter().enumerate() {
            let fails = !(d[0] < self.success_distance) && !(d[1] < self.success_distance);
            for (name, &di) in POLICIES.iter().zip(d) {
                scale_t.push(ScaleRow {
                    tracker_weight_scale: *s,
                    policy: name.to_string(),
                    final_distance: di,
                    each_tracker_fails: fails as i64,
                    chosen: (search.pick == Some(i)) as i64,
                });
            }
        }
        scale_t
    }

    /// The kept swing-up per start (with the family checks) and its DDP trace.
    fn swingup_tables(
        &self,
        cands: &[Candidate],
        best: &[usize],
        sols: &[&DdpSolution],
    ) -> SwingupTables {
        let mut swingups = Vec::new();
        let mut trace = Table::new(&[
            "start",
            "iteration",
            "cost",
            "regularization",
            "step",
            "gradient_norm",
            "accepted",
        ]);
        let lowest: Vec<f64> = cheapest(cands, self.starts.len(), |_| true)
            .iter()
            .map(|b| b.map_or(f64::NAN, |i| cands[i].sol.cost))
            .collect();
        let min_cost = sols.iter().map(|s| s.cost).fold(f64::INFINITY, f64::min);
        let swing = |s: &DdpSolution| first_swing_sign(&s.x);
        let same_family = sols
            .iter()
            .all(|s| swing(s) == swing(sols[0]) && swing(s) != 0)
            && sols
                .iter()
                .all(|s| s.cost <= self.max_cost_ratio * min_cost);
        for (i, (s, sol)) in self.starts.iter().zip(sols).enumerate() {
            swingups.push(SwingupRow {
                start: i as i64 + 1,
                theta1_deg: s[0],
                theta2_deg: s[1],
                iterations: sol.trace.len() as i64,
                cost: sol.cost,
                final_distance: distance_to_handstand(sol.x[sol.u.len()].as_slice()),
                termination: format!("{:?}", sol.termination),
                guess: cands[best[i]].guess.clone(),
                first_swing_sign: swing(sol),
                first_torque_sign: first_torque_sign(&sol.u),
                cost_ratio: sol.cost / min_cost,
                tape_correlation: tape_correlation(&sols[0].u, &sol.u),
                same_family: same_family as i64,
                max_abs_torque_n_m: sol.u.iter().fold(0.0, |m: f64, u| m.max(u[0].abs())),
                lowest_cost_any_family: lowest[i],
            });
            for r in &sol.trace {
                trace.push(row![
                    i + 1,
                    r.iteration,
                    r.cost,
                    r.regularization,
                    r.step,
                    r.gradient_norm,
                    r.accepted as i64
                ]);
            }
        }
        SwingupTables { swingups, trace }
    }

    /// Every policy from the test start `x0`: final state, trajectory, and α's entropy for
    /// LBC and the fixed-weight average.
    fn test_start_tables(
        &self,
        lp: &ClosedLoop,
        x0: &DVector<f64>,
    ) -> Result<TestStartTables, Error> {
        let (mut fin, mut traj, mut entropy_t) = (Vec::new(), Vec::new(), Vec::new());
        for (i, name) in POLICIES.iter().enumerate() {
            let r = self.run_policy(lp.map, &self.loop_blend(lp, mode(i), lp.lambda), x0)?;
            // α over time of LBC and of the fixed-weight average (the sum's α is the raw
            // weights, not a distribution).
            if matches!(mode(i), BlendMode::Lbc | BlendMode::Naive) {
                entropy_t.extend(entropy_rows(
                    "test start",
                    name,
                    self.dt,
                    &r.entropy,
                    &r.alpha_deviation,
                ));
            }
            let xn = &r.xs[r.xs.len() - 1];
            fin.push(FinalRow {
                policy: name.to_string(),
                final_distance: r.final_distance(),
                control_cost: r.control_cost,
                final_theta1_rad: xn[0],
                final_theta2_rad: xn[1],
                max_abs_torque_n_m: r.max_abs_torque(),
                mean_entropy: r.mean_entropy(),
            });
            for (k, x) in r.xs.iter().enumerate() {
                let (u, a, h) = if k < r.us.len() {
                    (r.us[k], r.alpha1[k], r.entropy[k])
                } else {
                    (f64::NAN, f64::NAN, f64::NAN)
                };
                traj.push(TrajectoryRow {
                    policy: name.to_string(),
                    t_s: k as f64 * self.dt,
                    theta1_rad: x[0],
                    theta2_rad: x[1],
                    omega1_rad_s: x[2],
                    omega2_rad_s: x[3],
                    u_n_m: u,
                    alpha1: a,
                    alpha_entropy: h,
                });
            }
        }
        Ok(TestStartTables {
            fin,
            traj,
            entropy: entropy_t,
        })
    }

    /// The sweep's start states (degrees): θ₁ fastest, then θ₂.
    fn start_grid(&self) -> Vec<(f64, f64)> {
        let n = self.sweep_points;
        let lin = |r: [f64; 2], i: usize| {
            if n == 1 {
                0.5 * (r[0] + r[1])
            } else {
                r[0] + (r[1] - r[0]) * i as f64 / (n - 1) as f64
            }
        };
        (0..n)
            .flat_map(|j| {
                (0..n).map(move |i| (lin(self.sweep_theta1, i), lin(self.sweep_theta2, j)))
            })
            .collect()
    }

    /// Sweep over start states: every policy at the spec's λ, and LBC at each swept λ.
    fn sweep_rows(
        &self,
        ctx: &RunContext,
        lp: &ClosedLoop,
        grid: &[(f64, f64)],
    ) -> Result<Vec<StartOutcomes>, Error> {
        let pb = ctx.progress(grid.len() as u64, "start-state sweep");
        let rows: Vec<Result<StartOutcomes, Error>> = ctx.stage("sweep", || {
            grid.par_iter()
                .map(|&(a, b)| {
                    let x0 = radians(&[a, b, 0.0, 0.0]);
                    let policies = (0..POLICIES.len())
                        .map(|i| {
                            Ok(summary(&self.run_policy(
                                lp.map,
                                &self.loop_blend(lp, mode(i), lp.lambda),
                                &x0,
                            )?))
                        })
                        .collect::<Result<Vec<_>, Error>>()?;
                    let lambdas = self
                        .lambda_sweep
                        .iter()
                        .map(|&l| {
                            Ok(summary(&self.run_policy(
                                lp.map,
                                &self.loop_blend(lp, BlendMode::Lbc, l),
                                &x0,
                            )?))
                        })
                        .collect::<Result<Vec<_>, Error>>()?;
                    // The same policies with the other value model's trackers.
                    let others = match lp.alt {
                        Some(ts) => (0..POLICIES.len())
                            .map(|i| {
                                Ok(summary(&self.run_policy(
                                    lp.map,
                                    &self.blend(ts, lp.limits, mode(i), lp.lambda),
                                    &x0,
                                )?))
                            })
                            .collect::<Result<Vec<_>, Error>>()?,
                        None => Vec::new(),
                    };
                    pb.inc(1);
                    Ok(StartOutcomes {
                        policies,
                        lambdas,
                        others,
                    })
                })
                .collect()
        });
        pb.finish_and_clear();
        rows.into_iter().collect::<Result<_, _>>()
    }

    /// `sweep` (every policy per start) and `value_model` (both value models per start).
    fn sweep_tables(&self, grid: &[(f64, f64)], rows: &[StartOutcomes]) -> SweepTables {
        let (mut sweep, mut models) = (Vec::new(), Vec::new());
        for (&(a, b), row) in grid.iter().zip(rows) {
            let (r, o) = (&row.policies, &row.others);
            for (name, &(d, c, m, h)) in POLICIES.iter().zip(r) {
                sweep.push(SweepRow {
                    theta1_deg: a,
                    theta2_deg: b,
                    policy: name.to_string(),
                    final_distance: d,
                    control_cost: c,
                    success: self.reaches(d) as i64,
                    max_abs_torque_n_m: m,
                    mean_entropy: h,
                });
            }
            for (model, outs) in [(self.value_model.as_str(), r), (self.other_model(), o)] {
                for (name, &(d, ..)) in POLICIES.iter().zip(outs) {
                    models.push(ValueModelRow {
                        value_model: model.to_string(),
                        theta1_deg: a,
                        theta2_deg: b,
                        policy: name.to_string(),
                        final_distance: d,
                        success: self.reaches(d) as i64,
                    });
                }
            }
        }
        SweepTables { sweep, models }
    }

    /// The showcase (GIF): tracker 1, tracker 2 and LBC from the first start LBC rescues
    /// (both trackers fail there), else from the test start.
    fn showcase_table(
        &self,
        lp: &ClosedLoop,
        grid: &[(f64, f64)],
        rows: &[StartOutcomes],
    ) -> Result<Vec<ShowcaseRow>, Error> {
        let ok = |d: f64| self.reaches(d);
        let rescued = rows.iter().position(|row| {
            let r = &row.policies;
            !ok(r[0].0) && !ok(r[1].0) && ok(r[mode_index(BlendMode::Lbc)].0)
        });
        let show = rescued.map_or(self.test_start, |i| [grid[i].0, grid[i].1, 0.0, 0.0]);
        let mut showcase = Vec::new();
        for i in [0, 1, mode_index(BlendMode::Lbc)] {
            let r = self.run_policy(
                lp.map,
                &self.loop_blend(lp, mode(i), lp.lambda),
                &radians(&show),
            )?;
            for (k, x) in r.xs.iter().enumerate() {
                showcase.push(ShowcaseRow {
                    policy: POLICIES[i].to_string(),
                    theta1_deg: show[0],
                    theta2_deg: show[1],
                    rescued: rescued.is_some() as i64,
                    t_s: k as f64 * self.dt,
                    theta1_rad: x[0],
                    theta2_rad: x[1],
                });
            }
        }
        Ok(showcase)
    }

    /// The λ sweep: LBC at the test start `x0` and over the sweep, the both-fail subset
    /// included.
    fn lambda_table(
        &self,
        lp: &ClosedLoop,
        x0: &DVector<f64>,
        rows: &[StartOutcomes],
    ) -> Result<Vec<LambdaRow>, Error> {
        let ok = |d: f64| self.reaches(d);
        let mut lam = Vec::new();
        for (li, &l) in self.lambda_sweep.iter().enumerate() {
            let r = self.run_policy(lp.map, &self.loop_blend(lp, BlendMode::Lbc, l), x0)?;
            let flags: Vec<Vec<bool>> = rows
                .iter()
                .map(|row| {
                    let (p, ls) = (&row.policies, &row.lambdas);
                    vec![ok(p[0].0), ok(p[1].0), ok(ls[li].0)]
                })
                .collect();
            let c = sweep_counts(&flags);
            let h: f64 = rows.iter().map(|row| row.lambdas[li].3).sum::<f64>() / rows.len() as f64;
            lam.push(LambdaRow {
                lambda: l,
                test_final_distance: r.final_distance(),
                test_mean_entropy: r.mean_entropy(),
                sweep_successes: c.successes[2] as i64,
                both_fail_successes: c.rescued[2] as i64,
                both_fail_starts: c.both_fail as i64,
                sweep_mean_entropy: h,
            });
        }
        Ok(lam)
    }
}
