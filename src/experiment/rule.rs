//! # Verdicts as data: checks that can fail, graded by one rule
//!
//! A family judges a paper's claim by a [`Rule`]: premise checks (the condition the claim
//! rests on), the checks that make it *held*, and which of them make it *partly held*. Each
//! [`Check`] holds its label, the measured value, the comparison and threshold (read from the
//! spec's typed parameters, never restated in prose), and its **null**: what doing nothing,
//! the starting point, an example alone or the baseline scores on the same measure.
//! [`Check::new`] refuses a check its null passes, so a check that cannot fail cannot be
//! written. The rule text, the yes/no lines and the verdict all come from the same objects
//! ([`Rule::text`], [`Rule::lines`], [`Rule::verdict`]): prose fills in values only.
//!
//! Where a value is stochastic, a check carries its 95% interval ([`Check::with_interval`]);
//! an interval that straddles the threshold makes the check *inconclusive*, and a verdict that
//! turns on an inconclusive check is [`Verdict::Inconclusive`].

use super::output::{df_f64, df_str, read_csv, Table, Tables};
use super::report::{sig, Verdict};
use super::Error;
use crate::row;
use std::fmt::Write as _;
use std::path::Path;

/// How a check's value must compare with its threshold to pass.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cmp {
    /// value ≥ threshold.
    AtLeast,
    /// value ≤ threshold.
    AtMost,
    /// value > threshold.
    Above,
    /// value < threshold.
    Below,
}

impl Cmp {
    /// Whether `value` passes against `threshold` (NaN never passes).
    pub fn passes(self, value: f64, threshold: f64) -> bool {
        match self {
            Cmp::AtLeast => value >= threshold,
            Cmp::AtMost => value <= threshold,
            Cmp::Above => value > threshold,
            Cmp::Below => value < threshold,
        }
    }

    /// The comparison as the report writes it.
    pub fn symbol(self) -> &'static str {
        match self {
            Cmp::AtLeast => ">=",
            Cmp::AtMost => "<=",
            Cmp::Above => ">",
            Cmp::Below => "<",
        }
    }
}

/// What a check's measure scores without the method under test: doing nothing, the start, an
/// example alone, the baseline.
#[derive(Debug, Clone, PartialEq)]
pub struct Null {
    /// What it is, e.g. "the initial random best" or "PD at x1".
    pub label: String,
    /// Its value on the check's measure.
    pub value: f64,
}

impl Null {
    /// A null named `label` scoring `value`.
    pub fn new(label: impl Into<String>, value: f64) -> Self {
        Self {
            label: label.into(),
            value,
        }
    }
}

/// Why a check cannot be written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RuleError {
    /// The null passes the check, so the check cannot fail for want of the method.
    #[error("check `{label}`: its null ({null}, {value}) passes {cmp} {threshold}, so the check cannot fail")]
    NullPasses {
        /// The check.
        label: String,
        /// The null's label.
        null: String,
        /// The null's value.
        value: f64,
        /// The comparison.
        cmp: &'static str,
        /// The threshold.
        threshold: f64,
    },
    /// The threshold is not a finite number.
    #[error("check `{label}`: threshold {threshold} is not finite")]
    Threshold {
        /// The check.
        label: String,
        /// The threshold.
        threshold: f64,
    },
}

/// A check's outcome.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// It passed (its whole interval, where it has one).
    Pass,
    /// It failed (its whole interval).
    Fail,
    /// Its interval straddles the threshold.
    Inconclusive,
}

impl Outcome {
    /// The report's word.
    pub fn word(self) -> &'static str {
        match self {
            Outcome::Pass => "yes",
            Outcome::Fail => "no",
            Outcome::Inconclusive => "inconclusive",
        }
    }
}

/// One check of a rule.
#[derive(Debug, Clone, PartialEq)]
pub struct Check {
    /// What it checks, e.g. "LBC lands every desired jump".
    pub label: String,
    /// The measured value.
    pub value: f64,
    /// A 95% interval of the value, where it is stochastic.
    pub interval: Option<(f64, f64)>,
    /// How the value must compare with the threshold.
    pub cmp: Cmp,
    /// The threshold (from the spec's parameters).
    pub threshold: f64,
    /// What the measure scores without the method.
    pub null: Null,
    /// A condition of the setup ([`Check::fact`]), not a measure of the method.
    pub fact: bool,
}

impl Check {
    /// A check `label`: `value` `cmp` `threshold`, whose `null` must fail it.
    pub fn new(
        label: impl Into<String>,
        value: f64,
        cmp: Cmp,
        threshold: f64,
        null: Null,
    ) -> Result<Self, RuleError> {
        let label = label.into();
        if !threshold.is_finite() {
            return Err(RuleError::Threshold { label, threshold });
        }
        if cmp.passes(null.value, threshold) {
            return Err(RuleError::NullPasses {
                label,
                null: null.label,
                value: null.value,
                cmp: cmp.symbol(),
                threshold,
            });
        }
        Ok(Self {
            label,
            value,
            interval: None,
            cmp,
            threshold,
            null,
            fact: false,
        })
    }

