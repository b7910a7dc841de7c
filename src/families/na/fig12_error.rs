//! `na_fig12_error` (NeuroAnimator §5.2, Fig. 12): how far emulated trajectories drift from
//! the physical simulation, for emulators with super timesteps N25, N50 and N100, on the passive
//! and the active pendulum.
//!
//! Each trial draws a state as the training data do — a start state from the training
//! distribution, then `warmup` seconds of physical simulation (for the active pendulum under a
//! random smooth torque signal within the training limits) — and from there simulates
//! `physical_steps` RK4 steps and rolls out every emulator from the same state, under the
//! continuing torque signal. The emulator
//! holds the torque over each super step at the signal's value at the middle of that step (the
//! best constant approximation of a smooth signal). Emulated states are resampled at the frame
//! times by linear interpolation (§3), and the error is the absolute difference to the
//! physical state, averaged over all state variables and over the trials:
//!
//! ```text
//! e(t) = 1/(T·N) Σ_trials Σ_i |s_i^emu(t) − s_i^phys(t)|
//! ```
//!
//! Table: `error` (variant, emulator, t, error); errors are in the state's units (rad and
//! rad/s mixed, as in the paper's average over all state variables).

use super::table1_structure::{build_emulators, build_spec, validate_nets, validate_training};
use crate::emulator::catalog::BuildSpec;
use crate::emulator::catalog::{NetModel, NetSpec, TrainSettings};
use crate::emulator::dataset::ControlSignal;
use crate::emulator::mlp::Mlp;
use crate::experiment::output::{written_csv, Tables};
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::report::{sig, Findings};
use crate::experiment::resolve::{ensure, positive, ParamError, Validate};
use crate::experiment::rows::{read_rows, table_of, TableRow};
use crate::experiment::rule::{
    rule_setting, rule_settings, rule_table, shown, Check, Cmp, Null, Partly, Rule,
};
use crate::experiment::stats::median_interval;
use crate::experiment::{Error, Family, Job, RunContext};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The family.
pub struct NaError;

/// Parameters of `na_fig12_error`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Physical steps per trial (the paper: 6,000), of each net's δt.
    pub physical_steps: usize,
    /// Trials per variant (the paper: 30).
    pub trials: usize,
    /// Frame interval at which trajectories are compared (s).
    pub frame_dt: f64,
    /// Physical simulation before a trial starts, so that trials start from states like those
    /// of the training data (s).
    pub warmup: f64,
    /// Emulators: physical steps per emulator step.
    pub emulators: Vec<usize>,
    /// Multiplies every net's example count.
    pub example_scale: f64,
    /// The pendulum nets (one per variant: passive and/or active).
    pub nets: Vec<NetSpec>,
    /// Training settings.
    pub training: TrainSettings,
    /// Hidden-unit counts tried beside each net's own, for every emulator, each with examples
    /// scaled to keep the net's examples per weight (empty: only the nets' own).
    #[serde(default)]
    pub capacity_hidden: Vec<usize>,
    /// The verdict's bars (ours).
    pub rule: Fig12Rule,
    /// Net seeds beyond the run's own: every emulator trained again under each (the same
    /// trials), so the verdict's ratios carry an interval over the nets' training randomness
    /// (`net_seeds.csv`; empty: the run's own nets alone).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub net_seeds: Vec<u64>,
}

/// The most further net seeds a run may ask for (each trains every emulator again).
pub const MAX_NET_SEEDS: usize = 16;

crate::result_rows! {
    /// One row of `error.csv`: an emulator's mean absolute error at one comparison frame.
    pub struct ErrorRow {
        /// The pendulum variant (`passive`, `active`).
        variant: String = "variant",
        /// The emulator (`N25`, `N50`, `N100`).
        emulator: String = "emulator",
        /// The frame's time (s).
        t: f64 = "t",
        /// Mean |emulated - simulated| over trials and state variables (rad and rad/s).
        error: f64 = "error",
    }
}

crate::result_rows! {
    /// One row of `capacity.csv`: an emulator at one capacity tried (the net's own first).
    pub struct CapacityRow {
        /// The pendulum variant.
        variant: String = "variant",
        /// The emulator.
        emulator: String = "emulator",
        /// Hidden units.
        hidden: i64 = "hidden",
        /// Training examples.
        examples: i64 = "examples",
        /// The error averaged over every frame.
        mean_error: f64 = "mean_error",
        /// The error averaged over the frames every emulator steps to (multiples of the
        /// longest super-step).
        common_mean_error: f64 = "common_mean_error",
    }
}

