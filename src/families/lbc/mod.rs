//! Linear Bellman combination (da Silva, Durand, Popović 2009), experiment ids `lbc_*`.

pub mod acrobot_swingup;
pub mod diver;
pub mod film;
pub mod grid_optimality;
pub mod projection;
pub mod push_recovery;

use crate::experiment::output::{df_f64, df_str, read_csv, Table};
use crate::experiment::Error;
use crate::row;
use std::path::Path;

/// The settings of an experiment's `rule` table (columns setting, value) in `dir`, by name;
/// NaN for a setting the table lacks.
pub(crate) fn rule_settings(dir: &Path) -> Result<impl Fn(&str) -> f64, Error> {
    let rule = read_csv(&dir.join("rule.csv"))?;
    let (rk, rv) = (df_str(&rule, "setting")?, df_f64(&rule, "value")?);
    Ok(move |k: &str| rk.iter().position(|s| s == k).map_or(f64::NAN, |i| rv[i]))
}

/// The `rule` table (columns setting, value) that [`rule_settings`] reads back: the verdict's
/// settings, written beside the results so the report judges with the run's own values.
pub(crate) fn rule_table(settings: &[(&str, f64)]) -> Table {
    let mut rule = Table::new(&["setting", "value"]);
    for &(k, v) in settings {
        rule.push(row![k, v]);
    }
    rule
}
