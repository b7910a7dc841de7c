//! # Trained-emulator cache
//!
//! Training a NeuroAnimator takes seconds to minutes; experiments that need the same network
//! (Table 1 trains the N50 nets that Table 2 times) reuse it. A trained emulator is stored as one
//! JSON file, `<dir>/<model>-n<steps>-<hash>.json`, where the hash (64-bit FNV-1a, hex) is taken
//! over a canonical JSON *key* holding everything that determines the result: the cache format
//! version, the [`BuildSpec`] (model, n, δt, hidden units, examples, training method and
//! settings, seed), the physical model's parameters and a fingerprint of its sampling recipe
//! (control limits, start states drawn with a fixed seed, transforms). The file repeats the key, and a load
//! checks it, so a hash collision cannot return a wrong network.
//!
//! Weights, normalization statistics and errors are stored as the bit patterns of their f64
//! values (`u64`), so a reloaded emulator is bit-identical to the trained one. Files are written
//! atomically (temporary file, then rename).
//!
//! The folder is `$MOTIONLAB_CACHE` when set, else `target/motionlab-cache` below the working
//! directory ([`EmulatorCache::from_env`]). Delete it to force retraining.

use super::catalog::{train_emulator, BuildError, BuildSpec, Trained};
use super::mlp::Mlp;
use super::train::TracePoint;
use super::transform::Normalizer;
use super::{Emulator, Transforms};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What a run did with emulator nets: how many distinct nets it loaded from the cache (and the
/// training seconds recorded when they were made) and how many it trained (and their seconds).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct NetUsage {
    /// Distinct nets loaded from the cache.
    pub loaded: usize,
    /// Training seconds recorded in those files (what training them cold cost then).
    pub loaded_train_s: f64,
    /// Nets trained (or fine-tuned) and stored.
    pub trained: usize,
    /// Their training seconds.
    pub trained_s: f64,
}

/// Every net file loaded or stored since the last [`take_usage`], with whether it was trained
/// and its training seconds; a net used twice counts once.
static USAGE: std::sync::Mutex<std::collections::BTreeMap<PathBuf, (bool, f64)>> =
    std::sync::Mutex::new(std::collections::BTreeMap::new());

fn note_use(path: &Path, trained: bool, seconds: f64) {
    let mut map = USAGE.lock().unwrap_or_else(|e| e.into_inner());
    let e = map.entry(path.to_path_buf()).or_insert((trained, seconds));
    // Trained in this run, then loaded again: it stays a trained net.
    if trained {
        *e = (true, seconds);
    }
}

/// The nets used (process-wide) since the last call, and forgets them. The runner takes it
/// before and after an experiment, which runs alone.
pub fn take_usage() -> NetUsage {
    let map = std::mem::take(&mut *USAGE.lock().unwrap_or_else(|e| e.into_inner()));
    let mut u = NetUsage::default();
    for (trained, s) in map.into_values() {
        if trained {
            u.trained += 1;
            u.trained_s += s;
        } else {
            u.loaded += 1;
            u.loaded_train_s += s;
        }
    }
    u
}

/// `train()`, announced on stderr before and after: a cold run trains for minutes at a time,
/// and this says what and how long (the cache's file names which net, for its key).
pub fn training<T, E>(what: &str, train: impl FnOnce() -> Result<T, E>) -> Result<T, E> {
    eprintln!("  training {what}: not in the emulator cache…");
    let t0 = std::time::Instant::now();
    let out = train()?;
    eprintln!("  trained {what} in {:.1} s", t0.elapsed().as_secs_f64());
    Ok(out)
}

