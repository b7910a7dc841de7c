//! `ms_spider_leap`, `ms_poodle_somersault`, `ms_table_pirouette` (MS Fig. 7–9): the
//! `ms_motion` family, one family for three experiment files. Each runs one parallel hill climb
//! of a reflex controller ([`MotionJob`], in [`super::search`], with the parameters shared with
//! `ms_learning`) for its motion's objective; [`super::search::Motion`] says which claim the report checks.
//!
//! Tables: see [`super::search`]. Figures: `<id>_filmstrip.png/svg`, `<id>_motion.gif`,
//! `<id>_search.png/svg`.

use super::lattice_draw::{draw_panels, front_face, write_gif, LatticePanel, Scene};
use super::motion_rule::{measures, motion_rule, seed_folders, unit, MotionFacts, MotionRule};
use super::rows::{
    BestTermRow, ControllerRow, MeasureRow, MotionSummaryRow, SearchRow, SpringRow, TrajectoryRow,
};
use super::search::{learning_panel, Motion, MotionJob, Params};
use crate::experiment::output::Tables;
use crate::experiment::plot::FigureSink;
use crate::experiment::plot::{Figure, Mark, Panel, Series};
use crate::experiment::report::{sig, yes_no, Findings};
use crate::experiment::resolve::{ParamError, Validate};
use crate::experiment::rows::{read_rows, TableRow};
use crate::experiment::rule::{rule_setting, rule_settings, rule_table_of, shown};
use crate::experiment::seeds::SeedMetric;
use crate::experiment::{Error, Family, Job, RunContext};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

/// The motion family.
pub struct MsMotion;

/// `ms_motion` parameters: the motion and its search, and the verdict's bars.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MotionSpec {
    /// The motion and its search.
    #[serde(flatten)]
    pub motion: Params,
    /// The verdict's bars (ours; [`super::motion_rule`]).
    pub rule: MotionRule,
}

impl Validate for MotionSpec {
    fn validate(&self) -> Result<(), ParamError> {
        MotionJob(self.motion.clone()).validate()?;
        self.rule.validate()
    }
}

impl Job for MotionSpec {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let mut tables = MotionJob(self.motion.clone()).run(ctx)?;
        tables.insert("rule", rule_table_of(&self.rule)?);
        Ok(tables)
    }
}

/// Frames `(t, regime, positions)` of a `trajectory` table's rows (a frame starts at its
/// mass 0).
fn frames_of(rows: &[TrajectoryRow]) -> Vec<(f64, usize, Vec<[f64; 3]>)> {
    let mut out: Vec<(f64, usize, Vec<[f64; 3]>)> = Vec::new();
    for r in rows {
        if r.mass == 0 {
            out.push((r.t, r.regime as usize, Vec::new()));
        }
        if let Some(f) = out.last_mut() {
            f.2.push([r.x, r.y, r.z]);
        }
    }
    out
}

/// The paper's name of a motion (`summary.csv`'s `motion`).
fn motion_title(motion: &str) -> &str {
    match motion {
        "leap" => "Spider leap",
        "somersault" => "Poodle somersault",
        "pirouette" => "Table pirouette",
        other => other,
    }
}

fn com(p: &[[f64; 3]]) -> [f64; 3] {
    // Shipped lattices have equal masses.
    let n = p.len().max(1) as f64;
    let mut c = [0.0; 3];
    for q in p {
        for k in 0..3 {
            c[k] += q[k] / n;
        }
    }
    c
}

