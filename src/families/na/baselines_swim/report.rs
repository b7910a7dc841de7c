//! The report: every run's table row, and the verdict rule (BPTT fast, every gradient-free
//! method at least 10x slower, BPTT's knots swimming at least as far on the simulator).

use super::job::{BaselineRow, FinalRow, SearchSeedRow};
use super::{SwimRule, DAGGER_SUBSTRATE, SEARCHES};
use crate::experiment::other;
use crate::experiment::output::written_csv;
use crate::experiment::report::{sig, Findings, Verdict};
use crate::experiment::rows::{read_rows, TableRow};
use crate::experiment::rule::{read_rule, shown, Check, Cmp, Null, Partly, Rule};
use crate::experiment::stats::median_interval_with_infinities;
use crate::experiment::Error;
use std::path::Path;

/// The findings from the run folder `dir`.
pub(super) fn findings(dir: &Path) -> Result<Findings, Error> {
    let bars: SwimRule = read_rule(dir)?;
    let f = Finals::read(dir)?;
    let mom = f
        .row_of("bptt_momentum", "emulator")
        .ok_or_else(|| other("no bptt_momentum run"))?;
    let md = f.table_md();
    let runs = Runs {
        traces: Traces::read(dir)?,
        f,
    };
    let mut main = runs
        .judge("emulator", &bars)
        .ok_or_else(|| other("no bptt_momentum run"))?;
    // Over several search seeds the verdict reads their medians (search_seeds.csv).
    let seeds_line = over_seeds(dir, &bars, &mut main)?;
    let f = &runs.f;
    let (rival_sim, verdict) = (main.rival_sim, main.verdict);
    let (lines, text) = (&main.lines, &main.text);
    let (k_bptt, notes) = (f.rows[mom].iterations_to_bptt, runs.own_notes("emulator"));
    let sim_notes = f.sim_notes();
    // How the momentum iterate's J moved (a monotone descent never rises).
    let t = &runs.traces;
    let mom_j: Vec<f64> = t
        .rows
        .iter()
        .filter(|r| r.method == "bptt_momentum" && r.substrate == "emulator")
        .map(|r| r.current)
        .collect();
    let rises = mom_j.windows(2).filter(|w| w[1] > w[0]).count();
    let sim_target = f
        .rows
        .iter()
        .find(|r| r.substrate == "simulator")
        .map_or(f64::NAN, |r| r.target);
    let dagger_line = runs.dagger_line(&bars);
    Ok(Findings {
            ours: md,
            verdict,
            rule: main.rule.clone(),
            why: format!(
                "On the emulator, the {}. BPTT with momentum reaches its best emulator J = {} at iteration {} ({} s, the step-scale estimate included; its iterate's J rose in {rises} of {} steps; its knots swim {} m on the simulator vs {} m on the emulator). On the emulator, {}. On the physical simulator (target: BPTT's knots replayed there, J = {}), {}. Replayed on the simulator, BPTT's knots swim {} m, the gradient-free methods' emulator-learned knots at most {} m. Checks on the emulator:{lines} Rule (ours, in the spec's [params.rule], rewritten after results: see the rule history; J* lies target_fraction of the way from the initial J to the best J any method reaches): {text} An iteration is one annealing proposal, one simplex step, one hill-climbing batch (several evaluations) or one gradient step; budgets are far below the paper's hour, so 'never' means 'not within the budget'. Seconds are this machine's wall clock.",
                main.target_line,
                sig(f.rows[mom].objective_substrate),
                k_bptt,
                sig(f.rows[mom].seconds_to_bptt),
                mom_j.len().saturating_sub(1),
                sig(f.rows[mom].distance_simulator_m),
                sig(f.rows[mom].distance_emulator_m),
                notes.join("; "),
                sig(sim_target),
                sim_notes.join("; "),
                sig(f.rows[mom].distance_simulator_m),
                sig(rival_sim)
            ) + &seeds_line
                + &dagger_line,
        })
}

/// The rows of `final.csv`: one per (method, substrate) run.
struct Finals {
    rows: Vec<FinalRow>,
}

/// Every run's best-so-far J per iteration (`baselines.csv`), for the common target.
struct Traces {
    rows: Vec<BaselineRow>,
}

/// Both tables the rule reads.
struct Runs {
    f: Finals,
    traces: Traces,
}

impl Finals {
    /// `final.csv` of `dir`.
    fn read(dir: &Path) -> Result<Self, Error> {
        Ok(Finals {
            rows: read_rows(&dir.join("final.csv"))?,
        })
    }

