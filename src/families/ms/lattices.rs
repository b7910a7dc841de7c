//! `ms_lattices` (MS §2.1–2.2, Fig. 1–3): the three lattices (cube, pyramid "spider", chair)
//! and the 12 reflex deformations (scale, shear, splay, twist × 3 axes) applied to them.
//!
//! Tables: `lattices` (lattice, masses, springs, rigid_reflexes); `rest_lengths` (lattice,
//! reflex, reflex_name, alpha, spring, a, b, rest_length, rest_length_change) for α = ±`alpha`;
//! `positions` (lattice, reflex, alpha, mass, x, y, z; reflex −1 is the rest shape);
//! `springs` (lattice, spring, a, b).

use super::lattice_draw::{draw_panels, LatticePanel, Scene};
use crate::experiment::output::Tables;
use crate::experiment::plot::FigureSink;
use crate::experiment::report::Findings;
use crate::experiment::resolve::{distinct, ensure, ParamError, Validate};
use crate::experiment::rows::{read_rows, table_of, TableRow};
use crate::experiment::rule::{read_rule, rule_table_of, shown, Check, Partly, Rule};
use crate::experiment::{other, Error, Family, Job, RunContext};
use crate::physics::lattice::Lattice;
use crate::physics::reflex::{deform, Reflex, ReflexGains};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The family.
pub struct MsLattices;

crate::result_rows! {
    /// One row of `lattices.csv`: one lattice's size.
    pub struct LatticeRow {
        /// The lattice's name.
        lattice: String = "lattice",
        /// Its masses.
        masses: i64 = "masses",
        /// Its springs.
        springs: i64 = "springs",
        /// Reflexes that change no rest length (at +α).
        rigid_reflexes: i64 = "rigid_reflexes",
    }
}

crate::result_rows! {
    /// One row of `rest_lengths.csv`: one spring under one reflex at one α.
    pub struct RestLengthRow {
        /// The lattice's name.
        lattice: String = "lattice",
        /// The reflex's number.
        reflex: i64 = "reflex",
        /// The reflex's name.
        reflex_name: String = "reflex_name",
        /// The reflex coefficient α.
        alpha: f64 = "alpha",
        /// The spring's index.
        spring: i64 = "spring",
        /// Its first mass.
        a: i64 = "a",
        /// Its second mass.
        b: i64 = "b",
        /// Its deformed rest length (m).
        rest_length: f64 = "rest_length",
        /// Deformed minus undeformed rest length (m).
        rest_length_change: f64 = "rest_length_change",
    }
}

crate::result_rows! {
    /// One row of `positions.csv`: one mass of a lattice's shape under one reflex.
    pub struct PositionRow {
        /// The lattice's name.
        lattice: String = "lattice",
        /// The reflex's number (−1: the rest shape).
        reflex: i64 = "reflex",
        /// The reflex coefficient α (0 at rest).
        alpha: f64 = "alpha",
        /// The mass's index.
        mass: i64 = "mass",
        /// Its x (m).
        x: f64 = "x",
        /// Its y (m).
        y: f64 = "y",
        /// Its z (m).
        z: f64 = "z",
    }
}

crate::result_rows! {
    /// One row of `springs.csv`: one spring of a lattice.
    pub struct LatticeSpringRow {
        /// The lattice's name.
        lattice: String = "lattice",
        /// The spring's index.
        spring: i64 = "spring",
        /// Its first mass.
        a: i64 = "a",
        /// Its second mass.
        b: i64 = "b",
    }
}

/// Parameters of `ms_lattices`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Lattices to show: any of `cube`, `pyramid`, `chair`.
    pub lattices: Vec<String>,
    /// Reflex coefficient magnitude |α| shown (α = ±alpha are tabulated, +alpha drawn).
    pub alpha: f64,
    /// Reflex gains (κ, γ, σ, τ).
    pub gains: ReflexGains,
    /// The paper's numbers the check compares with.
    pub rule: LatticeRule,
}

/// The paper's lattice numbers (§2.1-2.2): the cube's masses and springs, and the ranges of
/// the lattices used.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LatticeRule {
    /// The cube's point masses.
    pub cube_masses: usize,
    /// The cube's springs.
    pub cube_springs: usize,
    /// Fewest masses of a lattice used.
    pub masses_min: usize,
    /// Most masses.
    pub masses_max: usize,
    /// Fewest springs.
    pub springs_min: usize,
    /// Most springs.
    pub springs_max: usize,
}

