//! # The `simulate` and `emulate` verbs: their inputs, checked before any work, and their rows,
//! streamed as they are computed
//!
//! Both verbs step a model (the physical one, or a Table 1 emulator of it) from a start state
//! under a schedule of controls and write a CSV `t,state...`, one row per step. What they share:
//!
//! - [`Controls`]: the `--controls` CSV, read and checked whole before any work (every control
//!   column present exactly once, a UTF-8 byte-order mark accepted, every value finite and at
//!   most [`MAX_CONTROL`] in magnitude).
//! - [`check_run`]: the start state (finite, of the model's dimension), `--duration` and the
//!   step (positive and finite), and the number of steps (at most [`MAX_STEPS`]), checked before
//!   any work (for `emulate`, before its net is loaded or trained).
//! - [`write_csv`] and [`CsvRows`]: each row goes out as soon as it is computed, to a buffered
//!   standard output or to the output file (a temporary file renamed into place at the end, so a
//!   file is never left half-written); no trajectory is held in memory. A write error (a reader
//!   that closed the pipe) stops the run at once and comes back as the io error it is.
//! - [`simulate_rows`] and [`emulate_rows`]: the stepping loops, each row bit for bit what
//!   [`Simulator::rollout`] and [`Table1Emulator::rollout`] give.

use crate::experiment::output::{rename_into_place, temp_path};
use crate::experiment::Error;
use crate::families::na::table1_structure::Table1Emulator;
use crate::physics::{check_finite, Ode, Simulator};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Most steps one `simulate` or `emulate` run may take (rows after the start row): a
/// `--duration` that is more than this many steps (of `--dt`, or of the emulator's super-step)
/// is refused before any work. Ten million rows of a 6-variable state are about 1.2 GB of CSV.
pub const MAX_STEPS: usize = 10_000_000;

/// Largest magnitude of a control value in a `--controls` file, in the model's units (N·m, N,
/// m/s², activation). Far above any model's working range (the largest, the lander's main
/// thrust, is clamped at 10⁴ N); what exceeds it is a typo or an overflow, which the physical
/// models turn into a blow-up and an emulator into a meaningless but finite trajectory.
pub const MAX_CONTROL: f64 = 1e6;

fn other(message: String) -> Error {
    Error::Other(message)
}

/// A control schedule read from a CSV file: a column `t` and one column per control (every
/// control of the model, each once, in any order), one row per time, held piecewise-constant
/// (each row from its `t` until the next row's; the first row also before its `t`).
#[derive(Debug, Clone, PartialEq)]
pub struct Controls {
    times: Vec<f64>,
    values: Vec<Vec<f64>>,
}

