//! `ms_lattices` (MS §2.1–2.2, Fig. 1–3): the three lattices (cube, pyramid "spider", chair)
//! and the 12 reflex deformations (scale, shear, splay, twist × 3 axes) applied to them.
//!
//! Tables: `lattices` (lattice, masses, springs, rigid_reflexes); `rest_lengths` (lattice,
//! reflex, reflex_name, alpha, spring, a, b, rest_length, rest_length_change) for α = ±`alpha`;
//! `positions` (lattice, reflex, alpha, mass, x, y, z; reflex −1 is the rest shape);
//! `springs` (lattice, spring, a, b).

use super::lattice_draw::{draw_panels, LatticePanel, Scene};
use crate::experiment::output::{df_f64, df_str, read_csv, Table, Tables};
use crate::experiment::plot::FigureSink;
use crate::experiment::report::Findings;
use crate::experiment::resolve::{distinct, ensure, ParamError, Validate};
use crate::experiment::rule::{read_rule, rule_table_of, shown, Check, Partly, Rule};
use crate::experiment::{other, Error, Family, Job, RunContext};
use crate::physics::lattice::Lattice;
use crate::physics::reflex::{deform, Reflex, ReflexGains};
use crate::row;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The family.
pub struct MsLattices;

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
        let mut lat = Table::new(&["lattice", "masses", "springs", "rigid_reflexes"]);
        let mut rl = Table::new(&[
            "lattice",
            "reflex",
            "reflex_name",
            "alpha",
            "spring",
            "a",
            "b",
            "rest_length",
            "rest_length_change",
        ]);
        let mut pos = Table::new(&["lattice", "reflex", "alpha", "mass", "x", "y", "z"]);
        let mut spr = Table::new(&["lattice", "spring", "a", "b"]);
        for name in &self.lattices {
            let l = lattice_by_name(name).ok_or_else(|| other("unknown lattice"))?;
            let rest = l.rest_lengths();
            for (j, s) in l.springs.iter().enumerate() {
                spr.push(row![name.as_str(), j, s.a, s.b]);
            }
            for (i, p) in l.rest_positions().iter().enumerate() {
                pos.push(row![name.as_str(), -1i64, 0.0, i, p[0], p[1], p[2]]);
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
                        rl.push(row![
                            name.as_str(),
                            r,
                            rname.as_str(),
                            alpha,
                            j,
                            s.a,
                            s.b,
                            d.rest_lengths[j],
                            dl
                        ]);
                    }
                    if alpha > 0.0 {
                        if change < 1e-9 {
                            rigid += 1;
                        }
                        for (i, p) in d.positions.iter().enumerate() {
                            pos.push(row![name.as_str(), r, alpha, i, p[0], p[1], p[2]]);
                        }
                    }
                }
            }
            lat.push(row![name.as_str(), l.n_masses(), l.springs.len(), rigid]);
        }
        Ok(Tables::from([
            ("lattices", lat),
            ("rest_lengths", rl),
            ("positions", pos),
            ("springs", spr),
            ("rule", rule_table_of(&self.rule)?),
        ]))
    }
}

/// Springs `(a, b)` of `lattice` from a `springs` table; `None`: every spring of a table of
/// one lattice's springs (which has no `lattice` column).
pub fn springs_of(t: &Table, lattice: Option<&str>) -> Vec<(usize, usize)> {
    let names = lattice.map(|_| t.strs("lattice"));
    let (a, b) = (t.f64s("a"), t.f64s("b"));
    (0..a.len())
        .filter(|&i| match (lattice, &names) {
            (Some(l), Some(names)) => names[i] == l,
            _ => true,
        })
        .map(|i| (a[i] as usize, b[i] as usize))
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
        let pos = tables.require("positions")?;
        let spr = tables.require("springs")?;
        let (names, reflex, alpha) = (pos.strs("lattice"), pos.f64s("reflex"), pos.f64s("alpha"));
        let (x, y, z) = (pos.f64s("x"), pos.f64s("y"), pos.f64s("z"));
        let shape = |l: &str, r: i64| -> Vec<[f64; 3]> {
            (0..x.len())
                .filter(|&i| names[i] == l && reflex[i] as i64 == r)
                .map(|i| [x[i], y[i], z[i]])
                .collect()
        };
        let mut lattices: Vec<String> = Vec::new();
        for n in &names {
            if !lattices.contains(n) {
                lattices.push(n.clone());
            }
        }
        let mut files = Vec::new();
        for l in &lattices {
            let springs = springs_of(spr, Some(l));
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
            let a = alpha
                .iter()
                .zip(&names)
                .find(|(a, n)| **a > 0.0 && *n == l)
                .map(|(a, _)| *a)
                .unwrap_or(1.0);
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
        let df = read_csv(&dir.join("lattices.csv"))?;
        let names = df_str(&df, "lattice")?;
        let (m, s, rigid) = (
            df_f64(&df, "masses")?,
            df_f64(&df, "springs")?,
            df_f64(&df, "rigid_reflexes")?,
        );
        let rl = read_csv(&dir.join("rest_lengths.csv"))?;
        let change = df_f64(&rl, "rest_length_change")?;
        let minlen = df_f64(&rl, "rest_length")?
            .into_iter()
            .fold(f64::INFINITY, f64::min);
        let mut md = String::from(
            "| lattice | masses | springs | reflexes that change no rest length |\n| --- | --- | --- | --- |\n",
        );
        let r: LatticeRule = read_rule(dir)?;
        let within = |x: f64, lo: usize, hi: usize| (lo as f64..=hi as f64).contains(&x);
        let mut in_range = true;
        let mut cube_ok = false;
        for i in 0..names.len() {
            md.push_str(&format!(
                "| {} | {} | {} | {} |\n",
                names[i], m[i], s[i], rigid[i]
            ));
            in_range &= within(m[i], r.masses_min, r.masses_max)
                && within(s[i], r.springs_min, r.springs_max);
            if names[i] == "cube" {
                cube_ok = m[i] == r.cube_masses as f64
                    && s[i] == r.cube_springs as f64
                    && rigid[i] == 0.0;
            }
        }
        let largest = change.iter().fold(0.0f64, |a, v| a.max(v.abs()));
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