crate::result_rows! {
    /// One row of `net_seeds.csv`: per net seed (the run's own first), an emulator at one
    /// capacity, its time-averaged error over the trials.
    pub struct NetSeedRow {
        /// The net seed.
        net_seed: i64 = "net_seed",
        /// The pendulum variant.
        variant: String = "variant",
        /// The emulator.
        emulator: String = "emulator",
        /// Hidden units.
        hidden: i64 = "hidden",
        /// The error averaged over every frame.
        mean_error: f64 = "mean_error",
    }
}

/// The verdict's bars on the ratio of the largest to the smallest time-averaged error across
/// the emulators of a variant (ours).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fig12Rule {
    /// Held: every variant's ratio at most this.
    pub held_ratio: f64,
    /// Partly: every variant's ratio at most this.
    pub partly_ratio: f64,
}

impl Params {
    /// The null's ratio: an error proportional to the super-step, the longest emulator's
    /// steps over the shortest's.
    pub fn null_ratio(&self) -> f64 {
        let n = |f: fn(usize, usize) -> usize| self.emulators.iter().copied().reduce(f);
        match (n(usize::max), n(usize::min)) {
            (Some(hi), Some(lo)) if lo > 0 => hi as f64 / lo as f64,
            _ => f64::NAN,
        }
    }
}

/// Examples for `net` at `hidden` units: the net's own examples per weight.
fn scaled_examples(net: &NetSpec, hidden: usize) -> usize {
    let (n, m) = (net.model.state_dim(), net.model.control_dim());
    let w = |h| Mlp::weight_count(n + m, h, n) as f64;
    (net.examples as f64 * w(hidden) / w(net.hidden)).round() as usize
}

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        ensure(self.physical_steps >= 1, "physical_steps", "must be >= 1")?;
        ensure(self.trials >= 1, "trials", "must be >= 1")?;
        positive("frame_dt", self.frame_dt)?;
        ensure(
            self.warmup >= 0.0 && self.warmup.is_finite(),
            "warmup",
            "must be >= 0",
        )?;
        ensure(
            !self.emulators.is_empty() && self.emulators.iter().all(|&n| n >= 1),
            "emulators",
            "need at least one n >= 1",
        )?;
        validate_nets(&self.nets, self.example_scale)?;
        ensure(
            self.net_seeds.len() <= MAX_NET_SEEDS,
            "net_seeds",
            format!("at most {MAX_NET_SEEDS}"),
        )?;
        ensure(
            (1..self.net_seeds.len()).all(|i| !self.net_seeds[..i].contains(&self.net_seeds[i])),
            "net_seeds",
            "must not repeat a seed",
        )?;
        ensure(
            self.capacity_hidden.iter().all(|&h| h >= 1),
            "capacity_hidden",
            "every entry must be >= 1",
        )?;
        for (i, n) in self.nets.iter().enumerate() {
            ensure(
                matches!(
                    n.model,
                    NetModel::PendulumPassive | NetModel::PendulumActive
                ),
                &format!("nets[{i}].model"),
                "Fig. 12 covers pendulum_passive and pendulum_active",
            )?;
        }
        let (held, partly) = (self.rule.held_ratio, self.rule.partly_ratio);
        ensure(
            held >= 1.0 && partly >= held,
            "rule.held_ratio",
            "need 1 <= held_ratio <= partly_ratio (a ratio of largest to smallest error)",
        )?;
        // Quick runs may keep one emulator: no ratio, no rule (the report says so).
        let null = self.null_ratio();
        ensure(
            self.emulators.len() < 2 || partly < null,
            "rule.partly_ratio",
            format!(
                "must be below {null}, what an error proportional to the super-step scores (else the check cannot fail)"
            ),
        )?;
        validate_training(&self.training)
    }
}

fn variant(m: NetModel) -> &'static str {
    match m {
        NetModel::PendulumActive => "active",
        _ => "passive",
    }
}

