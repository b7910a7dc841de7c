//! The job: from one random start, the BPTT runs and the gradient-free searches on the
//! emulator and the simulator (and on the DAgger net, if asked), each run's best knots
//! evaluated on both substrates.

use super::report::{common_target, iterations_to};
use super::settings::SearchBudget;
use super::{Params, DAGGER_SUBSTRATE, SEARCHES};
use crate::control::bptt::{Bptt, Descent};
use crate::control::search::{
    anneal, bptt_search, hill_climb, nelder_mead, time_to_target, BpttProblem, Budget, ClimbConfig,
    ReplayProblem, SearchProblem, SearchResult, SimplexConfig,
};
use crate::emulator::hierarchy::{self, global_state};
use crate::experiment::output::{Table, Tables};
use crate::experiment::{other, Error, Job, RunContext};
use crate::families::na::table1_structure::build_dolphin_emulator;
use crate::row;
use crate::seed::mix_seed;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// One finished run.
struct Run {
    method: &'static str,
    substrate: &'static str,
    result: SearchResult,
}

impl Params {
    /// A gradient-free search on one problem.
    fn search<P: SearchProblem>(
        &self,
        method: &str,
        problem: &P,
        v0: &[f64],
        budget: &SearchBudget,
        seed: u64,
    ) -> Result<SearchResult, Error> {
        let b = budget.budget();
        let r = match method {
            "annealing" => anneal(
                problem,
                v0,
                &self.annealing.config(budget.evaluations),
                seed,
                &b,
            ),
            "simplex" => {
                let s = &self.simplex;
                let cfg = SimplexConfig {
                    step: s.step,
                    sd_tolerance: s.sd_tolerance,
                    penalty: s.penalty,
                    restarts: s.restarts,
                };
                nelder_mead(problem, v0, &cfg, &b)
            }
            _ => {
                let h = &self.hill_climbing;
                let cfg = ClimbConfig {
                    batch: h.batch,
                    step: h.step,
                    shrink: h.shrink,
                    grow: h.grow,
                };
                hill_climb(problem, v0, &cfg, seed, &b)
            }
        };
        r.map_err(other)
    }
}

impl Params {
    /// The two BPTT runs (momentum, plain) through `problem`'s net from `v0`, with the step
    /// scale λ measured there first (its cost charged to both); `substrate` names the net
    /// (`emulator`: the Table 1 net, whose stages keep their plain names).
    fn bptt_runs(
        &self,
        ctx: &RunContext,
        problem: &BpttProblem<'_, crate::emulator::Emulator>,
        v0: &[f64],
        substrate: &'static str,
        suffix: &str,
    ) -> Result<Vec<Run>, Error> {
        let label = |name: &str| {
            if substrate == "emulator" {
                format!("{name}{suffix}")
            } else {
                format!("{name} ({substrate}){suffix}")
            }
        };
        let (lambda, spent) = ctx.stage(&label("curvature"), || {
            problem.curvature(v0, self.curvature_iterations)
        });
        if !(lambda.is_finite() && lambda > 0.0) {
            return Err(other(format!(
                "dolphin ({substrate}): step scale λ = {lambda}"
            )));
        }
        let b = &self.bptt;
        let mut runs = vec![];
        for (method, descent) in [
            (
                "bptt_momentum",
                Descent::Momentum {
                    eta: b.eta,
                    alpha: b.alpha,
                },
            ),
            ("bptt_plain", Descent::Plain { eta: b.plain_eta }),
        ] {
            let (result, _) = ctx
                .stage(&label(method), || {
                    bptt_search(
                        problem,
                        v0,
                        descent,
                        lambda,
                        &Budget::iterations(b.iterations),
                        spent,
                    )
                })
                .map_err(other)?;
            runs.push(Run {
                method,
                substrate,
                result,
            });
        }
        Ok(runs)
    }
}

fn opt(v: Option<f64>) -> f64 {
    v.unwrap_or(f64::NAN)
}

