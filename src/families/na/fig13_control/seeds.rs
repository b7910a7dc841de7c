//! The headline over several Table 1 net seeds (ours): one trained net per task is
//! one draw of the training's randomness, and whether a net carries its learned controls to the
//! goal on the simulator turned on that draw (two `reproduce` runs whose nets differ only by
//! retraining noise gave 2 of 4 and 0 of 4). So every task of the paper's formulation (the
//! dolphin aside) is learned again, by the same headline (momentum η 1.5, α 0.5, λ at the
//! start, the paper's iteration count), through the net `na_table1_structure` trains under
//! each further seed ([`Params::net_seeds`]), each net calibrated as the run's own
//! ([`Task::calibrated`]), and its controls replayed on the simulator. `net_seeds.csv`: one row per
//! task and net seed, the run's own seed included.
//!
//! The verdict's rule ([`majority_at_goal`], written before the first run with several seeds):
//! a task reaches its goal when a strict majority of its net seeds reach it on the emulator
//! and on the simulator.

use super::rows::{NetLineRow, NetSeedRow, PathRow, PhysicsPathRow};
use super::{Formulation, Params, Task};
use crate::emulator::catalog::BuildSpec;
use crate::emulator::Emulator;
use crate::experiment::output::{unique, Tables};
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::report::sig;
use crate::experiment::rows::{written_rows, TableRow};
use crate::experiment::stats::median;
use crate::experiment::{other, Error, RunContext};
use crate::families::na::table1_structure::{build_emulators, build_spec};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// Columns of `net_seeds.csv` ([`NetSeedRow`]): `at_goal` is 1 when both final errors are at
/// most 1; `formulation` is `paper` (counted by the verdict) or `ours` (a second line, never
/// counted); `iterations_to_goal` (ours, a diagnostic beside the verdict) is the first
/// iteration of the same descent continued to twice the paper's count whose iterate is within
/// tolerance on the net and on the simulator replay (NaN: none is), so a seed that misses the
/// paper's count shows whether it is slow or never gets there; `physics_iterations_to_goal`
/// the same for the same descent (this seed's calibration) through the physical model itself.
pub const SEEDS_COLUMNS: &[&str] = NetSeedRow::COLUMNS;

/// The most net seeds a run may ask for (each trains one net per task).
pub const MAX_NET_SEEDS: usize = 16;

/// One headline run: the final errors on the emulator and on the simulator replay, and the
/// best iteration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadlineRun {
    /// Final error of the best iterate's emulator rollout.
    pub emulator_error: f64,
    /// Final error of the same controls replayed on the simulator.
    pub simulator_error: f64,
    /// Iteration of the best iterate.
    pub best_iteration: usize,
}

impl HeadlineRun {
    /// Both final errors within tolerance.
    pub fn at_goal(&self) -> bool {
        self.emulator_error <= 1.0 && self.simulator_error <= 1.0
    }

    /// The row of `net_seeds.csv` for `task` through the net of `seed`, with its [`ToGoal`].
    pub fn push(&self, table: &mut Vec<NetSeedRow>, task: &Task, seed: u64, to_goal: ToGoal) {
        table.push(NetSeedRow {
            task: task.name.clone(),
            net_seed: seed as i64,
            emulator_error: self.emulator_error,
            simulator_error: self.simulator_error,
            best_iteration: self.best_iteration as i64,
            at_goal: i64::from(self.at_goal()),
            formulation: task.formulation.name().into(),
            iterations_to_goal: iteration_or_nan(to_goal.net),
            physics_iterations_to_goal: iteration_or_nan(to_goal.physics),
        });
    }
}

/// Where a task's headline descent, continued, first reaches the goal: through the net (within
/// tolerance on it and on the simulator replay, [`super::job::iterations_to_goal`]) and through
/// the physics under the same calibration ([`super::conditioning::physics_iterations_to_goal`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ToGoal {
    /// Through the net.
    pub net: Option<usize>,
    /// Through the physics.
    pub physics: Option<usize>,
}