/// Linear interpolation of a trajectory sampled every `h` seconds (rows of `states`, width
/// `w`) at time `t`; beyond the last sample, the last state.
fn interp(states: &[f64], w: usize, h: f64, t: f64, out: &mut [f64]) {
    let last = states.len() / w - 1;
    let f = t / h;
    let k = (f.floor() as usize).min(last);
    if k >= last {
        out.copy_from_slice(&states[last * w..]);
        return;
    }
    let a = f - k as f64;
    for i in 0..w {
        out[i] = (1.0 - a) * states[k * w + i] + a * states[(k + 1) * w + i];
    }
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let (mut table, mut capacity, mut seeds_t) = (Vec::new(), Vec::new(), Vec::new());
        let steps = self.physical_steps;
        let mean = |curve: &[f64]| curve.iter().sum::<f64>() / curve.len() as f64;
        for (vi, net) in self.nets.iter().enumerate() {
            let dt = net.physical_dt;
            let frame_step = |j: usize| ((j as f64 * self.frame_dt) / dt).round() as usize;
            let model = net.model;
            let own = self.curves(ctx, ctx.seed, vi, net, "")?;
            for c in &own {
                if c.hidden == net.hidden {
                    for (f, e) in c.curve.iter().enumerate() {
                        table.push(ErrorRow {
                            variant: variant(model).to_string(),
                            emulator: format!("N{}", c.k),
                            t: frame_step(f).min(steps) as f64 * dt,
                            error: *e,
                        });
                    }
                }
                // The frames every emulator steps to (multiples of the longest super-step): no
                // interpolation between coarse steps in their error.
                let k_max = self.emulators.iter().copied().max().unwrap_or(1);
                let common: Vec<f64> = (0..c.curve.len())
                    .filter(|&f| frame_step(f).min(steps) % k_max == 0)
                    .map(|f| c.curve[f])
                    .collect();
                capacity.push(CapacityRow {
                    variant: variant(model).to_string(),
                    emulator: format!("N{}", c.k),
                    hidden: c.hidden as i64,
                    examples: c.examples as i64,
                    mean_error: mean(&c.curve),
                    common_mean_error: common.iter().sum::<f64>() / common.len().max(1) as f64,
                });
            }
            let mut seeds = vec![(ctx.seed, own)];
            for &seed in &self.net_seeds {
                if seed != ctx.seed {
                    let label = format!(", net seed {seed}");
                    seeds.push((seed, self.curves(ctx, seed, vi, net, &label)?));
                }
            }
            for (seed, curves) in &seeds {
                for c in curves {
                    seeds_t.push(NetSeedRow {
                        net_seed: *seed as i64,
                        variant: variant(model).to_string(),
                        emulator: format!("N{}", c.k),
                        hidden: c.hidden as i64,
                        mean_error: mean(&c.curve),
                    });
                }
            }
        }
        let rule = rule_table(&[
            ("held_ratio", self.rule.held_ratio),
            ("partly_ratio", self.rule.partly_ratio),
            ("null_ratio", self.null_ratio()),
        ]);
        Ok(Tables::from([
            ("error", table_of(&table)),
            ("capacity", table_of(&capacity)),
            ("net_seeds", table_of(&seeds_t)),
            ("rule", rule),
        ]))
    }
}

/// One emulator's mean absolute error per comparison frame over the trials.
struct Curve {
    /// Physical steps per emulator step.
    k: usize,
    /// Hidden units.
    hidden: usize,
    /// Training examples.
    examples: usize,
    /// Mean |error| over trials and state variables, per frame.
    curve: Vec<f64>,
}