    /// A condition of the setup (a premise such as "each desired jump's landing tracker lands
    /// from the desired take-off itself"), not of the method under test: 1 when it `holds`,
    /// needing 1, its null the condition absent (0).
    pub fn fact(label: impl Into<String>, holds: bool) -> Self {
        Self {
            label: label.into(),
            value: f64::from(u8::from(holds)),
            interval: None,
            cmp: Cmp::AtLeast,
            threshold: 1.0,
            null: Null::new("the condition absent", 0.0),
            fact: true,
        }
    }

    /// The same check with a 95% interval `(lo, hi)` of its value.
    pub fn with_interval(mut self, lo: f64, hi: f64) -> Self {
        self.interval = Some((lo.min(hi), lo.max(hi)));
        self
    }

    /// Pass, fail, or inconclusive where the interval straddles the threshold.
    pub fn outcome(&self) -> Outcome {
        let pass = self.cmp.passes(self.value, self.threshold);
        match self.interval {
            Some((lo, hi)) => {
                let (a, b) = (
                    self.cmp.passes(lo, self.threshold),
                    self.cmp.passes(hi, self.threshold),
                );
                if a && b {
                    Outcome::Pass
                } else if !a && !b {
                    Outcome::Fail
                } else {
                    Outcome::Inconclusive
                }
            }
            None if pass => Outcome::Pass,
            None => Outcome::Fail,
        }
    }

    /// The rule's wording of the check: "label (value >= threshold)", or the label alone for a
    /// [`Check::fact`].
    pub fn rule_text(&self) -> String {
        if self.fact {
            return self.label.clone();
        }
        format!(
            "{} (measure {} {})",
            self.label,
            self.cmp.symbol(),
            sig(self.threshold)
        )
    }

    /// The report's line: label, value (and interval), threshold and outcome.
    pub fn line(&self) -> String {
        if self.fact {
            return format!("{}: {}", self.label, self.outcome().word());
        }
        let interval = self.interval.map_or_else(String::new, |iv| {
            format!(" [95% interval {}]", interval_bounds(iv))
        });
        format!(
            "{}: {}{interval} {} {}: {}",
            self.label,
            sig(self.value),
            self.cmp.symbol(),
            sig(self.threshold),
            self.outcome().word(),
        )
    }
}

/// The fewest of `k` seeds (or runs) that are a strict majority.
pub fn majority(k: usize) -> usize {
    k / 2 + 1
}

/// "(a)", "(b)", … for the i-th held check.
fn tag(i: usize) -> String {
    format!("({})", (b'a' + (i % 26) as u8) as char)
}

/// Equal keys grouped as "(a)-(c)" / "(a), (d)" labels with the key, in order of first
/// appearance.
fn grouped<K: PartialEq + Clone>(keys: &[K]) -> Vec<(String, K)> {
    let mut out: Vec<(Vec<usize>, K)> = Vec::new();
    for (i, k) in keys.iter().enumerate() {
        match out.iter_mut().find(|(_, g)| g == k) {
            Some((ids, _)) => ids.push(i),
            None => out.push((vec![i], k.clone())),
        }
    }
    out.into_iter()
        .map(|(ids, k)| {
            let contiguous = ids.windows(2).all(|w| w[1] == w[0] + 1);
            let label = match (ids.first(), ids.last()) {
                (Some(&a), Some(&b)) if a == b => tag(a),
                (Some(&a), Some(&b)) if contiguous => format!("{}-{}", tag(a), tag(b)),
                _ => ids.iter().map(|&i| tag(i)).collect::<Vec<_>>().join(", "),
            };
            (label, k)
        })
        .collect()
}

/// Which held checks make a claim partly held.
#[derive(Debug, Clone, PartialEq)]
pub enum Partly {
    /// Any one of them.
    Any,
    /// All of these (indices into the held checks).
    All(Vec<usize>),
    /// Every check of any one of these groups (a claim over several tasks, each judged by
    /// one or more checks: partly when some task passes all of its own).
    AnyOf(Vec<Vec<usize>>),
    /// At least this many of the held checks, whichever.
    AtLeast(usize),
    /// No partly grade.
    Never,
}

/// A claim's rule: premise checks, held checks, and its partly grade.
#[derive(Debug, Clone, PartialEq)]
pub struct Rule {
    /// The condition the claim rests on (all must pass, else "premise not reproduced").
    pub premise: Vec<Check>,
    /// Held needs all of these.
    pub held: Vec<Check>,
    /// Which of them make it partly held.
    pub partly: Partly,
}

