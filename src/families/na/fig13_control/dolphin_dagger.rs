//! DAgger for the dolphin swim (ours; [`crate::emulator::hierarchy::dagger`]): the
//! swim is learned through the hierarchy's global net, so that net is refined on the states the
//! learned swims visit. Round r learns the swim through net_r exactly as the headline does
//! (momentum, the same seeded restarts and iterations), replays the knots on the simulator,
//! aggregates the global-state examples along that replay, `perturbations` perturbed-control
//! steps from each visited state, `perturbed_rollouts` perturbed replays from the start and (round
//! 0) the zero-control drift from the start, and fine-tunes net_{r+1} from net_r's weights on
//! the net's own training data plus everything aggregated, by L-BFGS on the one-step loss +
//! `rollout_weight` × the `rollout_k`-step rollout loss, early-stopped on held-out perturbed
//! replays. One `dolphin_dagger.csv` row per round; round r's net is cached under the base
//! net's key plus everything that determines it, so reruns are warm.

use super::rows::DolphinDaggerRow;
use super::{DolphinControl, Params};
use crate::emulator::cache::{EmulatorCache, NetRecord};
use crate::emulator::catalog::{stop_name, TrainSettings, TrainingData};
use crate::emulator::dagger::{
    aggregate, collect, fine_tune_aggregated, DaggerSettings, Plan, Visits,
};
use crate::emulator::dataset::Windows;
use crate::emulator::hierarchy::dagger::{
    derived_file_name, global_visits, load_derived, store_derived,
};
use crate::emulator::hierarchy::{
    control_limits, global_training_data, simulator, HierarchySpec, FRAME_DIM, GLOBAL_DIM,
};
use crate::emulator::train::mse;
use crate::emulator::Emulator;
use crate::experiment::resolve::{ensure, positive, ParamError};
use crate::experiment::rows::TableRow;
use crate::experiment::rule::{Check, Cmp, Null, Partly, Rule};
use crate::experiment::{other, Error, RunContext};
use crate::families::na::swim::periodicity;
use crate::physics::dolphin::{Dolphin, N_SEGMENTS};
use crate::seed::mix_seed;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// `[params.dolphin.dagger]`: aggregation settings and the fine-tuning's rollout loss.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DolphinDagger {
    /// Rounds, perturbations, fine-tuning budget.
    pub settings: DaggerSettings,
    /// Super-steps k of the fine-tuning's rollout windows.
    pub rollout_k: usize,
    /// Weight of the k-step rollout loss against the one-step loss.
    pub rollout_weight: f64,
}

impl DolphinDagger {
    /// Checks the settings.
    pub fn validate(&self, key: &str) -> Result<(), ParamError> {
        self.settings.validate(&format!("{key}.settings"))?;
        ensure(
            self.rollout_k >= 1,
            &format!("{key}.rollout_k"),
            "must be >= 1",
        )?;
        positive(&format!("{key}.rollout_weight"), self.rollout_weight)
    }
}

/// Columns of `dolphin_dagger.csv` ([`DolphinDaggerRow`]).
pub const COLUMNS: &[&str] = DolphinDaggerRow::COLUMNS;

/// The mean segment centroid of a global state.
fn centroid(g: &[f64]) -> [f64; 3] {
    let mut c = [0.0; 3];
    for s in 0..N_SEGMENTS {
        for (k, v) in c.iter_mut().enumerate() {
            *v += g[FRAME_DIM * s + k] / N_SEGMENTS as f64;
        }
    }
    c
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
}

