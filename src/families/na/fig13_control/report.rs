//! Report of `na_fig13_control`: the verdict (tasks at their goal), the table of every task,
//! and the sentences on the sweeps, the conditioning study and the best weights.

use super::rows::{
    BestWeightsRow, ConditioningRow, FinalRow, LadderRow, ObjectiveRow, SweepRow, SwimRow,
};
use super::{dagger, dolphin_dagger, Fig13Rule};
use crate::experiment::output::unique;
use crate::experiment::report::{sig, Findings};
use crate::experiment::rows::{read_rows, written_rows};
use crate::experiment::rule::{
    rule_settings, shown, Check, Cmp, Null, Outcome, Partly, Rule, RuleError,
};
use crate::experiment::stats::median_interval;
use crate::experiment::Error;
use std::path::Path;

/// What the verdict reads of one task of the paper's formulation.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum TaskFacts {
    /// A control task (pendulum, truck, lander).
    Control {
        /// The task.
        name: String,
        /// Per net seed, the larger of its learned controls' final errors on the emulator
        /// (within the paper's iterations) and on the simulator (tolerances).
        errors: Vec<f64>,
        /// The final error of the task's initial controls replayed on the simulator.
        start_error: f64,
    },
    /// The dolphin's swim.
    Swim {
        /// The learned swim's distance on the emulator over the hand-made wave's on the
        /// simulator.
        emulator: f64,
        /// The same on the simulator.
        simulator: f64,
        /// The periodicity of its muscle pattern.
        periodicity: f64,
    },
}

/// Seed of the bootstrap over net seeds (fixed, so a report is the same on every machine).
const BOOTSTRAP_SEED: u64 = 1;

/// The dolphin's two checks: the learned swim's `distance` over the hand-made wave's and its
/// muscle pattern's `periodicity`, at `r`'s bars (null: a dolphin at rest, constant controls).
fn swim_checks(distance: f64, periodicity: f64, r: &Fig13Rule) -> [Result<Check, RuleError>; 2] {
    [
        Check::new(
            "dolphin: the learned swim's distance over the hand-made wave's, the smaller of emulator and simulator",
            distance,
            Cmp::AtLeast,
            r.wave_fraction,
            Null::new("a dolphin at rest (0 m)", 0.0),
        ),
        Check::new(
            "dolphin: the periodicity of its learned muscle pattern",
            periodicity,
            Cmp::AtLeast,
            r.periodicity,
            Null::new("constant controls", 0.0),
        ),
    ]
}

/// The verdict's rule: per control task, the median over its net seeds of each seed's larger
/// final error (emulator within the paper's iterations, simulator), with its 95% bootstrap
/// interval, at most 1 tolerance (for an odd seed count the median is within tolerance exactly
/// when a strict majority of seeds reach the goal on both; null: the task's initial controls
/// replayed on the simulator); for the dolphin, [`swim_checks`] of the smaller of its distances
/// on emulator and simulator. Held when every task passes, partly when some task passes all of
/// its checks. `None` when a null passes.
pub(super) fn fig13_rule(tasks: &[TaskFacts], r: &Fig13Rule) -> Option<Rule> {
    let mut held = Vec::new();
    let mut groups = Vec::new();
    for t in tasks {
        match t {
            TaskFacts::Control {
                name,
                errors,
                start_error,
            } => {
                groups.push(vec![held.len()]);
                let (median, lo, hi) = median_interval(errors, BOOTSTRAP_SEED);
                held.push(
                    Check::new(
                        format!("{name}: the larger final error, emulator (the paper's iterations) or simulator, median over {} net seeds (tolerances)", errors.len()),
                        median,
                        Cmp::AtMost,
                        1.0,
                        Null::new("its initial controls replayed on the simulator", *start_error),
                    )
                    .map(|c| c.with_interval(lo, hi)),
                );
            }
            TaskFacts::Swim {
                emulator,
                simulator,
                periodicity,
            } => {
                groups.push(vec![held.len(), held.len() + 1]);
                let distance = if emulator.is_nan() || simulator.is_nan() {
                    f64::NAN
                } else {
                    emulator.min(*simulator)
                };
                held.extend(swim_checks(distance, *periodicity, r));
            }
        }
    }
    Rule::gated(vec![], held, Partly::AnyOf(groups))
}