/// Bumped whenever the meaning of a stored file changes (transforms, sampling, training code,
/// the network's arithmetic, the simulators' arithmetic: the key fingerprints the sampling
/// recipe, not the simulated transitions). 2: the network's σ and sums became fused
/// multiply–adds on lanes; 3: the pendulum's derivative takes its angle differences by the
/// angle identities and solves by L D Lᵀ; 4: the sampling's trigonometry (start
/// states, smooth and travelling-wave controls, the planar frame) through `crate::portable`
/// instead of the C library, and the batch products outside the register-tiled kernels in a
/// fixed order, so the same bits on every machine. A net trained before is not the net this
/// code trains.
pub const CACHE_FORMAT: u32 = 4;

/// 64-bit FNV-1a hash.
pub fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn floats(v: &[u64]) -> Vec<f64> {
    v.iter().map(|&b| f64::from_bits(b)).collect()
}

#[derive(Debug, Serialize, Deserialize)]
struct Stored {
    /// The key as canonical JSON text (compared as text: parsing floats back is not exact).
    key: String,
    shape: [usize; 3],
    dt: u64,
    weights: Vec<u64>,
    input_mean: Vec<u64>,
    input_std: Vec<u64>,
    output_mean: Vec<u64>,
    output_std: Vec<u64>,
    train_error: u64,
    heldout_error: u64,
    train_s: f64,
    stop: String,
    /// (iteration, train error bits, held-out error bits).
    trace: Vec<(usize, u64, u64)>,
    /// The rollout fine-tuning trace, same layout (absent when it was off).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    rollout_trace: Vec<(usize, u64, u64)>,
    /// FNV-1a of the file's text before this field, the last one ([`with_checksum`]): a file
    /// whose text no longer matches it (a flipped bit, an edit), or that lacks it, is rebuilt.
    /// `None` only while an entry is being written (the writer appends it to the text).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    checksum: Option<u64>,
}

impl Stored {
    /// Every number a net is built from is finite (weights, normalizations, the step).
    fn finite(&self) -> bool {
        [
            &self.weights,
            &self.input_mean,
            &self.input_std,
            &self.output_mean,
            &self.output_std,
        ]
        .iter()
        .flat_map(|v| v.iter())
        .chain(std::iter::once(&self.dt))
        .all(|&b| f64::from_bits(b).is_finite())
    }
}

/// The key of the checksum field, the last in the file's text.
const CHECKSUM_KEY: &str = ",\"checksum\":";

/// `text` (an entry's JSON object without a checksum) with its checksum appended as the last
/// field: the hash is of the text itself, byte for byte (parsing the numbers back and writing
/// them again would not do: serde_json's default float parsing is not exact).
fn with_checksum(text: &str) -> String {
    let body = text.strip_suffix('}').unwrap_or(text);
    format!("{body}{CHECKSUM_KEY}{}}}", fnv1a(text.as_bytes()))
}

/// Whether `text` ends with a checksum field, and if so whether it matches the text before it.
fn checksum_matches(text: &str) -> Option<bool> {
    let at = text.rfind(CHECKSUM_KEY)?;
    let digits = text[at + CHECKSUM_KEY.len()..].strip_suffix('}')?;
    let sum: u64 = digits.parse().ok()?;
    Some(fnv1a(format!("{}}}", &text[..at]).as_bytes()) == sum)
}

