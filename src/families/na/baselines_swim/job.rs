//! The job: from one random start, the BPTT runs and the gradient-free searches on the
//! emulator and the simulator (and on the DAgger net, if asked), each run's best knots
//! evaluated on both substrates.

use super::report::{common_target, iterations_to};
use super::settings::SearchBudget;
use super::{Params, Search, DAGGER_SUBSTRATE};
use crate::control::bptt::{Bptt, Descent};
use crate::control::search::{
    anneal, bptt_search, hill_climb, nelder_mead, time_to_target, BpttProblem, Budget, ClimbConfig,
    ReplayProblem, SearchProblem, SearchResult, SimplexConfig,
};
use crate::emulator::hierarchy::{self, global_state};
use crate::experiment::output::Tables;
use crate::experiment::rows::table_of;
use crate::experiment::runner::one_core_each;
use crate::experiment::{other, Error, Job, RunContext};
use crate::families::na::table1_structure::build_dolphin_emulator;
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
        method: Search,
        problem: &P,
        v0: &[f64],
        budget: &SearchBudget,
        seed: u64,
    ) -> Result<SearchResult, Error> {
        let b = budget.budget();
        let r = match method {
            Search::Annealing => anneal(
                problem,
                v0,
                &self.annealing.config(budget.evaluations),
                seed,
                &b,
            ),
            Search::Simplex => {
                let s = &self.simplex;
                let cfg = SimplexConfig {
                    step: s.step,
                    sd_tolerance: s.sd_tolerance,
                    penalty: s.penalty,
                    restarts: s.restarts,
                };
                nelder_mead(problem, v0, &cfg, &b)
            }
            Search::HillClimbing => {
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

crate::result_rows! {
    /// One row of `search_seeds.csv`: per search seed and emulator run, the seed's common
    /// target J* (the rule's: `rule.target_fraction` of the way from the initial J to the best
    /// J any run from that start reaches), where the run's best J first reached it, and how far
    /// its best knots swim replayed on the simulator.
    pub struct SearchSeedRow {
        /// The search seed.
        seed: i64 = "seed",
        /// The method's name.
        method: String = "method",
        /// BPTT-momentum's initial J from the seed's start.
        initial_objective: f64 = "initial_objective",
        /// The run's best J.
        best_objective: f64 = "best_objective",
        /// The seed's common target J*.
        target: f64 = "target",
        /// Iterations until the run's best J first reached J* (NaN: never).
        iterations_to_target: f64 = "iterations_to_target",
        /// How far its best knots swim replayed on the simulator (m; NaN for knots not finite).
        distance_simulator_m: f64 = "distance_simulator_m",
    }
}

crate::result_rows! {
    /// One row of `baselines.csv`: one run's state after one iteration.
    pub struct BaselineRow {
        /// The method's name.
        method: String = "method",
        /// The substrate it learned on (`emulator`, `simulator`, the DAgger net's).
        substrate: String = "substrate",
        /// The iteration.
        iteration: i64 = "iteration",
        /// Objective evaluations so far.
        evaluations: i64 = "evaluations",
        /// Wall-clock seconds so far.
        seconds: f64 = "seconds",
        /// The best J so far.
        objective: f64 = "objective",
        /// Gradients so far.
        gradients: i64 = "gradients",
        /// The current iterate's J.
        current: f64 = "current",
    }
}

crate::result_rows! {
    /// One row of `final.csv`: one run's end, its best knots on both substrates and when it
    /// reached its substrate's target (BPTT-momentum's J there) and its own best J.
    pub struct FinalRow {
        /// The method's name.
        method: String = "method",
        /// The substrate it learned on.
        substrate: String = "substrate",
        /// Iterations run.
        iterations: i64 = "iterations",
        /// Objective evaluations run.
        evaluations: i64 = "evaluations",
        /// Wall-clock seconds run.
        seconds: f64 = "seconds",
        /// Its best J on its substrate.
        objective_substrate: f64 = "objective_substrate",
        /// Its best knots' J on the emulator.
        objective_emulator: f64 = "objective_emulator",
        /// Its best knots' J on the simulator.
        objective_simulator: f64 = "objective_simulator",
        /// Its best knots' swim on the emulator (m).
        distance_emulator_m: f64 = "distance_emulator_m",
        /// Its best knots' swim on the simulator (m).
        distance_simulator_m: f64 = "distance_simulator_m",
        /// Its substrate's target: BPTT-momentum's J there.
        target: f64 = "target",
        /// Iterations to the target (NaN: never).
        iterations_to_bptt: f64 = "iterations_to_bptt",
        /// Evaluations to the target (NaN: never).
        evaluations_to_bptt: f64 = "evaluations_to_bptt",
        /// Seconds to the target (NaN: never).
        seconds_to_bptt: f64 = "seconds_to_bptt",
        /// The iteration it first reached its own best J.
        best_iteration: f64 = "best_iteration",
    }
}

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
        table: &mut Vec<SearchSeedRow>,
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
            table.push(SearchSeedRow {
                seed: seed as i64,
                method: r.method.to_string(),
                initial_objective: j0,
                best_objective: r.result.best_value,
                target,
                iterations_to_target: opt(iterations_to(&k, &j, target)),
                distance_simulator_m: replay_distance(&r.result.best),
            });
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
            ("baselines", table_of(&baselines)),
            ("final", table_of(&final_t)),
            ("search_seeds", table_of(&seeds_t)),
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
        let pb = ctx.progress(2 * Search::ALL.len() as u64, "gradient-free searches");
        // Every search on both substrates, each on a core of its own (their seconds are
        // reported), side by side.
        let jobs: Vec<(usize, Search, &'static str)> = Search::ALL
            .into_iter()
            .enumerate()
            .flat_map(|(k, search)| ["emulator", "simulator"].map(|on| (k, search, on)))
            .collect();
        let results = one_core_each(&jobs, |&(k, search, substrate)| {
            let seed = search_seed(ctx.seed, k);
            let result = ctx.stage(&format!("{} {substrate}", search.name()), || {
                if substrate == "emulator" {
                    self.search(search, emulator, v0, &self.budget.emulator, seed)
                } else {
                    self.search(search, simulator, v0, &self.budget.simulator, seed)
                }
            });
            pb.inc(1);
            result
        })?;
        for ((_, search, substrate), result) in jobs.into_iter().zip(results) {
            runs.push(Run {
                method: search.name(),
                substrate,
                result: result?,
            });
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
        for (k, search) in Search::ALL.into_iter().enumerate() {
            let method = search.name();
            let seed = search_seed(ctx.seed, k);
            let result = ctx.stage(&format!("{method} ({DAGGER_SUBSTRATE})"), || {
                self.search(search, &problem, v0, &self.budget.emulator, seed)
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
    ) -> Result<Vec<SearchSeedRow>, Error> {
        let swim = &self.swim;
        let replay_distance = |v: &[f64]| -> f64 {
            if v.iter().any(|x| !x.is_finite()) {
                return f64::NAN;
            }
            swim.distance(&simulator.rollout(v).states)
        };
        let mut seeds_t = Vec::new();
        let own: Vec<&Run> = runs.iter().filter(|r| r.substrate == "emulator").collect();
        self.seed_rows(ctx.seed, &own, &replay_distance, &mut seeds_t);
        for s in self.further_search_seeds(ctx.seed) {
            let v0 = self.initial_knots(s, knots_len);
            let mut more =
                self.bptt_runs(ctx, emulator, &v0, "emulator", &format!(", seed {s}"))?;
            for (k, search) in Search::ALL.into_iter().enumerate() {
                let method = search.name();
                let result = ctx.stage(&format!("{method} emulator, seed {s}"), || {
                    self.search(
                        search,
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
fn baselines_table(runs: &[Run]) -> Vec<BaselineRow> {
    runs.iter()
        .flat_map(|r| {
            r.result.trace.iter().map(|t| BaselineRow {
                method: r.method.to_string(),
                substrate: r.substrate.to_string(),
                iteration: t.iteration as i64,
                evaluations: t.evaluations as i64,
                seconds: t.seconds,
                objective: t.best,
                gradients: t.gradients as i64,
                current: t.current,
            })
        })
        .collect()
}

/// `final.csv`: every run's end, its best knots on both substrates and when it reached its
/// substrate's target (BPTT-momentum's J there) and its own best J.
fn final_table(runs: &[Run], evaluated: &[OnBoth]) -> Vec<FinalRow> {
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
    let mut final_t = Vec::with_capacity(runs.len());
    for (r, e) in runs.iter().zip(evaluated) {
        let target = match r.substrate {
            "emulator" => targets.0,
            DAGGER_SUBSTRATE => dagger_target,
            "simulator" => targets.1,
            other => unreachable!(
                "the runs are on the emulator, the DAgger net or the simulator, not {other}"
            ),
        };
        let trace = &r.result.trace;
        let last = trace.last().expect("a search has iteration 0");
        let reached = time_to_target(trace, target);
        let own = time_to_target(trace, r.result.best_value);
        final_t.push(FinalRow {
            method: r.method.to_string(),
            substrate: r.substrate.to_string(),
            iterations: last.iteration as i64,
            evaluations: last.evaluations as i64,
            seconds: last.seconds,
            objective_substrate: r.result.best_value,
            objective_emulator: e.j_emulator,
            objective_simulator: e.j_simulator,
            distance_emulator_m: e.d_emulator,
            distance_simulator_m: e.d_simulator,
            target,
            iterations_to_bptt: opt(reached.map(|x| x.iteration as f64)),
            evaluations_to_bptt: opt(reached.map(|x| x.evaluations as f64)),
            seconds_to_bptt: opt(reached.map(|x| x.seconds)),
            best_iteration: opt(own.map(|x| x.iteration as f64)),
        });
    }
    final_t
}