/// The findings ([`crate::experiment::Family::report`]).
pub(super) fn report(dir: &Path) -> Result<Findings, Error> {
    let finals = Finals {
        objective: read_rows(&dir.join("objective.csv"))?,
        tasks: read_rows(&dir.join("final.csv"))?,
    };
    let mut md = String::from(
        "| task | formulation | iterations | J start | J end | final error, emulator | final error, simulator |\n| --- | --- | --- | --- | --- | --- | --- |\n",
    );
    // The dolphin's swims: no rows without `[params.dolphin]`.
    let swims: Vec<SwimRow> = read_rows(&dir.join("swim.csv"))?;
    let swim = swim_sentence(&swims);
    let goal = swim_goal(&swims);
    let settings = rule_settings(dir)?;
    let bars = Fig13Rule {
        wave_fraction: settings("wave_fraction"),
        periodicity: settings("periodicity"),
    };
    // The headline over several Table 1 net seeds: a task of the paper's formulation is judged
    // by its median net seed, with the median's interval; where net_seeds.csv has one seed for a
    // task (or none: the dolphin), final.csv's row decides.
    let seeds = super::seeds::seed_counts(dir)?;
    if let Some(seeds) = &seeds {
        every_control_task_over_seeds(dir, &finals.tasks, seeds)?;
    }
    let seeds = seeds.unwrap_or_default();
    let h = headline(&finals, &seeds, &goal, &bars, &mut md);
    let (net_misses, seed_lines, ours) = h.sentences();
    let sweeps: String = [
        ("sweep.csv", "Step-size sweep through the emulator"),
        (
            "physics_sweep.csv",
            "The same learned through the physical model's RK4 step",
        ),
    ]
    .iter()
    .filter_map(|(f, title)| sweep_summary(dir, f, title).transpose())
    .collect::<Result<Vec<_>, _>>()?
    .concat();
    let rule = fig13_rule(&h.facts, &bars);
    let (verdict, lines, text) = shown(
        rule.as_ref(),
        " No rule: a task's initial controls already end within tolerance.",
    );
    // Tasks at their goal: those whose checks all pass.
    let both = rule.as_ref().map_or(0, Rule::groups_passing);
    let control: Vec<&str> = finals
        .tasks
        .iter()
        .filter(|t| t.is_paper_control())
        .map(|t| t.task.as_str())
        .collect();
    let (path_why, study_why, dagger_why) = push_sections(dir, &control, &mut md)?;
    let sweeps = format!("{sweeps}{study_why}");
    let Headline {
        counts,
        reached,
        reached_sim,
        headline,
        ..
    } = h;
    let wave = goal.wave;
    Ok(Findings {
        ours: md,
        verdict,
        rule: rule.clone(),
        why: format!(
            "{both} of {headline} tasks of the paper's formulation pass every check{}. A task passes when its median Table 1 net seed (where several ran) reaches the goal on the emulator within the paper's iteration counts and ends within tolerance when its controls are replayed on the physical simulator, the median's 95% bootstrap interval inside the tolerance (through this run's nets: {reached} reach it on the emulator, {reached_sim} on the simulator; every task scored at its best-so-far iterate, the lowest emulator J; the headline is the paper's eta = 1.5, alpha = 0.5 with lambda fixed at the start). Checks:{lines} Rule (the dolphin's bars ours, in the spec's [params.rule]): {text} Final error = RMS of (s_M - s_d)/tolerance over the weighted state variables (<= 1: goal reached); for the dolphin, the shortfall (m) of its forward distance from that of a hand-made 1 Hz travelling wave on the simulator ({} m; 0: swims at least as far), its learned pattern's periodicity {}.{seed_lines}{path_why}{net_misses}{ours}{swim}{sweeps}{dagger_why}",
            if counts.is_empty() {
                String::new()
            } else {
                format!(" (net seeds at the goal on both: {})", counts.join("; "))
            },
            sig(wave),
            sig(goal.learned_periodicity)
        ),
    })
}

/// Every control task of the paper's formulation in `final.csv` has its rows in
/// `net_seeds.csv` (the run writes this run's own net seed at least for each): a table that
/// lost a task's rows would otherwise judge it by the single-seed rule, so it is an error
/// naming the file.
fn every_control_task_over_seeds(
    dir: &Path,
    tasks: &[FinalRow],
    seeds: &[super::seeds::SeedCount],
) -> Result<(), Error> {
    let missing: Vec<&str> = tasks
        .iter()
        .filter(|t| t.is_paper_control())
        .filter(|t| !seeds.iter().any(|c| c.task == t.task))
        .map(|t| t.task.as_str())
        .collect();
    if missing.is_empty() {
        Ok(())
    } else {
        Err(crate::experiment::other(format!(
            "{}: no rows for {}, of the paper's formulation in final.csv (a truncated or edited table)",
            dir.join("net_seeds.csv").display(),
            missing.join(", ")
        )))
    }
}

/// The tables the headline reads.
struct Finals {
    /// `objective.csv`: every task's objective per iteration.
    objective: Vec<ObjectiveRow>,
    /// `final.csv`: one row per task.
    tasks: Vec<FinalRow>,
}

/// The dolphin's swim distances against the hand-made wave's (NaN without its swims).
struct SwimGoal {
    wave: f64,
    emu_distance: f64,
    sim_distance: f64,
    learned_periodicity: f64,
}

/// What the task-by-task pass over `final.csv` collects for the verdict and its sentences.
struct Headline {
    facts: Vec<TaskFacts>,
    seed_lines: Vec<String>,
    /// The headline's short form: per task over its net seeds, how many reach the goal on both.
    counts: Vec<String>,
    reached: usize,
    reached_sim: usize,
    headline: usize,
    ours: Vec<String>,
    /// Paper tasks at their goal on the emulator but not on the simulator: the net's error.
    net_misses: Vec<String>,
}