impl ToGoal {
    /// Both measured for the calibrated `task` through `net`; where `path` is given, the
    /// physics' descent with the net's gradient beside it goes to it (`physics_path.csv`)
    /// under the given net seed.
    pub(super) fn measure(
        task: &Task,
        net: &Emulator,
        steps: usize,
        curvature_iterations: usize,
        path: Option<(&mut Vec<PhysicsPathRow>, u64)>,
    ) -> Result<Self, Error> {
        let (physics, iterates) =
            super::conditioning::physics_descent(task, steps, curvature_iterations)?;
        if let Some((table, seed)) = path {
            let fidelity = super::job::gradient_fidelity(task, net, &iterates)?;
            for (it, (cosine, relative)) in iterates.iter().zip(fidelity) {
                table.push(PhysicsPathRow {
                    task: task.name.clone(),
                    net_seed: seed as i64,
                    iteration: it.iteration as i64,
                    physics_error: it.error,
                    gradient_cosine: cosine,
                    gradient_relative_error: relative,
                });
            }
        }
        Ok(Self {
            net: super::job::iterations_to_goal(task, net, steps, curvature_iterations)?,
            physics,
        })
    }
}

/// An iteration count as a table value: NaN for none.
fn iteration_or_nan(i: Option<usize>) -> f64 {
    i.map_or(f64::NAN, |i| i as f64)
}

/// An iteration read back from a table, for the report: the whole number, or "never" for NaN.
pub(super) fn iteration_words(x: f64) -> String {
    if x.is_finite() {
        format!("{}", x.round() as i64)
    } else {
        "never".into()
    }
}

impl Params {
    /// The seeds beyond the run's own (`own`), in the spec's order, without repeats.
    pub(super) fn further_net_seeds(&self, own: u64) -> Vec<u64> {
        crate::experiment::seeds::further_seeds(&self.net_seeds, own)
    }

    /// Whether `task` is learned over the net seeds (`net_seeds.csv`): every task of the
    /// paper's formulation, and ours named in [`Params::net_seeds_ours`].
    pub(super) fn over_net_seeds(&self, task: &Task) -> bool {
        task.formulation == Formulation::Paper || self.net_seeds_ours.contains(&task.name)
    }

    /// The headline of `task` (uncalibrated) through `net`: calibrated there, learned by the
    /// task's own η, α and step rule for its iteration count, scored at the best iterate.
    /// Where `path` is given, the descent's `path.csv` rows go to its table. Returns the run
    /// and the calibrated task.
    pub(super) fn headline_run(
        &self,
        task: &Task,
        net: &Emulator,
        path: Option<(&mut Vec<PathRow>, u64)>,
    ) -> Result<(HeadlineRun, Task), Error> {
        let x0 = task.start_state();
        let task = task.calibrated(net, &x0).map_err(other)?;
        let steps = self.steps;
        let (run, _) =
            super::job::learn_and_replay_path(&task, net, steps, self.curvature_iterations, path)?
                .ok_or_else(|| other(format!("{}: no finite step scale λ", task.name)))?;
        Ok((run, task))
    }

