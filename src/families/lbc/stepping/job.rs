//! `lbc_stepping`'s job: the start, the step targets, the DDP steps and their trackers, the
//! controllers run on the simulator, and the walk over gaps.

use super::rows::{AverageRow, ComponentRow, MotionRow, StepRow, WalkStepRow, WeightRow};
use super::Params;
use crate::bellman::combine::{BlendMode, TrackerBlend};
use crate::control::ddp::DdpSolution;
use crate::control::lqr::TrackingController;
use crate::control::simbicon::{applet_start, Gait, Simbicon};
use crate::control::{QuadraticCost, Rk4Map, StateCost};
use crate::experiment::output::{Table, Tables};
use crate::experiment::rows::table_of;
use crate::experiment::{other, Error, Job, RunContext};
use crate::families::lbc::{optimized_tracker, projected_weights, rule_table, scale_lambda};
use crate::physics::biped::point::{LEFT_HEEL, RIGHT_HEEL, RIGHT_TOE};
use crate::physics::biped::{Biped, Side, DOF, FOOT_HEEL, FOOT_TOE, TORQUES};
use crate::physics::linearize::FiniteDifference;
use crate::physics::{check_finite, Dynamics, IntegratorKind, Model, Simulator};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use std::time::Instant;

/// DDP's discrete dynamics: one RK4 step of the biped per knot, Jacobians by differences.
type Map = Rk4Map<FiniteDifference<Biped>>;

/// Step length (right heel x − left heel x, m) and the right heel's height above the ground
/// (m) at state `x`.
pub fn step_length(b: &Biped, x: &[f64]) -> (f64, f64) {
    let p = b.contact_points(&x[..DOF]);
    let h = b.terrain.height_slope(p[RIGHT_HEEL][0]).0;
    (p[RIGHT_HEEL][0] - p[LEFT_HEEL][0], p[RIGHT_HEEL][1] - h)
}

/// The terminal target of a step of `length`: state `end` (a heel-strike state) with the pelvis
/// position and both hip angles moved, each ankle turned back by its hip's change so the feet
/// keep their angles, until the left heel stays where it is in `end` and the right heel lies on
/// level ground `length` ahead of it; velocities, torso and knees unchanged. Newton's method on
/// the four heel coordinates.
pub fn step_target(b: &Biped, end: &[f64], length: f64) -> Result<Vec<f64>, Error> {
    let left = b.contact_points(&end[..DOF])[LEFT_HEEL];
    let goal = [left[0], left[1], left[0] + length, 0.0];
    let resid = |x: &[f64]| {
        let p = b.contact_points(&x[..DOF]);
        [
            p[LEFT_HEEL][0] - goal[0],
            p[LEFT_HEEL][1] - goal[1],
            p[RIGHT_HEEL][0] - goal[2],
            p[RIGHT_HEEL][1] - goal[3],
        ]
    };
    // Unknowns: pelvis x, y, left hip (ankle compensating), right hip (likewise).
    let (left, right) = (Biped::leg(Side::Left), Biped::leg(Side::Right));
    let nudge = |x: &mut [f64], i: usize, d: f64| match i {
        0 | 1 => x[i] += d,
        2 => {
            x[left.hip] += d;
            x[left.ankle] -= d;
        }
        _ => {
            x[right.hip] += d;
            x[right.ankle] -= d;
        }
    };
    let mut x = end.to_vec();
    for _ in 0..50 {
        let r = resid(&x);
        if r.iter().all(|v| v.abs() < 1e-12) {
            return Ok(x);
        }
        let mut j = DMatrix::zeros(4, 4);
        for i in 0..4 {
            let mut xp = x.clone();
            nudge(&mut xp, i, 1e-7);
            let rp = resid(&xp);
            for k in 0..4 {
                j[(k, i)] = (rp[k] - r[k]) / 1e-7;
            }
        }
        let d = j
            .lu()
            .solve(&DVector::from_row_slice(&r))
            .ok_or_else(|| other(format!("step target {length} m: singular leg Jacobian")))?;
        for i in 0..4 {
            nudge(&mut x, i, -d[i]);
        }
    }
    Err(other(format!(
        "step target {length} m: the legs cannot place the heels (Newton did not converge)"
    )))
}

