//! The trained hierarchy from the emulator cache or trained now ([`build_dolphin`]): cache
//! keys and paths, the nets' shapes, the composed emulator and the per-net records.

use super::super::{
    global_transforms, global_transforms_of, DolphinEmulator, LocalLayout, LocalNet, GLOBAL_DIM,
    HIERARCHY_FORMAT,
};
use super::nets::{train_global_only, train_hierarchy};
use super::sampling::{control_process, start_state, CHUNK, EPISODE_S};
use super::HierarchySpec;
use crate::emulator::cache::{
    fnv1a, read_record, training, write_record, EmulatorCache, NetRecord,
};
use crate::emulator::catalog::BuildError;
use crate::emulator::train::TracePoint;
use crate::emulator::{Emulator, Transforms};
use crate::physics::dolphin::{Dolphin, N_SEGMENTS};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::path::PathBuf;

/// Training record of one net of the hierarchy (a Table 1 row).
#[derive(Debug, Clone, PartialEq)]
pub struct NetReport {
    /// `dolphin_global` or `dolphin_local1` … `dolphin_local6`.
    pub name: String,
    /// Network inputs.
    pub inputs: usize,
    /// Hidden units.
    pub hidden: usize,
    /// Network outputs.
    pub outputs: usize,
    /// Training examples.
    pub examples: usize,
    /// Training MSE per output (normalized space).
    pub train_error: f64,
    /// Held-out MSE per output (normalized space).
    pub heldout_error: f64,
    /// Wall time of its training (the shared sampling time is added to the global net) (s).
    pub train_s: f64,
    /// Why training stopped.
    pub stop: String,
    /// Whether it came from the cache.
    pub from_cache: bool,
    /// Training trace.
    pub trace: Vec<TracePoint>,
    /// Trace of the k-step rollout fine-tuning (the global net's, when its settings ask for
    /// one; empty otherwise).
    pub rollout_trace: Vec<TracePoint>,
}

/// The trained hierarchy with a record per net.
#[derive(Debug, Clone)]
pub struct BuiltDolphin {
    /// The composed emulator.
    pub emulator: DolphinEmulator,
    /// Global net first, then the six local nets.
    pub nets: Vec<NetReport>,
}

/// Name of net `k` of the hierarchy (0 = global, 1..=6 local).
pub fn net_name(k: usize) -> String {
    if k == 0 {
        "dolphin_global".into()
    } else {
        format!("dolphin_local{k}")
    }
}

pub(in crate::emulator::hierarchy) fn cache_key(
    spec: &HierarchySpec,
    d: &Dolphin,
    k: usize,
) -> String {
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let starts: Vec<Vec<f64>> = (0..2).map(|_| start_state(d, &mut rng)).collect();
    serde_json::json!({
        "format": crate::emulator::cache::CACHE_FORMAT,
        "hierarchy_format": HIERARCHY_FORMAT,
        "hierarchy": spec,
        "net": net_name(k),
        "physics": d,
        "recipe": {
            "process": control_process(),
            "episode": EPISODE_S,
            "chunk": CHUNK,
            "transforms": format!("{:?}", if k == 0 {
                global_transforms_of(spec.global_transforms)
            } else {
                global_transforms()
            }),
            "starts": starts,
        },
    })
    .to_string()
}

fn cache_path(cache: &EmulatorCache, spec: &HierarchySpec, key: &str, k: usize) -> PathBuf {
    cache.dir.join(format!(
        "{}-n{}-{:016x}.json",
        net_name(k),
        spec.steps,
        fnv1a(key.as_bytes())
    ))
}

pub(in crate::emulator::hierarchy) fn shape(spec: &HierarchySpec, k: usize) -> [usize; 3] {
    if k == 0 {
        [GLOBAL_DIM + N_SEGMENTS, spec.global.hidden, GLOBAL_DIM]
    } else {
        let l = LocalLayout::new(k - 1);
        [l.n_in(), spec.local.hidden, l.n_out()]
    }
}