    /// Every task of the paper's formulation, and those of ours in
    /// [`Params::net_seeds_ours`], learned through the nets of the further seeds (trained side
    /// by side, or loaded from the cache), one row each in `table`; the descents of the
    /// paper's tasks go to `path` (`path.csv`).
    pub(super) fn run_seeds(
        &self,
        ctx: &RunContext,
        table: &mut Vec<NetSeedRow>,
        path: &mut Vec<PathRow>,
        physics_path: &mut Vec<PhysicsPathRow>,
    ) -> Result<(), Error> {
        let seeds = self.further_net_seeds(ctx.seed);
        let tasks: Vec<&Task> = self
            .tasks
            .iter()
            .filter(|t| self.over_net_seeds(t))
            .collect();
        let runs: Vec<(&Task, u64)> = seeds
            .iter()
            .flat_map(|&s| tasks.iter().map(move |&t| (t, s)))
            .collect();
        if runs.is_empty() {
            return Ok(());
        }
        let specs: Vec<BuildSpec> = runs
            .iter()
            .map(|(t, s)| build_spec(*s, &t.net, self.steps, self.example_scale, &self.training))
            .collect();
        let built = ctx.stage(
            &format!(
                "train N{} emulators of {} further seeds",
                self.steps,
                seeds.len()
            ),
            || build_emulators(&specs),
        )?;
        // Each (task, seed) run is independent: side by side, each into rows of its own,
        // appended in the runs' order.
        let rows = (0..runs.len())
            .into_par_iter()
            .map(|i| -> Result<_, Error> {
                let ((task, seed), net) = (runs[i], &built[i].emulator);
                let paper = task.formulation == Formulation::Paper;
                let (mut own_path, mut own_physics, mut own_seeds) = (vec![], vec![], vec![]);
                let (run, calibrated) =
                    ctx.stage(&format!("learn {} (net seed {seed})", task.name), || {
                        let path = paper.then_some((&mut own_path, seed));
                        self.headline_run(task, net, path)
                    })?;
                let to_goal = ctx.stage(
                    &format!("{} to its goal (net seed {seed})", task.name),
                    || {
                        let path = paper.then_some((&mut own_physics, seed));
                        let ci = self.curvature_iterations;
                        ToGoal::measure(&calibrated, net, self.steps, ci, path)
                    },
                )?;
                run.push(&mut own_seeds, task, seed, to_goal);
                Ok((own_path, own_physics, own_seeds))
            })
            .collect::<Result<Vec<_>, Error>>()?;
        for (own_path, own_physics, own_seeds) in rows {
            path.extend(own_path);
            physics_path.extend(own_physics);
            table.extend(own_seeds);
        }
        Ok(())
    }
}

/// Columns of `net_lines.csv` ([`NetLineRow`]): `line` names the net's change (`paper` is the
/// headline's own nets, as in `net_seeds.csv`); `iterations_to_goal` as in [`SEEDS_COLUMNS`].
pub const LINES_COLUMNS: &[&str] = NetLineRow::COLUMNS;

impl Params {
    /// `net_lines.csv`: every task of the paper's formulation (the dolphin aside) learned
    /// through each of [`Params::net_lines`]' nets under the run's own and the further net
    /// seeds (trained side by side, or from the cache), as the headline is.
    pub(super) fn run_lines(&self, ctx: &RunContext) -> Result<Vec<NetLineRow>, Error> {
        let mut table = Vec::new();
        let mut seeds = vec![ctx.seed];
        seeds.extend(self.further_net_seeds(ctx.seed));
        let tasks: Vec<&Task> = self
            .tasks
            .iter()
            .filter(|t| t.formulation == Formulation::Paper)
            .collect();
        let mut runs: Vec<(&Task, &str, u64, BuildSpec)> = Vec::new();
        for line in &self.net_lines {
            for &t in &tasks {
                for &s in &seeds {
                    let net = line.apply(&t.net);
                    let spec = build_spec(s, &net, self.steps, self.example_scale, &self.training);
                    runs.push((t, line.name.as_str(), s, spec));
                }
            }
        }
        if runs.is_empty() {
            return Ok(table);
        }
        let specs: Vec<BuildSpec> = runs.iter().map(|r| r.3.clone()).collect();
        let built = ctx.stage("train the second lines' nets", || build_emulators(&specs))?;
        for ((task, line, seed, _), trained) in runs.iter().zip(&built) {
            let net = &trained.emulator;
            let (run, to_goal) = ctx.stage(
                &format!("learn {} ({line}, net seed {seed})", task.name),
                || -> Result<_, Error> {
                    let (run, calibrated) = self.headline_run(task, net, None)?;
                    let to_goal = super::job::iterations_to_goal(
                        &calibrated,
                        net,
                        self.steps,
                        self.curvature_iterations,
                    )?;
                    Ok((run, to_goal))
                },
            )?;
            table.push(NetLineRow {
                task: task.name.clone(),
                line: line.to_string(),
                net_seed: *seed as i64,
                emulator_error: run.emulator_error,
                simulator_error: run.simulator_error,
                best_iteration: run.best_iteration as i64,
                at_goal: i64::from(run.at_goal()),
                iterations_to_goal: iteration_or_nan(to_goal),
            });
        }
        Ok(table)
    }
}