/// The reached step length: the right heel at `end` from the left (stance) heel at `start`
/// (m), the measure of `targets.csv` and `components.csv` alike.
pub fn reached_length(b: &Biped, start: &[f64], end: &[f64]) -> f64 {
    b.contact_points(&end[..DOF])[RIGHT_HEEL][0] - b.contact_points(&start[..DOF])[LEFT_HEEL][0]
}

/// SIMBICON's walk from the applet's start, at its first left heel strike after `warmup` s.
pub(super) fn start_state(b: &Biped, gait: &Gait, warmup: f64) -> Result<Vec<f64>, Error> {
    let dt = b.default_dt();
    let mut sim = Simulator::new(b.clone(), IntegratorKind::Rk4);
    let mut c = Simbicon::new(gait.clone(), 0);
    let mut x = applet_start(b, 0.0);
    let mut u = vec![0.0; TORQUES];
    let mut t = 0.0;
    while t < warmup + 5.0 {
        let before = c.state;
        c.control(b, &x, dt, &mut u);
        if c.state != before && c.state == 0 && t >= warmup {
            return Ok(x);
        }
        sim.step(&mut x, &u, dt);
        t += dt;
        if b.fallen(&x) {
            return Err(other(format!("the start's SIMBICON walk fell at {t:.2} s")));
        }
    }
    Err(other("the start's SIMBICON walk made no left heel strike"))
}

/// SIMBICON's step from `x0` on DDP's map until the right heel strikes: states x_0..x_N and
/// torques u_0..u_{N−1}.
fn simbicon_step(
    b: &Biped,
    map: &Map,
    gait: &Gait,
    x0: &[f64],
) -> Result<(Vec<DVector<f64>>, Vec<DVector<f64>>), Error> {
    let mut ws = map.workspace();
    let mut c = Simbicon::new(gait.clone(), 0);
    let mut x = DVector::from_row_slice(x0);
    let mut next = x.clone();
    let mut u = vec![0.0; TORQUES];
    let (mut xs, mut us) = (vec![x.clone()], Vec::new());
    while (us.len() as f64) * map.dt < 2.0 {
        let before = c.state;
        c.control(b, x.as_slice(), map.dt, &mut u);
        if c.state != before && c.state == 2 {
            return Ok((xs, us));
        }
        let uu = DVector::from_row_slice(&u);
        map.step(&x, &uu, &mut next, &mut ws);
        std::mem::swap(&mut x, &mut next);
        xs.push(x.clone());
        us.push(uu);
    }
    Err(other("SIMBICON's step from the start did not end in 2 s"))
}

/// One controller's step on the simulator.
#[derive(Debug, Clone, Default)]
pub(super) struct StepRun {
    /// Reached step length (m): the right heel at the step's end from the left heel at its
    /// start.
    pub reached: f64,
    /// Whether the right heel is within 1 cm of the ground at the end.
    pub landed: bool,
    /// Whether the body fell during the step or SIMBICON's walking after it.
    pub fell: bool,
    /// ½∫uᵀRu dt over the step.
    pub effort: f64,
    /// The state at every knot (for the walk's motion), and α_short at every knot.
    pub states: Vec<Vec<f64>>,
    /// (see `states`)
    pub alpha_short: Vec<f64>,
}

/// What the run builds once: the body, the map, the start, the horizon and the cost pieces.
struct Setup {
    body: Biped,
    map: Map,
    x0: Vec<f64>,
    /// SIMBICON's step from the start: the average trajectory and DDP's initial torques.
    nominal_x: Vec<DVector<f64>>,
    nominal_u: Vec<DVector<f64>>,
    q_final: DMatrix<f64>,
    q_run: DMatrix<f64>,
    r: DMatrix<f64>,
    /// The scale of the average-trajectory term in `q_run`.
    average_scale: f64,
}