impl Controls {
    /// Reads and checks the schedule in `path` for a model with controls `names`; every error
    /// names the file, and the line and column where there is one.
    pub fn load(path: &Path, names: &[String]) -> Result<Self, Error> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| other(format!("--controls: {}: {e}", path.display())))?;
        Self::parse(&text, path, names)
    }

    /// Parses the text of a controls CSV (`path` only names it in errors); see [`Controls`].
    pub fn parse(text: &str, path: &Path, names: &[String]) -> Result<Self, Error> {
        let file = path.display();
        // A spreadsheet's UTF-8 export starts with a byte-order mark.
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty());
        let (_, header) = lines
            .next()
            .ok_or_else(|| other(format!("{file}: empty file")))?;
        let cols: Vec<&str> = header.split(',').map(|s| s.trim()).collect();
        for (i, c) in cols.iter().enumerate() {
            if let Some(j) = cols[..i].iter().position(|d| d == c) {
                return Err(other(format!(
                    "{file}:1: column `{c}` appears twice (columns {} and {})",
                    j + 1,
                    i + 1
                )));
            }
            if *c != "t" && !names.iter().any(|n| n == c) {
                return Err(other(format!(
                    "{file}:1: unknown control column `{c}` (controls: {})",
                    names.join(", ")
                )));
            }
        }
        let t_col = cols
            .iter()
            .position(|c| *c == "t")
            .ok_or_else(|| other(format!("{file}:1: no column `t`")))?;
        let missing: Vec<&str> = names
            .iter()
            .filter(|n| !cols.contains(&n.as_str()))
            .map(|n| n.as_str())
            .collect();
        if !missing.is_empty() {
            return Err(other(format!(
                "{file}:1: no column for control{} `{}` (every control needs a column: {})",
                if missing.len() > 1 { "s" } else { "" },
                missing.join("`, `"),
                names.join(", ")
            )));
        }
        let idx: Vec<usize> = names
            .iter()
            .map(|n| cols.iter().position(|c| c == n).expect("checked above"))
            .collect();
        let (mut times, mut values) = (Vec::new(), Vec::new());
        for (ln, line) in lines {
            let ln = ln + 1;
            let cells: Vec<&str> = line.split(',').map(|s| s.trim()).collect();
            if cells.len() != cols.len() {
                return Err(other(format!(
                    "{file}:{ln}: expected {} values, got {}",
                    cols.len(),
                    cells.len()
                )));
            }
            let num = |i: usize| -> Result<f64, Error> {
                let v: f64 = cells[i].parse().map_err(|_| {
                    other(format!(
                        "{file}:{ln}: column `{}`: not a number: {}",
                        cols[i], cells[i]
                    ))
                })?;
                if !v.is_finite() {
                    return Err(other(format!(
                        "{file}:{ln}: column `{}`: not finite",
                        cols[i]
                    )));
                }
                Ok(v)
            };
            let t = num(t_col)?;
            if let Some(&last) = times.last() {
                if t <= last {
                    return Err(other(format!("{file}:{ln}: times must increase")));
                }
            }
            let row = idx
                .iter()
                .map(|&i| num(i))
                .collect::<Result<Vec<f64>, _>>()?;
            for (&i, v) in idx.iter().zip(&row) {
                if v.abs() > MAX_CONTROL {
                    return Err(other(format!(
                        "{file}:{ln}: column `{}`: {v:?} is beyond the limit of ±{MAX_CONTROL:e} \
                         on any control",
                        cols[i]
                    )));
                }
            }
            times.push(t);
            values.push(row);
        }
        if times.is_empty() {
            return Err(other(format!("{file}: no rows")));
        }
        Ok(Self { times, values })
    }

    /// The controls in force at time `t`, in the model's control order.
    pub fn at(&self, t: f64) -> &[f64] {
        let k = self.times.partition_point(|&s| s <= t + 1e-12);
        &self.values[k.saturating_sub(1)]
    }
}

/// Checks what a `simulate` or `emulate` run is asked before any work and returns its number of
/// steps, `round(duration / dt)`. `label` names the model in errors (`pendulum3`, `truck
/// emulates truck, which`), `state_names` are its state variables; `dt_flag` names where the
/// step comes from (`--dt`, `the emulator's super-step`). Refused: a start state of the wrong
/// length or with a NaN or infinite value, a `--duration` or step that is not positive and
/// finite, and more than [`MAX_STEPS`] steps. (The controls are checked by [`Controls::load`].)
pub fn check_run(
    label: &str,
    state_names: &[String],
    state: &[f64],
    duration: f64,
    dt_flag: &str,
    dt: f64,
) -> Result<usize, Error> {
    if state.len() != state_names.len() {
        return Err(other(format!(
            "--state: {label} has {} state variables ({}), got {}",
            state_names.len(),
            state_names.join(", "),
            state.len()
        )));
    }
    if let Some(i) = state.iter().position(|v| !v.is_finite()) {
        return Err(other(format!(
            "--state: {} (value {}) is {:?}, not a finite number",
            state_names[i],
            i + 1,
            state[i]
        )));
    }
    if !(duration.is_finite() && duration > 0.0) {
        return Err(other(format!(
            "--duration must be > 0 and finite, got {duration:?}"
        )));
    }
    if !(dt.is_finite() && dt > 0.0) {
        return Err(other(format!(
            "{dt_flag} must be > 0 and finite, got {dt:?}"
        )));
    }
    let steps = (duration / dt).round();
    if !(steps <= MAX_STEPS as f64) {
        return Err(other(format!(
            "--duration {duration:?} s at {dt_flag} = {dt:?} s is {steps:e} steps, more than the \
             limit of {MAX_STEPS} steps per run; shorten --duration{}",
            if dt_flag == "--dt" {
                " or lengthen --dt"
            } else {
                ""
            }
        )));
    }
    Ok(steps as usize)
}

/// A write error to `target` (`None`: standard output): on standard output the io error itself
/// (its kind tells a closed pipe), on a file a message naming it.
fn write_error(target: Option<&Path>, source: std::io::Error) -> Error {
    match target {
        None => Error::Io {
            path: PathBuf::from("standard output"),
            source,
        },
        Some(path) => other(format!("--out: {}: {source}", path.display())),
    }
}