/// The report's before/after table from `net_lines.csv` and `net_seeds.csv` in `dir`: per
/// paper task, how many net seeds reach the goal on both and on the emulator alone through
/// the headline's nets (`paper`) and through each second line's. Empty without `net_lines.csv`.
pub(super) fn lines_md(dir: &Path) -> Result<String, Error> {
    // A spec without second lines writes the table without rows.
    let Some(lines) = written_rows::<NetLineRow>(dir, "net_lines.csv")? else {
        return Ok(String::new());
    };
    if lines.is_empty() {
        return Ok(String::new());
    }
    /// Per task and line: seeds at the goal on both, on the emulator alone, at the goal on
    /// both when continued, and run.
    struct Count {
        task: String,
        line: String,
        both: usize,
        emulator: usize,
        continued: usize,
        seeds: usize,
    }
    let mut counts: Vec<Count> = Vec::new();
    if let Some(paper) = seed_counts(dir)? {
        let paper_tasks = unique(&lines.iter().map(|r| r.task.clone()).collect::<Vec<_>>());
        for c in paper.into_iter().filter(|c| paper_tasks.contains(&c.task)) {
            counts.push(Count {
                continued: c.to_goal.iter().filter(|t| t.0.is_finite()).count(),
                task: c.task,
                line: "paper".into(),
                both: c.both,
                emulator: c.emulator,
                seeds: c.seeds,
            });
        }
    }
    for r in &lines {
        let i = match counts
            .iter()
            .position(|c| c.task == r.task && c.line == r.line)
        {
            Some(i) => i,
            None => {
                counts.push(Count {
                    task: r.task.clone(),
                    line: r.line.clone(),
                    both: 0,
                    emulator: 0,
                    continued: 0,
                    seeds: 0,
                });
                counts.len() - 1
            }
        };
        counts[i].both += usize::from(r.at_goal == 1);
        counts[i].emulator += usize::from(r.emulator_error <= 1.0);
        counts[i].continued += usize::from(r.iterations_to_goal.is_finite());
        counts[i].seeds += 1;
    }
    counts.sort_by(|a, b| {
        a.task
            .cmp(&b.task)
            .then((a.line != "paper").cmp(&(b.line != "paper")))
    });
    let mut md = format!("\nBefore and after (`net_lines.csv`, ours; reported, never counted): each paper task learned the headline's way through its net with one change, over the same net seeds. `paper`: the headline's nets (typical manoeuvres, the truck's and the lander's with the controls the tasks' regime bounds kept inside it: the truck's drive within +-0.3 m/s^2, the lander's thrust within 0.5-1.5 x hover and its roll and pitch torques within +-30 N m; no input noise); `box`: trained on knots uniform over the whole control box from wide starts (our data before); `noise`: with input noise 0.05 (ours before); `typical`: the typical manoeuvres with every channel over its whole box (the truck's and the lander's data before; the pendulums' nets are the headline's). The last column continues each descent to {}x the paper's iterations (ours).\n\n| task | nets | seeds at the goal on both | on the emulator alone | at the goal on both, continued |\n| --- | --- | --- | --- | --- |\n", super::job::TO_GOAL_FACTOR);
    for c in counts {
        let n = c.seeds;
        md.push_str(&format!(
            "| {} | {} | {} of {n} | {} of {n} | {} of {n} |\n",
            c.task, c.line, c.both, c.emulator, c.continued
        ));
    }
    Ok(md)
}