/// Columns of `search_seeds.csv`: per search seed and emulator run, the seed's common target
/// J* (the rule's: `rule.target_fraction` of the way from the initial J to the best J any run
/// from that start reaches), where the run's best J first reached it (NaN: never), and how far
/// its best knots swim replayed on the simulator.
pub const SEEDS_COLUMNS: [&str; 7] = [
    "seed",
    "method",
    "initial_objective",
    "best_objective",
    "target",
    "iterations_to_target",
    "distance_simulator_m",
];

/// The seed of gradient-free method `k`'s randomness from search seed `seed`.
fn search_seed(seed: u64, k: usize) -> u64 {
    mix_seed(seed, 410 + k as u64)
}

impl Params {
    /// The random initial knots of search seed `seed` (for the run's own seed, the first start
    /// of `na_fig13_control`'s dolphin: stream 400).
    fn initial_knots(&self, seed: u64, n: usize) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(seed, 400));
        (0..n)
            .map(|_| self.init_spread * (2.0 * rng.random::<f64>() - 1.0))
            .collect()
    }

    /// The search seeds after the run's own: `own + 1 ..= own + search_seeds - 1`.
    fn further_search_seeds(&self, own: u64) -> Vec<u64> {
        (1..self.search_seeds as u64).map(|k| own + k).collect()
    }

    /// The rows of `search_seeds.csv` for the emulator runs `runs` from search seed `seed`'s
    /// start: the common target over them and each run's iterations to it.
    fn seed_rows(
        &self,
        seed: u64,
        runs: &[&Run],
        replay_distance: &dyn Fn(&[f64]) -> f64,
        table: &mut Table,
    ) {
        let j0 = runs
            .iter()
            .find(|r| r.method == "bptt_momentum")
            .and_then(|r| r.result.trace.first())
            .map_or(f64::NAN, |t| t.best);
        let j_best = runs
            .iter()
            .flat_map(|r| r.result.trace.iter().map(|t| t.best))
            .fold(f64::INFINITY, f64::min);
        let target = common_target(j0, j_best, &self.rule);
        for r in runs {
            let (k, j): (Vec<f64>, Vec<f64>) = r
                .result
                .trace
                .iter()
                .map(|t| (t.iteration as f64, t.best))
                .unzip();
            table.push(row![
                seed as i64,
                r.method,
                j0,
                r.result.best_value,
                target,
                opt(iterations_to(&k, &j, target)),
                replay_distance(&r.result.best)
            ]);
        }
    }
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let spec = self.nets.spec(ctx.seed, self.steps, self.example_scale);
        let built = ctx.stage("train dolphin hierarchy", || build_dolphin_emulator(&spec))?;
        let body = built.emulator.dolphin().clone();
        let global = built.emulator.global();
        let swim = &self.swim;
        let objective = swim.objective();
        let knots = swim.knot_layout();
        let (x0, g0) = swim.start(&body);
        let bptt = Bptt::new(global, &objective, knots, swim.bounds(), &g0).map_err(other)?;
        // The initial knots of na_fig13_control's dolphin.
        let v0 = self.initial_knots(ctx.seed, knots.len());
        let emulator = BpttProblem::new(&bptt);
        let simulator = ReplayProblem::new(
            &bptt,
            || Box::new(hierarchy::simulator(&body)) as Box<dyn crate::physics::Dynamics>,
            &x0,
            self.nets.physical_dt,
            self.steps,
            Box::new(|x: &[f64], out: &mut [f64]| global_state(&body, x, out)),
        )
        .map_err(other)?;

        let mut runs = self.headline_runs(ctx, &emulator, &simulator, &v0)?;
        // The same runs on the dolphin's last-round DAgger net (ours), from the same start.
        let dagger_net = match &self.dagger {
            Some(d) => Some(self.fig13(d).dolphin_dagger_net(ctx)?),
            None => None,
        };
        let dagger_bptt = match &dagger_net {
            Some(net) => {
                Some(Bptt::new(net, &objective, knots, swim.bounds(), &g0).map_err(other)?)
            }
            None => None,
        };
        if let Some(b) = &dagger_bptt {
            runs.extend(self.dagger_runs(ctx, b, &v0)?);
        }

        let baselines = baselines_table(&runs);
        let evaluated = self.evaluate_runs(&runs, &emulator, &simulator);
        let final_t = final_table(&runs, &evaluated);
        let seeds_t = self.seeds_table(ctx, &runs, &emulator, &simulator, knots.len())?;
        Ok(Tables::from([
            ("baselines", baselines),
            ("final", final_t),
            ("search_seeds", seeds_t),
            ("rule", crate::experiment::rule::rule_table_of(&self.rule)?),
        ]))
    }
}