impl Family for MsMotion {
    const KIND: &'static str = "ms_motion";
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "filmstrip",
            "the best controller found by parallel hill climbing: the lattice every few tenths of a second (time above each frame, with the reflex acting then), its centre-of-mass path in red and the face in front at t = 0 in orange.",
        ),
        (
            "search",
            "hill climbing's search: every evaluation's objective and the best so far vs iteration (blow-ups left out, counted on the axis).",
        ),
        (
            "motion",
            "the best controller's motion in real time, time on every frame.",
        ),
        (
            "heading",
            "how the body turns: the heading of the face in front at t = 0 about the vertical (a pirouette turns it) and its pitch about the sideways axis (a somersault turns it), unwrapped, vs time, with the verdict's bars (the spec's [params.rule]) dashed; for the leap also the centre of mass's travel along +x with its bars.",
        ),
    ];
    type Params = MotionSpec;
    // The verdict judges the seeds together (medians and a majority of seeds).
    const SEEDS_POOLED: bool = true;
    const SEED_METRICS: &'static [SeedMetric] = &[
        SeedMetric {
            table: "summary",
            column: "best_objective",
            row: None,
            label: "objective J after hill climbing",
        },
        SeedMetric {
            table: "summary",
            column: "initial_best",
            row: None,
            label: "J of the best random controller",
        },
    ];

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        let springs: Vec<(usize, usize)> = SpringRow::from_table(tables.require("springs")?)
            .iter()
            .map(|s| (s.a as usize, s.b as usize))
            .collect();
        let frames = frames_of(&TrajectoryRow::from_table(tables.require("trajectory")?));
        let ctl = ControllerRow::from_table(tables.require("controller")?);
        let trail: Vec<[f64; 3]> = frames.iter().map(|f| com(&f.2)).collect();
        let label = |reg: usize| {
            let regime = ctl.iter().find(|c| c.regime == reg as i64);
            format!(
                "{} {:+.2}",
                regime.map_or("?", |c| c.reflex_name.as_str()),
                regime.map_or(f64::NAN, |c| c.alpha)
            )
        };
        let mut files = Vec::new();
        if frames.is_empty() {
            return Ok(files);
        }
        // The motion's name, a side camera (looking along +y: the floor level, the motion along x
        // across the picture), the front face at t = 0 marked, a 1 m bar.
        let summary = MotionSummaryRow::from_table(tables.require("summary")?);
        let summary = summary.first();
        let motion_id = summary.map_or("", |s| s.motion.as_str());
        let name = motion_title(motion_id);
        let lattice = summary.map(|s| s.lattice.clone()).unwrap_or_default();
        let scene = Scene {
            caption: Some(format!(
                "{name} ({lattice} lattice): red line = centre-of-mass path, orange = the face in front at t = 0, floor grid 0.5 m, black bar 1 m"
            )),
            azimuth: 0.0,
            elevation: 0.3,
            marked: front_face(&frames[0].2),
            scale_bar: true,
        };
        let strip = summary
            .map_or(8, |s| s.filmstrip_frames as usize)
            .clamp(1, frames.len());
        let picks: Vec<usize> = (0..strip)
            .map(|i| {
                if strip == 1 {
                    frames.len() - 1
                } else {
                    i * (frames.len() - 1) / (strip - 1)
                }
            })
            .collect();
        let panels: Vec<LatticePanel> = picks
            .iter()
            .map(|&i| LatticePanel {
                title: format!("t = {:.2} s, {}", frames[i].0, label(frames[i].1)),
                positions: frames[i].2.clone(),
                ghost: None,
                trail: trail[..=i].to_vec(),
            })
            .collect();
        files.extend(draw_panels(
            &fig.dir,
            &format!("{}_filmstrip", fig.id),
            &panels,
            &springs,
            2,
            (720, 250),
            true,
            &scene,
        )?);
        // GIF in real time with at most ~100 frames.
        let dt = if frames.len() > 1 {
            frames[1].0 - frames[0].0
        } else {
            0.04
        };
        let every = frames.len().div_ceil(100).max(1);
        let gif_frames: Vec<(String, Vec<[f64; 3]>)> = frames
            .iter()
            .step_by(every)
            .map(|f| {
                (
                    format!("{name}  t = {:.2} s  {}", f.0, label(f.1)),
                    f.2.clone(),
                )
            })
            .collect();
        let delay = ((every as f64 * dt * 1000.0).round() as u32).max(20);
        let gif_trail: Vec<[f64; 3]> = trail.iter().step_by(every).copied().collect();
        files.push(write_gif(
            &fig.dir,
            &format!("{}_motion", fig.id),
            &gif_frames,
            &gif_trail,
            &springs,
            (640, 460),
            delay,
            &Scene {
                caption: Some(
                    "red: centre-of-mass path; orange: front face at t = 0; grid 0.5 m; bar 1 m"
                        .into(),
                ),
                ..scene.clone()
            },
        )?);
        let bars = MotionRule {
            held: rule_setting(tables, "held").unwrap_or(f64::NAN),
            partly: rule_setting(tables, "partly").unwrap_or(f64::NAN),
        };
        files.extend(fig.draw(
            "heading",
            &heading_figure(&frames, &scene.marked, motion_id, &bars),
        )?);
        let search = SearchRow::from_table(tables.require("search")?);
        files.extend(fig.draw(
            "search",
            &Figure::grid(
                vec![learning_panel(
                    "hill climbing: objective of every evaluation",
                    &[("hill climbing", &search)],
                    "iteration (0: initial random controllers)",
                )],
                1,
            ),
        )?);
        Ok(files)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        let folders = seed_folders(dir)?;
        let (first_seed, first) = folders.first().cloned().ok_or_else(|| {
            crate::experiment::other(format!("{}: no seed's results", dir.display()))
        })?;
        let summary: Vec<MotionSummaryRow> = read_rows(&first.join("summary.csv"))?;
        let s = summary
            .first()
            .ok_or_else(|| crate::experiment::other("summary.csv: no row"))?;
        let motion = Motion::from_name(&s.motion).ok_or_else(|| {
            crate::experiment::other(format!("summary.csv: unknown motion `{}`", s.motion))
        })?;
        let (evals, secs, best, init) = (
            s.evaluations as f64,
            s.search_seconds,
            s.best_objective,
            s.initial_best,
        );
        let mv = measures(&first)?;
        let names: Vec<String> = read_rows::<MeasureRow>(&first.join("measures.csv"))?
            .into_iter()
            .map(|m| m.measure)
            .collect();
        let terms: Vec<BestTermRow> = read_rows(&first.join("best.csv"))?;
        let mut md = match first_seed {
            Some(seed) => format!("The best motion of seed {seed} (the figures show it):\n\n"),
            None => String::new(),
        };
        md.push_str("| objective term | value | weighted |\n| --- | --- | --- |\n");
        for t in &terms {
            md.push_str(&format!(
                "| {} | {} | {} |\n",
                t.term,
                sig(t.value),
                sig(t.weighted)
            ));
        }
        md.push_str("\n| measure of the best motion | value |\n| --- | --- |\n");
        for n in &names {
            md.push_str(&format!("| {n} | {} |\n", sig(mv(n))));
        }
        md.push_str(&format!(
            "\nSearch: {} evaluations in {} s ({} evaluations/s); best of the initial random set {}, final best {}.\n",
            evals,
            sig(secs),
            sig(evals / secs.max(1e-9)),
            sig(init),
            sig(best)
        ));
        let settings = rule_settings(&first)?;
        let bars = MotionRule {
            held: settings("held"),
            partly: settings("partly"),
        };
        let mut facts = Vec::new();
        md.push_str(&format!(
            "\n| seed | {} | held bar with its conditions | partly bar with its conditions |\n| --- | --- | --- | --- |\n",
            unit(motion)
        ));
        for (seed, folder) in &folders {
            let f = MotionFacts::from_measures(motion, measures(folder)?);
            md.push_str(&format!(
                "| {} | {} | {} | {} |\n",
                seed.map_or("–".into(), |s| s.to_string()),
                sig(f.measure),
                yes_no(Some(f.held(&bars))),
                yes_no(Some(f.partly(&bars)))
            ));
            facts.push(f);
        }
        let rule = motion_rule(motion, &facts, &bars);
        let (verdict, lines, text) = shown(rule.as_ref(), "");
        // The lead quotes the rule's own first check: the median with its interval.
        let (med, (lo, hi)) = rule
            .as_ref()
            .and_then(|r| r.held.first())
            .map_or((f64::NAN, (f64::NAN, f64::NAN)), |c| {
                (c.value, c.interval.unwrap_or((f64::NAN, f64::NAN)))
            });
        let lead = match motion {
            Motion::Leap => format!(
                "The spider travels a median {} m along +x over {} seeds [95% interval {}-{}] (1 m = its base width)",
                sig(med),
                facts.len(),
                sig(lo),
                sig(hi)
            ),
            Motion::Somersault => format!(
                "The poodle turns a median {} backward turns over {} seeds [95% interval {}-{}]",
                sig(med),
                facts.len(),
                sig(lo),
                sig(hi)
            ),
            Motion::Pirouette => format!(
                "The table turns a median {}° about the vertical over {} seeds [95% interval {}-{}]",
                sig(med),
                facts.len(),
                sig(lo),
                sig(hi)
            ),
        };
        let conditions = match motion {
            Motion::Leap => "the held bar also needs the spider upright and off the ground at least once, the partly bar upright",
            Motion::Somersault => "the held bar also needs forward travel, on the ground at T and no rolling or turning beyond 45°, the partly bar forward travel",
            Motion::Pirouette => "the held bar also needs the table upright, a jump and on the ground at T, the partly bar upright",
        };
        Ok(Findings {
            ours: md,
            verdict,
            rule: rule.clone(),
            why: format!(
                "{lead}. Checks:{lines} Rule (bars ours, in the spec's [params.rule]; {conditions}): {text}"
            ),
        })
    }
}