/// The check's rule: (a) the cube has the paper's masses and springs and every reflex deforms
/// it (`cube_ok`); (b) every lattice's masses and springs lie in the paper's ranges
/// (`in_range`). Held when both hold, partly when one does.
fn lattice_rule(cube_ok: bool, in_range: bool, r: &LatticeRule) -> Option<Rule> {
    let held = vec![
        Ok(Check::fact(
            format!(
                "the cube has {} masses and {} springs and every reflex deforms it",
                r.cube_masses, r.cube_springs
            ),
            cube_ok,
        )),
        Ok(Check::fact(
            format!(
                "every lattice has {}-{} masses and {}-{} springs",
                r.masses_min, r.masses_max, r.springs_min, r.springs_max
            ),
            in_range,
        )),
    ];
    Rule::gated(vec![], held, Partly::Any)
}

/// The shipped lattice called `name` (`cube`, `pyramid`, `chair`).
pub fn lattice_by_name(name: &str) -> Option<Lattice> {
    match name {
        "cube" => Some(Lattice::cube()),
        "pyramid" => Some(Lattice::pyramid()),
        "chair" => Some(Lattice::chair()),
        _ => None,
    }
}

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        ensure(!self.lattices.is_empty(), "lattices", "need at least one")?;
        distinct("lattices", &self.lattices)?;
        for (i, l) in self.lattices.iter().enumerate() {
            ensure(
                lattice_by_name(l).is_some(),
                &format!("lattices[{i}]"),
                format!("unknown lattice `{l}` (cube, pyramid, chair)"),
            )?;
        }
        ensure(
            self.alpha > 0.0 && self.alpha <= 1.0,
            "alpha",
            "must be in (0, 1]",
        )?;
        for (k, v) in [
            ("gains.scale", self.gains.scale),
            ("gains.shear", self.gains.shear),
            ("gains.splay", self.gains.splay),
            ("gains.twist", self.gains.twist),
        ] {
            ensure(v.is_finite() && v >= 0.0, k, "must be finite and >= 0")?;
        }
        let r = &self.rule;
        ensure(
            r.masses_min <= r.masses_max && r.springs_min <= r.springs_max,
            "rule",
            "each range's minimum must not exceed its maximum",
        )?;
        ensure(
            self.gains.scale < 1.0 && self.gains.splay < 1.0,
            "gains",
            "scale and splay gains must be < 1 (else a rest length reaches 0)",
        )
    }
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, _ctx: &RunContext) -> Result<Tables, Error> {
        let (mut lat, mut rl, mut pos, mut spr) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for name in &self.lattices {
            let l = lattice_by_name(name).ok_or_else(|| other("unknown lattice"))?;
            let rest = l.rest_lengths();
            for (j, s) in l.springs.iter().enumerate() {
                spr.push(LatticeSpringRow {
                    lattice: name.clone(),
                    spring: j as i64,
                    a: s.a as i64,
                    b: s.b as i64,
                });
            }
            let position = |reflex: i64, alpha: f64, i: usize, p: &[f64; 3]| PositionRow {
                lattice: name.clone(),
                reflex,
                alpha,
                mass: i as i64,
                x: p[0],
                y: p[1],
                z: p[2],
            };
            for (i, p) in l.rest_positions().iter().enumerate() {
                pos.push(position(-1, 0.0, i, p));
            }
            let mut rigid = 0usize;
            for r in 0..Reflex::COUNT {
                let rname = Reflex::from_number(r).map_err(other)?.name();
                for alpha in [self.alpha, -self.alpha] {
                    let d = deform(&l, r, alpha, &self.gains).map_err(other)?;
                    let mut change = 0.0f64;
                    for (j, s) in l.springs.iter().enumerate() {
                        let dl = d.rest_lengths[j] - rest[j];
                        change = change.max(dl.abs());
                        rl.push(RestLengthRow {
                            lattice: name.clone(),
                            reflex: r as i64,
                            reflex_name: rname.clone(),
                            alpha,
                            spring: j as i64,
                            a: s.a as i64,
                            b: s.b as i64,
                            rest_length: d.rest_lengths[j],
                            rest_length_change: dl,
                        });
                    }
                    if alpha > 0.0 {
                        if change < 1e-9 {
                            rigid += 1;
                        }
                        for (i, p) in d.positions.iter().enumerate() {
                            pos.push(position(r as i64, alpha, i, p));
                        }
                    }
                }
            }
            lat.push(LatticeRow {
                lattice: name.clone(),
                masses: l.n_masses() as i64,
                springs: l.springs.len() as i64,
                rigid_reflexes: rigid as i64,
            });
        }
        Ok(Tables::from([
            ("lattices", table_of(&lat)),
            ("rest_lengths", table_of(&rl)),
            ("positions", table_of(&pos)),
            ("springs", table_of(&spr)),
            ("rule", rule_table_of(&self.rule)?),
        ]))
    }
}

/// Springs `(a, b)` of `lattice` among a `springs` table's rows.
fn springs_of(rows: &[LatticeSpringRow], lattice: &str) -> Vec<(usize, usize)> {
    rows.iter()
        .filter(|s| s.lattice == lattice)
        .map(|s| (s.a as usize, s.b as usize))
        .collect()
}