/// Why a cache file is not used: absent or another net's (a plain miss), or damaged.
enum Damage {
    Missing,
    Damaged(&'static str),
}

/// Reads and checks the entry at `path`: parsed, stored under `key` with `shape`, finite, and
/// carrying a checksum that matches its text (without one, nothing vouches for its numbers: a
/// flipped bit in a weight would be used silently).
fn checked_entry(path: &Path, key: &str, shape: [usize; 3]) -> Result<Stored, Damage> {
    let Ok(text) = std::fs::read_to_string(path) else {
        return Err(Damage::Missing);
    };
    let s: Stored = serde_json::from_str(&text).map_err(|_| Damage::Damaged("cannot be parsed"))?;
    let [n_in, hidden, n_out] = shape;
    if s.key != key || s.shape != shape {
        return Err(Damage::Missing);
    }
    if s.weights.len() != Mlp::weight_count(n_in, hidden, n_out)
        || s.input_mean.len() != n_in
        || s.input_std.len() != n_in
        || s.output_mean.len() != n_out
        || s.output_std.len() != n_out
    {
        return Err(Damage::Damaged("has the wrong number of weights"));
    }
    match checksum_matches(&text) {
        None => return Err(Damage::Damaged("has no checksum")),
        Some(false) => return Err(Damage::Damaged("does not match its checksum")),
        Some(true) => {}
    }
    if !s.finite() {
        return Err(Damage::Damaged("holds a non-finite weight"));
    }
    Ok(s)
}

/// One trained network with its normalization and training record, as a cache file holds it.
#[derive(Debug, Clone, PartialEq)]
pub struct NetRecord {
    /// The network.
    pub mlp: Mlp,
    /// Input normalization.
    pub input_norm: Normalizer,
    /// Output normalization.
    pub output_norm: Normalizer,
    /// Super timestep Δt (s).
    pub dt: f64,
    /// Training MSE per output at the kept weights.
    pub train_error: f64,
    /// Held-out MSE per output at the kept weights.
    pub heldout_error: f64,
    /// Wall time of sampling and training when it was built (s).
    pub train_s: f64,
    /// Why training stopped.
    pub stop: String,
    /// Training trace.
    pub trace: Vec<TracePoint>,
    /// Rollout fine-tuning trace (empty when it was off).
    pub rollout_trace: Vec<TracePoint>,
}

/// Reads the record at `path` if it exists, was stored under `key` and has `shape`
/// (inputs, hidden, outputs); `None` otherwise (a stale or foreign file is a cache miss). A
/// damaged entry (unparsable, a wrong weight count, non-finite numbers, or a checksum that is
/// missing or no longer matches its content) is a miss too, so the net is rebuilt, with a line
/// on stderr naming the file.
pub fn read_record(path: &Path, key: &str, shape: [usize; 3]) -> Option<NetRecord> {
    let s = match checked_entry(path, key, shape) {
        Ok(s) => s,
        Err(Damage::Missing) => return None,
        Err(Damage::Damaged(why)) => {
            eprintln!(
                "emulator cache: {} {why}; rebuilding the net",
                path.display()
            );
            return None;
        }
    };
    let [n_in, hidden, n_out] = shape;
    let rec = NetRecord {
        mlp: Mlp::from_weights(n_in, hidden, n_out, floats(&s.weights)),
        input_norm: Normalizer {
            mean: floats(&s.input_mean),
            std: floats(&s.input_std),
        },
        output_norm: Normalizer {
            mean: floats(&s.output_mean),
            std: floats(&s.output_std),
        },
        dt: f64::from_bits(s.dt),
        train_error: f64::from_bits(s.train_error),
        heldout_error: f64::from_bits(s.heldout_error),
        train_s: s.train_s,
        stop: s.stop,
        trace: trace_from_bits(&s.trace),
        rollout_trace: trace_from_bits(&s.rollout_trace),
    };
    note_use(path, false, rec.train_s);
    Some(rec)
}

fn trace_from_bits(t: &[(usize, u64, u64)]) -> Vec<TracePoint> {
    t.iter()
        .map(|&(iteration, a, b)| TracePoint {
            iteration,
            train_error: f64::from_bits(a),
            held_out_error: f64::from_bits(b),
        })
        .collect()
}

fn trace_bits(t: &[TracePoint]) -> Vec<(usize, u64, u64)> {
    t.iter()
        .map(|p| {
            (
                p.iteration,
                p.train_error.to_bits(),
                p.held_out_error.to_bits(),
            )
        })
        .collect()
}

/// Writes `rec` under `key` to `path` atomically (temporary file, then rename), creating the
/// folder, with the checksum of its content.
pub fn write_record(path: &Path, key: &str, rec: &NetRecord) -> Result<(), BuildError> {
    let mlp = &rec.mlp;
    let stored = Stored {
        key: key.to_string(),
        shape: [mlp.n_in(), mlp.n_hidden(), mlp.n_out()],
        dt: rec.dt.to_bits(),
        weights: bits(mlp.weights()),
        input_mean: bits(&rec.input_norm.mean),
        input_std: bits(&rec.input_norm.std),
        output_mean: bits(&rec.output_norm.mean),
        output_std: bits(&rec.output_norm.std),
        train_error: rec.train_error.to_bits(),
        heldout_error: rec.heldout_error.to_bits(),
        train_s: rec.train_s,
        stop: rec.stop.clone(),
        trace: trace_bits(&rec.trace),
        rollout_trace: trace_bits(&rec.rollout_trace),
        checksum: None,
    };
    let fail = |message: String| BuildError::Cache {
        path: path.display().to_string(),
        message,
    };
    let text = with_checksum(&serde_json::to_string(&stored).map_err(|e| fail(e.to_string()))?);
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| fail(e.to_string()))?;
    }
    // A temporary name of this call's own: two threads of one run may train and store the
    // same net at once (two experiments that need it, side by side under `--jobs`); with a name
    // per process the second rename found the file already moved and failed the run.
    static WRITES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = WRITES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = path.with_extension(format!("json.tmp{}-{n}", std::process::id()));
    std::fs::write(&tmp, text).map_err(|e| fail(e.to_string()))?;
    std::fs::rename(&tmp, path).map_err(|e| fail(e.to_string()))?;
    note_use(path, true, rec.train_s);
    Ok(())
}