    /// The row of method `m` on substrate `s`.
    fn row_of(&self, m: &str, s: &str) -> Option<usize> {
        (0..self.rows.len()).find(|&r| self.rows[r].method == m && self.rows[r].substrate == s)
    }

    /// Row `r`'s iterations / evaluations / seconds to BPTT's J, or "never".
    fn reach(&self, r: usize) -> String {
        if self.rows[r].iterations_to_bptt.is_finite() {
            format!(
                "{} / {} / {}",
                self.rows[r].iterations_to_bptt,
                self.rows[r].evaluations_to_bptt,
                sig(self.rows[r].seconds_to_bptt)
            )
        } else {
            "never".into()
        }
    }

    /// The report's table: every run's row.
    fn table_md(&self) -> String {
        let mut md = String::from(
            "| method | substrate | iterations / evaluations / s run | to BPTT's J: iterations / evaluations / s | J on substrate | J emulator | J simulator | distance emulator (m) | distance simulator (m) |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
        );
        for r in 0..self.rows.len() {
            md.push_str(&format!(
                "| {} | {} | {} / {} / {} | {} | {} | {} | {} | {} | {} |\n",
                self.rows[r].method,
                self.rows[r].substrate,
                self.rows[r].iterations,
                self.rows[r].evaluations,
                sig(self.rows[r].seconds),
                self.reach(r),
                sig(self.rows[r].objective_substrate),
                sig(self.rows[r].objective_emulator),
                sig(self.rows[r].objective_simulator),
                sig(self.rows[r].distance_emulator_m),
                sig(self.rows[r].distance_simulator_m)
            ));
        }
        md
    }

    /// Per gradient-free method learned on the simulator, whether (and when) it reached
    /// BPTT's J there.
    fn sim_notes(&self) -> Vec<String> {
        SEARCHES
            .iter()
            .filter_map(|m| self.row_of(m, "simulator"))
            .map(|r| {
                if self.rows[r].iterations_to_bptt.is_finite() {
                    format!(
                        "{} reached it after {} iterations ({} s)",
                        self.rows[r].method,
                        self.rows[r].iterations_to_bptt,
                        sig(self.rows[r].seconds_to_bptt)
                    )
                } else {
                    format!(
                        "{} never did in {} iterations / {} evaluations / {} s (best J {})",
                        self.rows[r].method,
                        self.rows[r].iterations,
                        self.rows[r].evaluations,
                        sig(self.rows[r].seconds),
                        sig(self.rows[r].objective_substrate)
                    )
                }
            })
            .collect()
    }
}

impl Traces {
    /// `baselines.csv` of `dir`.
    fn read(dir: &Path) -> Result<Self, Error> {
        Ok(Traces {
            rows: read_rows(&dir.join("baselines.csv"))?,
        })
    }

    /// The (iterations, best-so-far J) of method `m` on substrate `sub`.
    fn trace(&self, m: &str, sub: &str) -> (Vec<f64>, Vec<f64>) {
        self.rows
            .iter()
            .filter(|r| r.method == m && r.substrate == sub)
            .map(|r| (r.iteration as f64, r.objective))
            .unzip()
    }
}

