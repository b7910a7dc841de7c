//! The rows of `na_fig13_control`'s headline tables that its figures and report read back, and
//! the reading of typed rows from a table that a run may not have written (also used by
//! `na_fig14_momentum`).

use crate::experiment::output::{read_csv, written_csv};
use crate::experiment::rows::{Frame, TableRow};
use crate::experiment::Error;
use std::path::Path;

/// The rows of frame `df`, read from the file at `path` (errors name it). A table without rows
/// is read as no rows once its header has every column: its CSV holds no value from which
/// the reader could tell an integer column from a text one.
fn frame_rows<R: TableRow>(path: &Path, df: &Frame) -> Result<Vec<R>, Error> {
    let named = |e: &dyn std::fmt::Display| Error::Other(format!("{}: {e}", path.display()));
    if df.height() == 0 {
        let names = df.get_column_names();
        return match R::COLUMNS.iter().find(|c| !names.iter().any(|n| n == *c)) {
            Some(c) => Err(named(&format!("no column {c}"))),
            None => Ok(Vec::new()),
        };
    }
    R::from_frame(df).map_err(|e| named(&e))
}

/// The rows of the CSV file at `path` ([`crate::experiment::rows::read_rows`], a table
/// without rows included): an error naming the file when it is missing, not whole or lacks a
/// column.
pub(crate) fn required_rows<R: TableRow>(path: &Path) -> Result<Vec<R>, Error> {
    frame_rows(path, &read_csv(path)?)
}

/// The rows of `dir/name`, a table a run writes only when its spec asks for the study behind
/// it ([`written_csv`]): `None` when the run did not write it, an error naming the file when it
/// wrote it and it is now missing, not whole or lacks a column.
pub(crate) fn written_rows<R: TableRow>(dir: &Path, name: &str) -> Result<Option<Vec<R>>, Error> {
    written_csv(dir, name)?
        .map(|df| frame_rows(&dir.join(name), &df))
        .transpose()
}

crate::result_rows! {
    /// One iteration of one task's descent: a row of `objective.csv`.
    pub struct ObjectiveRow {
        /// The task.
        task: String = "task",
        /// The iteration (0: the start).
        iteration: i64 = "iteration",
        /// The objective J there.
        objective: f64 = "objective",
    }
}

crate::result_rows! {
    /// One task's learned controls, scored: a row of `final.csv`.
    pub struct FinalRow {
        /// The task.
        task: String = "task",
        /// RMS of (s_M − s_d)/σ over the weighted state variables when the controls drive the
        /// emulator (≤ 1: within tolerance); for the dolphin, its shortfall (m) from the
        /// hand-made wave's distance.
        emulator_error: f64 = "emulator_error",
        /// The same when they are replayed on the physical simulator.
        simulator_error: f64 = "simulator_error",
        /// The best-so-far iterate scored (the lowest emulator J).
        best_iteration: i64 = "best_iteration",
        /// `paper` or `ours` ([`super::Formulation::name`]).
        formulation: String = "formulation",
        /// The final error of the task's initial controls replayed on the simulator (NaN for
        /// the dolphin).
        start_simulator_error: f64 = "start_simulator_error",
    }
}

impl FinalRow {
    /// The task is of the paper's formulation (counted in the headline).
    pub fn is_paper(&self) -> bool {
        self.formulation == super::Formulation::Paper.name()
    }
}

crate::result_rows! {
    /// One of the dolphin's swims: a row of `swim.csv` (no rows without `[params.dolphin]`).
    pub struct SwimRow {
        /// `emulator`, `simulator` (the learned controls) or `reference_wave_simulator` (the
        /// hand-made travelling wave).
        source: String = "source",
        /// The forward distance swum (m).
        distance_m: f64 = "distance_m",
        /// The controls' effort.
        effort: f64 = "effort",
        /// The muscle pattern's periodicity (mean over muscles of the largest autocorrelation
        /// at lags of 3 steps to half the horizon; 1: a sinusoid, 0: noise or constant).
        periodicity: f64 = "periodicity",
        /// The lag of that autocorrelation (s).
        period_s: f64 = "period_s",
    }
}