/// A folder of trained emulators.
#[derive(Debug, Clone)]
pub struct EmulatorCache {
    /// The folder.
    pub dir: PathBuf,
}

impl EmulatorCache {
    /// A cache in `dir` (created on the first store).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    /// `$MOTIONLAB_CACHE`, else `target/motionlab-cache` below the working directory.
    pub fn from_env() -> Self {
        match std::env::var_os("MOTIONLAB_CACHE") {
            Some(d) if !d.is_empty() => Self::new(PathBuf::from(d)),
            _ => Self::new(Path::new("target").join("motionlab-cache")),
        }
    }

    /// The canonical key of `spec`.
    pub fn key(spec: &BuildSpec) -> serde_json::Value {
        serde_json::json!({
            "format": CACHE_FORMAT,
            "spec": spec,
            "physics": spec.net.model.physics_json(),
            "recipe": spec.net.model.recipe_json(spec.net.data),
        })
    }

    /// The key of a net derived from `spec`'s (e.g. a DAgger round, [`super::dagger`]): the
    /// base key plus `derived`, everything else that determines it.
    pub fn derived_key(spec: &BuildSpec, derived: &serde_json::Value) -> serde_json::Value {
        serde_json::json!({ "base": Self::key(spec), "derived": derived })
    }

    /// The file that holds (or would hold) the emulator of `spec`.
    pub fn path(&self, spec: &BuildSpec) -> PathBuf {
        self.file(spec, "", &Self::key(spec))
    }

    /// The file of the net derived from `spec`'s under `derived`, named with `tag`.
    pub fn derived_path(
        &self,
        spec: &BuildSpec,
        tag: &str,
        derived: &serde_json::Value,
    ) -> PathBuf {
        self.file(spec, tag, &Self::derived_key(spec, derived))
    }

    fn file(&self, spec: &BuildSpec, tag: &str, key: &serde_json::Value) -> PathBuf {
        let h = fnv1a(key.to_string().as_bytes());
        let tag = if tag.is_empty() {
            String::new()
        } else {
            format!("-{tag}")
        };
        self.dir.join(format!(
            "{}-n{}{tag}-{h:016x}.json",
            spec.net.model.name(),
            spec.steps
        ))
    }

    /// The cached emulator of `spec`, if a file with the same key exists and reads back.
    pub fn load(&self, spec: &BuildSpec) -> Option<Trained> {
        self.load_at(spec, &self.path(spec), &Self::key(spec))
    }