impl Params {
    /// The DAgger rounds of the dolphin swim from the base global net `base` of `spec`, one
    /// row each into `table`; `reference_m` is the hand-made wave's simulator distance.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn run_dolphin_dagger(
        &self,
        ctx: &RunContext,
        d: &DolphinControl,
        dd: &DolphinDagger,
        spec: &HierarchySpec,
        base: &Emulator,
        body: &Dolphin,
        reference_m: f64,
        table: &mut Vec<DolphinDaggerRow>,
    ) -> Result<Emulator, Error> {
        let swim = &d.swim;
        let (x0, g0) = swim.start(body);
        let (dt, n, k) = (d.nets.physical_dt, self.steps, dd.rollout_k);
        let limits = control_limits();
        let neutral = vec![0.0; N_SEGMENTS];
        let zero_u = vec![0.0; swim.horizon * N_SEGMENTS];
        let cache = EmulatorCache::from_env();
        let settings = TrainSettings {
            rollout_k: dd.rollout_k,
            rollout_weight: dd.rollout_weight,
            ..spec.settings
        };
        let stream = mix_seed(spec.seed, crate::emulator::cache::fnv1a(b"dagger-dolphin"));
        let mut sim = simulator(body);
        let (mut train, mut held) = (
            Visits::empty(GLOBAL_DIM, N_SEGMENTS, k),
            Visits::empty(GLOBAL_DIM, N_SEGMENTS, k),
        );
        let mut base_data: Option<TrainingData> = None;
        let mut net = base.clone();
        let mut fine_tune_iterations = 0usize;
        // The simulator's zero-control drift is the same every round.
        let (_, sim_drift) = swim.simulate(body, &x0, &zero_u, dt, n).map_err(other)?;
        let sim_end = centroid(&sim_drift[sim_drift.len() - GLOBAL_DIM..]);
        let start = centroid(&g0);
        for round in 0..=dd.settings.rounds {
            let label = format!(" (DAgger round {round})");
            let (r, best) = super::learn_swim(
                ctx,
                d,
                &net,
                body,
                self.steps,
                self.curvature_iterations,
                &label,
                None,
            )?;
            let (_, sim_g) = swim
                .simulate(body, &x0, &best.controls, dt, n)
                .map_err(other)?;
            let (emu_d, sim_d) = (swim.distance(&best.states), swim.distance(&sim_g));
            let (p, lag) = periodicity(&best.controls, N_SEGMENTS);
            // The net's drift from the start under zero controls.
            let (mut g, mut next, mut sc) = (g0.clone(), vec![0.0; GLOBAL_DIM], net.scratch());
            for _ in 0..swim.horizon {
                net.predict(&g, &neutral, &mut sc, &mut next);
                g.copy_from_slice(&next);
            }
            let emu_end = centroid(&g);
            table.push(DolphinDaggerRow {
                round: round as i64,
                examples: (spec.global.examples + train.len()) as i64,
                dagger_examples: train.len() as i64,
                dagger_windows: train.windows.len() as i64,
                fine_tune_iterations: fine_tune_iterations as i64,
                best_iteration: r.best_iteration as i64,
                best_objective: r.best_objective(),
                distance_emulator_m: emu_d,
                distance_simulator_m: sim_d,
                reference_distance_m: reference_m,
                fraction_of_reference: sim_d / reference_m,
                periodicity: p,
                period_s: lag * dt * n as f64,
                drift_emulator_m: dist(emu_end, start),
                drift_simulator_m: dist(sim_end, start),
                drift_gap_m: dist(emu_end, sim_end),
            });
            if round == dd.settings.rounds {
                break;
            }
            // Aggregate the states these knots visit, then fine-tune the next net.
            let plan = Plan {
                x0: &x0,
                controls: &best.controls,
                neutral: &neutral,
                limits: &limits,
                physical_dt: dt,
                substeps: n,
            };
            let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(stream, 2 * round as u64));
            let (t, h) = ctx
                .stage(&format!("dagger dolphin round {round}: collect"), || {
                    collect(&mut sim, &plan, &dd.settings, k, round == 0, &mut rng)
                })
                .map_err(other)?;
            train.extend(&global_visits(body, &t));
            held.extend(&global_visits(body, &h));
            let key = self.chain_key(ctx, d, dd, round + 1);
            let (next_net, rec) = match load_derived(&cache, spec, body, &key) {
                Some(found) => found,
                None => {
                    let what = format!(
                        "the dolphin's DAgger round {} global net ({})",
                        round + 1,
                        derived_file_name(&cache, spec, body, &key)
                    );
                    let (emulator, rec) = crate::emulator::cache::training(&what, || {
                        self.fine_tune_round(
                            ctx,
                            dd,
                            spec,
                            body,
                            &net,
                            &mut base_data,
                            (&train, &held),
                            &settings,
                            (stream, round),
                        )
                    })?;
                    store_derived(&cache, spec, body, &key, &rec).map_err(other)?;
                    (emulator, rec)
                }
            };
            fine_tune_iterations = rec.trace.last().map_or(0, |t| t.iteration);
            net = next_net;
        }
        Ok(net)
    }

    /// Round `round`'s fine-tune of `net` on the base data (built once into `base_data`) and
    /// the visits aggregated so far, with its record (timed from the start of the round's
    /// training); the aggregation's randomness is stream `2 round + 1` of `stream`.
    #[allow(clippy::too_many_arguments)]
    fn fine_tune_round(
        &self,
        ctx: &RunContext,
        dd: &DolphinDagger,
        spec: &HierarchySpec,
        body: &Dolphin,
        net: &Emulator,
        base_data: &mut Option<TrainingData>,
        (train, held): (&Visits, &Visits),
        settings: &TrainSettings,
        (stream, round): (u64, usize),
    ) -> Result<(Emulator, NetRecord), Error> {
        let k = dd.rollout_k;
        let t0 = std::time::Instant::now();
        if base_data.is_none() {
            let data = ctx.stage("dagger dolphin: base data", || {
                global_training_data(body, spec)
            });
            *base_data = Some(data.map_err(other)?);
        }
        let data = base_data.as_ref().expect("just built");
        let no_windows = Windows {
            k,
            state_dim: GLOBAL_DIM,
            control_dim: N_SEGMENTS,
            states: vec![],
            controls: vec![],
            episode: vec![],
            start_step: vec![],
        };
        let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(stream, 2 * round as u64 + 1));
        let agg =
            aggregate(net, data, &no_windows, train, held, settings, &mut rng).map_err(other)?;
        let mut emulator = net.clone();
        let report = ctx.stage(
            &format!("dagger dolphin round {}: fine-tune", round + 1),
            || {
                fine_tune_aggregated(
                    &mut emulator,
                    &agg,
                    &data.sigma,
                    settings,
                    dd.settings.iters,
                    None,
                )
            },
        );
        let report = report.map_err(other)?;
        let t = emulator.transforms();
        let rec = NetRecord {
            mlp: emulator.mlp().clone(),
            input_norm: t.input_norm.clone(),
            output_norm: t.output_norm.clone(),
            dt: emulator.dt(),
            train_error: mse(emulator.mlp(), &agg.clean),
            heldout_error: mse(emulator.mlp(), &agg.held),
            train_s: t0.elapsed().as_secs_f64(),
            stop: stop_name(&report.stop),
            trace: report.trace,
            rollout_trace: Vec::new(),
        };
        Ok((emulator, rec))
    }

    /// Everything besides the base net that determines round `round`'s global net.
    fn chain_key(
        &self,
        ctx: &RunContext,
        d: &DolphinControl,
        dd: &DolphinDagger,
        round: usize,
    ) -> serde_json::Value {
        serde_json::json!({
            "learner": {
                "iterations": d.iterations,
                "eta": d.eta,
                "alpha": d.alpha,
                "init_spread": d.init_spread,
                "restarts": d.restarts,
                "step_rule": d.step_rule,
                "curvature_iterations": self.curvature_iterations,
                "seed": ctx.seed,
            },
            "swim": d.swim,
            "dagger": dd,
            "round": round,
        })
    }

    /// The dolphin's last-round DAgger global net: from the emulator cache when there, else
    /// the chain runs (and stores its nets). What `na_baselines_swim` searches on beside the
    /// Table 1 net.
    pub(crate) fn dolphin_dagger_net(&self, ctx: &RunContext) -> Result<Emulator, Error> {
        let d = self
            .dolphin
            .as_ref()
            .ok_or_else(|| other("no dolphin task"))?;
        let dd = d
            .dagger
            .as_ref()
            .ok_or_else(|| other("no dolphin DAgger settings"))?;
        let spec = d.nets.spec(ctx.seed, self.steps, self.example_scale);
        let built = ctx.stage("train dolphin hierarchy", || {
            crate::families::na::table1_structure::build_dolphin_emulator(&spec)
        })?;
        let body = built.emulator.dolphin().clone();
        let last = self.chain_key(ctx, d, dd, dd.settings.rounds);
        if let Some((net, _)) = load_derived(&EmulatorCache::from_env(), &spec, &body, &last) {
            return Ok(net);
        }
        let mut rounds = Vec::new();
        self.run_dolphin_dagger(
            ctx,
            d,
            dd,
            &spec,
            built.emulator.global(),
            &body,
            f64::NAN,
            &mut rounds,
        )
    }
}