/// The global net of a stored record as an [`Emulator`].
pub(in crate::emulator::hierarchy) fn global_emulator(
    spec: &HierarchySpec,
    g: NetRecord,
) -> Result<Emulator, BuildError> {
    let mut t = Transforms::unfitted(
        &global_transforms_of(spec.global_transforms),
        GLOBAL_DIM,
        N_SEGMENTS,
    )?;
    t.input_norm = g.input_norm;
    t.output_norm = g.output_norm;
    Ok(Emulator::new(t, g.mlp, spec.super_dt())?)
}

fn assemble(
    d: &Dolphin,
    spec: &HierarchySpec,
    recs: Vec<NetRecord>,
) -> Result<DolphinEmulator, BuildError> {
    let mut it = recs.into_iter();
    let global = global_emulator(spec, it.next().expect("seven records"))?;
    let locals = it
        .enumerate()
        .map(|(s, r)| LocalNet {
            layout: LocalLayout::new(s),
            mlp: r.mlp,
            input_norm: r.input_norm,
            output_norm: r.output_norm,
        })
        .collect();
    Ok(DolphinEmulator::new(d.clone(), global, locals))
}

fn report(k: usize, spec: &HierarchySpec, r: &NetRecord, from_cache: bool) -> NetReport {
    let [inputs, hidden, outputs] = shape(spec, k);
    NetReport {
        name: net_name(k),
        inputs,
        hidden,
        outputs,
        examples: if k == 0 {
            spec.global.examples
        } else {
            spec.local.examples.min(spec.global.examples)
        },
        train_error: r.train_error,
        heldout_error: r.heldout_error,
        train_s: r.train_s,
        stop: r.stop.clone(),
        from_cache,
        trace: r.trace.clone(),
        rollout_trace: r.rollout_trace.clone(),
    }
}

/// The trained hierarchy of `spec` for the default dolphin, from `cache` when all seven nets
/// are there, else sampled and trained now (and stored).
pub fn build_dolphin(
    spec: &HierarchySpec,
    cache: &EmulatorCache,
) -> Result<BuiltDolphin, BuildError> {
    let d = Dolphin::default();
    let keys: Vec<String> = (0..=N_SEGMENTS).map(|k| cache_key(spec, &d, k)).collect();
    let cached: Option<Vec<NetRecord>> = (0..=N_SEGMENTS)
        .map(|k| {
            read_record(
                &cache_path(cache, spec, &keys[k], k),
                &keys[k],
                shape(spec, k),
            )
        })
        .collect();
    if let Some(recs) = cached {
        let nets = recs
            .iter()
            .enumerate()
            .map(|(k, r)| report(k, spec, r, true))
            .collect();
        return Ok(BuiltDolphin {
            emulator: assemble(&d, spec, recs)?,
            nets,
        });
    }
    let recs = training(
        "the dolphin's hierarchy (a global and six local nets)",
        || train_hierarchy(&d, spec),
    )?;
    for (k, r) in recs.iter().enumerate() {
        write_record(&cache_path(cache, spec, &keys[k], k), &keys[k], r)?;
    }
    let nets = recs
        .iter()
        .enumerate()
        .map(|(k, r)| report(k, spec, r, false))
        .collect();
    Ok(BuiltDolphin {
        emulator: assemble(&d, spec, recs)?,
        nets,
    })
}

