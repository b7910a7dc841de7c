//! The task description the NeuroAnimator control experiments share (`na_fig13_control`'s
//! tasks, `na_fig14_momentum`, `x_lbc_emulator`): horizon, knots, budget, start, goal and
//! weights, the shared part of their validation, and the flattening that keeps its keys flat.

use crate::params::{ensure, ParamError};
use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize};

/// A control-learning task through an emulator: from `start`, `horizon` emulator steps of
/// piecewise-constant controls (`knots` per actuator), learned in `iterations` descent steps,
/// should end at `target` within `final_tolerance`, effort weighted by `effort_mu`.
///
/// Each experiment embeds it as `#[serde(flatten, deserialize_with = "keyed")] pub task:
/// ControlTask`, so its keys sit beside the experiment's own (`horizon = 40`, not
/// `task.horizon = 40`) and the experiment's `deny_unknown_fields` still rejects unknown keys.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ControlTask {
    /// Emulator steps M.
    pub horizon: usize,
    /// Knots per actuator K (piecewise-constant controls; K ≤ M).
    pub knots: usize,
    /// Descent iterations of each learning run.
    pub iterations: usize,
    /// Start state.
    pub start: Vec<f64>,
    /// Target final state.
    pub target: Vec<f64>,
    /// Tolerance σ_k per state variable of the final-state term (weight 1/σ²; 0 = ignore).
    pub final_tolerance: Vec<f64>,
    /// Effort weight μ_u (each experiment checks its range: see its `validate`).
    pub effort_mu: f64,
}

impl ControlTask {
    /// The checks every experiment makes, keys as written (`horizon`; the caller prefixes them,
    /// e.g. `tasks[0].`): horizon ≥ 1, knots in [1, horizon], iterations ≥ 1, and `start`,
    /// `target` and `final_tolerance` of `n_state` finite values. The signs of the tolerances
    /// and of `effort_mu` are the experiment's to check (their rules differ).
    pub fn validate(&self, n_state: usize) -> Result<(), ParamError> {
        ensure(self.horizon >= 1, "horizon", "must be >= 1")?;
        ensure(
            self.knots >= 1 && self.knots <= self.horizon,
            "knots",
            "must be in [1, horizon]",
        )?;
        ensure(self.iterations >= 1, "iterations", "must be >= 1")?;
        for (key, v) in [
            ("start", &self.start),
            ("target", &self.target),
            ("final_tolerance", &self.final_tolerance),
        ] {
            ensure(v.len() == n_state, key, format!("needs {n_state} values"))?;
            ensure(v.iter().all(|x| x.is_finite()), key, "must be finite")?;
        }
        Ok(())
    }
}

/// Deserializes a `#[serde(flatten)]`ed struct so that an error inside it names its key.
///
/// serde buffers a flattened struct's values and deserializes them after the enclosing map,
/// outside `serde_path_to_error`'s tracking, so a wrong-typed `horizon = "x"` would come back
/// with the enclosing table's path alone. This tracks the path inside the flattened struct and
/// puts it in front of the message (`` `horizon`: invalid type: … ``); errors at the struct
/// itself (`missing field `horizon``) pass unchanged. `parse_params`
/// ([`crate::experiment::resolve::parse_params`]) joins that key to the enclosing table's path,
/// so the [`ParamError`] names `horizon` (or `tasks[0].horizon`) as for any other key.
pub fn keyed<'de, D, T>(deserializer: D) -> Result<T, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    serde_path_to_error::deserialize(deserializer).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        if path == "." {
            inner
        } else {
            D::Error::custom(format_args!("`{path}`: {}", inner.to_string().trim_end()))
        }
    })
}

#[cfg(test)]
mod tests {
    use crate::experiment::resolve::parse_params;
    use crate::experiment::spec::SpecFile;
    use crate::families::na::{fig13_control, fig14_momentum};

    /// The `[params]` table of an experiment file.
    fn params(file: &str) -> toml::Table {
        SpecFile::load(std::path::Path::new(file))
            .unwrap()
            .raw
            .params
    }

    #[test]
    fn flattened_keys_parse_flat_and_serialize_flat() {
        let raw = params("experiments/na_fig14_momentum.toml");
        let p: fig14_momentum::Params = parse_params(&toml::Value::Table(raw.clone())).unwrap();
        assert_eq!(
            p.task.horizon,
            raw["horizon"].as_integer().unwrap() as usize
        );
        assert_eq!(p.task.knots, raw["knots"].as_integer().unwrap() as usize);
        let json = serde_json::to_value(&p).unwrap();
        for key in [
            "horizon",
            "knots",
            "iterations",
            "start",
            "target",
            "final_tolerance",
            "effort_mu",
        ] {
            assert!(json.get(key).is_some(), "{key} at the top of params_json");
        }
        assert!(json.get("task").is_none(), "no `task` key in params_json");
    }