/// The sentence on the dolphin's swim distances and its controls' periodicity (empty without
/// its swims, `swim.csv`'s rows).
fn swim_sentence(swims: &[SwimRow]) -> String {
    let parts: Vec<String> = swims
        .iter()
        .map(|r| format!("{} {} m", r.source, sig(r.distance_m)))
        .collect();
    let at = |name: &str| swims.iter().find(|r| r.source == name);
    let period = match (at("simulator"), at("reference_wave_simulator")) {
        (Some(a), Some(b)) => format!(
            " Periodicity of the muscle controls (mean over muscles of the largest autocorrelation at lags of 3 steps to half the horizon; 1: a sinusoid, 0: noise or constant): learned {} (period {} s), hand-made wave {} (period {} s).",
            sig(a.periodicity),
            sig(a.period_s),
            sig(b.periodicity),
            sig(b.period_s)
        ),
        _ => String::new(),
    };
    if parts.is_empty() {
        String::new()
    } else {
        format!(" Dolphin swim distances: {}.{period}", parts.join(", "))
    }
}

/// The dolphin's goal (the spec's, fixed before the 20 s swim's first run): its learned
/// knots swim at least half as far as the hand-made wave on the simulator (shortfall <=
/// half the wave's distance), on the emulator and on the simulator each, with a periodic
/// muscle pattern (periodicity >= 0.5, ours, as the DAgger line's).
fn swim_goal(swims: &[SwimRow]) -> SwimGoal {
    let at = |name: &str| swims.iter().find(|r| r.source == name);
    let d = |name: &str| at(name).map_or(f64::NAN, |r| r.distance_m);
    SwimGoal {
        wave: d("reference_wave_simulator"),
        emu_distance: d("emulator"),
        sim_distance: d("simulator"),
        learned_periodicity: at("emulator").map_or(f64::NAN, |r| r.periodicity),
    }
}

/// Every task of `final.csv` in turn: its row of the table pushed to `md`, and for the paper's
/// tasks the verdict's facts (over the net seeds where several ran) and the counts, for ours a
/// second line.
fn headline(
    f: &Finals,
    seeds: &[super::seeds::SeedCount],
    goal: &SwimGoal,
    bars: &Fig13Rule,
    md: &mut String,
) -> Headline {
    let SwimGoal {
        wave,
        emu_distance,
        sim_distance,
        learned_periodicity,
    } = *goal;
    let by_seeds = |name: &str| seeds.iter().find(|c| c.task == name && c.seeds > 1);
    let mut h = Headline {
        facts: Vec::new(),
        seed_lines: Vec::new(),
        counts: Vec::new(),
        reached: 0,
        reached_sim: 0,
        headline: 0,
        ours: Vec::new(),
        net_misses: Vec::new(),
    };
    for row in &f.tasks {
        let name = &row.task;
        let (ee, se) = (row.emulator_error, row.simulator_error);
        let js: Vec<f64> = f
            .objective
            .iter()
            .filter(|o| &o.task == name)
            .map(|o| o.objective)
            .collect();
        md.push_str(&format!(
            "| {name} | {} | {} | {} | {} | {} | {} |\n",
            row.formulation,
            js.len().saturating_sub(1),
            sig(js.first().copied().unwrap_or(f64::NAN)),
            sig(js.last().copied().unwrap_or(f64::NAN)),
            sig(ee),
            sig(se)
        ));
        // The dolphin's error is its shortfall (m) from the reference wave's distance.
        let ok = |e: f64| {
            if name == "dolphin" {
                dolphin_at_goal(e, wave, learned_periodicity, bars)
            } else {
                e <= 1.0
            }
        };
        if row.is_paper() {
            h.headline += 1;
            h.reached += usize::from(ok(ee));
            h.reached_sim += usize::from(ok(se));
            let this_net = ok(ee) && ok(se);
            if name == "dolphin" {
                h.counts.push(format!(
                    "the dolphin swims {} of the hand-made wave's distance",
                    sig((emu_distance / wave).min(sim_distance / wave))
                ));
                h.facts.push(TaskFacts::Swim {
                    emulator: emu_distance / wave,
                    simulator: sim_distance / wave,
                    periodicity: learned_periodicity,
                });
            } else {
                let errors = match by_seeds(name) {
                    Some(c) => {
                        h.counts.push(format!("{name} {} of {}", c.both, c.seeds));
                        h.seed_lines.push(format!(
                            "{name} {} of {} (on the emulator alone {} of {}; this run's net {}; {})",
                            c.both,
                            c.seeds,
                            c.emulator,
                            c.seeds,
                            if this_net { "at its goal" } else { "not" },
                            c.to_goal_words()
                        ));
                        c.errors.clone()
                    }
                    None => vec![ee.max(se)],
                };
                h.facts.push(TaskFacts::Control {
                    name: name.clone(),
                    errors,
                    start_error: row.start_simulator_error,
                });
            }
            if ok(ee) && !ok(se) && name != "dolphin" {
                h.net_misses
                    .push(format!("{name} ({} vs {})", sig(ee), sig(se)));
            }
        } else {
            let over_seeds = by_seeds(name).map_or(String::new(), |c| {
                format!(
                    " (net seeds at the goal on both: {} of {}; on the emulator alone {})",
                    c.both, c.seeds, c.emulator
                )
            });
            h.ours.push(format!(
                "{name} {} on the emulator, {} on the simulator{over_seeds}",
                sig(ee),
                sig(se)
            ));
        }
    }
    h
}

