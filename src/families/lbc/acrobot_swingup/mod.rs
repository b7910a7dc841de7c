//! `lbc_acrobot_swingup` (LBC §6.2, Fig. 7): DDP swing-ups of the torque-limited acrobot to the
//! handstand from two start states, minimizing ½∫uᵀu plus a quadratic terminal cost; LQR
//! trackers with the quadratic value functions of eq. 12; from a third start, compare tracker 1,
//! tracker 2, the naive blend (as the paper's sum u₁ + u₂ and as the average) and linear Bellman
//! combination (w = 1); then a sweep over a grid of start states, judged on the starts where
//! both trackers fail (the paper's premise), and a sweep over the temperature λ.
//!
//! - **Same family.** Each swing-up is solved from several initial guesses (sinusoids, then
//!   warm starts from the other swing-up's best tape); the lowest cost is kept. The output
//!   records the first-swing sign (direction of the shoulder's first excursion beyond
//!   [`FIRST_SWING`]), the sign of the first hip-torque lobe, the cost ratio to the cheaper
//!   swing-up and the correlation of the tapes, so that the two components are seen to be
//!   temporally aligned (LBC §3, §3.4).
//! - **λ from a noise model.** With the cost ½uᵀRu (R = 1 here, eq. 8) the linear Bellman
//!   equation holds when the control-channel noise has covariance λR⁻¹; the spec states the
//!   hip-torque noise intensity σ (N·m·√s), so λ = σ²R, used in z = exp(−v̂/λ).
//! - **Torque limits** |τ| ≤ `torque_limit` in DDP (box constraints) and in every closed loop.
//! - **Value model.** The trackers' gains and quadratic value functions come from the LQR
//!   recursion (first-order dynamics) or from DDP's backward pass with the second-order
//!   dynamics terms (LBC §5.2), chosen by `value_model`; the sweep is also run with the other
//!   model (`value_model.csv`, judged by the same rule in the report, not in the verdict).
//!
//! Tables: `final` (policy, final_distance, control_cost, final_theta1, final_theta2,
//! max_abs_torque, mean_entropy) with rows `tracker1`, `tracker2`, `naive`, `lbc`, `naive_sum`;
//! `trajectories` (policy, t, theta1, theta2, omega1, omega2, u, alpha1, alpha_entropy);
//! `swingups` (one row per optimized swing-up, with its family markers); `swingup_candidates`
//! (every DDP run); `ddp_trace` (of the kept runs); `sweep` (theta1_deg, theta2_deg, policy,
//! final_distance, control_cost, success, max_abs_torque, mean_entropy); `lambda_sweep`;
//! `value_model` (value_model, theta1_deg, theta2_deg, policy, final_distance, success: the
//! sweep's policies with trackers of both value models); `showcase` (policy, t, theta1,
//! theta2: tracker 1, tracker 2 and LBC from the first sweep start LBC rescues, for the GIF).
//!
//! Here: the parameters and their validation; `setup` (swing-ups, trackers, rollouts), `job`,
//! `rows` (the row of each table read back), `verdict`, `figures` and `report` hold the rest.

mod figures;
mod job;
mod report;
mod rows;
mod setup;
mod verdict;

pub use setup::{distance_to_handstand, first_swing_sign, first_torque_sign, tape_correlation};
pub use verdict::{
    choose_scale, judge_test_start, premise_checks, sweep_checks, sweep_counts, sweep_rule,
    SweepCounts,
};

use crate::experiment::output::Tables;
use crate::experiment::plot::FigureSink;
use crate::experiment::report::Findings;
use crate::experiment::resolve::{distinct, ensure, positive, ParamError, Validate};
use crate::experiment::{Error, Family};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The family.
pub struct LbcAcrobot;

/// Control weight R of the running cost ½uᵀRu: the paper's ½uᵀu (eq. 8, §6.2).
pub const CONTROL_WEIGHT: f64 = 1.0;

/// The shoulder's first swing is the sign of its first excursion beyond this from the start (rad).
pub const FIRST_SWING: f64 = 0.1;