impl Params {
    /// Every emulator of `net` (variant `vi`) trained under net seed `seed` (at the net's own
    /// hidden units, then at each extra capacity), rolled out beside the simulator on the run's
    /// trials (the same trials whatever the net seed: they test the nets, whose training
    /// randomness the seed draws). `label` tells the stages of a further seed apart.
    fn curves(
        &self,
        ctx: &RunContext,
        seed: u64,
        vi: usize,
        net: &NetSpec,
        label: &str,
    ) -> Result<Vec<Curve>, Error> {
        let steps = self.physical_steps;
        let dt = net.physical_dt;
        let duration = steps as f64 * dt;
        let frames = (duration / self.frame_dt + 1e-9).floor() as usize;
        let frame_step = |j: usize| ((j as f64 * self.frame_dt) / dt).round() as usize;
        let model = net.model;
        let (n, m) = (model.state_dim(), model.control_dim());
        let mut hiddens = vec![net.hidden];
        hiddens.extend(self.capacity_hidden.iter().filter(|&&h| h != net.hidden));
        let mut specs = vec![];
        for &hidden in &hiddens {
            let mut sized = net.clone();
            (sized.hidden, sized.examples) = (hidden, scaled_examples(net, hidden));
            for &k in &self.emulators {
                let spec = build_spec(seed, &sized, k, self.example_scale, &self.training);
                specs.push((k, hidden, spec));
            }
        }
        let only: Vec<BuildSpec> = specs.iter().map(|s| s.2.clone()).collect();
        let stage = format!("train {} emulators (side by side){label}", model.name());
        let built = ctx.stage(&stage, || build_emulators(&only))?;
        let emulators: Vec<_> = specs
            .into_iter()
            .zip(built)
            .map(|((k, hidden, spec), t)| (k, hidden, spec.net.examples, t.emulator))
            .collect();
        // Sum of |error| per emulator and frame over trials and variables.
        let mut sums = vec![vec![0.0; frames + 1]; emulators.len()];
        let mut sim = model.simulator();
        let mut phys = vec![0.0; (steps + 1) * n];
        let mut u = vec![0.0; m];
        let mut x = vec![0.0; n];
        let mut y = vec![0.0; n];
        let mut s_int = vec![0.0; n];
        ctx.stage(&format!("trials {}{label}", variant(model)), || {
            for trial in 0..self.trials {
                let mut rng = ctx.rng(1000 * (vi as u64 + 1) + trial as u64);
                let mut x0 = model.start_state_in(net.data, &mut rng);
                let warm = (self.warmup / dt).round() as usize;
                let signal = ControlSignal::sample(
                    model.control_process_in(net.data),
                    &model.sampling_limits(net.data),
                    duration + warm as f64 * dt,
                    &mut rng,
                );
                for k in 0..warm {
                    signal.at(k as f64 * dt, &mut u);
                    sim.step(&mut x0, &u, dt);
                }
                let t0 = warm as f64 * dt;
                x.copy_from_slice(&x0);
                phys[..n].copy_from_slice(&x);
                for k in 0..steps {
                    signal.at(t0 + k as f64 * dt, &mut u);
                    sim.step(&mut x, &u, dt);
                    phys[(k + 1) * n..(k + 2) * n].copy_from_slice(&x);
                }
                for (ei, (k, _, _, e)) in emulators.iter().enumerate() {
                    let h = *k as f64 * dt;
                    let count = steps.div_ceil(*k);
                    let mut traj = Vec::with_capacity((count + 1) * n);
                    traj.extend_from_slice(&x0);
                    let mut scratch = e.scratch();
                    x.copy_from_slice(&x0);
                    for j in 0..count {
                        signal.at(t0 + (j as f64 + 0.5) * h, &mut u);
                        e.predict(&x, &u, &mut scratch, &mut y);
                        std::mem::swap(&mut x, &mut y);
                        traj.extend_from_slice(&x);
                    }
                    for (f, sum) in sums[ei].iter_mut().enumerate() {
                        let ps = frame_step(f).min(steps);
                        interp(&traj, n, h, ps as f64 * dt, &mut s_int);
                        *sum += s_int
                            .iter()
                            .zip(&phys[ps * n..(ps + 1) * n])
                            .map(|(a, b)| (a - b).abs())
                            .sum::<f64>();
                    }
                }
            }
        });
        Ok(emulators
            .iter()
            .zip(sums)
            .map(|((k, hidden, examples, _), sum)| Curve {
                k: *k,
                hidden: *hidden,
                examples: *examples,
                curve: sum.iter().map(|s| s / (self.trials * n) as f64).collect(),
            })
            .collect())
    }
}

