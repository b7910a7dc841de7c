//! Building the Table 1 networks: the build spec of a net (seeded so that every experiment
//! needing the same net shares it through the cache), the nets from the cache or trained now,
//! and a Table 1 emulator by name for `motionlab emulate`.

use super::Params;
use crate::emulator::cache::{fnv1a, EmulatorCache};
#[cfg(test)]
use crate::emulator::catalog::DataRegime;
use crate::emulator::catalog::{BuildSpec, NetModel, NetSpec, TrainSettings, Trained};
use crate::emulator::hierarchy::{build_dolphin, BuiltDolphin, DolphinEmulator, HierarchySpec};
use crate::experiment::{other, Error};
use crate::seed::mix_seed;

/// The dolphin hierarchy of `spec`, from the cache or trained now.
pub fn build_dolphin_emulator(spec: &HierarchySpec) -> Result<BuiltDolphin, Error> {
    build_dolphin(spec, &EmulatorCache::from_env()).map_err(other)
}

/// The build spec of `net` at `steps` physical steps per emulator step. The seed depends only on
/// the run seed, the model and n, so experiments that need the same network share it through
/// the cache.
pub fn build_spec(
    seed: u64,
    net: &NetSpec,
    steps: usize,
    example_scale: f64,
    settings: &TrainSettings,
) -> BuildSpec {
    let mut net = net.clone();
    net.examples = (net.examples as f64 * example_scale).round() as usize;
    let stream = fnv1a(format!("{}-n{steps}", net.model.name()).as_bytes());
    BuildSpec {
        net,
        steps,
        settings: *settings,
        seed: mix_seed(seed, stream),
    }
}

/// The emulator of `spec`, from the cache ([`EmulatorCache::from_env`]) or trained now.
pub fn build_emulator(spec: &BuildSpec) -> Result<Trained, Error> {
    EmulatorCache::from_env().get_or_train(spec).map_err(other)
}

/// The emulators of `specs`, in order, each as [`build_emulator`] builds it, the ones not in the
/// cache trained side by side (rayon): nets are independent and each is seeded by its spec, so
/// the nets, and everything made from them, are the same as built one by one. A cold run
/// otherwise trains its nets serially on one core.
/// A spec listed more than once (tasks that share a net) is built once and copied: two copies
/// trained side by side would cost a core and race to store the same cache file.
pub fn build_emulators(specs: &[BuildSpec]) -> Result<Vec<Trained>, Error> {
    build_each_once(specs, build_emulator)
}

/// `build` of every distinct spec of `specs` side by side (rayon), copied to each place it is
/// listed, in order.
fn build_each_once(
    specs: &[BuildSpec],
    build: impl Fn(&BuildSpec) -> Result<Trained, Error> + Sync,
) -> Result<Vec<Trained>, Error> {
    use rayon::prelude::*;
    let mut unique: Vec<&BuildSpec> = Vec::new();
    let slot: Vec<usize> = specs
        .iter()
        .map(|s| match unique.iter().position(|u| *u == s) {
            Some(i) => i,
            None => {
                unique.push(s);
                unique.len() - 1
            }
        })
        .collect();
    let built: Vec<Trained> = unique
        .par_iter()
        .map(|s| build(s))
        .collect::<Result<_, _>>()?;
    Ok(slot.into_iter().map(|i| built[i].clone()).collect())
}

/// A Table 1 emulator ready to step, catalog net or dolphin hierarchy (`motionlab emulate`).
pub enum Table1Emulator {
    /// A single net (pendulums, truck, lander).
    Net(NetModel, Box<crate::emulator::Emulator>),
    /// The hierarchical dolphin.
    Dolphin(Box<DolphinEmulator>),
}

/// Net names `motionlab emulate` accepts.
pub const EMULATOR_NAMES: [&str; 6] = [
    "pendulum_passive",
    "pendulum_active",
    "pendulum_ext",
    "truck",
    "lander",
    "dolphin",
];

