//! Typed result rows: a table's columns declared once, as a row struct that the job writes and
//! the figures and the report read back, from the job's own [`Table`] or from its CSV file.
//!
//! [`result_rows!`](crate::result_rows) declares the struct with each field's column name; the
//! column order is the declaration's, so the CSV a job writes through [`table_of`] is the one it
//! wrote with `row![..]` cells in that order. [`read_rows`] reads the file back strictly: a
//! missing file, a missing column or a value of the wrong type is an error naming the file.

use super::output::{df_f64, df_i64, df_str, read_csv, Cell, Table};
use super::Error;
use std::path::Path;

/// The data frame a typed table is read from.
pub use polars::prelude::DataFrame as Frame;

/// A value that one column of a typed table holds.
pub trait ColumnValue: Sized {
    /// The column `name` of a frame read from a file.
    fn frame_column(df: &Frame, name: &str) -> Result<Vec<Self>, Error>;
    /// The column `name` of a table built in this program (a missing column panics: see
    /// [`Table::f64s`]).
    fn table_column(t: &Table, name: &str) -> Vec<Self>;
    /// The value as a table cell.
    fn cell(&self) -> Cell;
}

impl ColumnValue for f64 {
    fn frame_column(df: &Frame, name: &str) -> Result<Vec<Self>, Error> {
        df_f64(df, name)
    }
    fn table_column(t: &Table, name: &str) -> Vec<Self> {
        t.f64s(name)
    }
    fn cell(&self) -> Cell {
        Cell::F(*self)
    }
}

impl ColumnValue for i64 {
    fn frame_column(df: &Frame, name: &str) -> Result<Vec<Self>, Error> {
        df_i64(df, name)
    }
    fn table_column(t: &Table, name: &str) -> Vec<Self> {
        t.i64s(name)
    }
    fn cell(&self) -> Cell {
        Cell::I(*self)
    }
}

impl ColumnValue for String {
    fn frame_column(df: &Frame, name: &str) -> Result<Vec<Self>, Error> {
        df_str(df, name)
    }
    fn table_column(t: &Table, name: &str) -> Vec<Self> {
        t.strs(name)
    }
    fn cell(&self) -> Cell {
        Cell::S(self.clone())
    }
}

/// A row of a result table; implemented by [`result_rows!`](crate::result_rows).
pub trait TableRow: Sized {
    /// The column names, in the file's order.
    const COLUMNS: &'static [&'static str];
    /// The row's cells, in the order of [`TableRow::COLUMNS`].
    fn cells(&self) -> Vec<Cell>;
    /// Every row of a frame read from a file.
    fn from_frame(df: &Frame) -> Result<Vec<Self>, Error>;
    /// Every row of a table built in this program.
    fn from_table(t: &Table) -> Vec<Self>;
}

/// The table of `rows`, its columns in [`TableRow::COLUMNS`]' order.
pub fn table_of<R: TableRow>(rows: &[R]) -> Table {
    let mut t = Table::new(R::COLUMNS);
    for r in rows {
        t.push(r.cells());
    }
    t
}

/// The rows of the CSV file at `path`, written by [`table_of`]'s table: an error naming the file
/// when it is missing, not whole, or lacks a column of `R`.
pub fn read_rows<R: TableRow>(path: &Path) -> Result<Vec<R>, Error> {
    let df = read_csv(path)?;
    R::from_frame(&df).map_err(|e| Error::Other(format!("{}: {e}", path.display())))
}

/// The rows of `dir/name`, a table the run writes only when its spec asks for the study behind
/// it ([`written_csv`](super::output::written_csv)): `None` when the run did not write it; a
/// table it wrote that is missing, not whole or lacks a column of `R` is an error naming it.
pub fn written_rows<R: TableRow>(dir: &Path, name: &str) -> Result<Option<Vec<R>>, Error> {
    let Some(df) = super::output::written_csv(dir, name)? else {
        return Ok(None);
    };
    R::from_frame(&df)
        .map(Some)
        .map_err(|e| Error::Other(format!("{}: {e}", dir.join(name).display())))
}

/// A column the harness prepends to a table when its run sweeps that axis (or runs over
/// seeds): `None` in every row of a table without it.
#[derive(Debug, Clone, PartialEq)]
pub struct Swept<T>(pub Option<T>);

impl<T: ColumnValue + Clone> ColumnValue for Swept<T> {
    fn frame_column(df: &Frame, name: &str) -> Result<Vec<Self>, Error> {
        if df.column(name).is_err() {
            return Ok(vec![Swept(None); df.height()]);
        }
        Ok(T::frame_column(df, name)?
            .into_iter()
            .map(|v| Swept(Some(v)))
            .collect())
    }

    fn table_column(t: &Table, name: &str) -> Vec<Self> {
        if !t.names().iter().any(|n| n == name) {
            return vec![Swept(None); t.len()];
        }
        T::table_column(t, name)
            .into_iter()
            .map(|v| Swept(Some(v)))
            .collect()
    }