/// The rule of the dolphin DAgger line (ours; the bars are the headline's, `Fig13Rule`): the
/// learned swim at the last round, replayed on the simulator, (a) covers at least
/// `wave_fraction` of the hand-made wave's distance and (b) has a muscle pattern of
/// periodicity at least `periodicity` (null for both: a dolphin at rest, 0). Held needs both,
/// partly (a).
pub fn dagger_rule(fraction: f64, periodicity: f64, bars: &super::Fig13Rule) -> Option<Rule> {
    let rest = || Null::new("a dolphin at rest", 0.0);
    let held = vec![
        Check::new(
            "the learned swim's simulator distance over the hand-made wave's",
            fraction,
            Cmp::AtLeast,
            bars.wave_fraction,
            rest(),
        ),
        Check::new(
            "the periodicity of its muscle pattern",
            periodicity,
            Cmp::AtLeast,
            bars.periodicity,
            rest(),
        ),
    ];
    Rule::gated(vec![], held, Partly::All(vec![0]))
}

/// The dolphin DAgger figure: the learned swim's forward distance on the simulator (solid) and
/// on the net learned through (dashed) against the round, with the hand-made wave's simulator
/// distance and half of it.
pub fn figure(
    fig: &crate::experiment::plot::FigureSink,
    tables: &crate::experiment::output::Tables,
) -> Result<Vec<std::path::PathBuf>, Error> {
    use crate::experiment::plot::{Figure, Mark, Panel, Series};
    // Written only where the spec asks for the dolphin's DAgger.
    let Some(t) = tables.get("dolphin_dagger") else {
        return Ok(vec![]);
    };
    let rounds = DolphinDaggerRow::from_table(t);
    let Some(first) = rounds.first() else {
        return Err(other("dolphin_dagger: the DAgger rounds have no rows"));
    };
    let pts = |v: fn(&DolphinDaggerRow) -> f64| -> Vec<(f64, f64)> {
        rounds.iter().map(|r| (r.round as f64, v(r))).collect()
    };
    let reference = first.reference_distance_m;
    let last = rounds.iter().map(|r| r.round as f64).fold(0.0, f64::max);
    let line = |y: f64| {
        (0..=20)
            .map(|i| (last * i as f64 / 20.0, y))
            .collect::<Vec<_>>()
    };
    let mut series = vec![
        Series::line(
            "learned swim: simulator",
            pts(|r| r.distance_simulator_m),
            0,
        ),
        Series::line(
            "learned swim: DAgger net",
            pts(|r| r.distance_emulator_m),
            0,
        )
        .mark(Mark::Dashed),
        Series::line("hand-made 1 Hz wave (simulator)", line(reference), 2),
    ];
    if let Some(f) = crate::experiment::rule::rule_setting(tables, "wave_fraction") {
        series.push(
            Series::line(
                format!(
                    "{} of the wave (the bar)",
                    crate::experiment::report::sig(f)
                ),
                line(f * reference),
                7,
            )
            .mark(Mark::Points),
        );
    }
    // The swim's duration: the last time of the headline swim's motion (the same task).
    let horizon = tables
        .get("dolphin_motion")
        .map(|m| {
            super::rows::DolphinMotionRow::from_table(m)
                .iter()
                .map(|r| r.t)
                .fold(0.0, f64::max)
        })
        .filter(|h| *h > 0.0);
    let over = horizon.map_or(String::new(), |h| format!(" in {h} s"));
    let panel = Panel {
        title: format!("Dolphin DAgger (ours): distance swum{over}, by round"),
        x_label: "DAgger round (0: the Table 1 global net)".into(),
        y_label: "forward distance of the mean segment centroid (m)".into(),
        series,
        ..Panel::default()
    };
    fig.draw("dolphin_dagger", &Figure::grid(vec![panel], 1))
}