impl Runs {
    /// The rule on one emulator substrate: the common target
    /// J* (halfway from the initial J to the best J any method reaches there), the iterations
    /// BPTT-momentum and each gradient-free method need to reach it, a note per method, the
    /// farthest the methods' knots learned there swim on the simulator, and the verdict.
    fn judge(&self, substrate: &str, bars: &SwimRule) -> Option<Judged> {
        let (f, t) = (&self.f, &self.traces);
        let mom = f.row_of("bptt_momentum", substrate)?;
        let (mi, mo) = t.trace("bptt_momentum", substrate);
        let j0 = *mo.first()?;
        let j_best = t
            .rows
            .iter()
            .filter(|r| r.substrate == substrate)
            .map(|r| r.objective)
            .fold(f64::INFINITY, f64::min);
        let target = common_target(j0, j_best, bars);
        let k_bptt = iterations_to(&mi, &mo, target);
        let (mut rivals, mut notes) = (vec![], vec![]);
        for m in SEARCHES {
            if f.row_of(m, substrate).is_none() {
                continue;
            }
            let (ti, to) = t.trace(m, substrate);
            let k = iterations_to(&ti, &to, target);
            rivals.push(k);
            notes.push(match (k, k_bptt) {
                (Some(k), Some(kb)) => {
                    format!("{m} after {k} iterations ({}x)", sig(k / kb.max(1.0)))
                }
                (Some(k), None) => format!("{m} after {k} iterations"),
                (None, _) => format!(
                    "{m} never in {} iterations",
                    ti.last().copied().unwrap_or(0.0)
                ),
            });
        }
        let rival_sim = SEARCHES
            .iter()
            .filter_map(|m| f.row_of(m, substrate))
            .map(|r| f.rows[r].distance_simulator_m)
            .fold(f64::NEG_INFINITY, f64::max);
        let rule = swim_rule(
            k_bptt,
            &rivals,
            f.rows[mom].distance_simulator_m,
            rival_sim,
            bars,
        );
        let (verdict, lines, text) = shown(rule.as_ref(), " No rule: a bar its null meets.");
        let target_line = format!(
            "common target J* = {} (halfway from the initial J = {} to the best any method reaches, {}): BPTT with momentum {}; {}",
            sig(target),
            sig(j0),
            sig(j_best),
            match k_bptt {
                Some(k) => format!("reaches it at iteration {k}"),
                None => format!("never reaches it in its {} iterations (its best J = {})", mi.last().copied().unwrap_or(0.0), sig(f.rows[mom].objective_substrate)),
            },
            notes.join("; ")
        );
        Some(Judged {
            mom,
            target_line,
            rival_sim,
            verdict,
            lines,
            text,
            rule,
        })
    }

    /// The notes on reaching BPTT-momentum's own best J (the table's column; not the rule).
    fn own_notes(&self, substrate: &str) -> Vec<String> {
        let f = &self.f;
        let Some(mom) = f.row_of("bptt_momentum", substrate) else {
            return vec![];
        };
        let k_bptt = f.rows[mom].iterations_to_bptt;
        let mut notes = vec![];
        for m in SEARCHES {
            let Some(r) = f.row_of(m, substrate) else {
                continue;
            };
            notes.push(if f.rows[r].iterations_to_bptt.is_finite() {
                format!(
                    "{m} reached it after {} iterations ({}x, {} s vs {} s)",
                    f.rows[r].iterations_to_bptt,
                    sig(f.rows[r].iterations_to_bptt / k_bptt.max(1.0)),
                    sig(f.rows[r].seconds_to_bptt),
                    sig(f.rows[mom].seconds_to_bptt)
                )
            } else {
                format!(
                    "{m} never did in {} iterations / {} evaluations (best J {})",
                    f.rows[r].iterations,
                    f.rows[r].evaluations,
                    sig(f.rows[r].objective_substrate)
                )
            });
        }
        notes
    }

    /// The same rule on the DAgger net (ours; a line beside the headline, rule in the spec).
    fn dagger_line(&self, bars: &SwimRule) -> String {
        let f = &self.f;
        match self.judge(DAGGER_SUBSTRATE, bars) {
            Some(g) => format!(
                " On the dolphin's last-round DAgger global net (ours, substrate `{DAGGER_SUBSTRATE}`, the same start and budgets): BPTT with momentum reaches its best J = {} at iteration {}; {}. Its {}. Replayed on the simulator, BPTT's knots learned there swim {} m, the gradient-free methods' at most {} m. The same rule on the DAgger net: {}.{}",
                sig(f.rows[g.mom].objective_substrate),
                f.rows[g.mom].iterations_to_bptt,
                self.own_notes(DAGGER_SUBSTRATE).join("; "),
                g.target_line,
                sig(f.rows[g.mom].distance_simulator_m),
                sig(g.rival_sim),
                g.verdict.label(),
                g.lines
            ),
            None => String::new(),
        }
    }
}

/// Over several search seeds (search_seeds.csv), `main`'s rule, verdict and checks replaced by
/// those on the seeds' medians; returns the sentence on every seed (empty with one seed or none).
fn over_seeds(dir: &Path, bars: &SwimRule, main: &mut Judged) -> Result<String, Error> {
    let mut seeds_line = String::new();
    if let Some(seeds) = seed_measures(dir, bars)?.filter(|s| s.len() > 1) {
        let measures: Vec<SwimMeasures> = seeds.iter().map(|(_, m)| *m).collect();
        main.rule = swim_rule_over(&measures, bars);
        let (verdict, lines, text) = shown(main.rule.as_ref(), " No rule: a bar its null meets.");
        (main.verdict, main.lines, main.text) = (verdict, lines, text);
        let per_seed: Vec<String> = seeds
            .iter()
            .map(|(s, m)| {
                format!(
                    "seed {s}: BPTT {}, {} of methods slow, {} faster, swims {} m farther",
                    if m.bptt.is_finite() {
                        format!("at iteration {}", m.bptt)
                    } else {
                        "never".into()
                    },
                    sig(m.slow_share),
                    m.faster,
                    sig(m.swim_margin)
                )
            })
            .collect();
        seeds_line = format!(
            " Over {} search seeds (each its own random start and gradient-free randomness, on the emulator; the checks read their medians): {}.",
            seeds.len(),
            per_seed.join("; ")
        );
    }
    Ok(seeds_line)
}