    /// The cached net derived from `spec`'s under `derived` (same shape and transforms).
    pub fn load_derived(
        &self,
        spec: &BuildSpec,
        tag: &str,
        derived: &serde_json::Value,
    ) -> Option<Trained> {
        let key = Self::derived_key(spec, derived);
        self.load_at(spec, &self.file(spec, tag, &key), &key)
    }

    fn load_at(&self, spec: &BuildSpec, path: &Path, key: &serde_json::Value) -> Option<Trained> {
        let model = spec.net.model;
        let (n, m) = (model.state_dim(), model.control_dim());
        let rec = read_record(path, &key.to_string(), [n + m, spec.net.hidden, n])?;
        let mut t = Transforms::unfitted(&spec.net.transform_config(), n, m).ok()?;
        t.input_norm = rec.input_norm;
        t.output_norm = rec.output_norm;
        let emulator = Emulator::new(t, rec.mlp, rec.dt).ok()?;
        Some(Trained {
            emulator,
            trace: rec.trace,
            train_error: rec.train_error,
            heldout_error: rec.heldout_error,
            train_s: rec.train_s,
            stop: rec.stop,
            from_cache: true,
            rollout_trace: rec.rollout_trace,
        })
    }

    /// Writes `trained` as the emulator of `spec` (atomically).
    pub fn store(&self, spec: &BuildSpec, trained: &Trained) -> Result<PathBuf, BuildError> {
        self.store_at(self.path(spec), &Self::key(spec), trained)
    }

    /// Writes `trained` as the net derived from `spec`'s under `derived` (atomically).
    pub fn store_derived(
        &self,
        spec: &BuildSpec,
        tag: &str,
        derived: &serde_json::Value,
        trained: &Trained,
    ) -> Result<PathBuf, BuildError> {
        let key = Self::derived_key(spec, derived);
        self.store_at(self.file(spec, tag, &key), &key, trained)
    }

    fn store_at(
        &self,
        path: PathBuf,
        key: &serde_json::Value,
        trained: &Trained,
    ) -> Result<PathBuf, BuildError> {
        let e = &trained.emulator;
        let t = e.transforms();
        write_record(
            &path,
            &key.to_string(),
            &NetRecord {
                mlp: e.mlp().clone(),
                input_norm: t.input_norm.clone(),
                output_norm: t.output_norm.clone(),
                dt: e.dt(),
                train_error: trained.train_error,
                heldout_error: trained.heldout_error,
                train_s: trained.train_s,
                stop: trained.stop.clone(),
                trace: trained.trace.clone(),
                rollout_trace: trained.rollout_trace.clone(),
            },
        )?;
        Ok(path)
    }

    /// The cached emulator of `spec`, or a freshly trained one (then stored).
    pub fn get_or_train(&self, spec: &BuildSpec) -> Result<Trained, BuildError> {
        if let Some(t) = self.load(spec) {
            return Ok(t);
        }
        let what = format!(
            "the {} N{} emulator ({} hidden units, {} examples, {})",
            spec.net.model.name(),
            spec.steps,
            spec.net.hidden,
            spec.net.examples,
            self.path(spec)
                .file_name()
                .map_or(String::new(), |f| f.to_string_lossy().into_owned())
        );
        let t = training(&what, || train_emulator(spec))?;
        self.store(spec, &t)?;
        Ok(t)
    }
}

#[cfg(test)]
mod tests {
    use super::super::catalog::{NetModel, NetSpec, TrainMethod, TrainSettings};
    use super::*;

    fn spec() -> BuildSpec {
        BuildSpec {
            net: NetSpec::for_tests(NetModel::PendulumPassive, 6, 120, TrainMethod::Cg),
            steps: 10,
            settings: TrainSettings::for_tests(20, 10, 5),
            seed: 7,
        }
    }