impl Params {
    /// The body, DDP's map, the start, SIMBICON's step from it and the objective's weights
    /// with the average-trajectory term at scale `average_scale`.
    fn setup_with(&self, average_scale: f64) -> Result<Setup, Error> {
        let body = Biped::default();
        let map = Rk4Map::new(FiniteDifference::new(body.clone()), self.knot_dt).map_err(other)?;
        let x0 = start_state(&body, &self.gait, self.warmup_s)?;
        let (nominal_x, nominal_u) = simbicon_step(&body, &map, &self.gait, &x0)?;
        let d = self.cost.terminal_diagonal(DOF);
        let horizon = nominal_u.len() as f64 * self.knot_dt;
        let mut run = d.clone();
        run[0] = 0.0;
        run[DOF..].iter_mut().for_each(|v| *v = 0.0);
        run.iter_mut().for_each(|v| *v *= average_scale / horizon);
        Ok(Setup {
            body,
            map,
            x0,
            nominal_x,
            nominal_u,
            q_final: DMatrix::from_diagonal(&DVector::from_vec(d)),
            q_run: DMatrix::from_diagonal(&DVector::from_vec(run)),
            r: self.cost.control_weight(TORQUES),
            average_scale,
        })
    }
}

impl Setup {
    fn horizon(&self) -> usize {
        self.nominal_u.len()
    }

    fn target(&self, length: f64) -> Result<DVector<f64>, Error> {
        let end = self.nominal_x[self.horizon()].as_slice();
        Ok(DVector::from_vec(step_target(&self.body, end, length)?))
    }

    fn cost(&self, target: DVector<f64>) -> QuadraticCost {
        QuadraticCost {
            dt: self.map.dt,
            r: self.r.clone(),
            state: Some(StateCost {
                weight: self.q_run.clone(),
                reference: self.nominal_x[..self.horizon()].to_vec(),
            }),
            q_final: self.q_final.clone(),
            x_final: target,
        }
    }

    /// DDP step to `length` and its tracker, with the seconds both took.
    fn optimize(&self, p: &Params, length: f64) -> Result<Solved, Error> {
        let cost = self.cost(self.target(length)?);
        let (solution, tracker, seconds) = optimized_tracker(
            &self.map,
            &cost,
            &self.x0,
            &self.nominal_u,
            p.torque_limit,
            p.max_iterations,
            p.tol_cost,
        )?;
        Ok(Solved {
            solution,
            tracker,
            seconds,
        })
    }

    /// Runs `blend` on the simulator from `x0` (stance on the left) for the step's knots, the
    /// control held over each knot's `substeps`, then SIMBICON for `continue_s` seconds.
    fn execute(
        &self,
        p: &Params,
        blend: &TrackerBlend,
        x0: &[f64],
        continue_s: f64,
        keep_states: bool,
    ) -> Result<StepRun, Error> {
        let b = &self.body;
        let sim_dt = p.knot_dt / p.substeps as f64;
        let mut sim = Simulator::new(b.clone(), IntegratorKind::Rk4);
        let mut x = x0.to_vec();
        let n = blend.trackers.len();
        let (mut u, mut ui, mut alpha) = (vec![0.0; TORQUES], vec![0.0; TORQUES], vec![0.0; n]);
        let mut run = StepRun::default();
        for k in 0..self.horizon() {
            blend
                .control(&x, k, &mut u, &mut alpha, &mut ui)
                .map_err(other)?;
            if keep_states {
                run.states.push(x.clone());
            }
            run.alpha_short.push(alpha[0]);
            let ru: f64 = (0..TORQUES).map(|i| u[i] * u[i] * self.r[(i, i)]).sum();
            run.effort += 0.5 * ru * p.knot_dt;
            for s in 0..p.substeps {
                sim.step(&mut x, &u, sim_dt);
                check_finite(
                    "biped",
                    k * p.substeps + s,
                    (k * p.substeps + s) as f64 * sim_dt,
                    &x,
                )
                .map_err(other)?;
            }
            if b.fallen(&x) {
                run.fell = true;
                break;
            }
        }
        if keep_states {
            run.states.push(x.clone());
        }
        let pts = b.contact_points(&x[..DOF]);
        let height = pts[RIGHT_HEEL][1] - b.terrain.height_slope(pts[RIGHT_HEEL][0]).0;
        run.reached = reached_length(b, x0, &x);
        run.landed = !run.fell && height.abs() < 0.01;
        if !run.fell && continue_s > 0.0 {
            run.fell = walks_on_falls(b, &p.gait, &x, continue_s)?;
        }
        Ok(run)
    }