/// The verdict rule's parts on one emulator substrate (see `report`).
struct Judged {
    mom: usize,
    target_line: String,
    rival_sim: f64,
    verdict: Verdict,
    lines: String,
    text: String,
    rule: Option<Rule>,
}

/// The common target J* on a substrate: `bars.target_fraction` of the way from the initial J
/// `j0` (the common initial knots') to the best J `j_best` any method reaches there.
pub fn common_target(j0: f64, j_best: f64, bars: &SwimRule) -> f64 {
    j0 + bars.target_fraction * (j_best - j0)
}

/// The first iteration of a run (`iterations`, with its best-so-far J `best`) whose J is at or
/// below `target`; `None` when it never gets there.
pub fn iterations_to(iterations: &[f64], best: &[f64], target: f64) -> Option<f64> {
    iterations
        .iter()
        .zip(best)
        .find(|(_, &j)| j <= target)
        .map(|(&k, _)| k)
}

/// What the verdict's rule measures from one start on one substrate (see [`swim_rule`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SwimMeasures {
    /// BPTT-momentum's iterations to J* (+∞: never).
    pub bptt: f64,
    /// Share of the gradient-free methods needing at least `slow_factor` x BPTT's
    /// iterations or never getting there.
    pub slow_share: f64,
    /// Gradient-free methods reaching J* in fewer iterations than BPTT.
    pub faster: f64,
    /// How much farther BPTT's knots swim on the simulator than every method's (m).
    pub swim_margin: f64,
    /// Gradient-free methods compared.
    pub methods: usize,
}

/// The rule's measures from the iterations BPTT-momentum (`bptt`) and each gradient-free
/// method (`rivals`) need to reach the common target (`None`: never), and how far BPTT's knots
/// (`bptt_swim`) and the farthest of the methods' knots (`rival_swim`) swim on the simulator.
pub fn swim_measures(
    bptt: Option<f64>,
    rivals: &[Option<f64>],
    bptt_swim: f64,
    rival_swim: f64,
    bars: &SwimRule,
) -> SwimMeasures {
    let kb = bptt.unwrap_or(f64::INFINITY);
    let slow = rivals
        .iter()
        .filter(|k| k.is_none_or(|k| k >= bars.slow_factor * kb.max(1.0)))
        .count() as f64;
    SwimMeasures {
        bptt: kb,
        slow_share: if rivals.is_empty() {
            f64::NAN
        } else {
            slow / rivals.len() as f64
        },
        faster: rivals.iter().filter(|k| k.is_some_and(|k| k < kb)).count() as f64,
        swim_margin: bptt_swim - rival_swim,
        methods: rivals.len(),
    }
}

/// The verdict's rule on one substrate from one start: [`swim_rule_over`] of its
/// [`swim_measures`].
pub fn swim_rule(
    bptt: Option<f64>,
    rivals: &[Option<f64>],
    bptt_swim: f64,
    rival_swim: f64,
    bars: &SwimRule,
) -> Option<Rule> {
    swim_rule_over(
        &[swim_measures(bptt, rivals, bptt_swim, rival_swim, bars)],
        bars,
    )
}

/// Seed of the bootstrap over search seeds (fixed, so a report is the same on every machine).
const BOOTSTRAP_SEED: u64 = 1;

