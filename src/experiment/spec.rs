//! Raw experiment files: serde types that mirror the TOML, and the source positions of keys.
//!
//! An experiment file says *what* to run:
//!
//! ```toml
//! id = "physics_validation"            # experiment id (file stem by convention)
//! experiment = "physics_validation"    # which experiment family runs it
//! title = "Integrator convergence and energy drift"
//! paper_item = "beyond the papers"
//! paper_claim = "what the paper says, shown beside ours in REPORT.md"
//! claim = "the claim in at most 15 words, for the claims table"
//! paper_number = "the paper's number or statement, in a few words"
//! seed = 1
//!
//! [params]     # the family's parameters (checked by the family, unknown keys rejected)
//! duration = 2.0
//!
//! [quick]      # overrides of [params] for --quick
//! duration = 0.5
//!
//! [sweep]      # optional axes over [params] keys; their Cartesian product is run
//! duration = [1.0, 2.0]
//! ```

use serde::Deserialize;
use std::path::{Path, PathBuf};
use toml_edit::{ImDocument, Item, Value};

/// The top level of an experiment file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawSpec {
    /// Experiment id, e.g. `physics_validation`.
    pub id: String,
    /// Name of the experiment family that runs it.
    pub experiment: String,
    /// One-line title.
    pub title: String,
    /// Which paper item it reproduces (e.g. `LBC Fig. 3-4`).
    pub paper_item: String,
    /// The paper's number or claim, quoted beside ours in the report.
    #[serde(default)]
    pub paper_claim: String,
    /// The claim in at most [`CLAIM_WORDS`] words, for the report's claims table.
    #[serde(default)]
    pub claim: String,
    /// The paper's number or statement in a few words, for the claims table.
    #[serde(default)]
    pub paper_number: String,
    /// Root seed of every random choice.
    pub seed: u64,
    /// The family's parameters.
    #[serde(default)]
    pub params: toml::Table,
    /// Overrides of `params` applied by `--quick`.
    #[serde(default)]
    pub quick: toml::Table,
    /// Sweep axes: `params` key → array of values.
    #[serde(default)]
    pub sweep: toml::Table,
    /// The rule's and setup's history: every change made after a result was seen, oldest
    /// first (`[[history]]`), shown by the report in the section and flagged in its summary.
    #[serde(default)]
    pub history: Vec<HistoryEntry>,
}

/// The most words of a spec's short `claim`.
pub const CLAIM_WORDS: usize = 15;

/// One change of a verdict's rule or of an experiment's setup made after a result was seen.
#[derive(Debug, Clone, PartialEq, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct HistoryEntry {
    /// When (YYYY-MM-DD).
    pub date: String,
    /// What changed: `rule` (the verdict's rule or thresholds) or `setup` (what is run).
    pub kind: HistoryKind,
    /// The old rule or setup, in words.
    pub old: String,
    /// The verdict the old rule or setup gave, where one was recorded.
    #[serde(default)]
    pub old_verdict: String,
    /// Why it changed.
    pub reason: String,
}

/// What a [`HistoryEntry`] changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum HistoryKind {
    /// The verdict's rule or its thresholds.
    Rule,
    /// What is run (the task, its parameters, its premise).
    Setup,
}

impl HistoryEntry {
    /// Whether the date reads YYYY-MM-DD and the texts are not empty.
    pub fn is_well_formed(&self) -> bool {
        let d = self.date.as_bytes();
        let date = d.len() == 10
            && d[4] == b'-'
            && d[7] == b'-'
            && d.iter()
                .enumerate()
                .all(|(i, c)| i == 4 || i == 7 || c.is_ascii_digit());
        date && !self.old.trim().is_empty() && !self.reason.trim().is_empty()
    }

    /// The report section's line: when, what kind, the verdict then and why.
    pub fn short(&self) -> String {
        format!(
            "{}, {} changed{}. Why: {}",
            self.date,
            self.kind_word(),
            self.verdict_then(),
            self.reason.trim()
        )
    }

    /// The entry in full: when, what kind, the old rule or setup, the verdict then, and why.
    pub fn line(&self) -> String {
        format!(
            "{}, {} changed after a result: was {}{}. Why: {}",
            self.date,
            self.kind_word(),
            self.old.trim(),
            self.verdict_then(),
            self.reason.trim()
        )
    }

