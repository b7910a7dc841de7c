//! The run of `lbc_walking`: the hill walker's search, the two gaits' value functions, the
//! walks of every controller on every terrain, the temperature sweep.

use super::rows::{MotionRow, SearchRow, SweepRow, WalkRow, WeightRow};
use super::Params;
use crate::bellman::combine::{blend_controls, blend_weights};
use crate::control::gait_value::GaitCycle;
use crate::control::simbicon::{applet_start, Gait, Simbicon};
use crate::experiment::output::{Table, Tables};
use crate::experiment::rows::table_of;
use crate::experiment::{other, Error, Job, RunContext};
use crate::families::lbc::rule_table;
use crate::physics::biped::{Biped, DOF, TORQUES};
use crate::physics::ground::{Contact, Terrain};
use crate::physics::{Dynamics, IntegratorKind, Model, Simulator};
use crate::row;
use rayon::prelude::*;

/// Who drives the body.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Driver {
    /// The flat walker alone.
    Flat,
    /// The hill walker alone.
    Hill,
    /// Both walkers' torques averaged with weights ½, ½.
    Naive,
    /// LBC at temperature λ.
    Lbc(f64),
}

impl Driver {
    fn name(self) -> &'static str {
        match self {
            Driver::Flat => "flat",
            Driver::Hill => "hill",
            Driver::Naive => "naive",
            Driver::Lbc(_) => "lbc",
        }
    }
}

/// What a walk did.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Walk {
    /// Pelvis x advance (m) up to the end or the fall.
    pub distance: f64,
    /// When it fell (s).
    pub fell_at: Option<f64>,
    /// Heel strikes of the (first) state machine.
    pub steps: usize,
    /// Seconds walked (to the fall or the end).
    pub seconds: f64,
    /// One every `sample_dt`.
    pub samples: Vec<Sample>,
}

/// The body and the blend at one instant of a walk.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Sample {
    /// Time (s).
    pub t: f64,
    /// The state.
    pub x: Vec<f64>,
    /// The hill walker's weight (0 or 1 alone, ½ naive).
    pub alpha_hill: f64,
    /// The walkers' values (NaN unless LBC).
    pub v_flat: f64,
    /// (see `v_flat`)
    pub v_hill: f64,
}

/// The two walkers and their gaits' value functions (needed by LBC only).
pub(super) struct Walkers<'a> {
    pub flat: &'a Gait,
    pub hill: &'a Gait,
    pub cycles: Option<(&'a GaitCycle, &'a GaitCycle)>,
}

/// LBC's weight of the hill walker: exp(−v_hill/λ) / (exp(−v_flat/λ) + exp(−v_hill/λ))
/// ([`blend_weights`] with weights one); NaN for non-finite values.
pub fn lbc_weight(v_flat: f64, v_hill: f64, lambda: f64) -> f64 {
    let mut alpha = [0.0; 2];
    blend_weights(&[1.0, 1.0], &[v_flat, v_hill], lambda, &mut alpha).map_or(f64::NAN, |_| alpha[1])
}