    fn cell(&self) -> Cell {
        match &self.0 {
            Some(v) => v.cell(),
            None => Cell::S(String::new()),
        }
    }
}

/// Declares a result table's row struct, each field with its column's name:
///
/// ```
/// motionlab::result_rows! {
///     /// One row of `runs.csv`.
///     pub struct Run {
///         /// The method's name.
///         method: String = "method",
///         /// Its error (m).
///         error_m: f64 = "error_m",
///     }
/// }
/// use motionlab::experiment::rows::{table_of, TableRow};
/// let rows = vec![Run { method: "lbc".into(), error_m: 0.5 }];
/// let t = table_of(&rows);
/// assert_eq!(t.names(), ["method", "error_m"]);
/// assert_eq!(Run::from_table(&t), rows);
/// ```
#[macro_export]
macro_rules! result_rows {
    (
        $(#[$meta:meta])*
        $vis:vis struct $name:ident {
            $( $(#[$fmeta:meta])* $field:ident : $ty:ty = $column:literal ),* $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, PartialEq)]
        $vis struct $name {
            $( $(#[$fmeta])* pub $field: $ty, )*
        }

        impl $crate::experiment::rows::TableRow for $name {
            const COLUMNS: &'static [&'static str] = &[$($column),*];

            fn cells(&self) -> Vec<$crate::experiment::output::Cell> {
                vec![$( $crate::experiment::rows::ColumnValue::cell(&self.$field) ),*]
            }

            fn from_frame(
                df: &$crate::experiment::rows::Frame,
            ) -> Result<Vec<Self>, $crate::experiment::Error> {
                $(
                    let mut $field =
                        <$ty as $crate::experiment::rows::ColumnValue>::frame_column(df, $column)?
                            .into_iter();
                )*
                Ok((0..df.height())
                    .map(|_| Self {
                        $( $field: $field.next().expect("a frame's columns have its height"), )*
                    })
                    .collect())
            }

            fn from_table(t: &$crate::experiment::output::Table) -> Vec<Self> {
                $(
                    let mut $field =
                        <$ty as $crate::experiment::rows::ColumnValue>::table_column(t, $column)
                            .into_iter();
                )*
                (0..t.len())
                    .map(|_| Self {
                        $( $field: $field.next().expect("a table's columns have its length"), )*
                    })
                    .collect()
            }
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::output::write_table;

    crate::result_rows! {
        /// A test row.
        struct Probe {
            /// A name.
            name: String = "name",
            /// A number.
            x: f64 = "x_m",
            /// A count.
            n: i64 = "n",
        }
    }

    /// A table of a header and no rows (an empty sweep) reads back as no rows, its integer
    /// column untyped in the file; without one of the columns it is still an error naming it.
    #[test]
    fn an_empty_table_reads_as_no_rows() {
        let dir = tempfile::tempdir().unwrap();
        write_table(dir.path(), "empty", &table_of::<Probe>(&[])).unwrap();
        let rows: Vec<Probe> = read_rows(&dir.path().join("empty.csv")).unwrap();
        assert!(rows.is_empty());
        write_table(dir.path(), "short", &Table::new(&["name", "n"])).unwrap();
        let err = read_rows::<Probe>(&dir.path().join("short.csv")).unwrap_err();
        assert!(err.to_string().contains("short.csv"), "{err}");
        assert!(err.to_string().contains("x_m"), "{err}");
    }

    /// Rows written through their table and read back from the file and from the table are
    /// the rows; the CSV's columns are the declaration's; a file without one of the columns is
    /// an error naming the file and the column.
    #[test]
    fn rows_round_trip_and_a_missing_column_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let rows = vec![
            Probe {
                name: "a".into(),
                x: 0.5,
                n: 3,
            },
            Probe {
                name: "b".into(),
                x: f64::INFINITY,
                n: -1,
            },
        ];
        let t = table_of(&rows);
        assert_eq!(t.names(), ["name", "x_m", "n"]);
        assert_eq!(Probe::from_table(&t), rows);
        write_table(dir.path(), "probe", &t).unwrap();
        let back: Vec<Probe> = read_rows(&dir.path().join("probe.csv")).unwrap();
        assert_eq!(back, rows);
        assert!(Probe::from_table(&table_of::<Probe>(&[])).is_empty());

        let mut other = Table::new(&["name", "y", "n"]);
        other.push(crate::row!["a", 1.0, 2i64]);
        write_table(dir.path(), "other", &other).unwrap();
        let err = read_rows::<Probe>(&dir.path().join("other.csv"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("other.csv") && err.contains("x_m"), "{err}");
        // Integers are read as integers: a column of fractions is refused, naming it.
        let mut fractions = Table::new(&["name", "x_m", "n"]);
        fractions.push(crate::row!["a", 1.0, 2.5]);
        write_table(dir.path(), "fractions", &fractions).unwrap();
        let err = read_rows::<Probe>(&dir.path().join("fractions.csv"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("fractions.csv") && err.contains("column n"),
            "{err}"
        );
        let err = read_rows::<Probe>(&dir.path().join("absent.csv"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("absent.csv"), "{err}");
    }
}