    fn kind_word(&self) -> &'static str {
        match self.kind {
            HistoryKind::Rule => "rule",
            HistoryKind::Setup => "setup",
        }
    }

    fn verdict_then(&self) -> String {
        if self.old_verdict.is_empty() {
            String::new()
        } else {
            format!(" (verdict then: {})", self.old_verdict)
        }
    }
}

/// An experiment file as read: its path, text, typed top level and a span-preserving parse.
#[derive(Debug)]
pub struct SpecFile {
    /// Where it was read from.
    pub path: PathBuf,
    /// The typed top level.
    pub raw: RawSpec,
    doc: ImDocument<String>,
}

/// An error in an experiment file, with where it is.
#[derive(Debug, Clone, thiserror::Error, PartialEq)]
#[error("{}{}: key `{key}`: {message}", path.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
pub struct SpecError {
    /// The file (or `--set` for a command-line override).
    pub path: PathBuf,
    /// 1-based line, when known.
    pub line: Option<usize>,
    /// Dotted key path, e.g. `params.dt`.
    pub key: String,
    /// What is wrong.
    pub message: String,
}

fn line_of(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())].matches('\n').count() + 1
}

impl SpecFile {
    /// Reads and parses an experiment file; syntax errors, unknown top-level keys and wrong
    /// types come back as [`SpecError`] with the line and key.
    pub fn load(path: &Path) -> Result<Self, SpecError> {
        let text = std::fs::read_to_string(path).map_err(|e| SpecError {
            path: path.to_path_buf(),
            line: None,
            key: String::new(),
            message: format!("cannot read: {e}"),
        })?;
        Self::parse(path, text)
    }

    /// Parses experiment text that came from `path`.
    pub fn parse(path: &Path, text: String) -> Result<Self, SpecError> {
        let err = |line: Option<usize>, key: String, message: String| SpecError {
            path: path.to_path_buf(),
            line,
            key,
            message,
        };
        let doc = ImDocument::parse(text.clone()).map_err(|e| {
            let line = e.span().map(|s| line_of(&text, s.start));
            err(line, String::new(), e.message().trim().to_string())
        })?;
        let raw: RawSpec = toml::from_str(&text).map_err(|e| {
            let msg = e.message().trim().to_string();
            let line = e.span().map(|s| line_of(&text, s.start));
            let key = if msg.starts_with("unknown field") || msg.starts_with("missing field") {
                backticked(&msg).unwrap_or_default()
            } else {
                key_on_line(&text, line)
            };
            err(line, key, msg)
        })?;
        let spec = Self {
            path: path.to_path_buf(),
            raw,
            doc,
        };
        // The id names the experiment's output folders (`<out>/<id>/`, `<figures>/<id>_*`): a
        // path (`../x`, `/tmp/x`), `.` or an empty id would write outside them or into their
        // root.
        if !is_valid_id(&spec.raw.id) {
            return Err(spec.error_at(
                "id",
                format!(
                    "must be a non-empty name of lowercase letters, digits and _ (it names the output folder), got {:?}",
                    spec.raw.id
                ),
            ));
        }
        Ok(spec)
    }

    /// 1-based line of the dotted key `path` (e.g. `params.dts` or `params.dts[2]`), if present.
    pub fn line_of_key(&self, key: &str) -> Option<usize> {
        let text = self.doc.raw();
        let mut parts = split_key(key).into_iter();
        let first = parts.next()?;
        let (mut k, mut item) = match first {
            KeyPart::Name(n) => self.doc.as_table().get_key_value(&n)?,
            KeyPart::Index(_) => return None,
        };
        let mut span = k.span().or_else(|| item.span());
        for part in parts {
            match (part, item) {
                (KeyPart::Name(n), Item::Table(t)) => {
                    let (k2, i2) = t.get_key_value(&n)?;
                    k = k2;
                    item = i2;
                    span = k.span().or_else(|| item.span());
                }
                (KeyPart::Name(n), Item::Value(Value::InlineTable(t))) => {
                    let (k2, i2) = t.get_key_value(&n)?;
                    k = k2;
                    item = i2;
                    span = k.span().or_else(|| item.span());
                }
                (KeyPart::Index(i), Item::Value(Value::Array(a))) => {
                    let v = a.get(i)?;
                    return v
                        .span()
                        .map(|s| line_of(text, s.start))
                        .or(span.map(|s| line_of(text, s.start)));
                }
                _ => return span.map(|s| line_of(text, s.start)),
            }
        }
        span.map(|s| line_of(text, s.start))
    }