impl Headline {
    /// The sentences on the net's misses, the net seeds and our formulations (each empty when
    /// there is nothing to say).
    fn sentences(&self) -> (String, String, String) {
        let net_misses = if self.net_misses.is_empty() {
            String::new()
        } else {
            format!(
                " At their goal on the emulator but not on the simulator: {}; the same controls drive both from the same start, so the difference is the Table 1 net's own open-loop error along the learned trajectory over the task's super-steps (the DAgger line below learns the same tasks through nets refined on the states such controls visit).",
                self.net_misses.join(", ")
            )
        };
        let seed_lines = if self.seed_lines.is_empty() {
            String::new()
        } else {
            format!(
                " Over the Table 1 net seeds (net_seeds.csv; the same headline learned through the net trained under each seed, each calibrated through its own net), net seeds at the goal on both: {}.",
                self.seed_lines.join(", ")
            )
        };
        let ours = if self.ours.is_empty() {
            String::new()
        } else {
            format!(
                " Our earlier formulations, kept as second lines (not counted): {}.",
                self.ours.join("; ")
            )
        };
        (net_misses, seed_lines, ours)
    }
}

/// The report's further sections pushed to `md` (net seeds, net lines, path, conditioning,
/// ladder, DAgger, dolphin DAgger); returns their sentences: the path's, the conditioning
/// study's (conditioning and ladder) and the DAgger lines' (the lander's and the dolphin's).
/// `control`: the control tasks of the paper's formulation, whose descents `path.csv` holds.
fn push_sections(
    dir: &Path,
    control: &[&str],
    md: &mut String,
) -> Result<(String, String, String), Error> {
    md.push_str(&super::seeds::table_md(dir)?);
    md.push_str(&super::seeds::lines_md(dir)?);
    let (path_md, mut path_why) = super::seeds::path_md(dir, control)?;
    md.push_str(&path_md);
    let (physics_md, physics_why) = super::conditioning::physics_path_md(dir, control)?;
    md.push_str(&physics_md);
    path_why.push_str(&physics_why);
    let (cond_md, cond_why) = conditioning_summary(dir)?.unwrap_or_default();
    md.push_str(&cond_md);
    let (ladder_md, ladder_why) = ladder_summary(dir)?.unwrap_or_default();
    md.push_str(&ladder_md);
    let (dagger_md, mut dagger_why) = dagger::summary(dir)?.unwrap_or_default();
    md.push_str(&dagger_md);
    let (dolphin_md, dolphin_why) = dolphin_dagger::summary(dir)?.unwrap_or_default();
    md.push_str(&dolphin_md);
    dagger_why.push_str(&dolphin_why);
    Ok((path_why, format!("{cond_why}{ladder_why}"), dagger_why))
}

/// One sentence per task of a sweep table: the fewest iterations to the goal over its rules and
/// rates (and the simulator error of those controls), or the lowest final error reached.
/// `None` when the run wrote no such table (a spec without the sweep); a written one without
/// rows is an error naming it.
fn sweep_summary(dir: &Path, file: &str, title: &str) -> Result<Option<String>, Error> {
    // Written where the spec asks for the sweep, with a row per task at least.
    let Some(runs) = written_rows::<SweepRow>(dir, file)? else {
        return Ok(None);
    };
    if runs.is_empty() {
        return Err(crate::experiment::other(format!(
            "{}: the sweep has no rows",
            dir.join(file).display()
        )));
    }
    // One clause for a group of runs: the fewest iterations to the goal, or the lowest error.
    let clause = |rows: &[&SweepRow]| -> String {
        let budget = rows.iter().map(|r| r.iterations as f64).fold(0.0, f64::max);
        let setting = |r: &SweepRow| {
            if r.eta.is_finite() {
                format!("{} rule, eta {}", r.rule, r.eta)
            } else {
                format!("{} rule", r.rule)
            }
        };
        let fastest = rows
            .iter()
            .filter(|r| r.reached())
            .min_by(|a, b| a.iterations_to_goal.total_cmp(&b.iterations_to_goal));
        match fastest {
            Some(r) => format!(
                "reaches its goal in {} iterations at best ({}; simulator error {}; {} of {} runs reach it)",
                r.iterations_to_goal,
                setting(r),
                sig(r.simulator_error),
                rows.iter().filter(|r| r.reached()).count(),
                rows.len()
            ),
            None => {
                let r = rows
                    .iter()
                    .min_by(|a, b| a.rollout_error.total_cmp(&b.rollout_error))
                    .expect("a group has rows");
                format!(
                    "never does in {budget} iterations (lowest final error {} with the {}; simulator {})",
                    sig(r.rollout_error),
                    setting(r),
                    sig(r.simulator_error)
                )
            }
        }
    };
    let lm = "levenberg_marquardt";
    let task: Vec<String> = runs.iter().map(|r| r.task.clone()).collect();
    let parts: Vec<String> = unique(&task)
        .into_iter()
        .map(|name| {
            let (second, first): (Vec<&SweepRow>, Vec<&SweepRow>) = runs
                .iter()
                .filter(|r| r.task == name)
                .partition(|r| r.rule == lm);
            let mut out = name.clone();
            if !first.is_empty() {
                out += &format!(" {}", clause(&first));
            }
            if !second.is_empty() {
                let sep = if first.is_empty() { "" } else { ", and" };
                out += &format!("{sep} with Levenberg-Marquardt (ours) {}", clause(&second));
            }
            out
        })
        .collect();
    Ok(Some(format!(" {title}: {}.", parts.join("; "))))
}