/// The verdict's rule over the measures of one or more search seeds (each its own random
/// start; with several, each check reads the median over them with its 95% bootstrap
/// interval, a "never" counting as the slowest): (a) BPTT reaches J* within
/// `fast_iterations` (null: the initial knots, which never do); (b) the share of methods
/// needing at least `slow_factor` times BPTT's iterations or never getting there is 1, and
/// (c) above `partly_slow_share` (null for both: methods as fast as BPTT, 0); (d) no method
/// needs fewer iterations than BPTT (null: every method faster); (e) BPTT's knots swim farther
/// on the simulator than every method's (null: the farthest method's knots themselves, 0 m
/// farther). Held needs all; partly (a), (c), (d).
pub fn swim_rule_over(seeds: &[SwimMeasures], bars: &SwimRule) -> Option<Rule> {
    let k = seeds.len();
    let over = |f: fn(&SwimMeasures) -> f64| -> (f64, Option<(f64, f64)>) {
        let v: Vec<f64> = seeds.iter().map(f).collect();
        if k > 1 {
            let (m, lo, hi) = median_interval_with_infinities(&v, BOOTSTRAP_SEED);
            (m, Some((lo, hi)))
        } else {
            (v.first().copied().unwrap_or(f64::NAN), None)
        }
    };
    let label = |what: String| -> String {
        if k > 1 {
            format!("{what}, median over {k} search seeds")
        } else {
            what
        }
    };
    let n = seeds.iter().map(|m| m.methods).max().unwrap_or(0) as f64;
    let slow_label = format!(
        "share of gradient-free methods needing >= {}x BPTT's iterations to J* (or never reaching it)",
        sig(bars.slow_factor)
    );
    let as_fast = "methods as fast as BPTT";
    let check = |what: String,
                 (value, interval): (f64, Option<(f64, f64)>),
                 cmp: Cmp,
                 bar: f64,
                 null: Null| {
        Check::new(label(what), value, cmp, bar, null).map(|c| match interval {
            Some((lo, hi)) => c.with_interval(lo, hi),
            None => c,
        })
    };
    let held = vec![
        check(
            "BPTT-momentum's iterations to J*".into(),
            over(|m| m.bptt),
            Cmp::AtMost,
            bars.fast_iterations,
            Null::new("the initial knots (never)", f64::INFINITY),
        ),
        check(
            slow_label.clone(),
            over(|m| m.slow_share),
            Cmp::AtLeast,
            1.0,
            Null::new(as_fast, 0.0),
        ),
        check(
            slow_label,
            over(|m| m.slow_share),
            Cmp::Above,
            bars.partly_slow_share,
            Null::new(as_fast, 0.0),
        ),
        check(
            "gradient-free methods reaching J* in fewer iterations than BPTT".into(),
            over(|m| m.faster),
            Cmp::AtMost,
            0.0,
            Null::new("every method faster", n.max(1.0)),
        ),
        check(
            "how much farther BPTT's knots swim on the simulator than every method's (m)".into(),
            over(|m| m.swim_margin),
            Cmp::Above,
            0.0,
            Null::new("the farthest method's knots themselves", 0.0),
        ),
    ];
    Rule::gated(vec![], held, Partly::All(vec![0, 2, 3]))
}

/// The measures of every search seed in `search_seeds.csv` (`None` without the table).
pub fn seed_measures(
    dir: &Path,
    bars: &SwimRule,
) -> Result<Option<Vec<(i64, SwimMeasures)>>, Error> {
    let Some(df) = written_csv(dir, "search_seeds.csv")? else {
        return Ok(None);
    };
    let rows = SearchSeedRow::from_frame(&df)
        .map_err(|e| Error::Other(format!("{}: {e}", dir.join("search_seeds.csv").display())))?;
    let mut seeds: Vec<i64> = rows.iter().map(|r| r.seed).collect();
    seeds.dedup();
    let out = seeds
        .into_iter()
        .map(|s| {
            let of = |m: &str| rows.iter().find(|r| r.seed == s && r.method == m);
            let finite = |r: &SearchSeedRow| Some(r.iterations_to_target).filter(|x| x.is_finite());
            let mom = of("bptt_momentum");
            let rivals: Vec<Option<f64>> =
                SEARCHES.iter().filter_map(|m| of(m)).map(finite).collect();
            let rival_swim = SEARCHES
                .iter()
                .filter_map(|m| of(m))
                .map(|r| r.distance_simulator_m)
                .fold(f64::NEG_INFINITY, f64::max);
            let m = swim_measures(
                mom.and_then(finite),
                &rivals,
                mom.map_or(f64::NAN, |r| r.distance_simulator_m),
                rival_swim,
                bars,
            );
            (s, m)
        })
        .collect();
    Ok(Some(out))
}

#[cfg(test)]
mod tests {
    use super::*;

    const BARS: SwimRule = SwimRule {
        target_fraction: 0.5,
        fast_iterations: 30.0,
        slow_factor: 10.0,
        partly_slow_share: 0.5,
    };