/// The verdict's rule over each variant's largest/smallest error ratio: held needs every
/// variant's at most `held_ratio`, partly at most `partly_ratio`; each check's null an error
/// proportional to the super-step (`null_ratio`). A ratio may carry its 95% interval over net
/// seeds and `over` names the statistic (e.g. ", median over 5 net seeds"). `None` without
/// ratios or when a bar is not below the null's ratio.
pub fn fig12_rule(
    ratios: &[(&str, f64, Option<(f64, f64)>)],
    over: &str,
    bars: &Fig12Rule,
    null_ratio: f64,
) -> Option<Rule> {
    if ratios.is_empty() {
        return None;
    }
    let null = || Null::new("an error proportional to the super-step", null_ratio);
    let check = |v: &str, r: f64, interval: Option<(f64, f64)>, bar: f64| {
        Check::new(
            format!("{v} pendulum: largest over smallest time-averaged error{over}"),
            r,
            Cmp::AtMost,
            bar,
            null(),
        )
        .map(|c| match interval {
            Some((lo, hi)) => c.with_interval(lo, hi),
            None => c,
        })
    };
    let mut held: Vec<_> = ratios
        .iter()
        .map(|(v, r, i)| check(v, *r, *i, bars.held_ratio))
        .collect();
    let partly: Vec<usize> = (held.len()..2 * held.len()).collect();
    held.extend(
        ratios
            .iter()
            .map(|(v, r, i)| check(v, *r, *i, bars.partly_ratio)),
    );
    Rule::gated(vec![], held, Partly::All(partly))
}

/// The largest over the smallest of `errors` (None for fewer than two).
fn spread(errors: &[f64]) -> Option<f64> {
    (errors.len() >= 2).then(|| {
        let lo = errors.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = errors.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        hi / lo
    })
}

/// Physical steps per emulator step of an emulator's name (`N50`: 50).
fn super_step(emulator: &str) -> Option<f64> {
    emulator.trim_start_matches('N').parse::<f64>().ok()
}

/// Seed of the bootstrap over net seeds (fixed, so a report is the same on every machine).
const BOOTSTRAP_SEED: u64 = 1;

/// Per variant, the verdict's ratio (each emulator at the best capacity tried) under each net
/// seed of `net_seeds.csv`: (variant, ratio per seed in the table's order). `None` without the
/// table or with one seed.
fn seed_ratios(dir: &Path) -> Result<Option<Vec<(String, Vec<f64>)>>, Error> {
    let Some(df) = written_csv(dir, "net_seeds.csv")? else {
        return Ok(None);
    };
    let rows = NetSeedRow::from_frame(&df)
        .map_err(|e| Error::Other(format!("{}: {e}", dir.join("net_seeds.csv").display())))?;
    let mut seeds: Vec<i64> = vec![];
    let mut variants: Vec<String> = vec![];
    for r in &rows {
        if !seeds.contains(&r.net_seed) {
            seeds.push(r.net_seed);
        }
        if !variants.contains(&r.variant) {
            variants.push(r.variant.clone());
        }
    }
    if seeds.len() < 2 {
        return Ok(None);
    }
    let out = variants
        .into_iter()
        .map(|v| {
            let ratios = seeds
                .iter()
                .filter_map(|&s| {
                    let mut best: Vec<(&str, f64)> = vec![];
                    for r in rows.iter().filter(|r| r.net_seed == s && r.variant == v) {
                        match best.iter_mut().find(|b| b.0 == r.emulator) {
                            Some(b) => b.1 = b.1.min(r.mean_error),
                            None => best.push((r.emulator.as_str(), r.mean_error)),
                        }
                    }
                    spread(&best.iter().map(|b| b.1).collect::<Vec<_>>())
                })
                .collect();
            (v, ratios)
        })
        .collect();
    Ok(Some(out))
}

/// The best of an emulator's own time-averaged error `own` and its mean error at every
/// capacity tried.
fn best_of(tried: &[CapacityRow], v: &str, e: &str, own: f64) -> f64 {
    tried
        .iter()
        .filter(|t| t.variant == v && t.emulator == e)
        .map(|t| t.mean_error)
        .fold(own, f64::min)
}