    #[test]
    fn a_rerun_reuses_the_file_and_a_changed_parameter_retrains() {
        let dir = tempfile::tempdir().unwrap();
        let cache = EmulatorCache::new(dir.path().join("c"));
        let s = spec();
        let a = cache.get_or_train(&s).unwrap();
        assert!(!a.from_cache);
        assert!(cache.path(&s).exists());
        let b = cache.get_or_train(&s).unwrap();
        assert!(b.from_cache);
        // Bit-identical network, statistics and record.
        assert_eq!(a.emulator.mlp(), b.emulator.mlp());
        assert_eq!(a.emulator.transforms(), b.emulator.transforms());
        assert_eq!(a.emulator.dt(), b.emulator.dt());
        assert_eq!(a.trace, b.trace);
        assert_eq!(a.heldout_error.to_bits(), b.heldout_error.to_bits());
        // A retrain from scratch gives the same network (determinism), so reuse is exact.
        let c = train_emulator(&s).unwrap();
        assert_eq!(a.emulator.mlp(), c.emulator.mlp());
        // Any determining parameter changes the file: retrained, not loaded.
        for changed in [
            BuildSpec {
                seed: 8,
                ..s.clone()
            },
            BuildSpec {
                steps: 11,
                ..s.clone()
            },
            BuildSpec {
                net: NetSpec {
                    hidden: 7,
                    ..s.net.clone()
                },
                ..s.clone()
            },
            BuildSpec {
                net: NetSpec {
                    transforms: crate::emulator::catalog::TransformSet::Plain,
                    data: Default::default(),
                    ..s.net.clone()
                },
                ..s.clone()
            },
            BuildSpec {
                settings: TrainSettings {
                    patience: 6,
                    ..s.settings
                },
                ..s.clone()
            },
            BuildSpec {
                settings: TrainSettings {
                    input_noise: 0.1,
                    rollout_k: 0,
                    rollout_weight: 0.0,
                    rollout_iters: 0,
                    ..s.settings
                },
                ..s.clone()
            },
        ] {
            assert_ne!(cache.path(&changed), cache.path(&s));
            assert!(cache.load(&changed).is_none());
            let t = cache.get_or_train(&changed).unwrap();
            assert!(!t.from_cache);
        }
        assert_eq!(std::fs::read_dir(cache.dir).unwrap().count(), 7);
    }

    #[test]
    fn a_file_with_another_key_is_not_loaded() {
        let dir = tempfile::tempdir().unwrap();
        let cache = EmulatorCache::new(dir.path());
        let s = spec();
        let a = cache.get_or_train(&s).unwrap();
        // Write s's network under the file name of another spec: the key check refuses it.
        let other = BuildSpec {
            seed: 99,
            ..s.clone()
        };
        let text = std::fs::read_to_string(cache.path(&s)).unwrap();
        std::fs::write(cache.path(&other), text).unwrap();
        assert!(cache.load(&other).is_none());
        assert!(cache.load(&s).unwrap().emulator.mlp() == a.emulator.mlp());
    }

    /// The file's text with `f` applied to its first weight (a u64 of the f64's bits), edited
    /// in place: every other byte as written.
    fn with_first_weight(path: &Path, f: impl Fn(u64) -> u64) {
        let text = std::fs::read_to_string(path).unwrap();
        let start = text.find("\"weights\":[").unwrap() + "\"weights\":[".len();
        let end = start + text[start..].find(',').unwrap();
        let w: u64 = text[start..end].parse().unwrap();
        let edited = format!("{}{}{}", &text[..start], f(w), &text[end..]);
        assert_ne!(edited, text);
        std::fs::write(path, edited).unwrap();
    }

    /// The checksum is of the text as written: it holds for it, fails after a one-character
    /// edit anywhere before it, and is absent from a text without it.
    #[test]
    fn the_checksum_is_of_the_text_as_written() {
        let text = r#"{"key":"k","train_s":0.30000000000000004,"weights":[1,2,3]}"#;
        let stamped = with_checksum(text);
        assert!(stamped.starts_with(&text[..text.len() - 1]));
        assert_eq!(checksum_matches(&stamped), Some(true));
        let edited = stamped.replacen("0.3", "0.4", 1);
        assert_eq!(checksum_matches(&edited), Some(false));
        assert_eq!(checksum_matches(text), None);
    }