    /// (held, partly) of the rule on these facts.
    fn rule(k: Option<f64>, rivals: &[Option<f64>], swim: f64, rival: f64) -> (bool, bool) {
        let v = swim_rule(k, rivals, swim, rival, &BARS).unwrap().verdict();
        (
            v == Verdict::Held,
            matches!(v, Verdict::Held | Verdict::Partly),
        )
    }

    #[test]
    fn bptt_stalling_short_of_the_common_target_is_not_partly_held() {
        // The committed emulator runs: J* = -0.676, which BPTT never reaches in its 20
        // iterations; annealing needs 4526, simplex 17418, hill climbing 254.
        let rivals = [Some(4526.0), Some(17418.0), Some(254.0)];
        assert_eq!(rule(None, &rivals, 0.68, 0.86), (false, false));
        // BPTT reaches it at iteration 25 but only one method of three is 10x slower.
        let rivals = [Some(2000.0), Some(60.0), Some(40.0)];
        assert_eq!(rule(Some(25.0), &rivals, 0.9, 0.8), (false, false));
        // Two methods 10x slower, but one gets there before BPTT.
        let rivals = [Some(2000.0), None, Some(4.0)];
        assert_eq!(rule(Some(5.0), &rivals, 0.9, 0.8), (false, false));
        // Slow enough, but BPTT needs more than 30 iterations.
        assert_eq!(
            rule(Some(31.0), &[None, None, None], 0.9, 0.8),
            (false, false)
        );
    }

    #[test]
    fn bptt_fast_to_the_common_target_with_slow_rivals_holds() {
        // The committed DAgger-net runs: J* reached by BPTT at 3, annealing 297, simplex
        // 3474, hill climbing 36; BPTT's knots swim 0.959 m, the others' at most 0.797 m.
        let rivals = [Some(297.0), Some(3474.0), Some(36.0)];
        assert_eq!(rule(Some(3.0), &rivals, 0.959, 0.797), (true, true));
        // Swimming less far on the simulator leaves partly.
        assert_eq!(rule(Some(3.0), &rivals, 0.7, 0.797), (false, true));
        // Two of three slow, none faster: partly.
        let rivals = [Some(297.0), None, Some(20.0)];
        assert_eq!(rule(Some(3.0), &rivals, 0.959, 0.797), (false, true));
    }

    /// Over several search seeds each check reads the median with its interval: five seeds
    /// alike hold; one seed of five where BPTT never reaches J* (a "never" counts as the
    /// slowest) leaves the medians passing but their intervals reaching that seed's values
    /// (three or more of five resampled draws of it happen more than 2.5% of the time), so the
    /// verdict is inconclusive; one seed alone has no interval.
    #[test]
    fn over_search_seeds_the_rule_reads_medians_and_their_intervals() {
        let m = |bptt: Option<f64>, margin: f64| {
            swim_measures(bptt, &[Some(300.0), None, Some(3000.0)], margin, 0.0, &BARS)
        };
        let mut seeds = vec![m(Some(4.0), 0.2); 5];
        let r = swim_rule_over(&seeds, &BARS).unwrap();
        assert_eq!(r.verdict(), Verdict::Held, "{}", r.table());
        assert!(r.table().contains("median over 5 search seeds"));
        seeds[4] = m(None, 0.2);
        let r = swim_rule_over(&seeds, &BARS).unwrap();
        assert_eq!(r.verdict(), Verdict::Inconclusive, "{}", r.table());
        assert!(r.table().contains("4.00 [4.00-inf]"), "{}", r.table());
        // Every seed's knots swimming less far on the simulator: not held, whatever the rest.
        let behind = vec![m(Some(4.0), -0.3); 5];
        let r = swim_rule_over(&behind, &BARS).unwrap();
        assert_eq!(r.verdict(), Verdict::Partly, "{}", r.table());
        let one = swim_rule_over(&seeds[..1], &BARS).unwrap();
        assert!(!one.table().contains('['), "{}", one.table());
    }

    #[test]
    fn the_common_target_lies_halfway_and_is_reached_at_the_first_iteration_below_it() {
        assert!((common_target(0.242, -1.594, &BARS) - -0.676).abs() < 1e-12);
        let (k, j) = ([0.0, 1.0, 2.0, 3.0], [0.2, 0.0, -0.7, -0.8]);
        assert_eq!(iterations_to(&k, &j, -0.676), Some(2.0));
        assert_eq!(iterations_to(&k, &j, -1.0), None);
    }
}