/// Walks `driver` on `terrain` from the applet's start for `seconds`, stopping at a fall;
/// samples every `sample_dt`.
pub(super) fn walk(
    p: &Params,
    w: &Walkers,
    terrain: Terrain,
    driver: Driver,
    seconds: f64,
    sample_dt: f64,
) -> Result<Walk, Error> {
    let b = Biped::new(terrain, Contact::default());
    let dt = b.default_dt();
    let mut sim = Simulator::new(b.clone(), IntegratorKind::Rk4);
    let mut x = applet_start(&b, 0.0);
    let x0 = x[0];
    let (mut cf, mut ch) = (
        Simbicon::new(w.flat.clone(), 0),
        Simbicon::new(w.hill.clone(), 0),
    );
    let (mut uf, mut uh, mut u) = ([0.0; TORQUES], [0.0; TORQUES], [0.0; TORQUES]);
    let steps = (seconds / dt).round() as usize;
    let every = ((p.blend_every_s / dt).round() as usize).max(1);
    let sample = ((sample_dt / dt).round() as usize).max(1);
    let (mut alpha, mut vf, mut vh) = (
        match driver {
            Driver::Flat => 0.0,
            Driver::Hill => 1.0,
            Driver::Naive | Driver::Lbc(_) => 0.5,
        },
        f64::NAN,
        f64::NAN,
    );
    let mut samples = Vec::new();
    let mut fell_at = None;
    let mut k_end = steps;
    for k in 0..steps {
        let uses_flat = driver != Driver::Hill;
        let uses_hill = driver != Driver::Flat;
        if uses_flat {
            cf.control(&b, &x, dt, &mut uf);
        }
        if uses_hill {
            ch.control(&b, &x, dt, &mut uh);
        }
        if k % every == 0 {
            if let Driver::Lbc(lambda) = driver {
                let (fc, hc) = w
                    .cycles
                    .ok_or_else(|| other("lbc_walking: LBC needs the gaits' value functions"))?;
                vf = fc.value(&b, &x, cf.left_stance()).0;
                vh = hc.value(&b, &x, ch.left_stance()).0;
                alpha = lbc_weight(vf, vh, lambda);
                if !alpha.is_finite() {
                    return Err(other(format!(
                        "lbc_walking: LBC's weights at t = {:.4} s (values {vf}, {vh})",
                        k as f64 * dt
                    )));
                }
            }
        }
        if k % sample == 0 {
            samples.push(Sample {
                t: k as f64 * dt,
                x: x.clone(),
                alpha_hill: alpha,
                v_flat: vf,
                v_hill: vh,
            });
        }
        blend_controls(&[1.0 - alpha, alpha], &[&uf, &uh], &mut u);
        sim.step(&mut x, &u, dt);
        let t = (k + 1) as f64 * dt;
        crate::physics::check_finite("biped", k + 1, t, &x).map_err(other)?;
        if b.fallen(&x) {
            fell_at = Some(t);
            k_end = k + 1;
            break;
        }
    }
    Ok(Walk {
        distance: x[0] - x0,
        fell_at,
        steps: if driver == Driver::Hill {
            ch.steps
        } else {
            cf.steps
        },
        seconds: k_end as f64 * dt,
        samples,
    })
}

/// The hill walker of grid offsets (torso, swing hip): `flat` with both states' targets moved.
pub fn hill_gait(flat: &Gait, torso: f64, hip: f64) -> Gait {
    let mut g = flat.clone();
    for s in g.states.iter_mut() {
        s.torso += torso;
        s.swing_hip += hip;
    }
    g
}

/// The grid point the rule picks: the furthest walk without a fall, the first in grid order on
/// ties; `None` when every point fell.
pub fn choose_hill(results: &[(f64, bool)]) -> Option<usize> {
    let mut best: Option<usize> = None;
    for (i, &(d, fell)) in results.iter().enumerate() {
        if !fell && best.is_none_or(|b| d > results[b].0) {
            best = Some(i);
        }
    }
    best
}

/// The temperature the rule picks: the smallest whose LBC walks every terrain without falling
/// (`walked[i]` for `lambdas[i]`), else the largest (and the verdict's walk check fails).
pub fn choose_lambda(walked: &[bool]) -> usize {
    walked
        .iter()
        .position(|&w| w)
        .unwrap_or(walked.len().saturating_sub(1))
}