impl Rule {
    /// A rule whose held checks were built with [`Check::new`]: where the premise passes every
    /// one must have been built (a refused check there means its null passes: `None`); where
    /// it fails the verdict is "premise not reproduced" whatever they say, so the refused ones
    /// are left out (an example alone that does what the premise says it cannot passes them).
    pub fn gated(
        premise: Vec<Check>,
        held: Vec<Result<Check, RuleError>>,
        partly: Partly,
    ) -> Option<Self> {
        let holds = premise.iter().all(|c| c.outcome() != Outcome::Fail);
        let held: Vec<Check> = if holds {
            held.into_iter().collect::<Result<_, _>>().ok()?
        } else {
            held.into_iter().filter_map(Result::ok).collect()
        };
        Some(Self {
            premise,
            held,
            partly,
        })
    }

    /// The verdict under one resolution of inconclusive checks (`optimistic`: they pass).
    fn resolve(&self, optimistic: bool) -> Verdict {
        let ok = |c: &Check| match c.outcome() {
            Outcome::Pass => true,
            Outcome::Fail => false,
            Outcome::Inconclusive => optimistic,
        };
        if !self.premise.iter().all(ok) {
            return Verdict::PremiseNotReproduced;
        }
        let passed: Vec<bool> = self.held.iter().map(ok).collect();
        if !passed.is_empty() && passed.iter().all(|&p| p) {
            return Verdict::Held;
        }
        let partly = match &self.partly {
            Partly::Any => passed.iter().any(|&p| p),
            Partly::All(ids) => !ids.is_empty() && ids.iter().all(|&i| passed[i]),
            Partly::AnyOf(groups) => groups
                .iter()
                .any(|ids| !ids.is_empty() && ids.iter().all(|&i| passed[i])),
            Partly::AtLeast(k) => *k > 0 && passed.iter().filter(|&&p| p).count() >= *k,
            Partly::Never => false,
        };
        if partly {
            Verdict::Partly
        } else {
            Verdict::NotHeld
        }
    }

    /// The verdict: the same whether the inconclusive checks pass or fail, else
    /// [`Verdict::Inconclusive`].
    pub fn verdict(&self) -> Verdict {
        let (hi, lo) = (self.resolve(true), self.resolve(false));
        if hi == lo {
            hi
        } else {
            Verdict::Inconclusive
        }
    }