/// The report's table and sentence from `conditioning_ladder.csv` (written when the spec asks for the study): which
/// of the paper's changes to our earlier formulations moved the conditioning.
fn ladder_summary(dir: &Path) -> Result<Option<(String, String)>, Error> {
    // A spec without a formulation of ours beside a paper one writes no rungs.
    let Some(rungs) = written_rows::<LadderRow>(dir, "conditioning_ladder.csv")? else {
        return Ok(None);
    };
    if rungs.is_empty() {
        return Ok(None);
    }
    let task: Vec<String> = rungs.iter().map(|r| r.task.clone()).collect();
    let change: Vec<&str> = rungs.iter().map(|r| r.change.as_str()).collect();
    let dof: Vec<i64> = rungs.iter().map(|r| r.dof).collect();
    let kappa: Vec<f64> = rungs.iter().map(|r| r.condition).collect();
    let pace: Vec<f64> = rungs.iter().map(|r| r.iterations_per_decade).collect();
    let show = |k: f64| {
        if k.is_finite() && k < 1e12 {
            sig(k)
        } else {
            "singular".to_string()
        }
    };
    let mut md = String::from("\nWhich change mattered (ours; `conditioning_ladder.csv`): the condition of G through the task's Table 1 net at its initial knots, from our earlier formulation (rung 0) as the paper's changes are applied one at a time, in a fixed order (horizon and knots: the paper's duration on our net; super-step: the paper's net and step count; start, initial controls, target set and tolerances, control units, final-state weights); the last rung is the paper's task, each rung through its own net. Iterations per tenfold reduction at the headline's eta and alpha along the slowest direction.\n\n| task | rung | change | r | condition | iterations per tenfold reduction |\n| --- | --- | --- | --- | --- | --- |\n");
    let mut parts = vec![];
    for name in unique(&task) {
        let rows: Vec<usize> = (0..task.len()).filter(|&r| task[r] == name).collect();
        for &r in &rows {
            let p = if pace[r].is_finite() && kappa[r] < 1e12 {
                sig(pace[r])
            } else {
                "no progress".to_string()
            };
            md.push_str(&format!(
                "| {} | {} | {} | {} | {} | {p} |\n",
                task[r],
                r - rows[0],
                change[r],
                dof[r],
                show(kappa[r])
            ));
        }
        // The rung that divided the condition most.
        let biggest = rows
            .windows(2)
            .map(|w| (w[1], kappa[w[0]] / kappa[w[1]]))
            .filter(|(_, f)| f.is_finite() || f.is_infinite())
            .max_by(|a, b| a.1.total_cmp(&b.1));
        let first = rows[0];
        let last = *rows.last().expect("a task has rows");
        // Rungs that made the conditioning worse (by more than half again).
        let raised: String = rows
            .windows(2)
            .filter(|w| kappa[w[1]] > 1.5 * kappa[w[0]])
            .map(|w| {
                format!(
                    "; the {} raised it {} -> {}",
                    change[w[1]],
                    show(kappa[w[0]]),
                    show(kappa[w[1]])
                )
            })
            .collect();
        parts.push(match biggest {
            Some((r, _)) => format!(
                "{name} {} -> {} (most by the {}{raised})",
                show(kappa[first]),
                show(kappa[last]),
                change[r]
            ),
            None => format!("{name} {}", show(kappa[last])),
        });
    }
    let why = format!(
        " Conditioning from our earlier formulation to the paper's (conditioning_ladder.csv): {}.",
        parts.join("; ")
    );
    Ok(Some((md, why)))
}