impl Family for MsLattices {
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "cube",
            "the cube lattice: 8 masses and 28 springs at rest.",
        ),
        (
            "pyramid",
            "the pyramid lattice (the spider) at rest.",
        ),
        (
            "chair",
            "the chair lattice at rest.",
        ),
        (
            "cube_reflexes",
            "the 12 reflex deformations (scale, shear, splay, twist about each axis) applied to the cube's rest lengths.",
        ),
        (
            "pyramid_reflexes",
            "the 12 reflex deformations applied to the pyramid's rest lengths.",
        ),
        (
            "chair_reflexes",
            "the 12 reflex deformations applied to the chair's rest lengths.",
        ),
    ];
    const CHECK: bool = true;
    const KIND: &'static str = "ms_lattices";
    type Params = Params;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        let pos = PositionRow::from_table(tables.require("positions")?);
        let spr = LatticeSpringRow::from_table(tables.require("springs")?);
        let shape = |l: &str, r: i64| -> Vec<[f64; 3]> {
            pos.iter()
                .filter(|p| p.lattice == l && p.reflex == r)
                .map(|p| [p.x, p.y, p.z])
                .collect()
        };
        let mut lattices: Vec<String> = Vec::new();
        for p in &pos {
            if !lattices.contains(&p.lattice) {
                lattices.push(p.lattice.clone());
            }
        }
        let mut files = Vec::new();
        for l in &lattices {
            let springs = springs_of(&spr, l);
            let nm = shape(l, -1).len();
            files.extend(draw_panels(
                &fig.dir,
                &format!("{}_{l}", fig.id),
                &[LatticePanel {
                    title: format!("{l}: {nm} masses, {} springs", springs.len()),
                    positions: shape(l, -1),
                    ghost: None,
                    trail: Vec::new(),
                }],
                &springs,
                1,
                (420, 380),
                false,
                &Scene::default(),
            )?);
            let a = pos
                .iter()
                .find(|p| p.alpha > 0.0 && p.lattice == *l)
                .map_or(1.0, |p| p.alpha);
            let panels: Vec<LatticePanel> = (0..Reflex::COUNT as i64)
                .map(|r| LatticePanel {
                    title: format!(
                        "{r}: {} (alpha = {a})",
                        Reflex::from_number(r as usize)
                            .map(|x| x.name())
                            .unwrap_or_default()
                    ),
                    positions: shape(l, r),
                    ghost: Some(shape(l, -1)),
                    trail: Vec::new(),
                })
                .collect();
            files.extend(draw_panels(
                &fig.dir,
                &format!("{}_{l}_reflexes", fig.id),
                &panels,
                &springs,
                3,
                (340, 300),
                true,
                &Scene::default(),
            )?);
        }
        Ok(files)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        let lattices: Vec<LatticeRow> = read_rows(&dir.join("lattices.csv"))?;
        let rl: Vec<RestLengthRow> = read_rows(&dir.join("rest_lengths.csv"))?;
        let minlen = rl
            .iter()
            .map(|r| r.rest_length)
            .fold(f64::INFINITY, f64::min);
        let mut md = String::from(
            "| lattice | masses | springs | reflexes that change no rest length |\n| --- | --- | --- | --- |\n",
        );
        let r: LatticeRule = read_rule(dir)?;
        let within = |x: f64, lo: usize, hi: usize| (lo as f64..=hi as f64).contains(&x);
        let mut in_range = true;
        let mut cube_ok = false;
        for l in &lattices {
            md.push_str(&format!(
                "| {} | {} | {} | {} |\n",
                l.lattice, l.masses, l.springs, l.rigid_reflexes
            ));
            let (m, s) = (l.masses as f64, l.springs as f64);
            in_range &=
                within(m, r.masses_min, r.masses_max) && within(s, r.springs_min, r.springs_max);
            if l.lattice == "cube" {
                cube_ok = m == r.cube_masses as f64
                    && s == r.cube_springs as f64
                    && l.rigid_reflexes == 0;
            }
        }
        let largest = rl
            .iter()
            .fold(0.0f64, |a, v| a.max(v.rest_length_change.abs()));
        md.push_str(&format!(
            "\nLargest rest-length change of a reflex: {largest:.3} m; shortest deformed rest length: {minlen:.3} m.\n"
        ));
        let rule = lattice_rule(cube_ok, in_range, &r);
        let (verdict, lines, text) = shown(rule.as_ref(), "");
        Ok(Findings {
            ours: md,
            verdict,
            rule: rule.clone(),
            why: format!(
                "An implementation check against the paper's numbers (in the spec's [params.rule]).{lines} Rule: {text}"
            ),
        })
    }
}