/// The report's table and sentence from `path.csv` in `dir` (empty without it): per paper
/// task, over the net seeds, how far the curvature along the headline's descent rises above
/// the start's λ against momentum's stable limit, and how the simulator's final error follows
/// the net's at every iterate. The run records the descent of every control task of the
/// paper's formulation (`tasks`), so a written table without a task's rows is an error naming
/// it.
pub(super) fn path_md(dir: &Path, tasks: &[&str]) -> Result<(String, String), Error> {
    let Some(path) = written_rows::<PathRow>(dir, "path.csv")? else {
        return Ok(Default::default());
    };
    if let Some(t) = tasks.iter().find(|t| !path.iter().any(|r| r.task == **t)) {
        return Err(other(format!(
            "{}: no rows for {t}, of the paper's formulation in final.csv (a truncated or edited table)",
            dir.join("path.csv").display()
        )));
    }
    if path.is_empty() {
        return Ok(Default::default());
    }
    let task: Vec<String> = path.iter().map(|r| r.task.clone()).collect();
    let mut md = String::from("
Along the descent (ours; `path.csv`): every iterate of the headline through each net seed's Table 1 net, rolled out on the net and replayed on the simulator, and the largest Hessian eigenvalue of J through the net there over the one at the start (lambda, the fixed step's scale). The heavy-ball step eta/lambda contracts along a direction of curvature mu only while mu/lambda < 2(1 + alpha)/eta (the limit); a net that follows the physics along the whole descent has simulator errors near its own at every iterate, not only at the end.\n\n| task | net seeds | iterates | largest curvature ratio, median over seeds (range) | limit | iterates above the limit | simulator / emulator final error, median over iterates | iterates within tolerance on the net | of them within tolerance on the simulator |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
    let mut why = Vec::new();
    for name in unique(&task) {
        let rows: Vec<&PathRow> = path.iter().filter(|r| r.task == name).collect();
        let seeds = unique(
            &rows
                .iter()
                .map(|r| r.net_seed.to_string())
                .collect::<Vec<_>>(),
        );
        let peaks: Vec<f64> = seeds
            .iter()
            .map(|s| {
                rows.iter()
                    .filter(|r| r.net_seed.to_string() == *s)
                    .map(|r| r.curvature_ratio)
                    .fold(f64::NAN, f64::max)
            })
            .collect();
        let lim = rows[0].stable_ratio;
        let above = rows.iter().filter(|r| r.curvature_ratio > lim).count();
        let gap: Vec<f64> = rows
            .iter()
            .map(|r| r.simulator_error / r.emulator_error)
            .collect();
        let on_net: Vec<&&PathRow> = rows.iter().filter(|r| r.emulator_error <= 1.0).collect();
        let both = on_net.iter().filter(|r| r.simulator_error <= 1.0).count();
        let (lo, hi) = peaks
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        md.push_str(&format!(
            "| {name} | {} | {} | {} ({}-{}) | {} | {above} | {} | {} | {both} |\n",
            seeds.len(),
            rows.len(),
            sig(median(&peaks)),
            sig(lo),
            sig(hi),
            sig(lim),
            sig(median(&gap)),
            on_net.len(),
        ));
        why.push(format!(
            "{name}: curvature up to {}x the start's (median over seeds; limit {}), {above} of {} iterates above the limit, simulator/emulator error {} (median), {both} of {} iterates within tolerance on the net also on the simulator",
            sig(median(&peaks)),
            sig(lim),
            rows.len(),
            sig(median(&gap)),
            on_net.len()
        ));
    }
    let why = format!(" Along the descent (path.csv): {}.", why.join("; "));
    Ok((md, why))
}

/// Whether a strict majority of `at_goal` (one flag per net seed) is set: the rule by which
/// the verdict counts a task as reaching its goal when `net_seeds.csv` has several seeds for it.
pub fn majority_at_goal(at_goal: &[bool]) -> bool {
    2 * at_goal.iter().filter(|&&b| b).count() > at_goal.len()
}