/// The report's table: per (variant, emulator) its time-averaged error, its mean error at
/// each further capacity tried (`hiddens` past the first, the nets' own) and the best.
fn capacity_md(means: &[(String, String, f64)], tried: &[CapacityRow], hiddens: &[i64]) -> String {
    let best = |v: &str, e: &str, own: f64| best_of(tried, v, e, own);
    let mut md = String::from("| variant | emulator | time-averaged error |");
    for h in &hiddens[1.min(hiddens.len())..] {
        md.push_str(&format!(" with {h} hidden |"));
    }
    md.push_str(" best |\n|");
    md.push_str(&" --- |".repeat(4 + hiddens.len().saturating_sub(1)));
    md.push('\n');
    for (v, e, s) in means {
        md.push_str(&format!("| {v} | {e} | {} |", sig(*s)));
        for h in &hiddens[1.min(hiddens.len())..] {
            let x = tried
                .iter()
                .find(|t| t.variant == *v && t.emulator == *e && t.hidden == *h);
            md.push_str(&format!(
                " {} |",
                x.map_or("-".into(), |t| sig(t.mean_error))
            ));
        }
        md.push_str(&format!(" {} |\n", sig(best(v, e, *s))));
    }
    md
}

/// Diagnostic (ours, not the verdict): the same ratio at the frames every emulator steps
/// to, where no emulator's error includes linear interpolation between its coarse steps, at
/// the nets' own capacity (the first tried).
fn common_text(tried: &[CapacityRow]) -> String {
    let common_ratio = |v: &str| -> Option<f64> {
        let own = tried.first()?.hidden;
        let vals: Vec<f64> = tried
            .iter()
            .filter(|t| t.variant == v && t.hidden == own)
            .map(|t| t.common_mean_error)
            .collect();
        spread(&vals)
    };
    let common: Vec<String> = ["passive", "active"]
        .iter()
        .filter_map(|v| common_ratio(v).map(|r| format!("{v} {}", sig(r))))
        .collect();
    if common.is_empty() {
        String::new()
    } else {
        format!(" Diagnostic (ours, not the verdict): at the paper's Table 1 capacity, at the frames every emulator steps to (multiples of the longest super-step, so no error from interpolating between coarse steps): {}.", common.join(", "))
    }
}

/// Time-averaged error per (variant, emulator), in first-seen order.
fn mean_errors(rows: &[ErrorRow]) -> Vec<(String, String, f64)> {
    let mut out: Vec<(String, String, f64, usize)> = vec![];
    for r in rows {
        match out
            .iter_mut()
            .find(|o| o.0 == r.variant && o.1 == r.emulator)
        {
            Some(o) => {
                o.2 += r.error;
                o.3 += 1;
            }
            None => out.push((r.variant.clone(), r.emulator.clone(), r.error, 1)),
        }
    }
    out.into_iter()
        .map(|(v, e, s, c)| (v, e, s / c as f64))
        .collect()
}