    /// The rule in words, generated from its checks: premise, held (checks with one comparison
    /// and threshold grouped), partly, and each check's null.
    pub fn text(&self) -> String {
        let mut t = String::new();
        if !self.premise.is_empty() {
            let p: Vec<String> = self.premise.iter().map(Check::rule_text).collect();
            let _ = write!(
                t,
                "Premise (else \"premise not reproduced\"): {}. ",
                p.join("; ")
            );
        }
        let bars: Vec<(&'static str, String)> = self
            .held
            .iter()
            .map(|c| (c.cmp.symbol(), sig(c.threshold)))
            .collect();
        let h: Vec<String> = grouped(&bars)
            .into_iter()
            .map(|(ids, (cmp, th))| format!("{ids} {cmp} {th}"))
            .collect();
        let _ = write!(t, "Held needs every check: {}", h.join("; "));
        match &self.partly {
            Partly::Any => t.push_str("; partly needs any one of them"),
            Partly::All(ids) => {
                let p: Vec<String> = ids.iter().map(|&i| tag(i)).collect();
                let _ = write!(t, "; partly needs {}", p.join(" and "));
            }
            Partly::AnyOf(groups) => {
                let g: Vec<String> = groups
                    .iter()
                    .map(|ids| {
                        ids.iter()
                            .map(|&i| tag(i))
                            .collect::<Vec<_>>()
                            .join(" and ")
                    })
                    .collect();
                let _ = write!(t, "; partly needs {}", g.join(", or "));
            }
            Partly::AtLeast(k) => {
                let _ = write!(t, "; partly needs any {k} of them");
            }
            Partly::Never => {}
        }
        let nulls: Vec<(String, String)> = self
            .held
            .iter()
            .map(|c| (c.null.label.clone(), sig(c.null.value)))
            .collect();
        let n: Vec<String> = grouped(&nulls)
            .into_iter()
            .map(|(ids, (label, v))| format!("{ids} {label}, {v}"))
            .collect();
        let _ = write!(
            t,
            ". Each check's null (what doing nothing, the start, an example alone or the baseline scores on it) fails it: {}. An interval that straddles a threshold makes a check inconclusive.",
            n.join("; ")
        );
        t
    }

    /// How the grades are given, as [`Rule::text`] words it after "Held needs" (up to the
    /// nulls).
    fn grading(&self) -> String {
        let text = self.text();
        text.split_once("Held needs")
            .map(|(_, g)| g.split(". Each check's null").next().unwrap_or(g))
            .unwrap_or("")
            .to_string()
    }

    /// Every check's line (premise first), each with its outcome.
    pub fn lines(&self) -> String {
        let mut t = String::new();
        for c in &self.premise {
            let _ = write!(t, " Premise, {}.", c.line());
        }
        for (i, c) in self.held.iter().enumerate() {
            let _ = write!(t, " {} {}.", tag(i), c.line());
        }
        t
    }
}

/// A check's interval as the report writes it after its value: " [lo-hi]", or " [lo to hi]"
/// when a bound is negative (a hyphen beside a minus sign reads as a double minus).
fn interval_text(iv: (f64, f64)) -> String {
    format!(" [{}]", interval_bounds(iv))
}

/// An interval's bounds in words: "lo-hi", or "lo to hi" when a bound is negative.
fn interval_bounds((lo, hi): (f64, f64)) -> String {
    if lo < 0.0 || hi < 0.0 {
        format!("{} to {}", sig(lo), sig(hi))
    } else {
        format!("{}-{}", sig(lo), sig(hi))
    }
}

impl Rule {
    /// The claims table's one-line reason: for held, that every check passed; otherwise the
    /// first premise check that failed, else the first held check that was inconclusive (for an
    /// inconclusive verdict) or failed, with its value against its bar.
    pub fn reason(&self) -> String {
        let verdict = self.verdict();
        let short = |tag: &str, c: &Check| {
            let interval = c.interval.map_or_else(String::new, interval_text);
            if c.fact {
                format!("{tag}{}: no", c.label)
            } else {
                format!(
                    "{tag}{}: {}{interval}, needs {} {}",
                    c.label,
                    sig(c.value),
                    c.cmp.symbol(),
                    sig(c.threshold)
                )
            }
        };
        if let Some(c) = self.premise.iter().find(|c| c.outcome() == Outcome::Fail) {
            return format!("premise: {}", short("", c));
        }
        if verdict == Verdict::Held {
            return format!("all {} checks pass", self.held.len());
        }
        let wanted = if verdict == Verdict::Inconclusive {
            Outcome::Inconclusive
        } else {
            Outcome::Fail
        };
        let failed = self
            .held
            .iter()
            .filter(|c| c.outcome() != Outcome::Pass)
            .count();
        match self
            .held
            .iter()
            .enumerate()
            .find(|(_, c)| c.outcome() == wanted)
        {
            Some((i, c)) => {
                let more = if failed > 1 {
                    format!(" (and {} more)", failed - 1)
                } else {
                    String::new()
                };
                format!("{}{more}", short(&format!("{} ", tag(i)), c))
            }
            None => String::new(),
        }
    }

    /// The report's bullets: every check (premise first) with its value, bar, null and
    /// outcome, then how the grades are given.
    pub fn bullets(&self) -> String {
        let mut t = String::new();
        let null = |c: &Check| {
            if c.fact {
                String::new()
            } else {
                format!(" (null: {}, {})", c.null.label, sig(c.null.value))
            }
        };
        for c in &self.premise {
            let _ = writeln!(t, "- Premise: {}{}", c.line(), null(c));
        }
        for (i, c) in self.held.iter().enumerate() {
            let _ = writeln!(t, "- {} {}{}", tag(i), c.line(), null(c));
        }
        let grading = self.grading();
        let _ = writeln!(t, "- Grades: held needs{grading}.");
        t
    }
}

impl Rule {
    /// How many groups of a [`Partly::AnyOf`] rule (each a task, say) pass every one of their
    /// checks (inconclusive is not a pass); 0 under another grading.
    pub fn groups_passing(&self) -> usize {
        match &self.partly {
            Partly::AnyOf(groups) => groups
                .iter()
                .filter(|g| {
                    g.iter().all(|&i| {
                        self.held
                            .get(i)
                            .is_some_and(|c| c.outcome() == Outcome::Pass)
                    })
                })
                .count(),
            _ => 0,
        }
    }