/// Rows of a CSV going out one at a time (see [`write_csv`]).
pub struct CsvRows<'a> {
    w: &'a mut dyn Write,
    /// The output file, `None` for standard output.
    target: Option<&'a Path>,
}

impl CsvRows<'_> {
    fn io(&self, source: std::io::Error) -> Error {
        write_error(self.target, source)
    }

    /// Writes the header `t,<names>`.
    pub fn header(&mut self, names: &[String]) -> Result<(), Error> {
        let mut line = String::from("t");
        for n in names {
            line.push(',');
            line.push_str(n);
        }
        line.push('\n');
        self.w.write_all(line.as_bytes()).map_err(|e| self.io(e))
    }

    /// Writes the row `t,x...` (each number as Rust's `Display` writes it: the shortest text
    /// that reads back to the same f64).
    pub fn row(&mut self, t: f64, x: &[f64]) -> Result<(), Error> {
        let written = (|| {
            write!(self.w, "{t}")?;
            for v in x {
                write!(self.w, ",{v}")?;
            }
            self.w.write_all(b"\n")
        })();
        written.map_err(|e| self.io(e))
    }
}

/// Runs `body` with rows going to `out`, or to standard output when `None`: standard output
/// locked and buffered; a file through a temporary sibling ([`temp_path`]) renamed into place
/// once `body` has succeeded and everything is on disk, removed when it fails. An io error on
/// standard output keeps its kind (`BrokenPipe` when the reader has gone).
pub fn write_csv(
    out: Option<&Path>,
    body: impl FnOnce(&mut CsvRows) -> Result<(), Error>,
) -> Result<(), Error> {
    match out {
        None => {
            let mut w = std::io::BufWriter::new(std::io::stdout().lock());
            let mut rows = CsvRows {
                w: &mut w,
                target: None,
            };
            body(&mut rows)?;
            let flushed = w.flush();
            flushed.map_err(|e| write_error(None, e))
        }
        Some(path) => {
            let io = |e| write_error(Some(path), e);
            if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir).map_err(io)?;
            }
            let tmp: PathBuf = temp_path(path);
            let made = (|| {
                let f = std::fs::File::create(&tmp).map_err(io)?;
                let mut w = std::io::BufWriter::new(f);
                body(&mut CsvRows {
                    w: &mut w,
                    target: Some(path),
                })?;
                let f = w.into_inner().map_err(|e| io(e.into_error()))?;
                f.sync_all().map_err(io)
            })();
            rename_into_place(&tmp, path, made)
        }
    }
}

/// Simulates `steps` steps of `dt` from `x0` under `controls` (zero without), writing the start
/// row and one row per step to `rows` as each is computed: the rows of
/// [`Simulator::rollout`], the same floating-point operations in the same order. Stops at the
/// first write error, or with [`crate::physics::BlowUp`] when the state stops being finite.
pub fn simulate_rows<M: Ode>(
    sim: &mut Simulator<M>,
    x0: &[f64],
    dt: f64,
    steps: usize,
    controls: Option<&Controls>,
    rows: &mut CsvRows,
) -> Result<(), Error> {
    sim.try_rollout(
        x0,
        dt,
        steps,
        |_, t, _, u| {
            if let Some(s) = controls {
                u.copy_from_slice(s.at(t));
            }
        },
        |_, t, x| rows.row(t, x),
    )
    .map(|_| ())
}