    /// A [`SpecError`] at the dotted key `key`.
    pub fn error_at(&self, key: &str, message: impl Into<String>) -> SpecError {
        // Fall back to the closest enclosing key that exists in the file.
        let mut probe = key.to_string();
        let line = loop {
            if let Some(l) = self.line_of_key(&probe) {
                break Some(l);
            }
            match probe.rfind(['.', '[']) {
                Some(p) => probe.truncate(p),
                None => break None,
            }
        };
        SpecError {
            path: self.path.clone(),
            line,
            key: key.to_string(),
            message: message.into(),
        }
    }
}

/// The key assigned on a given line (`key = value`), or the table header there.
fn key_on_line(text: &str, line: Option<usize>) -> String {
    let Some(l) = line else { return String::new() };
    let src = text.lines().nth(l - 1).unwrap_or("").trim();
    match src.split_once('=') {
        Some((k, _)) => k.trim().to_string(),
        None => src.trim_matches(['[', ']']).to_string(),
    }
}

/// The first `backticked` word of a serde message (the offending field name).
pub(crate) fn backticked(msg: &str) -> Option<String> {
    let start = msg.find('`')? + 1;
    let len = msg[start..].find('`')?;
    Some(msg[start..start + len].to_string())
}

enum KeyPart {
    Name(String),
    Index(usize),
}

fn split_key(key: &str) -> Vec<KeyPart> {
    let mut out = Vec::new();
    for seg in key.split('.') {
        let mut rest = seg;
        if let Some(b) = rest.find('[') {
            if b > 0 {
                out.push(KeyPart::Name(rest[..b].to_string()));
            }
            rest = &rest[b..];
            while let Some(stripped) = rest.strip_prefix('[') {
                let end = stripped.find(']').unwrap_or(stripped.len());
                if let Ok(i) = stripped[..end].parse() {
                    out.push(KeyPart::Index(i));
                }
                rest = stripped.get(end + 1..).unwrap_or("");
            }
        } else if !rest.is_empty() {
            out.push(KeyPart::Name(rest.to_string()));
        }
    }
    out
}

/// Whether `id` is an experiment id: non-empty, of `a-z`, `0-9` and `_` only.
pub fn is_valid_id(id: &str) -> bool {
    !id.is_empty()
        && id
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_')
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An id that is a path, `.`, empty or not lowercase is refused with file, line and key,
    /// before anything runs (it would name folders outside `--out` / `--figures`).
    #[test]
    fn an_id_that_is_not_a_plain_name_is_refused_at_its_line() {
        for bad in ["../x", "/tmp/x", ".", "", "a/b", "X", "na-fig", "a b"] {
            let text = GOOD.replace("id = \"x\"", &format!("id = {bad:?}"));
            let e = SpecFile::parse(Path::new("a.toml"), text).unwrap_err();
            assert_eq!((e.key.as_str(), e.line), ("id", Some(1)), "{bad:?}: {e}");
            assert!(e.message.contains("lowercase"), "{e}");
        }
        for good in ["x", "na_fig13_control", "x_lbc_emulator", "a1"] {
            let text = GOOD.replace("id = \"x\"", &format!("id = {good:?}"));
            assert!(SpecFile::parse(Path::new("a.toml"), text).is_ok(), "{good}");
        }
    }

    const GOOD: &str = "id = \"x\"\nexperiment = \"physics_validation\"\ntitle = \"t\"\npaper_item = \"p\"\nseed = 3\n\n[params]\ndts = [0.1, 0.2]\nduration = 1.0\n";

    #[test]
    fn finds_lines_of_nested_keys() {
        let f = SpecFile::parse(Path::new("a.toml"), GOOD.into()).unwrap();
        assert_eq!(f.line_of_key("seed"), Some(5));
        assert_eq!(f.line_of_key("params.duration"), Some(9));
        assert_eq!(f.line_of_key("params.dts[1]"), Some(8));
        assert_eq!(f.error_at("params.nothing", "x").line, Some(7));
    }

    #[test]
    fn unknown_top_level_key_names_line_and_key() {
        let text = GOOD.replace("seed = 3", "seed = 3\nsede = 4");
        let e = SpecFile::parse(Path::new("a.toml"), text).unwrap_err();
        assert_eq!(e.key, "sede");
        assert_eq!(e.line, Some(6));
    }

    #[test]
    fn wrong_type_names_line() {
        let text = GOOD.replace("seed = 3", "seed = \"three\"");
        let e = SpecFile::parse(Path::new("a.toml"), text).unwrap_err();
        assert_eq!(e.line, Some(5), "{e}");
    }
}