/// Parameters of `lbc_acrobot_swingup`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Duration of each swing-up (s).
    pub horizon: f64,
    /// Time step of the RK4 discretization (s).
    pub dt: f64,
    /// Start states of the optimized swing-ups (θ1, θ2 in degrees, ω1, ω2 in deg/s): two.
    pub starts: Vec<[f64; 4]>,
    /// The test start state (degrees, deg/s).
    pub test_start: [f64; 4],
    /// Diagonal of the terminal weight Q_f about the handstand (π/2, 0, 0, 0).
    pub terminal_weights: [f64; 4],
    /// `ilqr` or `full` (second-order DDP).
    pub variant: String,
    /// DDP iteration limit.
    pub max_iterations: usize,
    /// Initial guesses u(t) = a sin(ω t + φ), each `[a (N·m), ω (rad/s), φ (rad)]`; every
    /// swing-up is solved from each, and the lowest cost is kept.
    pub init_guesses: Vec<[f64; 3]>,
    /// Also solve each swing-up warm-started from the other swing-up's best tape.
    pub warm_start: bool,
    /// Hip torque limit |τ| ≤ this (N·m), in DDP and in every closed loop.
    pub torque_limit: f64,
    /// Intensity σ of the white hip-torque noise (N·m·√s); λ = σ² R (eq. 8: noise λR⁻¹).
    pub torque_noise: f64,
    /// Temperatures λ of the λ sweep (the spec's λ = σ²R is the one judged).
    pub lambda_sweep: Vec<f64>,
    /// Two swing-ups are of the same family when their first swings agree and the costlier
    /// costs at most this multiple of the cheaper.
    pub max_cost_ratio: f64,
    /// Fixed weights w of the combination (1 = coordination).
    pub weights: Vec<f64>,
    /// A policy succeeds when it ends closer than this to the handstand (state-space norm).
    pub success_distance: f64,
    /// Held needs LBC to succeed on at least this fraction of the starts where both trackers
    /// fail (and more of them than either naive blend, and overall at least as many starts as
    /// the better tracker).
    pub held_fraction: f64,
    /// Partly needs LBC to succeed on at least this fraction of them.
    pub partly_fraction: f64,
    /// Range of θ1 (degrees) of the start-state sweep.
    pub sweep_theta1: [f64; 2],
    /// Range of θ2 (degrees) of the start-state sweep.
    pub sweep_theta2: [f64; 2],
    /// Grid points per axis of the sweep.
    pub sweep_points: usize,
    /// Value model of the trackers the verdict judges: `lqr` (first-order dynamics, the
    /// default) or `ddp` (with DDP's second-order dynamics terms, LBC §5.2); the other model
    /// is run over the same sweep for comparison.
    #[serde(default = "default_value_model")]
    pub value_model: String,
    /// Scales of the trackers' LQR terminal weights tried, in the order listed: the
    /// trackers' gains and value functions come from the LQR recursion with Q_f × scale (the
    /// swing-ups themselves keep `terminal_weights`); the run uses the first scale at which
    /// each tracker alone fails from the test start ([`choose_scale`]), or the first listed
    /// when none does (premise not reproduced). Empty: scale 1 alone, as before.
    #[serde(default)]
    pub tracker_weight_scales: Vec<f64>,
}

fn default_value_model() -> String {
    VALUE_MODELS[0].into()
}