/// Emulates `steps` super-steps of `emulator` from `x0` under `controls` (read at each
/// super-step's start and held), writing the start row and one row per super-step to `rows` as
/// each is computed: the rows of [`Table1Emulator::rollout`], the same arithmetic in the same
/// order. Stops at the first write error, or with [`crate::physics::BlowUp`] when the state
/// stops being finite.
pub fn emulate_rows(
    emulator: &Table1Emulator,
    x0: &[f64],
    steps: usize,
    controls: Option<&Controls>,
    rows: &mut CsvRows,
) -> Result<(), Error> {
    let n = x0.len();
    let (mut x, mut next) = (x0.to_vec(), vec![0.0; n]);
    let name = emulator.physics_name();
    rows.row(0.0, &x)?;
    let dt = emulator.dt();
    let mut u = vec![0.0; crate::physics::model_by_name(name).map_or(0, |m| m.control_dim())];
    enum Scratch {
        Net(crate::emulator::EmulatorScratch),
        Dolphin(crate::emulator::hierarchy::DolphinScratch),
    }
    let mut scratch = match emulator {
        Table1Emulator::Net(_, e) => Scratch::Net(e.scratch()),
        Table1Emulator::Dolphin(d) => Scratch::Dolphin(d.scratch()),
    };
    for k in 0..steps {
        let t = k as f64 * dt;
        if let Some(s) = controls {
            u.copy_from_slice(s.at(t));
        }
        match (emulator, &mut scratch) {
            (Table1Emulator::Net(_, e), Scratch::Net(sc)) => e.predict(&x, &u, sc, &mut next),
            (Table1Emulator::Dolphin(d), Scratch::Dolphin(sc)) => d.predict(&x, &u, sc, &mut next),
            _ => unreachable!("scratch made for this emulator"),
        }
        std::mem::swap(&mut x, &mut next);
        let t1 = (k + 1) as f64 * dt;
        check_finite(name, k + 1, t1, &x)?;
        rows.row(t1, &x)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(n: &[&str]) -> Vec<String> {
        n.iter().map(|s| s.to_string()).collect()
    }

    fn parse(text: &str) -> Result<Controls, String> {
        Controls::parse(text, Path::new("u.csv"), &names(&["a", "b"])).map_err(|e| e.to_string())
    }

    #[test]
    fn controls_accept_a_byte_order_mark_and_columns_in_any_order() {
        let plain = parse("t,a,b\n0,1,2\n1,3,4\n").unwrap();
        assert_eq!(parse("\u{feff}t,a,b\n0,1,2\n1,3,4\n").unwrap(), plain);
        assert_eq!(parse("b,t,a\n2,0,1\n4,1,3\n").unwrap(), plain);
        assert_eq!(plain.at(-1.0), &[1.0, 2.0]);
        assert_eq!(plain.at(0.5), &[1.0, 2.0]);
        assert_eq!(plain.at(1.0), &[3.0, 4.0]);
    }

    #[test]
    fn controls_refuse_a_missing_or_repeated_column_naming_file_column_and_positions() {
        let e = parse("t,a\n0,1\n").unwrap_err();
        assert!(e.contains("u.csv:1") && e.contains("`b`"), "{e}");
        let e = parse("t,a,b,a\n0,1,2,3\n").unwrap_err();
        assert!(
            e.contains("u.csv:1") && e.contains("`a`") && e.contains("columns 2 and 4"),
            "{e}"
        );
        let e = parse("t,a,t,b\n0,1,2,3\n").unwrap_err();
        assert!(e.contains("`t`") && e.contains("columns 1 and 3"), "{e}");
    }

    #[test]
    fn controls_refuse_values_beyond_the_limit_naming_line_and_column() {
        let e = parse("t,a,b\n0,0,0\n1,1e308,0\n").unwrap_err();
        assert!(e.contains("u.csv:3") && e.contains("`a`"), "{e}");
        assert!(parse(&format!("t,a,b\n0,{MAX_CONTROL},-{MAX_CONTROL}\n")).is_ok());
    }

    #[test]
    fn runs_are_checked_before_any_work() {
        let n = names(&["x", "v"]);
        let run = |state: &[f64], duration: f64, dt: f64| {
            check_run("m", &n, state, duration, "--dt", dt).map_err(|e| e.to_string())
        };
        let err = |state: &[f64], duration: f64, dt: f64| run(state, duration, dt).unwrap_err();
        assert_eq!(run(&[0.0, 1.0], 1.0, 0.01), Ok(100));
        assert!(err(&[0.0], 1.0, 0.1).contains("2 state variables"));
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let e = err(&[0.0, bad], 1.0, 0.1);
            assert!(e.contains("--state: v (value 2)"), "{e}");
        }
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(err(&[0.0, 0.0], bad, 0.1).contains("--duration"));
            assert!(err(&[0.0, 0.0], 1.0, bad).contains("--dt"));
        }
        // The step count: at the limit, accepted; beyond it (or absurd), refused.
        let dt = 1.0 / MAX_STEPS as f64;
        assert_eq!(run(&[0.0, 0.0], 1.0, dt), Ok(MAX_STEPS));
        assert!(err(&[0.0, 0.0], 2.0, dt).contains("limit"));
        assert!(err(&[0.0, 0.0], 1.0, 1e-300).contains("limit"));
        assert!(err(&[0.0, 0.0], 1e300, 1e-300).contains("limit"));
    }

    /// The rows `body` writes, as text.
    fn rows_of(body: impl FnOnce(&mut CsvRows) -> Result<(), Error>) -> String {
        let mut w: Vec<u8> = Vec::new();
        body(&mut CsvRows {
            w: &mut w,
            target: None,
        })
        .unwrap();
        String::from_utf8(w).unwrap()
    }

    /// The rows as the verbs wrote them before streaming: the whole trajectory collected in a
    /// string by `rollout`'s observer.
    fn collected(rollout: impl FnOnce(&mut dyn FnMut(f64, &[f64]))) -> String {
        let mut csv = String::new();
        rollout(&mut |t, x| {
            csv.push_str(&format!("{t}"));
            for v in x {
                csv.push_str(&format!(",{v}"));
            }
            csv.push('\n');
        });
        csv
    }

    #[test]
    fn streamed_simulation_rows_are_the_rollouts_bit_for_bit() {
        use crate::physics::{model_by_name, IntegratorKind};
        let controls = Controls::parse(
            "t,torque1,torque2,torque3\n0,0.5,-0.2,0.1\n0.05,-1,0.3,0\n",
            Path::new("u.csv"),
            &names(&["torque1", "torque2", "torque3"]),
        )
        .unwrap();
        let x0 = [0.3, -0.2, 0.1, 0.0, 0.5, -1.0];
        for kind in ["rk4", "euler", "rk45"] {
            let kind = IntegratorKind::from_name(kind).unwrap();
            let sim = || Simulator::new(model_by_name("pendulum3").unwrap(), kind);
            let streamed =
                rows_of(|rows| simulate_rows(&mut sim(), &x0, 0.013, 20, Some(&controls), rows));
            let reference = collected(|observe| {
                sim()
                    .rollout(
                        &x0,
                        0.013,
                        20,
                        |_, t, _, u| u.copy_from_slice(controls.at(t)),
                        |_, t, x| observe(t, x),
                    )
                    .unwrap();
            });
            assert_eq!(streamed, reference);
            assert_eq!(streamed.lines().count(), 21);
        }
    }

    #[test]
    fn streamed_emulator_rows_are_the_rollouts_bit_for_bit() {
        use crate::emulator::catalog::NetModel;
        use crate::emulator::mlp::{Mlp, WeightInit};
        use crate::emulator::{Emulator, TransformConfig, Transforms};
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let tf = Transforms::unfitted(&TransformConfig::standard(None), 6, 3).unwrap();
        let mlp = Mlp::new(9, 8, 6, WeightInit::FanIn, &mut rng);
        let e = Table1Emulator::Net(
            NetModel::PendulumActive,
            Box::new(Emulator::new(tf, mlp, 0.5).unwrap()),
        );
        let controls = Controls::parse(
            "t,torque1,torque2,torque3\n0,0.5,-0.2,0.1\n1.2,-1,0.3,0\n",
            Path::new("u.csv"),
            &names(&["torque1", "torque2", "torque3"]),
        )
        .unwrap();
        let x0 = [0.3, -0.2, 0.1, 0.0, 0.5, -1.0];
        let streamed = rows_of(|rows| emulate_rows(&e, &x0, 7, Some(&controls), rows));
        let reference = collected(|observe| {
            e.rollout(
                &x0,
                7,
                |t, u| u.copy_from_slice(controls.at(t)),
                |t, x| observe(t, x),
            )
            .unwrap();
        });
        assert_eq!(streamed, reference);
        assert_eq!(streamed.lines().count(), 8);
    }

    #[test]
    fn a_failed_write_stops_the_run_with_its_io_error() {
        /// A reader that went away after `left` bytes.
        struct Closing {
            left: usize,
        }
        impl Write for Closing {
            fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
                if self.left == 0 {
                    return Err(std::io::ErrorKind::BrokenPipe.into());
                }
                let n = buf.len().min(self.left);
                self.left -= n;
                Ok(n)
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        let mut w = Closing { left: 100 };
        let mut sim = Simulator::new(
            crate::physics::model_by_name("pendulum3").unwrap(),
            crate::physics::IntegratorKind::Rk4,
        );
        let (mut seen, x0) = (0, [0.3, -0.2, 0.1, 0.0, 0.5, -1.0]);
        let mut rows = CsvRows {
            w: &mut w,
            target: None,
        };
        let e = sim
            .try_rollout(
                &x0,
                0.01,
                MAX_STEPS,
                |_, _, _, _| {},
                |_, t, x| {
                    seen += 1;
                    rows.row(t, x)
                },
            )
            .unwrap_err();
        assert!(
            matches!(&e, Error::Io { source, .. } if source.kind() == std::io::ErrorKind::BrokenPipe),
            "{e}"
        );
        // Stopped at the first failed write, not after MAX_STEPS steps.
        assert!(seen <= 3, "{seen}");
    }
}