/// The report's dolphin DAgger paragraph and verdict line (rule in the spec). `None` when
/// the run wrote no `dolphin_dagger.csv` (a spec without the dolphin's DAgger); a written one
/// without rows is an error naming it (the run writes round 0 at least).
pub fn summary(dir: &std::path::Path) -> Result<Option<(String, String)>, Error> {
    use crate::experiment::report::sig;
    use crate::experiment::rows::written_rows;
    use crate::experiment::rule::{rule_settings, shown};
    let Some(rows) = written_rows::<DolphinDaggerRow>(dir, "dolphin_dagger.csv")? else {
        return Ok(None);
    };
    let Some(first) = rows.first() else {
        return Err(other(format!(
            "{}: the DAgger rounds have no rows",
            dir.join("dolphin_dagger.csv").display()
        )));
    };
    let reference = first.reference_distance_m;
    let mut md = format!(
        "\nThe dolphin through DAgger global nets (ours, `dolphin_dagger.csv`; the headline learner, momentum with the same restarts, through each round's global net, the knots replayed on the simulator; round 0 is the Table 1 net). The hand-made wave swims {} m on the simulator.\n\n| round | examples | distance, net (m) | distance, simulator (m) | of the wave | periodicity (period s) | zero-control drift gap (m) |\n| --- | --- | --- | --- | --- | --- | --- |\n",
        sig(reference)
    );
    for r in &rows {
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} ({}) | {} |\n",
            r.round,
            r.examples,
            sig(r.distance_emulator_m),
            sig(r.distance_simulator_m),
            sig(r.fraction_of_reference),
            sig(r.periodicity),
            sig(r.period_s),
            sig(r.drift_gap_m)
        ));
    }
    let last = rows.iter().max_by_key(|r| r.round).expect("rows");
    let settings = rule_settings(dir)?;
    let bars = super::Fig13Rule {
        wave_fraction: settings("wave_fraction"),
        periodicity: settings("periodicity"),
    };
    let rule = dagger_rule(last.fraction_of_reference, last.periodicity, &bars);
    let (v, lines, text) = shown(rule.as_ref(), " No rule: a bar its null meets.");
    let by_round: Vec<String> = rows.iter().map(|r| sig(r.distance_simulator_m)).collect();
    Ok(Some((
        md,
        format!(
            " The dolphin through DAgger global nets (ours), judged at the last round (rule fixed in the spec, the headline's bars): {}; the learned swim's simulator distance by round {} m; at round {} it is {} of the wave's with periodicity {}.{lines} Rule: {text}",
            v.label(),
            by_round.join(" -> "),
            last.round,
            sig(last.fraction_of_reference),
            sig(last.periodicity)
        ),
    )))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::output::write_table;
    use crate::experiment::rows::table_of;

    /// A `dolphin_dagger.csv` that lost its rows, or was cut mid-row, is an error naming it;
    /// no file (a spec without the dolphin's DAgger) is nothing to say.
    #[test]
    fn an_emptied_or_cut_dolphin_dagger_table_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        assert!(summary(dir.path()).unwrap().is_none());
        write_table(
            dir.path(),
            "dolphin_dagger",
            &table_of::<DolphinDaggerRow>(&[]),
        )
        .unwrap();
        let e = summary(dir.path()).unwrap_err().to_string();
        assert!(e.contains("dolphin_dagger.csv"), "{e}");
        let row = DolphinDaggerRow {
            round: 0,
            examples: 100,
            dagger_examples: 0,
            dagger_windows: 0,
            fine_tune_iterations: 0,
            best_iteration: 3,
            best_objective: -1.0,
            distance_emulator_m: 2.0,
            distance_simulator_m: 1.5,
            reference_distance_m: 3.0,
            fraction_of_reference: 0.5,
            periodicity: 0.6,
            period_s: 1.0,
            drift_emulator_m: 0.1,
            drift_simulator_m: 0.2,
            drift_gap_m: 0.1,
        };
        let path = dir.path().join("dolphin_dagger.csv");
        write_table(dir.path(), "dolphin_dagger", &table_of(&[row])).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::write(&path, &text[..text.len() - 8]).unwrap();
        let e = summary(dir.path()).unwrap_err().to_string();
        assert!(e.contains("dolphin_dagger.csv"), "{e}");
    }
}