/// One task's count over the net seeds of `net_seeds.csv`.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct SeedCount {
    /// The task.
    pub task: String,
    /// Net seeds at the goal on the emulator and on the simulator.
    pub both: usize,
    /// Net seeds at the goal on the emulator (whatever the simulator's error).
    pub emulator: usize,
    /// Net seeds run.
    pub seeds: usize,
    /// Per net seed (in the table's order), the larger of its final errors on the emulator
    /// and on the simulator: at most 1 exactly when it is at the goal on both.
    pub errors: Vec<f64>,
    /// Per net seed, the first iteration of its descent continued at which it is at the goal
    /// on both (NaN: none), and the same descent's through the physics.
    pub to_goal: Vec<(f64, f64)>,
}

impl SeedCount {
    /// "net seeds continued to the goal at …; through the physics at …" (the iterations per
    /// seed, "never" for none), for the report.
    pub fn to_goal_words(&self) -> String {
        let words = |xs: Vec<f64>| {
            xs.iter()
                .map(|x| iteration_words(*x))
                .collect::<Vec<_>>()
                .join(", ")
        };
        format!(
            "continued to {}x the paper's iterations, at the goal on both at iteration {} (per seed); the same descents through the physics at {}",
            super::job::TO_GOAL_FACTOR,
            words(self.to_goal.iter().map(|t| t.0).collect()),
            words(self.to_goal.iter().map(|t| t.1).collect())
        )
    }
}

/// Per task of `net_seeds.csv` in `dir` (first-seen order): how many net seeds reach the goal
/// on both, on the emulator, and how many were run. `None` when the run wrote no such table (a
/// spec without net seeds); a table that cannot be read, holds a non-finite error or whose
/// tasks ran different numbers of seeds (a truncated file) is an error naming it, never a
/// verdict on fewer seeds.
pub(super) fn seed_counts(dir: &Path) -> Result<Option<Vec<SeedCount>>, Error> {
    let path = dir.join("net_seeds.csv");
    let Some(rows) = written_rows::<NetSeedRow>(dir, "net_seeds.csv")? else {
        return Ok(None);
    };
    let damaged = |why: &str| crate::experiment::other(format!("{}: {why}", path.display()));
    let mut out: Vec<SeedCount> = Vec::new();
    for r in &rows {
        let i = match out.iter().position(|c| c.task == r.task) {
            Some(i) => i,
            None => {
                out.push(SeedCount {
                    task: r.task.clone(),
                    both: 0,
                    emulator: 0,
                    seeds: 0,
                    errors: Vec::new(),
                    to_goal: Vec::new(),
                });
                out.len() - 1
            }
        };
        out[i].both += usize::from(r.at_goal == 1);
        out[i].emulator += usize::from(r.emulator_error <= 1.0);
        out[i].seeds += 1;
        out[i].errors.push(r.emulator_error.max(r.simulator_error));
        out[i]
            .to_goal
            .push((r.iterations_to_goal, r.physics_iterations_to_goal));
    }
    if out.iter().flat_map(|c| &c.errors).any(|e| !e.is_finite()) {
        return Err(damaged("a net seed's final error is not a number"));
    }
    if out.windows(2).any(|w| w[0].seeds != w[1].seeds) {
        return Err(damaged(
            "its tasks ran different numbers of net seeds (a truncated or edited table)",
        ));
    }
    Ok(Some(out))
}