    /// The projected weights of `length` on the examples' `centers`.
    fn weights(
        &self,
        length: f64,
        lambda: f64,
        centers: &[DVector<f64>],
    ) -> Result<Vec<f64>, Error> {
        let what = format!("length {length} m");
        projected_weights(&self.q_final, lambda, centers, &self.target(length)?, &what)
    }
}

/// Whether SIMBICON, taking over at a right heel strike (state 2), falls within `seconds`.
fn walks_on_falls(b: &Biped, gait: &Gait, x0: &[f64], seconds: f64) -> Result<bool, Error> {
    let dt = b.default_dt();
    let mut sim = Simulator::new(b.clone(), IntegratorKind::Rk4);
    let mut c = Simbicon::new(gait.clone(), 2);
    let (mut x, mut u) = (x0.to_vec(), vec![0.0; TORQUES]);
    let steps = (seconds / dt).round() as usize;
    for k in 0..steps {
        c.control(b, &x, dt, &mut u);
        sim.step(&mut x, &u, dt);
        check_finite("biped", k, k as f64 * dt, &x).map_err(other)?;
        if b.fallen(&x) {
            return Ok(true);
        }
    }
    Ok(false)
}

/// The footholds' gap intervals: between the stance toe plus `margin` and the next foothold
/// minus `margin`, for footholds `f` (heel positions).
pub fn gaps(f: &[f64], margin: f64) -> Vec<(f64, f64)> {
    f.windows(2)
        .map(|w| (w[0] + FOOT_HEEL + FOOT_TOE + margin, w[1] - margin))
        .collect()
}

/// Whether the sole [heel, toe] overlaps any gap.
pub fn in_gap(heel: f64, toe: f64, gaps: &[(f64, f64)]) -> bool {
    gaps.iter().any(|&(a, b)| heel < b && toe > a)
}

pub(super) const METHODS: [&str; 5] = ["lbc", "naive", "short", "long", "direct"];

/// A compared step controller, in [`METHODS`]' order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stepper {
    /// Linear Bellman combination of the two examples' trackers.
    Lbc,
    /// The examples' torques averaged with the projected weights.
    Naive,
    /// The short example's tracker alone.
    Short,
    /// The long example's tracker alone.
    Long,
    /// The tracker of a DDP step solved for the desired length itself.
    Direct,
}

impl Stepper {
    /// Every controller, in `targets.csv`'s order.
    const ALL: [Stepper; 5] = [
        Stepper::Lbc,
        Stepper::Naive,
        Stepper::Short,
        Stepper::Long,
        Stepper::Direct,
    ];