/// A run's best knots evaluated on both substrates: J and swim distance on each (NaN for
/// knots that are not finite).
struct OnBoth {
    j_emulator: f64,
    j_simulator: f64,
    d_emulator: f64,
    d_simulator: f64,
}

impl Params {
    /// The BPTT runs on the emulator, then every gradient-free search on the emulator and on
    /// the simulator in turn, each from `v0` with its own search seed.
    fn headline_runs(
        &self,
        ctx: &RunContext,
        emulator: &BpttProblem<'_, crate::emulator::Emulator>,
        simulator: &ReplayProblem<'_>,
        v0: &[f64],
    ) -> Result<Vec<Run>, Error> {
        let mut runs: Vec<Run> = vec![];
        runs.extend(self.bptt_runs(ctx, emulator, v0, "emulator", "")?);
        let pb = ctx.progress(2 * SEARCHES.len() as u64, "gradient-free searches");
        for (k, method) in SEARCHES.into_iter().enumerate() {
            let seed = search_seed(ctx.seed, k);
            let result = ctx.stage(&format!("{method} emulator"), || {
                self.search(method, emulator, v0, &self.budget.emulator, seed)
            })?;
            runs.push(Run {
                method,
                substrate: "emulator",
                result,
            });
            pb.inc(1);
            let result = ctx.stage(&format!("{method} simulator"), || {
                self.search(method, simulator, v0, &self.budget.simulator, seed)
            })?;
            runs.push(Run {
                method,
                substrate: "simulator",
                result,
            });
            pb.inc(1);
        }
        pb.finish_and_clear();
        Ok(runs)
    }

    /// The BPTT runs and every gradient-free search through the DAgger net's descent `b`, from
    /// `v0` with the emulator's budgets and search seeds.
    fn dagger_runs(
        &self,
        ctx: &RunContext,
        b: &Bptt<'_, crate::emulator::Emulator>,
        v0: &[f64],
    ) -> Result<Vec<Run>, Error> {
        let problem = BpttProblem::new(b);
        let mut runs = self.bptt_runs(ctx, &problem, v0, DAGGER_SUBSTRATE, "")?;
        for (k, method) in SEARCHES.into_iter().enumerate() {
            let seed = search_seed(ctx.seed, k);
            let result = ctx.stage(&format!("{method} ({DAGGER_SUBSTRATE})"), || {
                self.search(method, &problem, v0, &self.budget.emulator, seed)
            })?;
            runs.push(Run {
                method,
                substrate: DAGGER_SUBSTRATE,
                result,
            });
        }
        Ok(runs)
    }

    /// Every run's best knots on both substrates.
    fn evaluate_runs(
        &self,
        runs: &[Run],
        emulator: &BpttProblem<'_, crate::emulator::Emulator>,
        simulator: &ReplayProblem<'_>,
    ) -> Vec<OnBoth> {
        let swim = &self.swim;
        let on_both = |v: &[f64]| -> OnBoth {
            if v.iter().any(|x| !x.is_finite()) {
                return OnBoth {
                    j_emulator: f64::NAN,
                    j_simulator: f64::NAN,
                    d_emulator: f64::NAN,
                    d_simulator: f64::NAN,
                };
            }
            let (je, de) = emulator.with_bptt(|b| {
                let j = b.rollout(v);
                (j, swim.distance(b.states()))
            });
            let sim = simulator.rollout(v);
            OnBoth {
                j_emulator: je,
                j_simulator: sim.objective,
                d_emulator: de,
                d_simulator: swim.distance(&sim.states),
            }
        };
        runs.iter().map(|r| on_both(&r.result.best)).collect()
    }