/// The report's table of `net_seeds.csv` in `dir` (empty when the run has none): every task and
/// net seed with both final errors and whether it reached the goal.
pub(super) fn table_md(dir: &Path) -> Result<String, Error> {
    let Some(rows) = written_rows::<NetSeedRow>(dir, "net_seeds.csv")? else {
        return Ok(String::new());
    };
    if rows.is_empty() {
        return Ok(String::new());
    }
    let mut md = String::from(
        "\nThe headline per Table 1 net seed (ours, `net_seeds.csv`; the same task, optimizer and iteration count through the net trained under each seed, each calibrated through its own net; final error <= 1 is within tolerance; the last two columns continue the same descent to twice the paper's iterations, ours: the first iteration at the goal on both, and the same descent's, under this seed's calibration, through the physical model itself):\n\n| task | net seed | best iteration | final error, emulator | final error, simulator | at the goal on both | continued: at the goal at iteration | through the physics |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n",
    );
    let mut order: Vec<usize> = (0..rows.len()).collect();
    let first = |r: usize| {
        rows.iter()
            .position(|o| o.task == rows[r].task)
            .unwrap_or(r)
    };
    order.sort_by(|&a, &b| {
        first(a)
            .cmp(&first(b))
            .then(rows[a].net_seed.cmp(&rows[b].net_seed))
    });
    for r in order.into_iter().map(|r| &rows[r]) {
        let (emu, sim) = (r.emulator_error, r.simulator_error);
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} |\n",
            r.task,
            r.net_seed,
            r.best_iteration,
            sig(emu),
            sig(sim),
            if emu <= 1.0 && sim <= 1.0 {
                "yes"
            } else {
                "no"
            },
            iteration_words(r.iterations_to_goal),
            iteration_words(r.physics_iterations_to_goal)
        ));
    }
    Ok(md)
}