    /// Fig. 14's lander is Fig. 13's paper lander: its DAgger task serializes
    /// exactly as Fig. 13's lander task, so the two share the DAgger chain's cache key.
    #[test]
    fn fig14s_lander_is_fig13s_paper_lander() {
        let p14: fig14_momentum::Params = parse_params(&toml::Value::Table(params(
            "experiments/na_fig14_momentum.toml",
        )))
        .unwrap();
        let p13: fig13_control::Params = parse_params(&toml::Value::Table(params(
            "experiments/na_fig13_control.toml",
        )))
        .unwrap();
        let lander = p13.tasks.iter().find(|t| t.name == "lander").unwrap();
        let d = p14.dagger.as_ref().unwrap();
        assert_eq!(
            serde_json::to_value(p14.dagger_task(d)).unwrap(),
            serde_json::to_value(lander).unwrap()
        );
    }

    #[test]
    fn unknown_keys_are_rejected_by_name_beside_a_flattened_task() {
        let mut raw = params("experiments/na_fig14_momentum.toml");
        raw.insert("horizn".into(), toml::Value::Integer(40));
        let e = parse_params::<fig14_momentum::Params>(&toml::Value::Table(raw)).unwrap_err();
        assert_eq!(e.key, "horizn", "{e}");
        assert!(e.message.starts_with("unknown field `horizn`"), "{e}");

        let mut raw = params("experiments/na_fig13_control.toml");
        let tasks = raw["tasks"].as_array_mut().unwrap();
        let task = tasks[1].as_table_mut().unwrap();
        task.insert("knts".into(), toml::Value::Integer(20));
        let e = parse_params::<fig13_control::Params>(&toml::Value::Table(raw)).unwrap_err();
        assert_eq!(e.key, "tasks[1].knts", "{e}");
    }

    #[test]
    fn a_missing_flattened_key_is_named() {
        let mut raw = params("experiments/na_fig14_momentum.toml");
        raw.remove("knots");
        let e = parse_params::<fig14_momentum::Params>(&toml::Value::Table(raw)).unwrap_err();
        assert_eq!(e.key, "knots", "{e}");
    }

    /// A wrong type inside the flattened task names its key ([`super::keyed`], joined to the
    /// enclosing path by `parse_params`).
    #[test]
    fn a_wrong_type_of_a_flattened_key_names_it_in_the_message() {
        let mut raw = params("experiments/na_fig14_momentum.toml");
        raw.insert("horizon".into(), toml::Value::String("x".into()));
        let e = parse_params::<fig14_momentum::Params>(&toml::Value::Table(raw)).unwrap_err();
        assert_eq!(e.key, "horizon", "{e}");
        assert!(e.message.starts_with("invalid type: string \"x\""), "{e}");

        let mut raw = params("experiments/na_fig14_momentum.toml");
        let start = raw["start"].as_array_mut().unwrap();
        start[1] = toml::Value::String("a".into());
        let e = parse_params::<fig14_momentum::Params>(&toml::Value::Table(raw)).unwrap_err();
        assert_eq!(e.key, "start[1]", "{e}");
        assert!(e.message.starts_with("invalid type"), "{e}");

        let mut raw = params("experiments/na_fig13_control.toml");
        let tasks = raw["tasks"].as_array_mut().unwrap();
        let task = tasks[0].as_table_mut().unwrap();
        task.insert("effort_mu".into(), toml::Value::String("x".into()));
        let e = parse_params::<fig13_control::Params>(&toml::Value::Table(raw)).unwrap_err();
        assert_eq!(e.key, "tasks[0].effort_mu", "{e}");
        assert!(e.message.starts_with("invalid type"), "{e}");
    }

    /// The experiments' own keys, beside the flattened ones, keep their full path.
    #[test]
    fn a_wrong_type_of_an_own_key_keeps_its_key() {
        let mut raw = params("experiments/x_lbc_emulator.toml");
        raw.insert("axis".into(), toml::Value::String("x".into()));
        let e = parse_params::<crate::families::beyond::x_lbc_emulator::Params>(
            &toml::Value::Table(raw),
        )
        .unwrap_err();
        assert_eq!(e.key, "axis", "{e}");
    }
}