/// The body's turning over time: the direction from the centre of mass to the centroid of the
/// `marked` masses (the face in front at t = 0), as a heading about the vertical (atan2 of its
/// y and x parts) and a pitch about the sideways y axis (atan2 of its z and x parts), each
/// unwrapped, in degrees.
/// The verdict's `bars` (the spec's `[params.rule]`) are drawn on it: the pirouette's in
/// degrees about the vertical, the somersault's in backward turns, and for the leap a second
/// panel of the centre of mass's travel along +x with its bars in metres.
// The heading and pitch figure only.
#[allow(clippy::disallowed_methods)]
fn heading_figure(
    frames: &[(f64, usize, Vec<[f64; 3]>)],
    marked: &[usize],
    motion: &str,
    bars: &MotionRule,
) -> Figure {
    let (mut heading, mut pitch) = (Vec::new(), Vec::new());
    let (mut last_h, mut last_p): (Option<f64>, Option<f64>) = (None, None);
    let unwrap = |last: &mut Option<f64>, a: f64| {
        let v = match *last {
            Some(l) => l + (a - l + PI).rem_euclid(2.0 * PI) - PI,
            None => a,
        };
        *last = Some(v);
        v
    };
    for (t, _, pos) in frames {
        let c = com(pos);
        let n = marked.len().max(1) as f64;
        let mut f = [0.0; 3];
        for &i in marked {
            for k in 0..3 {
                f[k] += pos[i][k] / n;
            }
        }
        let d = [f[0] - c[0], f[1] - c[1], f[2] - c[2]];
        heading.push((*t, unwrap(&mut last_h, d[1].atan2(d[0])).to_degrees()));
        pitch.push((*t, unwrap(&mut last_p, d[2].atan2(d[0])).to_degrees()));
    }
    let t_end = frames.last().map_or(1.0, |f| f.0);
    let bar = |label: String, y: f64, color: usize| {
        Series::line(label, vec![(0.0, y), (t_end, y)], color).mark(Mark::Dashed)
    };
    let mut series = vec![
        Series::line("heading about the vertical", heading.clone(), 0),
        Series::line("pitch about the sideways axis", pitch, 1),
    ];
    match motion {
        "pirouette" => {
            // The rule judges |turn|: the bars on the side the heading ends.
            let sign = heading
                .last()
                .map_or(1.0, |h| if h.1 < 0.0 { -1.0 } else { 1.0 });
            series.push(bar(
                format!("held bar: {}° about the vertical", sig(bars.held)),
                sign * bars.held,
                2,
            ));
            series.push(bar(
                format!("partly bar: {}°", sig(bars.partly)),
                sign * bars.partly,
                3,
            ));
        }
        "somersault" => {
            series.push(bar(
                format!(
                    "held bar: {} of a backward turn ({}°)",
                    sig(bars.held),
                    sig(bars.held * 360.0)
                ),
                bars.held * 360.0,
                2,
            ));
            series.push(bar(
                format!(
                    "partly bar: {} of a turn ({}°)",
                    sig(bars.partly),
                    sig(bars.partly * 360.0)
                ),
                bars.partly * 360.0,
                3,
            ));
        }
        _ => {}
    }
    let mut panels = vec![Panel {
        title: "turning of the face in front at t = 0".into(),
        x_label: "time (s)".into(),
        y_label: "angle (degrees, unwrapped)".into(),
        series,
        ..Panel::default()
    }];
    if motion == "leap" {
        let x0 = frames.first().map_or(0.0, |f| com(&f.2)[0]);
        let travel: Vec<(f64, f64)> = frames.iter().map(|f| (f.0, com(&f.2)[0] - x0)).collect();
        panels.push(Panel {
            title: "travel of the centre of mass".into(),
            x_label: "time (s)".into(),
            y_label: "distance along +x (m)".into(),
            series: vec![
                Series::line("centre of mass along +x", travel, 0),
                bar(format!("held bar: {} m", sig(bars.held)), bars.held, 2),
                bar(
                    format!("partly bar: {} m", sig(bars.partly)),
                    bars.partly,
                    3,
                ),
            ],
            ..Panel::default()
        });
    }
    let cols = panels.len();
    Figure::grid(panels, cols)
}