/// The report's conditioning table and sentence from `conditioning.csv` (written when the spec asks for the study).
fn conditioning_summary(dir: &Path) -> Result<Option<(String, String)>, Error> {
    let Some(rows) = written_rows::<ConditioningRow>(dir, "conditioning.csv")? else {
        return Ok(None);
    };
    // Above 1e12 the r-th eigenvalue is rounding: the matrix is singular at the start.
    let show = |k: f64| {
        if k.is_finite() && k < 1e12 {
            sig(k)
        } else {
            "singular".to_string()
        }
    };
    let mut md = String::from("\nHow fast the headline's fixed-step descent can reach these goals (ours; `conditioning.csv`, `spectrum.csv`, figure `spectrum`): the terminal Gauss-Newton matrix G = J^T W J of the final-state term over the normalized knots at the start, J = ds_M/dv, through the emulator and through the physics. Along G's r-th eigenvector (r: the independent final-state variables, the rank G can have) the headline's step eta/lambda shrinks the residual by the heavy-ball rate of that eigenvalue; the next column counts iterations per tenfold reduction (`src/control/conditioning.rs`; exact for a quadratic). Could other final-state weights help? With K = J J^T over the r independent weighted variables (the lander's quaternion scalar part left out), no positive diagonal weighting has a condition below kappa(equilibrated K)/r (van der Sluis), nor, with the headline's eta and alpha, fewer iterations per tenfold reduction than the last column.\n\n| task | substrate | knots | r | condition mu_1/mu_r | iterations per tenfold reduction (eta, alpha of the headline) | condition, equilibrated | condition, any weighting (at least) | iterations per tenfold reduction, any weighting (at least) |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
    let mut parts = vec![];
    // The physics' fewest iterations per tenfold reduction, and the tasks whose matrix is
    // singular at the start (no progress along some weighted direction).
    let mut fewest = f64::INFINITY;
    let (mut singular, mut within, mut beyond) = (vec![], vec![], vec![]);
    let mut weights = vec![];
    for c in &rows {
        let progress = c.iterations_per_decade.is_finite() && c.condition < 1e12;
        let p = if progress {
            sig(c.iterations_per_decade)
        } else {
            "no progress".to_string()
        };
        let (e, a) = (
            show(c.condition_equilibrated),
            show(c.condition_any_weighting),
        );
        let ap = if c.iterations_per_decade_any_weighting.is_finite() {
            sig(c.iterations_per_decade_any_weighting)
        } else {
            "no progress".to_string()
        };
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} (eta {}) | {e} | {a} | {ap} |\n",
            c.task,
            c.substrate,
            c.knots,
            c.dof,
            show(c.condition),
            p,
            sig(c.eta)
        ));
        if c.is_physics() {
            // The spec's reading: the bound against the paper's iteration count.
            weights.push(if !(c.iterations_per_decade_any_weighting.is_finite() && c.condition_any_weighting < 1e12) {
                format!("{}: singular under any weights", c.task)
            } else {
                let (link, reading) = if c.iterations_per_decade_any_weighting > (c.paper_iterations as f64) {
                    (
                        " against",
                        "the cause is the task's dynamics over its knots and horizon, not our weights",
                    )
                } else {
                    (", within", "our tolerance weights may be to blame")
                };
                format!(
                    "{}: condition at least {}, at least {} iterations per tenfold reduction under any weights{link} the paper's {}, so {reading}",
                    c.task,
                    sig(c.condition_any_weighting),
                    sig(c.iterations_per_decade_any_weighting),
                    c.paper_iterations
                )
            });
        }
        if c.is_physics() {
            parts.push(if progress {
                fewest = fewest.min(c.iterations_per_decade);
                if c.iterations_per_decade <= (c.paper_iterations as f64) {
                    within.push(c.task.clone());
                } else {
                    beyond.push(c.task.clone());
                }
                format!(
                    "{} {} ({p} iterations per tenfold reduction)",
                    c.task,
                    show(c.condition)
                )
            } else {
                singular.push(c.task.clone());
                format!("{} {} (no progress)", c.task, show(c.condition))
            });
        }
    }
    let why = if parts.is_empty() {
        String::new()
    } else {
        let singular = if singular.is_empty() {
            String::new()
        } else {
            format!(
                "; singular for {}: some weighted final-state directions do not respond to the knots at the start (a parked truck's steering moves nothing)",
                singular.join(", ")
            )
        };
        let list = |v: &[String]| {
            if v.is_empty() {
                "none".to_string()
            } else {
                v.join(", ")
            }
        };
        format!(
            " Why the headline's descent is fast or slow (ours, `conditioning.csv`): through the exact physics the terminal Gauss-Newton matrix at the start knots has condition mu_1/mu_r {}. Along the slowest weighted direction the headline's fixed step needs at least {} iterations per tenfold reduction of the residual (the fewest over the tasks): within the paper's iteration count for {}; beyond it for {}{singular}. Beyond it, 15-20 iterations of eq. 13-15 reach a goal only where the start's residual along the slow directions is already within tolerance, whatever the gradient's source (descent through the physics is in the sweep above); Levenberg-Marquardt is invariant to the conditioning. Conditioning is a property of the task formulation (knots, horizons, tolerance weights): a task beside our earlier formulation of it (`formulation = ours` in `final.csv`) shows what the paper's formulation changes.{}",
            parts.join(", "),
            sig(fewest),
            list(&within),
            list(&beyond),
            if weights.is_empty() {
                String::new()
            } else {
                format!(
                    " Could other final-state weights help (ours; the reading fixed in the spec, through the physics; no diagonal weighting beats kappa(equilibrated)/r)? {}.{}",
                    weights.join("; "),
                    best_weights_summary(dir, &rows)?
                )
            }
        )
    };
    Ok(Some((md, why)))
}