impl Table1Emulator {
    /// The physical model it emulates, by its `describe` name.
    pub fn physics_name(&self) -> &'static str {
        match self {
            Self::Net(m, _) => m.physics_name(),
            Self::Dolphin(_) => "dolphin",
        }
    }

    /// The super timestep Δt (s).
    pub fn dt(&self) -> f64 {
        match self {
            Self::Net(_, e) => e.dt(),
            Self::Dolphin(d) => d.dt(),
        }
    }

    /// Emulates `steps` super-steps from `x0` with controls `control(k, t, u)` held over each;
    /// `observe(t, x)` sees the start and every step.
    pub fn rollout(
        &self,
        x0: &[f64],
        steps: usize,
        mut control: impl FnMut(f64, &mut [f64]),
        mut observe: impl FnMut(f64, &[f64]),
    ) -> Result<(), crate::physics::BlowUp> {
        let n = x0.len();
        let (mut x, mut next) = (x0.to_vec(), vec![0.0; n]);
        let name = self.physics_name();
        observe(0.0, &x);
        let dt = self.dt();
        let mut u = vec![0.0; crate::physics::model_by_name(name).map_or(0, |m| m.control_dim())];
        // One scratch per kind, made once.
        let mut net_scratch = match self {
            Self::Net(_, e) => Some(e.scratch()),
            Self::Dolphin(_) => None,
        };
        let mut dolphin_scratch = match self {
            Self::Dolphin(d) => Some(d.scratch()),
            Self::Net(..) => None,
        };
        for k in 0..steps {
            let t = k as f64 * dt;
            control(t, &mut u);
            match self {
                Self::Net(_, e) => {
                    e.predict(&x, &u, net_scratch.as_mut().expect("made"), &mut next)
                }
                Self::Dolphin(d) => {
                    d.predict(&x, &u, dolphin_scratch.as_mut().expect("made"), &mut next)
                }
            }
            std::mem::swap(&mut x, &mut next);
            let t1 = (k + 1) as f64 * dt;
            crate::physics::check_finite(name, k + 1, t1, &x)?;
            observe(t1, &x);
        }
        Ok(())
    }
}