    /// Its name in the tables.
    fn name(self) -> &'static str {
        METHODS[self as usize]
    }

    /// How it mixes the two examples' trackers; `None`: it does not (the direct step).
    fn mode(self) -> Option<BlendMode> {
        match self {
            Stepper::Lbc => Some(BlendMode::Lbc),
            Stepper::Naive => Some(BlendMode::Naive),
            Stepper::Short => Some(BlendMode::Single(0)),
            Stepper::Long => Some(BlendMode::Single(1)),
            Stepper::Direct => None,
        }
    }

    /// Whether it is a blend run again at the compared average-term scales.
    fn blends(self) -> bool {
        matches!(self, Stepper::Lbc | Stepper::Naive)
    }
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).expect("params serialize")
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        // The run's setup, then one per compared average-term scale (same start and nominal).
        let setups: Vec<Setup> = ctx.stage("start", || {
            std::iter::once(self.cost.average_scale)
                .chain(self.compare_average_scales.iter().copied())
                .map(|a| self.setup_with(a))
                .collect::<Result<Vec<_>, _>>()
        })?;
        let s = &setups[0];
        let Solves {
            examples,
            direct,
            components,
        } = self.solve_steps(ctx, &setups)?;
        let centers = [s.target(self.short_m)?, s.target(self.long_m)?];
        let lambda = scale_lambda(&s.q_final, &centers[0], &centers[1]);
        let limits = vec![self.torque_limit; TORQUES];
        let pairs: Vec<[TrackingController; 2]> = examples
            .iter()
            .map(|e| [e.short.tracker.clone(), e.long.tracker.clone()])
            .collect();
        let blend_of = |pair: usize, w: &[f64], mode: BlendMode| TrackerBlend {
            trackers: &pairs[pair][..],
            weights: w.to_vec(),
            lambda,
            mode,
            limits: Some(&limits),
        };
        // 2. Every controller at every desired length, on the simulator.
        let cases = self.cases(setups.len());
        // The projected weights, once per desired length (their seconds are LBC's and the
        // naive blend's overhead, a millisecond at most; not counted in `seconds`).
        let projected = self
            .desired_m
            .iter()
            .map(|&l| s.weights(l, lambda, &centers))
            .collect::<Result<Vec<_>, _>>()?;
        let pb = ctx.progress(cases.len() as u64, "steps on the simulator");
        let runs: Vec<Result<(StepRun, Vec<f64>, f64), Error>> = ctx.stage("execute", || {
            cases
                .par_iter()
                .map(|&(k, d, _, m)| {
                    let t0 = Instant::now();
                    let w = projected[d].clone();
                    let r = match m.mode() {
                        None => {
                            let b = TrackerBlend {
                                trackers: std::slice::from_ref(&direct[d].tracker),
                                weights: vec![1.0],
                                lambda,
                                mode: BlendMode::Single(0),
                                limits: Some(&limits),
                            };
                            s.execute(self, &b, &s.x0, self.continue_s, false)?
                        }
                        Some(mode) => {
                            s.execute(self, &blend_of(k, &w, mode), &s.x0, self.continue_s, false)?
                        }
                    };
                    let mut secs = t0.elapsed().as_secs_f64();
                    if m == Stepper::Direct {
                        secs += direct[d].seconds;
                    }
                    pb.inc(1);
                    Ok((r, w, secs))
                })
                .collect()
        });
        pb.finish_and_clear();
        let runs = runs.into_iter().collect::<Result<Vec<_>, _>>()?;
        let (targets, average, weights) = self.step_tables(&setups, &cases, &runs);
        let blend = |w: &[f64], mode: BlendMode| blend_of(0, w, mode);
        // 3. The walk over gaps.
        let (walk, motion) = ctx.stage("walk", || self.walk(s, lambda, &centers, &blend))?;
        let rule = self.rule_settings(s, lambda);
        Ok(Tables::from([
            ("components", table_of(&components)),
            ("targets", table_of(&targets)),
            ("weights", table_of(&weights)),
            ("average_effect", table_of(&average)),
            ("walk", table_of(&walk)),
            ("motion", table_of(&motion)),
            ("rule", rule),
        ]))
    }
}

/// A case run on the simulator: (setup, desired length's index, desired length, method).
type Case = (usize, usize, f64, Stepper);