    /// The report's table of checks: one row per check (premise first) with its value and
    /// interval, its bar, its null and its outcome, then the grading as one line below it. A
    /// table reads faster than the bullets when a rule has many checks; the bullets stay in
    /// the details.
    pub fn table(&self) -> String {
        let cell = |s: &str| s.replace('|', "\\|");
        let row = |t: &mut String, tag: &str, c: &Check| {
            let (ours, needs, null) = if c.fact {
                (String::new(), String::new(), String::new())
            } else {
                let interval = c.interval.map_or_else(String::new, interval_text);
                (
                    format!("{}{interval}", sig(c.value)),
                    format!("{} {}", c.cmp.symbol(), sig(c.threshold)),
                    format!("{}, {}", c.null.label, sig(c.null.value)),
                )
            };
            let _ = writeln!(
                t,
                "| {tag} | {} | {ours} | {needs} | {} | {} |",
                cell(&c.label),
                cell(&null),
                c.outcome().word()
            );
        };
        let mut t = String::from("| | check | ours | needs | null (fails it) | result |\n| --- | --- | --- | --- | --- | --- |\n");
        for c in &self.premise {
            row(&mut t, "premise", c);
        }
        for (i, c) in self.held.iter().enumerate() {
            row(&mut t, &tag(i), c);
        }
        t.push('\n');
        let grading = self.grading();
        let _ = writeln!(t, "- Rule: held needs{grading}.");
        t
    }
}

/// What a report shows of a rule that may be missing: its verdict, its check lines and its
/// text; without a rule, not assessed, no lines and `missing` (why there is none) as the text.
pub fn shown(rule: Option<&Rule>, missing: &str) -> (Verdict, String, String) {
    rule.map_or_else(
        || (Verdict::NotAssessed, String::new(), missing.to_string()),
        |r| (r.verdict(), r.lines(), r.text()),
    )
}

/// The settings of an experiment's `rule` table (columns setting, value) in `dir`, by name;
/// NaN for a setting the table lacks.
pub fn rule_settings(dir: &Path) -> Result<impl Fn(&str) -> f64, Error> {
    let rule = read_csv(&dir.join("rule.csv"))?;
    let (rk, rv) = (df_str(&rule, "setting")?, df_f64(&rule, "value")?);
    Ok(move |k: &str| rk.iter().position(|s| s == k).map_or(f64::NAN, |i| rv[i]))
}

/// The setting `key` of a run's in-memory `rule` table (what [`rule_settings`] reads from the
/// CSV), for figures; `None` without the table or the key.
pub fn rule_setting(tables: &Tables, key: &str) -> Option<f64> {
    let rule = tables.get("rule")?;
    let (k, v) = (rule.strs("setting"), rule.f64s("value"));
    k.iter().position(|s| s == key).map(|i| v[i])
}

/// The `rule` table (columns setting, value) that [`rule_settings`] reads back: the verdict's
/// settings, written beside the results so the report judges with the run's own values.
pub fn rule_table(settings: &[(&str, f64)]) -> Table {
    let mut rule = Table::new(&["setting", "value"]);
    for &(k, v) in settings {
        rule.push(row![k, v]);
    }
    rule
}

/// The `rule` table of a thresholds struct `bars` whose fields are all numbers (its serde
/// field names are the settings), so the thresholds are written once, in the struct.
pub fn rule_table_of<T: serde::Serialize>(bars: &T) -> Result<Table, Error> {
    let settings = crate::params::bars_of(bars)
        .map_err(|e| super::other(format!("{}: {}", e.key, e.message)))?;
    let settings: Vec<(&str, f64)> = settings.iter().map(|(k, v)| (k.as_str(), *v)).collect();
    Ok(rule_table(&settings))
}

/// The thresholds struct that [`rule_table_of`] wrote to `dir`'s `rule.csv`, read back (a
/// setting the table lacks is an error naming it).
pub fn read_rule<T: serde::de::DeserializeOwned>(dir: &Path) -> Result<T, Error> {
    let rule = read_csv(&dir.join("rule.csv"))?;
    let (rk, rv) = (df_str(&rule, "setting")?, df_f64(&rule, "value")?);
    let mut map = serde_json::Map::new();
    for (k, v) in rk.into_iter().zip(rv) {
        // Whole numbers as integers, so counts read back into integer fields.
        let n = if v.fract() == 0.0 && v.abs() < 9.0e15 {
            serde_json::Number::from(v as i64)
        } else {
            serde_json::Number::from_f64(v)
                .ok_or_else(|| super::other(format!("rule setting `{k}` is {v}")))?
        };
        map.insert(k, serde_json::Value::Number(n));
    }
    serde_json::from_value(serde_json::Value::Object(map))
        .map_err(|e| super::other(format!("{}: {e}", dir.join("rule.csv").display())))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(value: f64, threshold: f64, null: f64) -> Check {
        Check::new(
            "gain",
            value,
            Cmp::AtLeast,
            threshold,
            Null::new("nothing", null),
        )
        .unwrap()
    }

    #[test]
    fn thresholds_round_trip_through_the_rule_table() {
        #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
        struct Bars {
            share: f64,
            seeds: usize,
        }
        let bars = Bars {
            share: 0.6,
            seeds: 5,
        };
        let dir = tempfile::tempdir().unwrap();
        let table = rule_table_of(&bars).unwrap();
        super::super::output::write_table(dir.path(), "rule", &table).unwrap();
        assert_eq!(read_rule::<Bars>(dir.path()).unwrap(), bars);
        // A struct with a setting the run did not write is refused by name.
        #[derive(Debug, serde::Deserialize)]
        #[allow(dead_code)]
        struct More {
            share: f64,
            seeds: usize,
            extra: f64,
        }
        let e = read_rule::<More>(dir.path()).unwrap_err().to_string();
        assert!(e.contains("extra") && e.contains("rule.csv"), "{e}");
    }

    #[test]
    fn a_check_whose_null_passes_is_refused() {
        // A search that makes no progress scores its initial best: a threshold below it
        // cannot fail.
        let e = Check::new(
            "final best",
            9.0,
            Cmp::AtLeast,
            2.21,
            Null::new("the initial random best", 2.30),
        )
        .unwrap_err();
        assert!(matches!(e, RuleError::NullPasses { .. }), "{e}");
        assert!(e.to_string().contains("cannot fail"));
        assert!(Check::new("x", 1.0, Cmp::Below, f64::NAN, Null::new("n", 2.0)).is_err());
        assert!(Check::new("x", 1.0, Cmp::Below, 1.5, Null::new("n", 2.0)).is_ok());
    }

    #[test]
    fn comparisons_are_strict_or_not_as_named() {
        assert!(Cmp::AtLeast.passes(1.0, 1.0) && !Cmp::Above.passes(1.0, 1.0));
        assert!(Cmp::AtMost.passes(1.0, 1.0) && !Cmp::Below.passes(1.0, 1.0));
        assert!(!Cmp::AtLeast.passes(f64::NAN, 0.0) && !Cmp::AtMost.passes(f64::NAN, 0.0));
    }

    #[test]
    fn an_interval_straddling_the_threshold_is_inconclusive() {
        assert_eq!(check(2.0, 1.0, 0.0).outcome(), Outcome::Pass);
        assert_eq!(
            check(2.0, 1.0, 0.0).with_interval(1.5, 2.5).outcome(),
            Outcome::Pass
        );
        assert_eq!(
            check(2.0, 1.0, 0.0).with_interval(0.5, 2.5).outcome(),
            Outcome::Inconclusive
        );
        assert_eq!(
            check(0.5, 1.0, 0.0).with_interval(0.2, 0.9).outcome(),
            Outcome::Fail
        );
    }

    #[test]
    fn the_rule_grades_premise_held_partly_and_inconclusive() {
        let (pass, fail) = (check(2.0, 1.0, 0.0), check(0.5, 1.0, 0.0));
        let rule = |premise: Vec<Check>, held: Vec<Check>, partly| Rule {
            premise,
            held,
            partly,
        };
        let r = rule(vec![], vec![pass.clone(), pass.clone()], Partly::Any);
        assert_eq!(r.verdict(), Verdict::Held);
        let r = rule(vec![], vec![pass.clone(), fail.clone()], Partly::Any);
        assert_eq!(r.verdict(), Verdict::Partly);
        let r = rule(
            vec![],
            vec![pass.clone(), fail.clone()],
            Partly::All(vec![1]),
        );
        assert_eq!(r.verdict(), Verdict::NotHeld);
        let groups = Partly::AnyOf(vec![vec![0], vec![1, 2]]);
        let r = rule(
            vec![],
            vec![fail.clone(), pass.clone(), fail.clone()],
            groups.clone(),
        );
        assert_eq!(r.verdict(), Verdict::NotHeld);
        assert!(r.text().contains("partly needs (a), or (b) and (c)"));
        let r = rule(
            vec![],
            vec![fail.clone(), pass.clone(), pass.clone()],
            groups,
        );
        assert_eq!(r.verdict(), Verdict::Partly);
        let r = rule(vec![], vec![fail.clone()], Partly::Any);
        assert_eq!(r.verdict(), Verdict::NotHeld);
        let three = vec![pass.clone(), fail.clone(), pass.clone()];
        let r = rule(vec![], three.clone(), Partly::AtLeast(2));
        assert_eq!(r.verdict(), Verdict::Partly);
        assert!(r.text().contains("partly needs any 2 of them"));
        let r = rule(vec![], three, Partly::AtLeast(3));
        assert_eq!(r.verdict(), Verdict::NotHeld);
        let r = rule(vec![fail.clone()], vec![pass.clone()], Partly::Any);
        assert_eq!(r.verdict(), Verdict::PremiseNotReproduced);
        // An inconclusive check that decides between held and partly.
        let unsure = pass.clone().with_interval(0.5, 2.5);
        let r = rule(vec![], vec![pass.clone(), unsure.clone()], Partly::Any);
        assert_eq!(r.verdict(), Verdict::Inconclusive);
        // One that cannot change the verdict (partly either way) does not make it so.
        let r = rule(vec![], vec![fail.clone(), unsure, pass], Partly::Any);
        assert_eq!(r.verdict(), Verdict::Partly);
    }

    #[test]
    fn the_reason_names_the_first_failing_check_or_that_all_pass() {
        let (pass, fail) = (check(2.0, 1.0, 0.0), check(0.5, 1.0, 0.0));
        let rule = |premise: Vec<Check>, held: Vec<Check>| Rule {
            premise,
            held,
            partly: Partly::Any,
        };
        assert_eq!(
            rule(vec![], vec![pass.clone()]).reason(),
            "all 1 checks pass"
        );
        let r = rule(vec![], vec![pass.clone(), fail.clone(), fail.clone()]);
        assert_eq!(r.reason(), "(b) gain: 0.500, needs >= 1.00 (and 1 more)");
        let r = rule(vec![fail.clone()], vec![pass.clone()]);
        assert_eq!(r.reason(), "premise: gain: 0.500, needs >= 1.00");
        let unsure = pass.clone().with_interval(0.5, 2.5);
        let r = rule(vec![], vec![pass.clone(), unsure]);
        assert_eq!(r.reason(), "(b) gain: 2.00 [0.500-2.50], needs >= 1.00");
        assert_eq!(interval_text((-1.31, -0.226)), " [-1.31 to -0.226]");
        let b = r.bullets();
        assert!(
            b.contains("- (a) gain: 2.00 >= 1.00: yes (null: nothing, 0)"),
            "{b}"
        );
        assert!(b.contains("- Grades: held needs every check"), "{b}");
        let t = r.table();
        assert!(
            t.contains("| (a) | gain | 2.00 | >= 1.00 | nothing, 0 | yes |"),
            "{t}"
        );
        assert!(
            t.contains("| (b) | gain | 2.00 [0.500-2.50] | >= 1.00 | nothing, 0 | inconclusive |"),
            "{t}"
        );
        assert!(t.contains("- Rule: held needs every check"), "{t}");
    }

    #[test]
    fn groups_passing_counts_groups_whose_checks_all_pass() {
        let (pass, fail) = (check(2.0, 1.0, 0.0), check(0.5, 1.0, 0.0));
        let unsure = pass.clone().with_interval(0.5, 2.5);
        let r = Rule {
            premise: vec![],
            held: vec![pass.clone(), pass.clone(), fail, unsure, pass],
            partly: Partly::AnyOf(vec![vec![0, 1], vec![2], vec![3], vec![4]]),
        };
        assert_eq!(r.groups_passing(), 2);
        let any = Rule {
            partly: Partly::Any,
            ..r
        };
        assert_eq!(any.groups_passing(), 0);
    }

    #[test]
    fn a_gated_rule_drops_refused_checks_only_where_its_premise_fails() {
        let refused = || Check::new("x", 2.0, Cmp::AtLeast, 1.0, Null::new("n", 1.5));
        assert!(refused().is_err());
        let held = || vec![Ok(check(2.0, 1.0, 0.0)), refused()];
        assert!(Rule::gated(vec![Check::fact("setup", true)], held(), Partly::Any).is_none());
        let r = Rule::gated(vec![Check::fact("setup", false)], held(), Partly::Any).unwrap();
        assert_eq!(r.held.len(), 1);
        assert_eq!(r.verdict(), Verdict::PremiseNotReproduced);
    }

    #[test]
    fn the_rule_text_and_lines_come_from_the_checks() {
        let r = Rule {
            premise: vec![check(3.0, 1.0, 0.0)],
            held: vec![check(2.0, 1.5, 0.0), check(0.5, 1.0, 0.0)],
            partly: Partly::All(vec![0]),
        };
        let t = r.text();
        assert!(
            t.contains("Held needs every check: (a) >= 1.50; (b) >= 1.00"),
            "{t}"
        );
        assert!(t.contains("partly needs (a)"), "{t}");
        assert!(t.contains("fails it: (a)-(b) nothing, 0."), "{t}");
        let l = r.lines();
        assert!(l.contains("(b) gain: 0.500 >= 1.00: no."), "{l}");
        assert!(l.contains("Premise, gain: 3.00 >= 1.00: yes."), "{l}");
        assert_eq!(r.verdict(), Verdict::Partly);
    }
}

/// The string literals of Rust source `src` (ordinary and raw strings; escapes kept as
/// written, comments and char literals skipped).
#[cfg(test)]
fn string_literals(src: &str) -> Vec<String> {
    let b = src.as_bytes();
    let (mut out, mut i) = (Vec::new(), 0);
    while i < b.len() {
        match b[i] {
            b'/' if b.get(i + 1) == Some(&b'/') => {
                while i < b.len() && b[i] != b'\n' {
                    i += 1;
                }
            }
            b'/' if b.get(i + 1) == Some(&b'*') => {
                i += 2;
                while i + 1 < b.len() && !(b[i] == b'*' && b[i + 1] == b'/') {
                    i += 1;
                }
                i += 2;
            }
            b'\'' => {
                // A char literal ('x', '\n', '\'') or a lifetime ('a): skip either.
                if b.get(i + 1) == Some(&b'\\') {
                    i += 3;
                    while i < b.len() && b[i] != b'\'' {
                        i += 1;
                    }
                    i += 1;
                } else if b.get(i + 2) == Some(&b'\'') {
                    i += 3;
                } else {
                    i += 1;
                }
            }
            b'r' if matches!(b.get(i + 1), Some(b'"' | b'#'))
                && (i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_')) =>
            {
                let mut j = i + 1;
                while b.get(j) == Some(&b'#') {
                    j += 1;
                }
                if b.get(j) != Some(&b'"') {
                    i += 1;
                    continue;
                }
                let hashes = j - i - 1;
                let close = format!("\"{}", "#".repeat(hashes));
                let start = j + 1;
                let end = src[start..].find(&close).map_or(b.len(), |k| start + k);
                out.push(src[start..end].to_string());
                i = end + close.len();
            }
            b'"' => {
                let start = i + 1;
                let mut j = start;
                while j < b.len() && b[j] != b'"' {
                    j += if b[j] == b'\\' { 2 } else { 1 };
                }
                out.push(src[start..j.min(b.len())].to_string());
                i = j + 1;
            }
            _ => i += 1,
        }
    }
    out
}

/// Whether a string literal states a verdict's rule by hand: it names a grade (held, partly)
/// and compares with a number ("held needs at least 0.9", "partly if <= 3").
#[cfg(test)]
fn states_a_rule(lit: &str) -> bool {
    let l = lit.to_lowercase();
    let grade = [
        "held needs",
        "held if",
        "held when",
        "held:",
        "partly needs",
        "partly if",
    ]
    .iter()
    .chain(&["partly when", "partly:", "held bar", "partly bar"])
    .any(|g| l.contains(g));
    let number_after = |word: &str| {
        l.match_indices(word).any(|(k, _)| {
            l[k + word.len()..]
                .trim_start()
                .trim_start_matches(['(', '$', '|'])
                .starts_with(|c: char| c.is_ascii_digit())
        })
    };
    let compares = [
        ">=",
        "<=",
        "> ",
        "< ",
        "at least",
        "at most",
        "more than",
        "less than",
        "below",
        "above",
        "within",
    ]
    .iter()
    .any(|w| number_after(w));
    grade && compares
}

#[cfg(test)]
mod literal_scan {
    use super::{states_a_rule, string_literals};
    use std::path::{Path, PathBuf};

    fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                rust_files(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }

    #[test]
    fn the_scanner_finds_literals_and_rules() {
        let src = "let a = 'x'; // \"not this\"\nlet s = \"held needs at least 0.9 \\\" turns\"; let r = r#\"partly if <= 3\"#; /* \"nor this\" */";
        let lits = string_literals(src);
        assert_eq!(lits.len(), 2, "{lits:?}");
        assert!(states_a_rule(&lits[0]) && states_a_rule(&lits[1]));
        assert!(!states_a_rule("held: {}"));
        assert!(!states_a_rule("at least 3 seeds"));
        assert!(states_a_rule("held bar: 1 m; partly more than 0.3 m"));
    }

    #[test]
    fn no_family_states_a_rule_in_a_string_literal() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut files = Vec::new();
        rust_files(&root.join("src/families"), &mut files);
        files.sort();
        let mut offenders = Vec::new();
        for f in &files {
            let rel = f
                .strip_prefix(root)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            let src = std::fs::read_to_string(f).unwrap();
            // Tests may spell a rule out to check it.
            let code = src.split("#[cfg(test)]").next().unwrap_or("");
            let bad: Vec<String> = string_literals(code)
                .into_iter()
                .filter(|l| states_a_rule(l))
                .collect();
            if let Some(b) = bad.first() {
                offenders.push(format!("{rel}: {:?}", &b[..b.len().min(160)]));
            }
        }
        assert!(offenders.is_empty(), "{}", offenders.join("\n"));
    }

    /// Every family's verdict comes from a [`super::Rule`]: no family names a grade itself
    /// outside its tests (not assessed, for a missing table, is not a grade).
    #[test]
    fn no_family_grades_a_claim_by_hand() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut files = Vec::new();
        rust_files(&root.join("src/families"), &mut files);
        files.sort();
        let grades = [
            "Verdict::Held",
            "Verdict::Partly",
            "Verdict::NotHeld",
            "Verdict::PremiseNotReproduced",
            "Verdict::Inconclusive",
        ];
        let mut offenders = Vec::new();
        for f in &files {
            let src = std::fs::read_to_string(f).unwrap();
            let code = src.split("#[cfg(test)]").next().unwrap_or("");
            for g in grades {
                if code.contains(g) {
                    offenders.push(format!("{}: {g}", f.strip_prefix(root).unwrap().display()));
                }
            }
        }
        assert!(offenders.is_empty(), "{}", offenders.join("\n"));
    }
}