/// The Table 1 emulator `name` (one of [`EMULATOR_NAMES`]) at `steps` physical steps per
/// emulator step, built exactly as `na_table1_structure` with these parameters and `seed` builds
/// it (size, data, training, seed), so it comes from the cache when any experiment trained it.
pub fn table1_emulator(
    params: &Params,
    seed: u64,
    name: &str,
    steps: usize,
) -> Result<Table1Emulator, Error> {
    if name == "dolphin" {
        let d = params
            .dolphin
            .as_ref()
            .ok_or_else(|| Error::Other("the Table 1 spec has no [params.dolphin]".into()))?;
        let built = build_dolphin_emulator(&d.spec(seed, steps, params.example_scale))?;
        return Ok(Table1Emulator::Dolphin(Box::new(built.emulator)));
    }
    let net = params
        .nets
        .iter()
        .find(|n| n.model.name() == name)
        .ok_or_else(|| {
            Error::Other(format!(
                "no net `{name}` in the Table 1 spec (nets: {})",
                EMULATOR_NAMES.join(", ")
            ))
        })?;
    let spec = build_spec(seed, net, steps, params.example_scale, &params.training);
    let t = build_emulator(&spec)?;
    Ok(Table1Emulator::Net(net.model, Box::new(t.emulator)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::resolve::merge;

    /// The `[params]` table of an experiment file, with its `[quick]` table merged when asked.
    fn params(id: &str, quick: bool) -> toml::Value {
        let path = format!("{}/experiments/{id}.toml", env!("CARGO_MANIFEST_DIR"));
        let spec: toml::Table = toml::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        let mut p = spec["params"].as_table().unwrap().clone();
        if quick {
            merge(&mut p, spec["quick"].as_table().unwrap());
        }
        toml::Value::Table(p)
    }

    #[test]
    fn a_net_listed_twice_is_trained_once_and_every_place_gets_its_own() {
        let spec = |seed: u64| BuildSpec {
            net: NetSpec::for_tests(
                NetModel::PendulumPassive,
                4,
                60,
                crate::emulator::catalog::TrainMethod::Cg,
            ),
            steps: 5,
            settings: TrainSettings::for_tests(5, 5, 2),
            seed,
        };
        let (a, b) = (spec(1), spec(2));
        let calls = std::sync::atomic::AtomicUsize::new(0);
        let built = build_each_once(&[a.clone(), b.clone(), a.clone()], |s| {
            calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            crate::emulator::catalog::train_emulator(s).map_err(other)
        })
        .unwrap();
        assert_eq!(calls.into_inner(), 2, "two distinct specs, two trainings");
        assert_eq!(built.len(), 3);
        let direct = |s: &BuildSpec| crate::emulator::catalog::train_emulator(s).unwrap();
        for (got, s) in built.iter().zip([&a, &b, &a]) {
            assert_eq!(got.emulator.mlp(), direct(s).emulator.mlp());
        }
        assert_ne!(built[0].emulator.mlp(), built[1].emulator.mlp());
    }

    #[test]
    fn control_experiments_use_table_1s_nets() {
        // Fig. 13 and Fig. 14 must learn through the very nets Table 1 trains and reports (the
        // same cache key: same model, size, data, settings), full and quick; Table 1 trains
        // them as the paper does: one step ahead, no input noise, no rollout fine-tuning, every
        // pendulum at the paper's physical step (0.01 s: 40 N50 super-steps for 20 s). Our
        // second lines at other steps (Fig. 13's `pendulum_4s`, `pendulum_200steps`) use
        // Table 1's net at their own step.
        for quick in [false, true] {
            let t1: Params = params("na_table1_structure", quick).try_into().unwrap();
            let key = |net: &NetSpec, steps: usize, scale: f64, s: &TrainSettings| {
                EmulatorCache::key(&build_spec(1, net, steps, scale, s))
            };
            let t1_net = |model: NetModel| t1.nets.iter().find(|n| n.model == model).unwrap();
            // Table 1's net of `model`, at `physical_dt`.
            let table1 = |model: NetModel, physical_dt: f64| {
                let mut net = t1_net(model).clone();
                net.physical_dt = physical_dt;
                key(&net, t1.steps, t1.example_scale, &t1.training)
            };
            assert_eq!(t1.training.rollout_k, 0, "one-step training");
            assert_eq!(t1.training.input_noise, 0.0, "no input noise");
            for net in &t1.nets {
                assert_eq!(net.input_noise, None, "{:?}", net.model);
                // The truck and the lander learn from their tasks' regime, the pendulums from
                // the typical manoeuvres (the spec says why).
                let data = match net.model {
                    NetModel::Truck | NetModel::Lander => DataRegime::Regime,
                    _ => DataRegime::Typical,
                };
                assert_eq!(net.data, data, "{:?}", net.model);
                assert_eq!(net.physical_dt, 0.01, "{:?}", net.model);
            }
            let f13: crate::families::na::fig13_control::Params =
                params("na_fig13_control", quick).try_into().unwrap();
            for task in &f13.tasks {
                assert_eq!(
                    key(&task.net, f13.steps, f13.example_scale, &f13.training),
                    table1(task.net.model, task.net.physical_dt),
                    "Fig. 13 {} (quick {quick})",
                    task.name
                );
            }
            let f14: crate::families::na::fig14_momentum::Params =
                params("na_fig14_momentum", quick).try_into().unwrap();
            assert_eq!(
                key(&f14.net, f14.steps, f14.example_scale, &f14.training),
                table1(f14.net.model, t1_net(f14.net.model).physical_dt),
                "Fig. 14 (quick {quick})"
            );
        }
    }

    #[test]
    fn fig14_learns_through_fig13s_lander_dagger_nets() {
        // Fig. 14's DAgger comparison must load the very nets Fig. 13's DAgger stage caches for
        // its lander task: the same base net and, for every round, the same derived key.
        use crate::families::na::fig13_control::dagger::derived_key;
        for quick in [false, true] {
            let f13: crate::families::na::fig13_control::Params =
                params("na_fig13_control", quick).try_into().unwrap();
            let f14: crate::families::na::fig14_momentum::Params =
                params("na_fig14_momentum", quick).try_into().unwrap();
            let d13 = f13.dagger.clone().expect("Fig. 13 runs DAgger");
            let t13 = f13.tasks.iter().find(|t| t.name == "lander").unwrap();
            let (g, d14) = f14.fig13(f14.dagger.as_ref().expect("Fig. 14 runs DAgger"));
            let t14 = &g.tasks[0];
            let base = |p: &crate::families::na::fig13_control::Params,
                        t: &crate::families::na::fig13_control::Task| {
                EmulatorCache::key(&build_spec(
                    1,
                    &t.net,
                    p.steps,
                    p.example_scale,
                    &p.training,
                ))
            };
            assert_eq!(base(&g, t14), base(&f13, t13), "base net (quick {quick})");
            assert_eq!(t14.name, t13.name);
            for round in 1..=d13.settings.rounds {
                assert_eq!(
                    derived_key(t14, &d14, g.curvature_iterations, round),
                    derived_key(t13, &d13, f13.curvature_iterations, round),
                    "round {round} (quick {quick})"
                );
            }
            assert_eq!(d14.settings.rounds, d13.settings.rounds);
        }
    }
}