    /// The emulator runs again from each further search seed's start (search_seeds.csv),
    /// after this run's own rows; knots not finite swim NaN.
    fn seeds_table(
        &self,
        ctx: &RunContext,
        runs: &[Run],
        emulator: &BpttProblem<'_, crate::emulator::Emulator>,
        simulator: &ReplayProblem<'_>,
        knots_len: usize,
    ) -> Result<Table, Error> {
        let swim = &self.swim;
        let replay_distance = |v: &[f64]| -> f64 {
            if v.iter().any(|x| !x.is_finite()) {
                return f64::NAN;
            }
            swim.distance(&simulator.rollout(v).states)
        };
        let mut seeds_t = Table::new(&SEEDS_COLUMNS);
        let own: Vec<&Run> = runs.iter().filter(|r| r.substrate == "emulator").collect();
        self.seed_rows(ctx.seed, &own, &replay_distance, &mut seeds_t);
        for s in self.further_search_seeds(ctx.seed) {
            let v0 = self.initial_knots(s, knots_len);
            let mut more =
                self.bptt_runs(ctx, emulator, &v0, "emulator", &format!(", seed {s}"))?;
            for (k, method) in SEARCHES.into_iter().enumerate() {
                let result = ctx.stage(&format!("{method} emulator, seed {s}"), || {
                    self.search(
                        method,
                        emulator,
                        &v0,
                        &self.budget.emulator,
                        search_seed(s, k),
                    )
                })?;
                more.push(Run {
                    method,
                    substrate: "emulator",
                    result,
                });
            }
            let more: Vec<&Run> = more.iter().collect();
            self.seed_rows(s, &more, &replay_distance, &mut seeds_t);
        }
        Ok(seeds_t)
    }
}

/// `baselines.csv`: every run's trace, iteration by iteration.
fn baselines_table(runs: &[Run]) -> Table {
    let mut baselines = Table::new(&[
        "method",
        "substrate",
        "iteration",
        "evaluations",
        "seconds",
        "objective",
        "gradients",
        "current",
    ]);
    for r in runs {
        for t in &r.result.trace {
            baselines.push(row![
                r.method,
                r.substrate,
                t.iteration,
                t.evaluations,
                t.seconds,
                t.best,
                t.gradients,
                t.current
            ]);
        }
    }
    baselines
}

/// `final.csv`: every run's end, its best knots on both substrates and when it reached its
/// substrate's target (BPTT-momentum's J there) and its own best J.
fn final_table(runs: &[Run], evaluated: &[OnBoth]) -> Table {
    let momentum = runs
        .iter()
        .position(|r| r.method == "bptt_momentum")
        .expect("the momentum run is first");
    let targets = (
        evaluated[momentum].j_emulator,
        evaluated[momentum].j_simulator,
    );
    // On the DAgger net: its own momentum run's best J there.
    let dagger_target = runs
        .iter()
        .find(|r| r.method == "bptt_momentum" && r.substrate == DAGGER_SUBSTRATE)
        .map_or(f64::NAN, |r| r.result.best_value);
    let mut final_t = Table::new(&[
        "method",
        "substrate",
        "iterations",
        "evaluations",
        "seconds",
        "objective_substrate",
        "objective_emulator",
        "objective_simulator",
        "distance_emulator_m",
        "distance_simulator_m",
        "target",
        "iterations_to_bptt",
        "evaluations_to_bptt",
        "seconds_to_bptt",
        "best_iteration",
    ]);
    for (r, e) in runs.iter().zip(evaluated) {
        let target = match r.substrate {
            "emulator" => targets.0,
            DAGGER_SUBSTRATE => dagger_target,
            _ => targets.1,
        };
        let trace = &r.result.trace;
        let last = trace.last().expect("a search has iteration 0");
        let reached = time_to_target(trace, target);
        let own = time_to_target(trace, r.result.best_value);
        final_t.push(row![
            r.method,
            r.substrate,
            last.iteration,
            last.evaluations,
            last.seconds,
            r.result.best_value,
            e.j_emulator,
            e.j_simulator,
            e.d_emulator,
            e.d_simulator,
            target,
            opt(reached.map(|x| x.iteration as f64)),
            opt(reached.map(|x| x.evaluations as f64)),
            opt(reached.map(|x| x.seconds)),
            opt(own.map(|x| x.iteration as f64))
        ]);
    }
    final_t
}