/// A DDP step and its tracker, with the seconds both took.
struct Solved {
    solution: DdpSolution,
    tracker: TrackingController,
    seconds: f64,
}

/// The two examples optimized on one setup.
struct Examples {
    short: Solved,
    long: Solved,
}

/// The DDP steps: each setup's two examples (the run's setup first, then one per compared
/// scale), the direct solve per desired length on the run's setup, and the components table.
struct Solves {
    examples: Vec<Examples>,
    /// In `desired_m`'s order.
    direct: Vec<Solved>,
    components: Vec<ComponentRow>,
}

impl Params {
    /// Step 1, DDP in parallel: the two examples and a direct solve per desired length, then
    /// the two examples at each compared scale.
    fn solve_steps(&self, ctx: &RunContext, setups: &[Setup]) -> Result<Solves, Error> {
        let s = &setups[0];
        let n = s.horizon();
        let mut jobs: Vec<(usize, f64)> = vec![(0, self.short_m), (0, self.long_m)];
        jobs.extend(self.desired_m.iter().map(|&l| (0, l)));
        for k in 1..setups.len() {
            jobs.extend([(k, self.short_m), (k, self.long_m)]);
        }
        let pb = ctx.progress(jobs.len() as u64, "DDP steps");
        let solved: Vec<Result<Solved, Error>> = ctx.stage("ddp", || {
            jobs.par_iter()
                .map(|&(k, l)| {
                    let r = setups[k].optimize(self, l);
                    pb.inc(1);
                    r
                })
                .collect()
        });
        pb.finish_and_clear();
        // Taken apart in `jobs`' order.
        let mut solved = solved
            .into_iter()
            .collect::<Result<Vec<_>, _>>()?
            .into_iter();
        let mut next = || solved.next().expect("one solve per job");
        let mut examples = vec![Examples {
            short: next(),
            long: next(),
        }];
        let direct: Vec<Solved> = self.desired_m.iter().map(|_| next()).collect();
        for _ in 1..setups.len() {
            examples.push(Examples {
                short: next(),
                long: next(),
            });
        }
        let mut components = Vec::new();
        for (e, setup) in examples.iter().zip(setups) {
            for (name, length, step) in [
                ("short", self.short_m, &e.short),
                ("long", self.long_m, &e.long),
            ] {
                let sol = &step.solution;
                components.push(ComponentRow {
                    component: name.to_string(),
                    target_length_m: length,
                    reached_length_m: reached_length(&s.body, &s.x0, sol.x[n].as_slice()),
                    iterations: sol.trace.len() as i64,
                    cost: sol.cost,
                    termination: format!("{:?}", sol.termination),
                    seconds: step.seconds,
                    average_scale: setup.average_scale,
                });
            }
        }
        Ok(Solves {
            examples,
            direct,
            components,
        })
    }

    /// Every controller at every desired length on the run's setup; at the compared scales
    /// (setups 1..) LBC and the naive blend only.
    fn cases(&self, setups: usize) -> Vec<Case> {
        let mut cases: Vec<Case> = Vec::new();
        for (d, &l) in self.desired_m.iter().enumerate() {
            for m in Stepper::ALL {
                cases.push((0, d, l, m));
            }
        }
        for k in 1..setups {
            for (d, &l) in self.desired_m.iter().enumerate() {
                for m in Stepper::ALL.into_iter().filter(|m| m.blends()) {
                    cases.push((k, d, l, m));
                }
            }
        }
        cases
    }