/// Mean α_hill of the (pelvis x, α_hill) pairs whose x is at most `before` (flat part) and at
/// least `after` (hill part); NaN for a part never reached.
pub fn part_means(samples: &[(f64, f64)], before: f64, after: f64) -> (f64, f64) {
    let mean = |f: &dyn Fn(f64) -> bool| {
        let v: Vec<f64> = samples.iter().filter(|s| f(s.0)).map(|s| s.1).collect();
        if v.is_empty() {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    (mean(&|x| x <= before), mean(&|x| x >= after))
}

/// (pelvis x, α_hill) of a walk's samples.
fn x_alpha(samples: &[Sample]) -> Vec<(f64, f64)> {
    samples.iter().map(|s| (s.x[0], s.alpha_hill)).collect()
}

/// The hill walker the search chose: its gait, its grid point and the search's table.
struct HillWalker {
    gait: Gait,
    torso_offset: f64,
    hip_offset: f64,
    search: Vec<SearchRow>,
}

/// The temperature sweep: every λ's walk on every terrain (λ-major) and the chosen λ's index.
struct Sweep {
    walks: Vec<Walk>,
    chosen: usize,
    rows: Vec<SweepRow>,
}

impl Params {
    /// Step 1, the hill walker: the grid's furthest walk up the incline.
    fn search_hill_walker(&self, ctx: &RunContext, incline: Terrain) -> Result<HillWalker, Error> {
        let s = &self.hill_search;
        let grid: Vec<(f64, f64)> = s
            .torso_offsets
            .iter()
            .flat_map(|&t| s.hip_offsets.iter().map(move |&h| (t, h)))
            .collect();
        let results: Vec<(f64, bool)> = ctx.stage("hill walker search", || {
            grid.par_iter()
                .map(|&(t, h)| -> Result<(f64, bool), Error> {
                    let g = hill_gait(&self.flat_gait, t, h);
                    let alone = Walkers {
                        flat: &g,
                        hill: &g,
                        cycles: None,
                    };
                    let r = walk(self, &alone, incline, Driver::Flat, s.seconds, s.seconds)?;
                    Ok((r.distance, r.fell_at.is_some()))
                })
                .collect::<Result<_, _>>()
        })?;
        let chosen = choose_hill(&results).ok_or_else(|| {
            other("lbc_walking: every hill walker of the grid fell on the incline")
        })?;
        let search: Vec<SearchRow> = grid
            .iter()
            .zip(&results)
            .enumerate()
            .map(|(i, (&(t, h), &(d, f)))| SearchRow {
                torso_offset: t,
                hip_offset: h,
                distance_m: d,
                fell: i64::from(f),
                chosen: i64::from(i == chosen),
            })
            .collect();
        let (torso_offset, hip_offset) = grid[chosen];
        Ok(HillWalker {
            gait: hill_gait(&self.flat_gait, torso_offset, hip_offset),
            torso_offset,
            hip_offset,
            search,
        })
    }

    /// Step 2: each walker's gait on its own ground and its value function, with their table.
    fn record_cycles(
        &self,
        ctx: &RunContext,
        hill: &Gait,
        incline: Terrain,
    ) -> Result<(Vec<GaitCycle>, Table), Error> {
        let cycles: Vec<GaitCycle> = ctx.stage("gaits and value functions", || {
            [(&self.flat_gait, Terrain::Flat), (hill, incline)]
                .par_iter()
                .map(|(g, t)| {
                    GaitCycle::record(
                        &Biped::new(*t, Contact::default()),
                        g,
                        &self.cost,
                        self.warmup_s,
                        self.knot_dt,
                        self.horizon_s,
                    )
                    .map_err(other)
                })
                .collect::<Result<_, _>>()
        })?;
        let mut cyc = Table::new(&[
            "walker",
            "terrain",
            "knots",
            "half_period_s",
            "speed_m_s",
            "horizon_knots",
        ]);
        for (name, terrain, c) in [
            ("flat", "flat", &cycles[0]),
            ("hill", "incline", &cycles[1]),
        ] {
            cyc.push(row![
                name,
                terrain,
                c.z.len(),
                c.half_period,
                c.speed,
                c.horizon
            ]);
        }
        Ok((cycles, cyc))
    }

    /// Step 3: LBC at every temperature on every terrain, and the λ chosen from them.
    fn lambda_sweep(
        &self,
        ctx: &RunContext,
        walkers: &Walkers,
        terrains: &[(&'static str, Terrain)],
    ) -> Result<Sweep, Error> {
        let track_split = (
            self.hill_start_m - self.rule.margin_m,
            self.hill_start_m + self.rule.margin_m,
        );
        let jobs: Vec<(usize, usize)> = (0..self.lambdas.len())
            .flat_map(|l| (0..terrains.len()).map(move |t| (l, t)))
            .collect();
        let sweep: Vec<Walk> = ctx.stage("LBC temperature sweep", || {
            jobs.par_iter()
                .map(|&(l, t)| {
                    walk(
                        self,
                        walkers,
                        terrains[t].1,
                        Driver::Lbc(self.lambdas[l]),
                        self.walk_s,
                        self.knot_dt,
                    )
                })
                .collect::<Result<_, _>>()
        })?;
        let mut rows = Vec::with_capacity(jobs.len());
        let mut walked = vec![true; self.lambdas.len()];
        for (&(l, t), r) in jobs.iter().zip(&sweep) {
            walked[l] &= r.fell_at.is_none();
            let (af, ah) = if terrains[t].0 == "flat_then_hill" {
                part_means(&x_alpha(&r.samples), track_split.0, track_split.1)
            } else {
                (f64::NAN, f64::NAN)
            };
            rows.push(SweepRow {
                lambda: self.lambdas[l],
                terrain: terrains[t].0.to_string(),
                distance_m: r.distance,
                fell: i64::from(r.fell_at.is_some()),
                alpha_hill_flat_part: af,
                alpha_hill_hill_part: ah,
            });
        }
        Ok(Sweep {
            walks: sweep,
            chosen: choose_lambda(&walked),
            rows,
        })
    }

    /// Step 4: every walker alone and the naive blend on every terrain (terrain-major, in
    /// [`DRIVERS_ALONE`]' order).
    fn walks_alone(
        &self,
        ctx: &RunContext,
        walkers: &Walkers,
        terrains: &[(&'static str, Terrain)],
    ) -> Result<Vec<Walk>, Error> {
        let jobs: Vec<(usize, usize)> = (0..terrains.len())
            .flat_map(|t| (0..DRIVERS_ALONE.len()).map(move |d| (t, d)))
            .collect();
        ctx.stage("walks", || {
            jobs.par_iter()
                .map(|&(t, d)| {
                    walk(
                        self,
                        walkers,
                        terrains[t].1,
                        DRIVERS_ALONE[d],
                        self.walk_s,
                        self.gif_frame_s.min(self.knot_dt),
                    )
                })
                .collect::<Result<_, _>>()
        })
    }

    /// The rule's settings table.
    fn rule_settings(&self, lambda: f64, cycles: &[GaitCycle], hill: &HillWalker) -> Table {
        let r = &self.rule;
        rule_table(&[
            ("lambda", lambda),
            ("advance_fraction", r.advance_fraction),
            ("climb_m", r.climb_m),
            ("shift", r.shift),
            ("margin_m", r.margin_m),
            ("hill_start_m", self.hill_start_m),
            ("hill_smoothing_m", self.hill_smoothing_m),
            ("incline_degrees", self.incline_degrees),
            ("walk_s", self.walk_s),
            ("knot_dt", self.knot_dt),
            ("horizon_s", cycles[0].horizon as f64 * self.knot_dt),
            ("hill_torso_offset", hill.torso_offset),
            ("hill_hip_offset", hill.hip_offset),
        ])
    }
}

/// The drivers of [`Params::walks_alone`], in its order.
const DRIVERS_ALONE: [Driver; 3] = [Driver::Flat, Driver::Hill, Driver::Naive];

/// `walks.csv`: every controller on every terrain, LBC's walks (`lbc`, one per terrain) at
/// `lambda`.
fn walks_table(
    terrains: &[(&'static str, Terrain)],
    alone: &[Walk],
    lbc: &[Walk],
    lambda: f64,
) -> Vec<WalkRow> {
    let mut walks = Vec::new();
    let mut push_walk = |terrain: &str, d: Driver, r: &Walk| {
        let l = match d {
            Driver::Lbc(l) => l,
            _ => f64::NAN,
        };
        walks.push(WalkRow {
            terrain: terrain.to_string(),
            controller: d.name().to_string(),
            distance_m: r.distance,
            fell: i64::from(r.fell_at.is_some()),
            mean_speed_m_s: r.distance / r.seconds.max(1e-9),
            steps: r.steps as i64,
            fell_at_s: r.fell_at.unwrap_or(f64::NAN),
            lambda: l,
        });
    };
    for (t, (name, _)) in terrains.iter().enumerate() {
        for (d, &driver) in DRIVERS_ALONE.iter().enumerate() {
            push_walk(name, driver, &alone[t * DRIVERS_ALONE.len() + d]);
        }
        push_walk(name, Driver::Lbc(lambda), &lbc[t]);
    }
    walks
}

/// `weights.csv`: LBC's weights and values over time on every terrain (`lbc`, one walk per
/// terrain) at the chosen λ.
fn weights_table(terrains: &[(&'static str, Terrain)], lbc: &[Walk]) -> Vec<WeightRow> {
    let mut weights = Vec::new();
    for (t, (name, terrain)) in terrains.iter().enumerate() {
        for sm in &lbc[t].samples {
            let slope = crate::portable::atan(terrain.height_slope(sm.x[0]).1).to_degrees();
            weights.push(WeightRow {
                terrain: name.to_string(),
                t_s: sm.t,
                x_m: sm.x[0],
                slope_deg: slope,
                alpha_flat: 1.0 - sm.alpha_hill,
                alpha_hill: sm.alpha_hill,
                v_flat: sm.v_flat,
                v_hill: sm.v_hill,
            });
        }
    }
    weights
}

/// `motion.csv`: the flat-then-hill walks of LBC and the flat walker, every `frame` samples,
/// for the animation.
fn motion_table(lbc: &Walk, flat: &Walk, frame: usize) -> Vec<MotionRow> {
    let mut motion = Vec::new();
    for (name, r) in [("lbc", lbc), ("flat", flat)] {
        for sm in r.samples.iter().step_by(frame) {
            motion.push(MotionRow::at(name, sm.t, sm.alpha_hill, &sm.x[..DOF]));
        }
    }
    motion
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).expect("params serialize")
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let incline = Terrain::Slope {
            degrees: self.incline_degrees,
        };
        let hill = self.search_hill_walker(ctx, incline)?;
        let (cycles, cyc) = self.record_cycles(ctx, &hill.gait, incline)?;
        let walkers = Walkers {
            flat: &self.flat_gait,
            hill: &hill.gait,
            cycles: Some((&cycles[0], &cycles[1])),
        };
        let terrains = self.terrains();
        let sweep = self.lambda_sweep(ctx, &walkers, &terrains)?;
        let li = sweep.chosen;
        let lambda = self.lambdas[li];
        let alone = self.walks_alone(ctx, &walkers, &terrains)?;
        // LBC's walks on each terrain are the sweep's at the chosen λ (the sweep is λ-major).
        let n = terrains.len();
        let lbc = &sweep.walks[li * n..(li + 1) * n];
        let walks = walks_table(&terrains, &alone, lbc, lambda);
        let weights = weights_table(&terrains, lbc);
        let track = terrains.len() - 1;
        let frame = ((self.gif_frame_s / self.knot_dt).round() as usize).max(1);
        let motion = motion_table(&lbc[track], &alone[track * DRIVERS_ALONE.len()], frame);
        let rule = self.rule_settings(lambda, &cycles, &hill);
        Ok(Tables::from([
            ("search", table_of(&hill.search)),
            ("cycles", cyc),
            ("walks", table_of(&walks)),
            ("weights", table_of(&weights)),
            ("lambda_sweep", table_of(&sweep.rows)),
            ("motion", table_of(&motion)),
            ("rule", rule),
        ]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lbc_weights_follow_the_lower_value_and_lambda_softens_them() {
        assert!((lbc_weight(1.0, 1.0, 0.5) - 0.5).abs() < 1e-15);
        assert!(lbc_weight(10.0, 1.0, 1.0) > 0.999);
        assert!(lbc_weight(1.0, 10.0, 1.0) < 0.001);
        // Large values do not overflow: only differences count.
        assert!((lbc_weight(1e6, 1e6 + 1.0, 1.0) - 1.0 / (1.0 + 1f64.exp())).abs() < 1e-12);
        // A hotter temperature pulls the weight toward ½.
        assert!(lbc_weight(1.0, 3.0, 10.0) > lbc_weight(1.0, 3.0, 1.0));
        assert!(lbc_weight(1.0, 3.0, 10.0) < 0.5);
    }

    #[test]
    fn the_rules_choose_the_furthest_standing_walker_and_the_coolest_walking_lambda() {
        assert_eq!(
            choose_hill(&[(5.0, true), (2.0, false), (3.0, false), (3.0, false)]),
            Some(2)
        );
        assert_eq!(choose_hill(&[(5.0, true)]), None);
        assert_eq!(choose_lambda(&[false, true, true]), 1);
        assert_eq!(choose_lambda(&[false, false]), 1);
        let s = |x: f64, a: f64| (x, a);
        let (f, h) = part_means(
            &[s(0.0, 0.1), s(1.0, 0.3), s(5.0, 0.9), s(2.5, 0.5)],
            2.0,
            3.0,
        );
        assert!((f - 0.2).abs() < 1e-15 && (h - 0.9).abs() < 1e-15);
        assert!(part_means(&[s(0.0, 0.1)], 2.0, 3.0).1.is_nan());
    }
}