/// Figure `net_seeds`: one panel per task of `net_seeds`, every net seed's final error on the
/// emulator (x) against its controls' on the simulator (y), log-log, each dot labelled with its
/// seed; dashed lines at 1 bound the goal (lower left: within tolerance on both). Each panel is
/// scaled to its own dots (and the tolerance), so a task's seeds do not crowd one corner.
pub(super) fn figure(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let seeds = NetSeedRow::from_table(tables.require("net_seeds")?);
    if seeds.is_empty() {
        return Ok(vec![]);
    }
    let task: Vec<String> = seeds.iter().map(|r| r.task.clone()).collect();
    let panels: Vec<Panel> = unique(&task)
        .into_iter()
        .enumerate()
        .map(|(c, name)| {
            let rows: Vec<&NetSeedRow> = seeds.iter().filter(|r| r.task == name).collect();
            let at = rows
                .iter()
                .filter(|r| r.emulator_error <= 1.0 && r.simulator_error <= 1.0)
                .count();
            let ours = if rows[0].formulation == "ours" {
                " (ours, not counted)"
            } else {
                ""
            };
            let (lo, hi) = rows
                .iter()
                .flat_map(|r| [r.emulator_error, r.simulator_error])
                .filter(|x| x.is_finite() && *x > 0.0)
                .fold((1.0f64, 1.0f64), |(a, b), x| (a.min(x), b.max(x)));
            let (lo, hi) = (lo / 1.5, hi * 1.5);
            // Headroom above the highest dot, where the legend goes without hiding one.
            let top = hi * 4.0;
            let series = vec![
                Series::line(
                    format!("{} net seeds", rows.len()),
                    rows.iter()
                        .map(|r| (r.emulator_error, r.simulator_error))
                        .collect(),
                    c,
                )
                .mark(Mark::Points)
                .labelled(rows.iter().map(|r| format!("{}", r.net_seed)).collect()),
                Series::line("tolerance (final error 1)", vec![(1.0, lo), (1.0, top)], 7)
                    .mark(Mark::Dashed),
                Series::line("", vec![(lo, 1.0), (hi, 1.0)], 7).mark(Mark::Dashed),
            ];
            Panel {
                title: format!("{name}{ours}: {at} of {} seeds at the goal", rows.len()),
                x_label: "final error through the emulator (1 = tolerance)".into(),
                y_label: "final error on the simulator (1 = tolerance)".into(),
                log_x: true,
                log_y: true,
                x_range: Some((lo, hi)),
                y_range: Some((lo, top)),
                series,
                ..Panel::default()
            }
        })
        .collect();
    fig.draw("net_seeds", &Figure::grid(panels, 2))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_path_summary_counts_iterates_above_the_limit_and_the_simulators_misses() {
        let dir = tempfile::tempdir().unwrap();
        let csv = "task,net_seed,iteration,objective,emulator_error,simulator_error,curvature_ratio,stable_ratio\n\
                   lander,1,0,9,4,4,1,2\n\
                   lander,1,1,3,0.5,2,3,2\n\
                   lander,2,0,9,4,4,1,2\n\
                   lander,2,1,2,0.5,0.5,1.5,2\n";
        std::fs::write(dir.path().join("path.csv"), csv).unwrap();
        let (md, why) = path_md(dir.path(), &["lander"]).unwrap();
        // Peaks 3 and 1.5 (median 2.25); one iterate above 2; sim/emu ratios 1, 4, 1, 1.
        assert!(
            md.contains("| lander | 2 | 4 | 2.25 (1.50-3.00) | 2.00 | 1 | 1.00 | 2 | 1 |"),
            "{md}"
        );
        assert!(why.contains("1 of 4 iterates above the limit"), "{why}");
        // A paper task without rows: the table was cut or edited.
        let e = path_md(dir.path(), &["lander", "truck"])
            .unwrap_err()
            .to_string();
        assert!(e.contains("path.csv") && e.contains("truck"), "{e}");
        std::fs::write(
            dir.path().join("path.csv"),
            &csv[..csv.find('\n').unwrap() + 1],
        )
        .unwrap();
        assert!(path_md(dir.path(), &["lander"]).is_err());
        let empty = tempfile::tempdir().unwrap();
        assert_eq!(
            path_md(empty.path(), &["lander"]).unwrap(),
            (String::new(), String::new())
        );
    }

    /// A truncated `net_seeds.csv` is an error naming the file, not a verdict on the seeds
    /// left; a missing one means a run without net seeds.
    #[test]
    fn a_truncated_seed_table_is_an_error_not_another_verdict() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(seed_counts(dir.path()).unwrap(), None);
        let mut csv = String::from(
            "task,net_seed,emulator_error,simulator_error,best_iteration,at_goal,formulation,iterations_to_goal,physics_iterations_to_goal\n",
        );
        for seed in 1..=5 {
            for task in ["pendulum", "truck"] {
                csv.push_str(&format!("{task},{seed},0.5,0.6,20,1,paper,{seed},NaN\n"));
            }
        }
        let path = dir.path().join("net_seeds.csv");
        std::fs::write(&path, &csv).unwrap();
        let counts = seed_counts(dir.path()).unwrap().unwrap();
        assert_eq!(counts.len(), 2);
        assert_eq!(counts[0].errors, vec![0.6; 5]);
        assert!(
            counts[0]
                .to_goal_words()
                .contains("at iteration 1, 2, 3, 4, 5 (per seed); the same descents through the physics at never, never"),
            "{}",
            counts[0].to_goal_words()
        );
        // Cut after the last seed's pendulum row, and mid-row.
        let lines: Vec<&str> = csv.lines().collect();
        std::fs::write(&path, lines[..lines.len() - 1].join("\n")).unwrap();
        let e = seed_counts(dir.path()).unwrap_err().to_string();
        assert!(e.contains("net_seeds.csv"), "{e}");
        std::fs::write(&path, &csv[..csv.len() - 12]).unwrap();
        assert!(seed_counts(dir.path()).is_err());
    }

    #[test]
    fn a_strict_majority_of_seeds_is_needed() {
        assert!(majority_at_goal(&[true, true, true, false, false]));
        assert!(!majority_at_goal(&[true, true, false, false, false]));
        assert!(!majority_at_goal(&[true, false]));
        assert!(majority_at_goal(&[true]));
        assert!(!majority_at_goal(&[false]));
        assert!(!majority_at_goal(&[]));
    }
}