impl Family for NaError {
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "error",
            "mean absolute state error of the N25, N50 and N100 emulators against the simulator vs time over 30 trials, passive and active pendulum (the paper's Fig. 12).",
        ),
        (
            "capacity",
            "the same error averaged over time vs the emulator's hidden units (examples per weight kept): each emulator at every capacity tried.",
        ),
    ];
    const KIND: &'static str = "na_fig12_error";
    type Params = Params;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        let rows = ErrorRow::from_table(tables.require("error")?);
        let mut panels = vec![];
        for v in ["passive", "active"] {
            let mut kinds: Vec<String> = vec![];
            for r in rows.iter().filter(|r| r.variant == v) {
                if !kinds.contains(&r.emulator) {
                    kinds.push(r.emulator.clone());
                }
            }
            if kinds.is_empty() {
                continue;
            }
            let marks = [Mark::Line, Mark::Dashed, Mark::Line];
            let series = kinds
                .iter()
                .enumerate()
                .map(|(i, k)| {
                    let pts = rows
                        .iter()
                        .filter(|r| r.variant == v && r.emulator == *k)
                        .map(|r| (r.t, r.error))
                        .collect();
                    Series::line(k.clone(), pts, i).mark(marks[i % 3])
                })
                .collect();
            panels.push(Panel {
                title: format!("{v} pendulum"),
                x_label: "time (s)".into(),
                y_label: "mean |emulated - simulated| over the state (rad and rad/s)".into(),
                series,
                ..Panel::default()
            });
        }
        let mut out = fig.draw("error", &Figure::grid(panels, 2))?;
        // Time-averaged error against the super step, one line per hidden-unit count.
        if let Some(c) = tables.get("capacity") {
            let cap = CapacityRow::from_table(c);
            let mut panels = vec![];
            for v in ["passive", "active"] {
                let mut hs: Vec<i64> = vec![];
                for r in cap.iter().filter(|r| r.variant == v) {
                    if !hs.contains(&r.hidden) {
                        hs.push(r.hidden);
                    }
                }
                if hs.is_empty() {
                    continue;
                }
                let series = hs
                    .iter()
                    .enumerate()
                    .map(|(i, h)| {
                        let pts = cap
                            .iter()
                            .filter(|r| r.variant == v && r.hidden == *h)
                            .filter_map(|r| super_step(&r.emulator).map(|n| (n, r.mean_error)))
                            .collect();
                        Series::line(format!("{h} hidden"), pts, i).mark(Mark::LinePoints)
                    })
                    .collect::<Vec<Series>>();
                // The verdict's limits: each N at its best capacity tried, within the held or
                // the partly ratio of the smallest such error.
                let mut best_per_n: Vec<(f64, f64)> = vec![];
                for r in cap.iter().filter(|r| r.variant == v) {
                    if let Some(n) = super_step(&r.emulator) {
                        match best_per_n.iter_mut().find(|b| b.0 == n) {
                            Some(b) => b.1 = b.1.min(r.mean_error),
                            None => best_per_n.push((n, r.mean_error)),
                        }
                    }
                }
                let smallest = best_per_n.iter().map(|b| b.1).fold(f64::INFINITY, f64::min);
                let (x0, x1) = best_per_n
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |a, b| {
                        (a.0.min(b.0), a.1.max(b.0))
                    });
                let mut series = series;
                if smallest.is_finite() && x1 > x0 {
                    let k = series.len();
                    let limits = [
                        (rule_setting(tables, "held_ratio"), "held"),
                        (rule_setting(tables, "partly_ratio"), "partly"),
                    ];
                    for (i, (f, what)) in limits.into_iter().enumerate() {
                        let Some(f) = f else { continue };
                        series.push(
                            Series::line(
                                format!(
                                    "{what} limit: {} x the smallest best-capacity error",
                                    sig(f)
                                ),
                                vec![(x0, f * smallest), (x1, f * smallest)],
                                k + i,
                            )
                            .mark(Mark::Dashed),
                        );
                    }
                }
                panels.push(Panel {
                    title: format!("{v} pendulum: capacity"),
                    x_label: "physical steps per emulator step N".into(),
                    y_label: "time-averaged mean |emulated - simulated| (rad and rad/s)".into(),
                    series,
                    ..Panel::default()
                });
            }
            if !panels.is_empty() {
                out.extend(fig.draw("capacity", &Figure::grid(panels, 2))?);
            }
        }
        Ok(out)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        let means = mean_errors(&read_rows::<ErrorRow>(&dir.join("error.csv"))?);
        // Every capacity tried, the nets' own first.
        let tried: Vec<CapacityRow> = read_rows(&dir.join("capacity.csv"))?;
        let mut hiddens: Vec<i64> = vec![];
        for t in &tried {
            if !hiddens.contains(&t.hidden) {
                hiddens.push(t.hidden);
            }
        }
        let best = |v: &str, e: &str, own: f64| best_of(&tried, v, e, own);
        let md = capacity_md(&means, &tried, &hiddens);
        // "Nearly the same": per variant, the largest time-averaged error within 1.5x of the
        // smallest (within 3x: partly), each emulator at the best capacity tried (the paper's
        // nets have O(N) hidden units; the capacity is the modeller's choice per emulator).
        let ratio_of = |v: &str, own_only: bool| -> Option<f64> {
            let vals: Vec<f64> = means
                .iter()
                .filter(|m| m.0 == v)
                .map(|m| if own_only { m.2 } else { best(&m.0, &m.1, m.2) })
                .collect();
            spread(&vals)
        };
        let variants = ["passive", "active"];
        let ratios: Vec<(&str, f64)> = variants
            .iter()
            .filter_map(|v| ratio_of(v, false).map(|r| (*v, r)))
            .collect();
        let own: Vec<String> = variants
            .iter()
            .filter_map(|v| ratio_of(v, true).map(|r| format!("{v} {}", sig(r))))
            .collect();
        let common_text = common_text(&tried);
        let settings = rule_settings(dir)?;
        let bars = Fig12Rule {
            held_ratio: settings("held_ratio"),
            partly_ratio: settings("partly_ratio"),
        };
        // Over several net seeds each variant's ratio is their median with its interval.
        let by_seed = seed_ratios(dir)?;
        let mut seeds_text = String::new();
        let (checked, over): (Vec<(&str, f64, Option<(f64, f64)>)>, String) = match &by_seed {
            Some(by_seed) => {
                let k = by_seed.iter().map(|v| v.1.len()).max().unwrap_or(0);
                let rows = variants
                    .iter()
                    .filter_map(|v| {
                        let (_, r) = by_seed.iter().find(|b| b.0 == *v)?;
                        let (m, lo, hi) = median_interval(r, BOOTSTRAP_SEED);
                        Some((*v, m, Some((lo, hi))))
                    })
                    .collect();
                let per: Vec<String> = by_seed
                    .iter()
                    .map(|(v, r)| {
                        let r: Vec<String> = r.iter().map(|x| sig(*x)).collect();
                        format!("{v} {}", r.join(", "))
                    })
                    .collect();
                seeds_text = format!(
                    " Per net seed (net_seeds.csv: every emulator trained again under each seed, the same trials; the run's own first), the ratio: {}.",
                    per.join("; ")
                );
                (rows, format!(", median over {k} net seeds"))
            }
            None => (
                ratios.iter().map(|(v, r)| (*v, *r, None)).collect(),
                String::new(),
            ),
        };
        let rule = fig12_rule(&checked, &over, &bars, settings("null_ratio"));
        let (verdict, lines, text) = shown(
            rule.as_ref(),
            " No rule: no variant has two emulators, or a bar is not below the null's ratio.",
        );
        Ok(Findings {
            ours: md,
            verdict,
            rule: rule.clone(),
            why: format!(
                "Largest / smallest time-averaged error across the emulators, each at the best capacity tried{over}: {}{}. Checks:{lines} Rule (bars ours, in the spec's [params.rule]): {text} At the paper's Table 1 capacity for all three: {}. Extra capacities keep the net's examples per weight.{seeds_text}{common_text}",
                checked
                    .iter()
                    .map(|(v, r, i)| match i {
                        Some((lo, hi)) => format!("{v} {} [{}-{}]", sig(*r), sig(*lo), sig(*hi)),
                        None => format!("{v} {}", sig(*r)),
                    })
                    .collect::<Vec<_>>()
                    .join(", "),
                if by_seed.is_some() {
                    let r: Vec<String> = ratios
                        .iter()
                        .map(|(v, r)| format!("{v} {}", sig(*r)))
                        .collect();
                    format!(" (the run's own nets: {})", r.join(", "))
                } else {
                    String::new()
                },
                own.join(", ")
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::report::Verdict;

    const BARS: Fig12Rule = Fig12Rule {
        held_ratio: 1.5,
        partly_ratio: 3.0,
    };

    /// The spread is the largest over the smallest error; the rule reads each variant's
    /// ratio (or its median over net seeds) against both bars, and a median whose interval
    /// straddles the partly bar leaves the verdict between partly and not held: inconclusive.
    #[test]
    fn the_rule_reads_each_variants_ratio_and_its_interval() {
        assert_eq!(spread(&[2.0, 1.0, 4.0]), Some(4.0));
        assert_eq!(spread(&[2.0]), None);
        let rule = |r: &[(&str, f64, Option<(f64, f64)>)]| {
            fig12_rule(r, "", &BARS, 4.0).unwrap().verdict()
        };
        assert_eq!(
            rule(&[("passive", 1.2, None), ("active", 1.4, None)]),
            Verdict::Held
        );
        assert_eq!(
            rule(&[("passive", 2.0, None), ("active", 1.4, None)]),
            Verdict::Partly
        );
        assert_eq!(
            rule(&[("passive", 14.5, None), ("active", 3.01, None)]),
            Verdict::NotHeld
        );
        assert_eq!(
            rule(&[("passive", 2.0, None), ("active", 2.9, Some((2.5, 3.4)))]),
            Verdict::Inconclusive
        );
        // A bar the null meets is refused: no rule.
        assert!(fig12_rule(&[("passive", 1.0, None)], "", &BARS, 2.0).is_none());
    }
}