/// The sentence on `best_weights*.csv` (empty when absent or empty): per task run under the
/// best-conditioned weights, the headline's iterations to the goal through the physics with
/// those weights and with the task's own (`physics_sweep.csv`), beside the paper's count.
fn best_weights_summary(dir: &Path, cond: &[ConditioningRow]) -> Result<String, Error> {
    let weights: Vec<BestWeightsRow> = read_rows(&dir.join("best_weights.csv"))?;
    let best: Vec<SweepRow> = read_rows(&dir.join("best_weights_sweep.csv"))?;
    let physics: Vec<SweepRow> = read_rows(&dir.join("physics_sweep.csv"))?;
    // Through the Table 1 net under the same weights.
    let emulator: Vec<SweepRow> = read_rows(&dir.join("best_weights_emulator_sweep.csv"))?;
    let to = |k: f64| {
        if k.is_finite() {
            format!("in {k} iterations")
        } else {
            "never".to_string()
        }
    };
    let mut parts = vec![];
    for b in &best {
        let Some(w) = weights.iter().find(|w| w.task == b.task) else {
            continue;
        };
        let ours = physics
            .iter()
            .find(|p| p.task == b.task && p.rule == "fixed" && p.eta == b.eta)
            .map_or(f64::NAN, |p| p.iterations_to_goal);
        let count = cond
            .iter()
            .find(|c| c.task == b.task)
            .map_or(f64::NAN, |c| c.paper_iterations as f64);
        let reading = if b.iterations_to_goal <= count {
            "our weights were to blame"
        } else {
            "our weights slow it but are not the whole cause"
        };
        let net = emulator
            .iter()
            .find(|e| e.task == b.task)
            .map(|e| {
                format!(
                    "; through the Table 1 net under the same weights it reaches the goal on the net {} (final error {} there, {} on the simulator replay)",
                    to(e.iterations_to_goal),
                    sig(e.rollout_error),
                    sig(e.simulator_error)
                )
            })
            .unwrap_or_default();
        parts.push(format!(
            "{}: condition {} with the best weights a search finds (ours: {}), at which the headline's step needs {} iterations per tenfold reduction, the headline reaches the goal through the physics {} with them (final error {}) and {} with ours (paper: {count}): {reading}{net}",
            b.task,
            sig(w.condition_best),
            sig(w.condition),
            sig(w.iterations_per_decade_best),
            to(b.iterations_to_goal),
            sig(b.rollout_error),
            to(ours)
        ));
    }
    Ok(if parts.is_empty() {
        String::new()
    } else {
        format!(
            " Under the best-conditioned weights (ours; `best_weights.csv`, `best_weights_sweep.csv`, the reading fixed in the spec): {}.",
            parts.join("; ")
        )
    })
}