/// The value models compared, by spec name: the LQR recursion and DDP's backward pass.
pub const VALUE_MODELS: [&str; 2] = ["lqr", "ddp"];

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        positive("horizon", self.horizon)?;
        positive("dt", self.dt)?;
        ensure(
            self.horizon >= 2.0 * self.dt,
            "horizon",
            "must cover at least two steps",
        )?;
        ensure(
            self.starts.len() == 2,
            "starts",
            "need exactly two swing-ups (tracker 1 and tracker 2)",
        )?;
        ensure(
            self.weights.len() == self.starts.len(),
            "weights",
            format!("need one weight per start ({})", self.starts.len()),
        )?;
        for (i, w) in self.weights.iter().enumerate() {
            positive(&format!("weights[{i}]"), *w)?;
        }
        for (i, w) in self.terminal_weights.iter().enumerate() {
            positive(&format!("terminal_weights[{i}]"), *w)?;
        }
        ensure(
            self.variant == "ilqr" || self.variant == "full",
            "variant",
            format!("unknown DDP variant `{}` (ilqr, full)", self.variant),
        )?;
        ensure(
            self.max_iterations >= 1,
            "max_iterations",
            "must be at least 1",
        )?;
        ensure(
            !self.init_guesses.is_empty(),
            "init_guesses",
            "need at least one initial guess",
        )?;
        for (i, g) in self.init_guesses.iter().enumerate() {
            ensure(
                g.iter().all(|v| v.is_finite()),
                &format!("init_guesses[{i}]"),
                "must be finite",
            )?;
        }
        positive("torque_limit", self.torque_limit)?;
        positive("torque_noise", self.torque_noise)?;
        for (i, l) in self.lambda_sweep.iter().enumerate() {
            positive(&format!("lambda_sweep[{i}]"), *l)?;
        }
        distinct("lambda_sweep", &self.lambda_sweep)?;
        ensure(
            self.max_cost_ratio >= 1.0,
            "max_cost_ratio",
            "must be at least 1",
        )?;
        positive("success_distance", self.success_distance)?;
        ensure(
            self.held_fraction > 0.0 && self.held_fraction <= 1.0,
            "held_fraction",
            "must be in (0, 1]",
        )?;
        ensure(
            self.partly_fraction > 0.0 && self.partly_fraction <= self.held_fraction,
            "partly_fraction",
            "must be in (0, held_fraction]",
        )?;
        ensure(self.sweep_points >= 1, "sweep_points", "must be at least 1")?;
        ensure(
            VALUE_MODELS.contains(&self.value_model.as_str()),
            "value_model",
            format!("unknown value model `{}` (lqr, ddp)", self.value_model),
        )?;
        for (i, v) in self.tracker_weight_scales.iter().enumerate() {
            positive(&format!("tracker_weight_scales[{i}]"), *v)?;
        }
        distinct("tracker_weight_scales", &self.tracker_weight_scales)?;
        for v in self.starts.iter().flatten().chain(&self.test_start) {
            ensure(v.is_finite(), "starts", "must be finite")?;
        }
        Ok(())
    }
}

impl Family for LbcAcrobot {
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "filmstrip",
            "each policy's acrobot pose every 0.5 s from the test start (the paper's Fig. 7): tracker 1, tracker 2, the naive blend, LBC and the naive sum, frames spaced along x for reading.",
        ),
        (
            "final_pose",
            "from the test start: the final poses, the shoulder angle over time and LBC's weight of tracker 1 with the entropy of α.",
        ),
        (
            "sweep",
            "final distance to the handstand from each start of the sweep (shoulder and elbow start angles), per policy: darker is closer.",
        ),
        (
            "lambda",
            "LBC over its temperature λ across the start sweep: success on all starts and on those where both trackers fail, and the mean entropy of α.",
        ),
        (
            "swingup",
            "tracker 1, tracker 2 and LBC side by side from the first sweep start where both trackers fail and LBC succeeds (else the test start), in real time.",
        ),
    ];
    const KIND: &'static str = "lbc_acrobot_swingup";
    type Params = Params;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        figures::figures(fig, tables)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        report::report(dir)
    }
}

#[cfg(test)]
mod tests {
    use super::setup::{mode, radians, Candidate, POLICIES};
    use super::*;
    use crate::bellman::combine::{BlendMode, TrackerBlend};
    use crate::control::ddp::DdpSolution;
    use crate::control::Rk4Map;
    use crate::physics::acrobot::Acrobot;
    use std::sync::OnceLock;