    /// `targets.csv`'s rows (the run's setup), `average_effect.csv` (LBC and the naive blend
    /// at every scale) and `weights.csv` (LBC's α over each step) from the runs of `cases`.
    fn step_tables(
        &self,
        setups: &[Setup],
        cases: &[Case],
        runs: &[(StepRun, Vec<f64>, f64)],
    ) -> (Vec<StepRow>, Vec<AverageRow>, Vec<WeightRow>) {
        let mut targets: Vec<StepRow> = Vec::new();
        let mut average = Vec::new();
        let mut weights = Vec::new();
        let frame = ((self.gif_frame_s / self.knot_dt).round() as usize).max(1);
        for (&(k, _, l, m), (r, w, secs)) in cases.iter().zip(runs) {
            if m.blends() {
                average.push(AverageRow {
                    average_scale: setups[k].average_scale,
                    desired_length_m: l,
                    method: m.name().to_string(),
                    reached_length_m: r.reached,
                    fell: r.fell as u8 as f64,
                    effort: r.effort,
                    landed: r.landed as u8 as f64,
                });
            }
            if k > 0 {
                continue;
            }
            targets.push(StepRow {
                desired_length_m: l,
                method: m.name().to_string(),
                reached_length_m: r.reached,
                fell: r.fell as u8 as f64,
                effort: r.effort,
                seconds: *secs,
                landed: r.landed as u8 as f64,
                length_error_m: r.reached - l,
                weight_short: w[0],
                weight_long: w[1],
            });
            if m == Stepper::Lbc {
                for (i, a) in r.alpha_short.iter().enumerate().step_by(frame) {
                    weights.push(WeightRow {
                        desired_length_m: l,
                        t_s: i as f64 * self.knot_dt,
                        alpha_short: *a,
                    });
                }
            }
        }
        (targets, average, weights)
    }

    /// The rule's settings table.
    fn rule_settings(&self, s: &Setup, lambda: f64) -> Table {
        let n = s.horizon();
        rule_table(&[
            ("tolerance_m", self.rule.tolerance_m),
            ("error_margin_m", self.rule.error_margin_m),
            ("lambda", lambda),
            ("short_m", self.short_m),
            ("long_m", self.long_m),
            ("step_s", n as f64 * self.knot_dt),
            ("knot_dt", self.knot_dt),
            ("continue_s", self.continue_s),
            ("walk_steps", self.walk_m.len() as f64),
            (
                "simbicon_length_m",
                step_length(&s.body, s.nominal_x[n].as_slice()).0,
            ),
        ])
    }