/// The global net of `spec` alone, wrapped in `spec.global_transforms`, from `cache` or trained
/// now (and stored): what `na_transforms_ablation` composes with the whole chain's local nets.
/// With the whole chain it is [`build_dolphin`]'s global net (the same cache entry).
pub fn build_global(
    spec: &HierarchySpec,
    cache: &EmulatorCache,
) -> Result<(Emulator, NetReport), BuildError> {
    let d = Dolphin::default();
    let key = cache_key(spec, &d, 0);
    let path = cache_path(cache, spec, &key, 0);
    let (rec, from_cache) = match read_record(&path, &key, shape(spec, 0)) {
        Some(r) => (r, true),
        None => {
            let r = training("the dolphin's global net", || train_global_only(&d, spec))?;
            write_record(&path, &key, &r)?;
            (r, false)
        }
    };
    let report = report(0, spec, &rec, from_cache);
    Ok((global_emulator(spec, rec)?, report))
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::spec;
    use super::*;
    use crate::emulator::hierarchy::training::global_heldout_errors;
    use crate::physics::Dynamics;

    #[test]
    fn tiny_hierarchy_trains_and_caches() {
        let dir = tempfile::tempdir().unwrap();
        let cache = EmulatorCache::new(dir.path());
        let sp = spec(60);
        let a = build_dolphin(&sp, &cache).unwrap();
        assert_eq!(a.nets.len(), 7);
        assert!(a
            .nets
            .iter()
            .all(|n| !n.from_cache && n.heldout_error.is_finite()));
        let b = build_dolphin(&sp, &cache).unwrap();
        assert!(b.nets.iter().all(|n| n.from_cache));
        let d = Dolphin::default();
        let x = start_state(&d, &mut ChaCha8Rng::seed_from_u64(1));
        let u = [0.3; 6];
        let (mut xa, mut xb) = (x.clone(), x.clone());
        let (mut ea, mut eb) = (a.emulator.clone(), b.emulator.clone());
        ea.step(&mut xa, &u, sp.super_dt());
        eb.step(&mut xb, &u, sp.super_dt());
        assert_eq!(xa, xb, "a cached hierarchy is bit-identical");
        assert!(xa.iter().all(|v| v.is_finite()));
        // The per-output breakdown of the global net's held-out error averages to its
        // held-out MSE (the same held-out examples, sampled again).
        let per = global_heldout_errors(&a.emulator, &sp).unwrap();
        assert_eq!(per.len(), GLOBAL_DIM);
        let mean = per.iter().map(|p| p.0).sum::<f64>() / per.len() as f64;
        assert!(per.iter().all(|p| p.1 >= 0.0));
        let reported = a.nets[0].heldout_error;
        assert!(
            (mean - reported).abs() <= 1e-9 * reported,
            "{mean} vs {reported}"
        );
    }

    #[test]
    fn a_global_net_alone_is_the_hierarchys_and_its_variants_cache_apart() {
        use crate::emulator::catalog::TransformSet;
        let dir = tempfile::tempdir().unwrap();
        let cache = EmulatorCache::new(dir.path());
        let sp = spec(60);
        let whole = build_dolphin(&sp, &cache).unwrap();
        let d = Dolphin::default();
        let mut g = vec![0.0; GLOBAL_DIM];
        crate::emulator::hierarchy::global_state(
            &d,
            &start_state(&d, &mut ChaCha8Rng::seed_from_u64(2)),
            &mut g,
        );
        let u = [0.2; N_SEGMENTS];
        let next = |e: &Emulator| {
            let mut out = vec![0.0; GLOBAL_DIM];
            e.predict(&g, &u, &mut e.scratch(), &mut out);
            out
        };
        let reference = next(whole.emulator.global());
        // The whole chain's global net alone: the hierarchy's cache entry.
        let (cached, rep) = build_global(&sp, &cache).unwrap();
        assert!(rep.from_cache);
        assert_eq!(next(&cached), reference);
        // Trained alone in an empty cache: the same examples, weights and training, bit for bit.
        let other = tempfile::tempdir().unwrap();
        let (alone, rep) = build_global(&sp, &EmulatorCache::new(other.path())).unwrap();
        assert!(!rep.from_cache);
        assert_eq!(next(&alone), reference);
        // A reduced chain is another net under its own key; the second build loads it.
        let plain = HierarchySpec {
            global_transforms: TransformSet::Plain,
            ..sp.clone()
        };
        let (p1, r1) = build_global(&plain, &cache).unwrap();
        let (p2, r2) = build_global(&plain, &cache).unwrap();
        assert!(!r1.from_cache && r2.from_cache);
        assert_eq!(next(&p1), next(&p2));
        assert_ne!(next(&p1), reference);
        assert!(next(&p1).iter().all(|v| v.is_finite()));
        // The whole hierarchy is still the cached one (no entry was overwritten).
        assert!(build_dolphin(&sp, &cache)
            .unwrap()
            .nets
            .iter()
            .all(|n| n.from_cache));
    }
}