    /// A damaged entry (one flipped bit in a weight, a NaN weight, a truncated file) is not
    /// used: the net is rebuilt, and the rebuilt net is the clean run's, bit for bit.
    #[test]
    fn a_damaged_entry_is_rebuilt_into_the_clean_net() {
        let dir = tempfile::tempdir().unwrap();
        let cache = EmulatorCache::new(dir.path());
        let s = spec();
        let clean = cache.get_or_train(&s).unwrap();
        let path = cache.path(&s);
        type Damage = Box<dyn Fn(&Path)>;
        let damages: Vec<(&str, Damage)> = vec![
            (
                "bit 40 flipped",
                Box::new(|p: &Path| with_first_weight(p, |w| w ^ (1 << 40))),
            ),
            (
                "a NaN weight",
                Box::new(|p: &Path| with_first_weight(p, |_| f64::NAN.to_bits())),
            ),
            (
                "truncated",
                Box::new(|p: &Path| {
                    let t = std::fs::read(p).unwrap();
                    std::fs::write(p, &t[..t.len() / 2]).unwrap();
                }),
            ),
        ];
        for (what, damage) in damages {
            damage(&path);
            assert!(
                cache.load(&s).is_none(),
                "{what}: the damaged entry was used"
            );
            let rebuilt = cache.get_or_train(&s).unwrap();
            assert!(!rebuilt.from_cache, "{what}");
            assert_eq!(rebuilt.emulator.mlp(), clean.emulator.mlp(), "{what}");
            assert!(
                cache.load(&s).unwrap().from_cache,
                "{what}: not stored again"
            );
        }
    }

    /// A non-finite number refused even under a checksum that matches it (written through
    /// the cache's own writer), and an entry without its checksum refused: a flipped bit in
    /// a weight there would otherwise be used silently.
    #[test]
    fn non_finite_entries_and_entries_without_a_checksum_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let cache = EmulatorCache::new(dir.path());
        let s = spec();
        let clean = cache.get_or_train(&s).unwrap();
        let path = cache.path(&s);
        let key = EmulatorCache::key(&s).to_string();
        let shape = [clean.emulator.mlp().n_in(), 6, clean.emulator.mlp().n_out()];
        let mut rec = read_record(&path, &key, shape).unwrap();
        let good = rec.clone();
        rec.output_norm.std[0] = f64::INFINITY;
        write_record(&path, &key, &rec).unwrap();
        assert!(read_record(&path, &key, shape).is_none());
        write_record(&path, &key, &good).unwrap();
        assert_eq!(read_record(&path, &key, shape).unwrap(), good);
        // The same entry without its checksum field, then with a flipped bit in a weight too.
        let text = std::fs::read_to_string(&path).unwrap();
        let at = text.rfind(CHECKSUM_KEY).unwrap();
        let bare = format!("{}}}", &text[..at]);
        std::fs::write(&path, &bare).unwrap();
        assert!(read_record(&path, &key, shape).is_none());
        let mut v: serde_json::Value = serde_json::from_str(&bare).unwrap();
        let w = v["weights"][0].as_u64().unwrap();
        v["weights"][0] = serde_json::json!(w ^ (1 << 40));
        std::fs::write(&path, serde_json::to_string(&v).unwrap()).unwrap();
        assert!(read_record(&path, &key, shape).is_none());
        // Rebuilt and stored with a checksum again.
        assert_eq!(
            cache.get_or_train(&s).unwrap().emulator.mlp(),
            clean.emulator.mlp()
        );
        assert!(checksum_matches(&std::fs::read_to_string(&path).unwrap()) == Some(true));
    }
}