    fn params() -> Params {
        Params {
            horizon: 4.0,
            dt: 0.02,
            starts: vec![[-90.0, 0.0, 0.0, 0.0], [-110.0, -20.0, 0.0, 0.0]],
            test_start: [-105.0, -15.0, 0.0, 0.0],
            terminal_weights: [1e4, 1e4, 1e3, 1e3],
            variant: "full".into(),
            max_iterations: 150,
            init_guesses: vec![[1.0, 3.0, 0.0], [-1.0, 3.0, 0.0], [3.0, 2.0, 0.0]],
            warm_start: true,
            torque_limit: 9.81,
            torque_noise: 1.0,
            lambda_sweep: vec![],
            max_cost_ratio: 3.0,
            weights: vec![1.0, 1.0],
            success_distance: 0.3,
            held_fraction: 0.5,
            partly_fraction: 0.25,
            sweep_theta1: [-125.0, -75.0],
            sweep_theta2: [-40.0, 20.0],
            sweep_points: 1,
            value_model: "lqr".into(),
            tracker_weight_scales: vec![],
        }
    }

    /// The swing-ups of [`params`], solved once for all tests.
    fn solved() -> &'static (Params, Vec<Candidate>, Vec<usize>) {
        static CELL: OnceLock<(Params, Vec<Candidate>, Vec<usize>)> = OnceLock::new();
        CELL.get_or_init(|| {
            let p = params();
            let map = Rk4Map::new(Acrobot::default(), p.dt).unwrap();
            let (c, b) = p.swing_ups(&map).unwrap();
            (p, c, b)
        })
    }

    #[test]
    fn kept_swing_ups_are_one_aligned_family_that_reaches_the_handstand() {
        let (p, cands, kept) = solved();
        let (a, b) = (&cands[kept[0]].sol, &cands[kept[1]].sol);
        assert_eq!(cands[kept[0]].start, 0);
        assert_eq!(cands[kept[1]].start, 1);
        let (sa, sb) = (first_swing_sign(&a.x), first_swing_sign(&b.x));
        assert!(sa != 0 && sa == sb, "first swings {sa} and {sb}");
        let ratio = a.cost.max(b.cost) / a.cost.min(b.cost);
        assert!(ratio <= p.max_cost_ratio, "cost ratio {ratio}");
        // Temporally aligned: the hip-torque tapes move together (not by construction).
        let r = tape_correlation(&a.u, &b.u);
        assert!(r > 0.5, "tape correlation {r}");
        for s in [a, b] {
            let d = distance_to_handstand(s.x[s.u.len()].as_slice());
            assert!(
                d < p.success_distance,
                "swing-up ends {d} from the handstand"
            );
            // DDP respects the box constraint.
            assert!(s.u.iter().all(|u| u[0].abs() <= p.torque_limit + 1e-12));
        }
        // Every kept run is no costlier than any other run of its start in the same family.
        for (i, c) in cands.iter().enumerate() {
            let k = kept[c.start];
            if first_swing_sign(&c.sol.x) == sa {
                assert!(
                    cands[k].sol.cost <= c.sol.cost,
                    "run {i} is cheaper than the kept one"
                );
            }
        }
    }

    #[test]
    fn every_closed_loop_respects_the_torque_limit() {
        let (p, cands, kept) = solved();
        let map = Rk4Map::new(Acrobot::default(), p.dt).unwrap();
        let sols: Vec<&DdpSolution> = kept.iter().map(|&k| &cands[k].sol).collect();
        let trackers = p.trackers(&map, &sols, "lqr", 1.0).unwrap();
        let limits = [p.torque_limit];
        let mut saturated = 0;
        for start in [
            [-125.0, -40.0, 0.0, 0.0],
            [-75.0, 20.0, 0.0, 0.0],
            p.test_start,
        ] {
            for i in 0..POLICIES.len() {
                let blend = TrackerBlend {
                    trackers: &trackers,
                    weights: p.weights.clone(),
                    lambda: p.lambda(),
                    mode: mode(i),
                    limits: Some(&limits),
                };
                let r = p.run_policy(&map, &blend, &radians(&start)).unwrap();
                assert!(!r.us.is_empty());
                let m = r.max_abs_torque();
                assert!(m <= p.torque_limit, "{} from {start:?}: {m}", POLICIES[i]);
                saturated += (m == p.torque_limit) as usize;
            }
        }
        // The limit binds: far from the references the LQR feedback asks for more.
        assert!(saturated > 0);
    }

    #[test]
    fn alpha_is_uniform_as_lambda_grows_and_a_switch_as_it_shrinks_in_closed_loop() {
        let (p, cands, kept) = solved();
        let map = Rk4Map::new(Acrobot::default(), p.dt).unwrap();
        let sols: Vec<&DdpSolution> = kept.iter().map(|&k| &cands[k].sol).collect();
        let trackers = p.trackers(&map, &sols, "lqr", 1.0).unwrap();
        let limits = [p.torque_limit];
        let x0 = radians(&p.test_start);
        let run = |m: BlendMode, lambda: f64| {
            p.run_policy(&map, &p.blend(&trackers, &limits, m, lambda), &x0)
                .unwrap()
        };
        let (small, large) = (run(BlendMode::Lbc, 1e-3), run(BlendMode::Lbc, 1e15));
        let spec = run(BlendMode::Lbc, p.lambda());
        let (hs, hm, hl) = (
            small.mean_entropy(),
            spec.mean_entropy(),
            large.mean_entropy(),
        );
        assert!(hs < 0.1 && hs < 0.5 * hm && hm < hl, "{hs} {hm} {hl}");
        assert!(hl > 1.0 - 1e-9, "{hl}");
        // At large λ LBC is the naive average (w = 1: α = 1/2), step for step.
        let naive = run(BlendMode::Naive, p.lambda());
        assert!(naive.diverged.is_none() && large.diverged.is_none());
        for (a, b) in large.xs.iter().zip(&naive.xs) {
            assert!((a - b).amax() < 1e-4, "{a} vs {b}");
        }
        // At small λ it is a switch: α₁ within 0.01 of 0 or 1 over the first 80 % of the
        // horizon (near its end the remaining costs, hence the values, converge).
        let n = small.alpha1.len() * 4 / 5;
        let mixed = small.alpha1[..n]
            .iter()
            .filter(|a| (0.01..0.99).contains(*a))
            .count();
        assert_eq!(mixed, 0, "{:?}", &small.alpha1[..n]);
    }

    #[test]
    fn value_models_build_different_trackers_and_the_rule_grades_counts() {
        let (p, cands, kept) = solved();
        let map = Rk4Map::new(Acrobot::default(), p.dt).unwrap();
        let sols: Vec<&DdpSolution> = kept.iter().map(|&k| &cands[k].sol).collect();
        let lqr = p.trackers(&map, &sols, "lqr", 1.0).unwrap();
        let ddp = p.trackers(&map, &sols, "ddp", 1.0).unwrap();
        // Same references and remaining cost; the second-order terms change the gains.
        let gap = (0..lqr[0].gains.len())
            .map(|k| (lqr[0].gains.matrix(k) - ddp[0].gains.matrix(k)).amax())
            .fold(0.0, f64::max);
        assert!(gap > 1e-3, "gains differ by {gap}");
        let (a, b) = (lqr[0].value_ref[0], ddp[0].value_ref[0]);
        assert!((a - b).abs() <= 1e-9 * a.abs(), "{a} vs {b}");
        let mut bad = params();
        bad.value_model = "ilqr".into();
        let e = bad.validate().unwrap_err();
        assert!(format!("{e}").contains("value_model"), "{e}");
        assert_eq!(params().other_model(), "ddp");
        // The rule: held, partly (a quarter rescued, as many as naive), and not held.
        let counts = |successes: Vec<usize>, rescued: Vec<usize>| SweepCounts {
            starts: 10,
            both_fail: 4,
            successes,
            rescued,
        };
        use crate::experiment::report::Verdict;
        let v = |c: &SweepCounts, same: bool| sweep_rule(c, same, 0.5, 0.25).map(|r| r.verdict());
        let held = counts(vec![5, 6, 3, 8, 2], vec![0, 0, 1, 2, 1]);
        assert_eq!(v(&held, true), Some(Verdict::Held));
        assert_eq!(v(&held, false), Some(Verdict::PremiseNotReproduced));
        let one = counts(vec![5, 6, 3, 6, 2], vec![0, 0, 1, 1, 1]);
        assert_eq!(v(&one, true), Some(Verdict::Partly));
        let none = counts(vec![5, 6, 3, 6, 2], vec![0, 0, 1, 0, 1]);
        assert_eq!(v(&none, true), Some(Verdict::NotHeld));
    }

    #[test]
    fn sweep_counts_judge_on_the_starts_where_both_trackers_fail() {
        // Columns: tracker1, tracker2, naive, lbc, naive_sum.
        let ok = vec![
            vec![true, false, false, true, false],
            vec![false, false, false, true, true],
            vec![false, false, true, false, false],
            vec![false, true, false, false, false],
        ];
        let c = sweep_counts(&ok);
        assert_eq!(c.starts, 4);
        assert_eq!(c.both_fail, 2);
        assert_eq!(c.successes, vec![1, 1, 1, 2, 1]);
        assert_eq!(c.rescued, vec![0, 0, 1, 1, 1]);
    }

    #[test]
    fn lambda_comes_from_the_noise_model_and_validation_names_the_key() {
        let mut p = params();
        p.torque_noise = 3.0;
        assert!((p.lambda() - 9.0 * CONTROL_WEIGHT).abs() < 1e-12);
        p.torque_limit = 0.0;
        let e = p.validate().unwrap_err();
        assert!(format!("{e}").contains("torque_limit"), "{e}");
        let mut p = params();
        p.lambda_sweep = vec![1.0, -1.0];
        let e = p.validate().unwrap_err();
        assert!(format!("{e}").contains("lambda_sweep[1]"), "{e}");
        // Tracker weight scales: positive, finite, distinct; left out, scale 1 alone.
        for (bad, key) in [
            (vec![1.0, 0.0], "tracker_weight_scales[1]"),
            (vec![f64::NAN], "tracker_weight_scales[0]"),
            (vec![1.0, f64::INFINITY], "tracker_weight_scales[1]"),
            (vec![1.0, 0.1, 1.0], "tracker_weight_scales[2]"),
        ] {
            let p = Params {
                tracker_weight_scales: bad,
                ..params()
            };
            let e = p.validate().unwrap_err();
            assert_eq!(e.key, key, "{e}");
        }
        let p = Params {
            tracker_weight_scales: vec![1.0, 0.1, 0.01],
            ..params()
        };
        assert!(p.validate().is_ok());
        assert_eq!(params().scales(), vec![1.0]);
        let json = serde_json::to_value(params()).unwrap();
        let mut obj = json.as_object().unwrap().clone();
        obj.remove("tracker_weight_scales");
        let back: Params = serde_json::from_value(obj.into()).unwrap();
        assert!(back.tracker_weight_scales.is_empty());
    }

    #[test]
    fn the_scale_rule_takes_the_first_scale_where_each_tracker_fails_from_the_test_start() {
        let s = 0.3;
        // (scale, tracker 1 distance, tracker 2 distance)
        let trials = [
            (1.0, 0.5, 0.05),
            (0.1, 0.4, 0.3),
            (0.01, f64::INFINITY, 2.0),
        ];
        // At 0.1 tracker 2 ends exactly at the success distance: a failure (success is <).
        assert_eq!(choose_scale(&trials, s), Some(1));
        assert_eq!(choose_scale(&trials[2..], s), Some(0));
        // A diverged tracker (NaN or infinite distance) fails.
        assert_eq!(choose_scale(&[(1.0, f64::NAN, 0.5)], s), Some(0));
        // One tracker succeeds at every scale: premise not reproduced.
        assert_eq!(choose_scale(&[(1.0, 0.5, 0.05), (0.1, 0.1, 0.9)], s), None);
        assert_eq!(choose_scale(&[], s), None);
    }

    #[test]
    fn the_test_start_claim_needs_lbc_to_succeed_and_beat_both_naive_blends() {
        let s = 0.3;
        assert!(judge_test_start(0.1, 0.5, 0.4, s));
        // LBC succeeds but the naive sum is closer: no.
        assert!(!judge_test_start(0.2, 0.5, 0.1, s));
        // LBC closest but not a success: no.
        assert!(!judge_test_start(0.35, 0.5, 0.9, s));
        // A diverged LBC fails; a diverged naive blend is beaten.
        assert!(!judge_test_start(f64::INFINITY, 0.5, 0.9, s));
        assert!(judge_test_start(0.1, f64::INFINITY, f64::NAN, s));
    }
}