    /// The walk: footholds `walk_m` apart from the start's left heel; each step LBC's toward the
    /// next foothold from wherever the stance heel is.
    fn walk<'a>(
        &self,
        s: &Setup,
        lambda: f64,
        centers: &[DVector<f64>],
        blend: &dyn Fn(&[f64], BlendMode) -> TrackerBlend<'a>,
    ) -> Result<(Vec<WalkStepRow>, Vec<MotionRow>), Error> {
        let b = &s.body;
        let home = b.contact_points(&s.x0[..DOF])[LEFT_HEEL][0];
        let mut footholds = vec![home];
        for l in &self.walk_m {
            footholds.push(footholds.last().copied().unwrap_or(home) + l);
        }
        let margin = self.rule.tolerance_m;
        let gap = gaps(&footholds, margin);
        let mut walk = Vec::new();
        let mut motion = Vec::new();
        let frame = ((self.gif_frame_s / self.knot_dt).round() as usize).max(1);
        let mut world = s.x0.clone();
        let step_s = s.horizon() as f64 * self.knot_dt;
        for (k, g) in gap.iter().enumerate() {
            let left_stance = k % 2 == 0;
            let mut local = if left_stance {
                world.clone()
            } else {
                Biped::mirror(&world)
            };
            let stance = b.contact_points(&local[..DOF])[LEFT_HEEL][0];
            let shift = home - stance;
            local[0] += shift;
            let desired = (footholds[k + 1] - stance).clamp(self.short_m, self.long_m);
            let w = s.weights(desired, lambda, centers)?;
            // SIMBICON walks on after the last step only.
            let walk_on = if k + 1 == gap.len() {
                self.continue_s
            } else {
                0.0
            };
            let r = s.execute(self, &blend(&w, BlendMode::Lbc), &local, walk_on, true)?;
            let back = |x: &[f64]| {
                let mut y = x.to_vec();
                y[0] -= shift;
                if left_stance {
                    y
                } else {
                    Biped::mirror(&y)
                }
            };
            for (i, x) in r.states.iter().enumerate().step_by(frame) {
                let y = back(x);
                let a = r.alpha_short.get(i).copied().unwrap_or(f64::NAN);
                let t = k as f64 * step_s + i as f64 * self.knot_dt;
                motion.push(MotionRow::at(k as i64 + 1, t, a, &y[..DOF]));
            }
            let end = r.states.last().cloned().unwrap_or_else(|| local.clone());
            let pts = b.contact_points(&end[..DOF]);
            let (heel, toe) = (pts[RIGHT_HEEL][0] - shift, pts[RIGHT_TOE][0] - shift);
            let in_any = in_gap(heel, toe, &gap);
            walk.push(WalkStepRow {
                step: k as i64 + 1,
                stance_heel_m: stance,
                foothold_m: footholds[k + 1],
                desired_length_m: desired,
                reached_length_m: r.reached,
                landing_heel_m: heel,
                landing_toe_m: toe,
                gap_start_m: g.0,
                gap_end_m: g.1,
                in_gap: in_any as u8 as f64,
                fell: r.fell as u8 as f64,
                weight_short: w[0] / (w[0] + w[1]),
            });
            if r.fell {
                break;
            }
            world = back(&end);
        }
        Ok((walk, motion))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mirroring_twice_is_the_identity_and_swaps_the_legs() {
        let x: Vec<f64> = (0..2 * DOF).map(|i| i as f64).collect();
        let m = Biped::mirror(&x);
        assert_eq!(m[3..6], x[6..9]);
        assert_eq!(m[DOF + 6..], x[DOF + 3..DOF + 6]);
        assert_eq!(m[..3], x[..3]);
        assert_eq!(Biped::mirror(&m), x);
    }

    #[test]
    fn step_targets_put_both_heels_on_the_ground_the_length_apart() {
        let b = Biped::default();
        let x = applet_start(&b, 0.3);
        for l in [0.25, 0.35, 0.45] {
            let t = step_target(&b, &x, l).unwrap();
            let (len, h) = step_length(&b, &t);
            assert!((len - l).abs() < 1e-9 && h.abs() < 1e-9, "{l}: {len} {h}");
            let p0 = b.contact_points(&x[..DOF])[LEFT_HEEL];
            let p1 = b.contact_points(&t[..DOF])[LEFT_HEEL];
            assert!((p0[0] - p1[0]).abs() < 1e-9 && (p0[1] - p1[1]).abs() < 1e-9);
            // Feet keep their absolute angles; torso and knees and velocities are untouched.
            let foot = |x: &[f64], first: usize| x[2] + x[first] + x[first + 1] + x[first + 2];
            assert!((foot(&t, 3) - foot(&x, 3)).abs() < 1e-12);
            assert!((foot(&t, 6) - foot(&x, 6)).abs() < 1e-12);
            assert_eq!(t[2], x[2]);
            assert_eq!((t[4], t[7]), (x[4], x[7]));
            assert_eq!(t[DOF..], x[DOF..]);
        }
        assert!(step_target(&b, &x, 3.0).is_err(), "beyond the legs' reach");
    }

    #[test]
    fn a_sole_is_in_a_gap_when_it_overlaps_one() {
        let g = gaps(&[0.0, 0.4, 0.7], 0.02);
        assert!((g[0].0 - 0.18).abs() < 1e-12 && (g[0].1 - 0.38).abs() < 1e-12);
        assert!(!in_gap(0.39, 0.55, &g), "on the foothold");
        assert!(in_gap(0.37, 0.53, &g), "the heel in the gap");
        assert!(in_gap(0.0, 0.2, &g), "the toe in the gap");
        assert!(!in_gap(0.69, 0.85, &g));
    }
}