/// The dolphin's goal: a shortfall from the hand-made wave's distance `wave` that passes
/// [`swim_checks`] with its `periodicity`.
pub(super) fn dolphin_at_goal(shortfall: f64, wave: f64, periodicity: f64, r: &Fig13Rule) -> bool {
    swim_checks(1.0 - shortfall / wave, periodicity, r)
        .iter()
        .all(|c| c.as_ref().is_ok_and(|c| c.outcome() == Outcome::Pass))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::report::Verdict;
    use crate::families::na::fig13_control::Formulation;

    const BARS: Fig13Rule = Fig13Rule {
        wave_fraction: 0.5,
        periodicity: 0.5,
    };

    /// Half the wave's distance and a periodic pattern, both needed; unknown values fail.
    #[test]
    fn the_dolphins_goal_needs_half_the_wave_and_a_periodic_pattern() {
        let at = |s, w, p| dolphin_at_goal(s, w, p, &BARS);
        assert!(at(0.0, 6.0, 0.9));
        assert!(at(3.0, 6.0, 0.5));
        assert!(!at(3.01, 6.0, 0.9));
        assert!(!at(1.0, 6.0, 0.49));
        assert!(!at(1.0, f64::NAN, 0.9));
        assert!(!at(1.0, 6.0, f64::NAN));
    }

    /// A paper control task of `final.csv` without rows in `net_seeds.csv` (a table cut or
    /// edited) is an error naming the file, not a verdict by the single-seed rule; the
    /// dolphin and our formulations need none.
    #[test]
    fn a_paper_task_missing_from_the_seed_table_is_an_error() {
        let row = |task: &str, formulation: Formulation| FinalRow {
            task: task.into(),
            emulator_error: 0.5,
            simulator_error: 0.6,
            best_iteration: 3,
            formulation: formulation.name().into(),
            start_simulator_error: 4.0,
        };
        let tasks = [
            row("pendulum", Formulation::Paper),
            row("truck", Formulation::Paper),
            row("pendulum_200steps", Formulation::Ours),
            row("dolphin", Formulation::Paper),
        ];
        let count = |task: &str| super::super::seeds::SeedCount {
            task: task.into(),
            both: 1,
            emulator: 1,
            seeds: 1,
            errors: vec![0.6],
            to_goal: vec![(3.0, f64::NAN)],
        };
        let dir = Path::new("results/x");
        every_control_task_over_seeds(dir, &tasks, &[count("pendulum"), count("truck")]).unwrap();
        let e = every_control_task_over_seeds(dir, &tasks, &[count("pendulum")])
            .unwrap_err()
            .to_string();
        assert!(e.contains("net_seeds.csv") && e.contains("truck"), "{e}");
    }

    /// A sweep table the run wrote that lost its rows is an error naming it; no table (a spec
    /// without the sweep) is nothing to say.
    #[test]
    fn an_emptied_sweep_table_is_an_error() {
        use crate::experiment::output::write_table;
        use crate::experiment::rows::table_of;
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(
            sweep_summary(dir.path(), "sweep.csv", "Sweep").unwrap(),
            None
        );
        write_table(dir.path(), "sweep", &table_of::<SweepRow>(&[])).unwrap();
        let e = sweep_summary(dir.path(), "sweep.csv", "Sweep")
            .unwrap_err()
            .to_string();
        assert!(e.contains("sweep.csv"), "{e}");
    }

    /// A control task whose 5 net seeds end at `errors` (tolerances).
    fn control(name: &str, errors: [f64; 5], start_error: f64) -> TaskFacts {
        TaskFacts::Control {
            name: name.into(),
            errors: errors.to_vec(),
            start_error,
        }
    }

    /// Held needs every task; partly some task with all of its checks (the dolphin's two
    /// together); a task whose median seed is within tolerance but whose interval reaches
    /// beyond it is inconclusive; a task whose initial controls already end within tolerance
    /// leaves no rule.
    #[test]
    fn the_rule_judges_a_task_by_its_median_net_seed_and_its_interval() {
        let swim = |d: f64, p: f64| TaskFacts::Swim {
            emulator: d,
            simulator: d,
            periodicity: p,
        };
        let rule = |facts: &[TaskFacts]| fig13_rule(facts, &BARS);
        let verdict = |facts: &[TaskFacts]| rule(facts).map(|r| r.verdict());
        let at_goal = [0.5, 0.6, 0.7, 0.8, 0.9];
        let missed = [2.0, 3.0, 4.0, 5.0, 6.0];
        let good = [
            control("pendulum", at_goal, 12.0),
            control("truck", at_goal, 4.9),
            swim(0.6, 0.7),
        ];
        assert_eq!(verdict(&good), Some(Verdict::Held));
        assert_eq!(rule(&good).unwrap().groups_passing(), 3);
        // Two seeds of five at the goal: the median seed misses, but its interval reaches
        // inside the tolerance, so held or partly is undecided.
        let two = [
            control("pendulum", [0.5, 0.6, 3.0, 4.0, 5.0], 12.0),
            control("truck", at_goal, 4.9),
        ];
        let r = rule(&two).unwrap();
        assert!(r.held[0].value > 1.0);
        assert_eq!(r.held[0].outcome(), Outcome::Inconclusive);
        assert_eq!(r.verdict(), Verdict::Inconclusive);
        // None at the goal: the task fails outright; the truck alone makes it partly.
        let none = [
            control("pendulum", missed, 12.0),
            control("truck", at_goal, 4.9),
        ];
        assert_eq!(verdict(&none), Some(Verdict::Partly));
        // Four of five: the median seed is at the goal, but one bad seed in five leaves a
        // resampled median beyond the tolerance more than 2.5% of the time.
        let four = [control("truck", [0.5, 0.6, 0.7, 0.8, 5.0], 4.9)];
        let r = rule(&four).unwrap();
        assert!(r.held[0].value <= 1.0);
        assert_eq!(r.held[0].outcome(), Outcome::Inconclusive);
        assert_eq!(r.verdict(), Verdict::Inconclusive);
        // A dolphin that swims far without a periodic pattern is not at its goal.
        let aperiodic = [control("pendulum", missed, 12.0), swim(0.9, 0.3)];
        assert_eq!(verdict(&aperiodic), Some(Verdict::NotHeld));
        assert_eq!(
            verdict(&[control("pendulum", missed, 12.0), swim(0.6, 0.6)]),
            Some(Verdict::Partly)
        );
        // Doing nothing would already be at the goal: the check cannot be written.
        assert_eq!(verdict(&[control("truck", at_goal, 0.8)]), None);
    }
}
