//! A checkpoint file's metadata: its schema (the format's name, the file layout's version, the
//! fields and what each must be), checked here before any field is used, and the
//! `checkpoint_every` setting. Writing and reading the file itself (an archive of the
//! metadata as JSON and the [`super::Snapshot`]'s arrays, replaced atomically) is the front
//! end's.

use super::CHECKPOINT_VERSION;
use crate::error::{Error, Result};
use crate::model::node::{Kind, Node, py_g, py_repr};

/// The `format` field of every checkpoint file.
pub const FORMAT: &str = "oxyline-checkpoint";
/// The layout of the file (its metadata fields and arrays); another is refused.
pub const FILE_VERSION: i64 = 1;
/// The snapshot's numbers, kept in the metadata's `state` (its arrays are the file's arrays).
pub const STATE_SCALARS: [&str; 5] = ["version", "cycles_run", "steps", "dt", "periodic_error"];
/// The longest wall time between checkpoints (~32 years): any longer means never.
pub const MAX_EVERY_SECONDS: f64 = 1e9;
/// The most cycles between checkpoints (`"N cycles"`, N of at most 12 digits).
pub const MAX_EVERY_CYCLES: u64 = 999_999_999_999;
/// The settings a resumed run may change: they change how it runs, not its results
/// (`threads`: the same bits on any number of threads). A checkpoint stores the others.
pub const RUN_CONTROL: [&str; 6] = [
    "progress",
    "cancel",
    "checkpoint",
    "checkpoint_every",
    "max_memory",
    "threads",
];

/// When to write checkpoints, as the setting gives it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Interval {
    /// At the end of every n-th cycle.
    Cycles(u64),
    /// At the end of the first cycle this many seconds of wall time after the last.
    Seconds(f64),
}

/// `checkpoint_every`: seconds of wall time (a number from 0 to [`MAX_EVERY_SECONDS`], or
/// text such as `"90 s"`), or `"N cycles"` (N from 1); None when not given (the run's
/// default). Anything else is a `ModelError` naming the setting and the value, and so is a
/// `checkpoint_every` without a `checkpoint` file (`file`: one is given).
pub fn parse_every<N: Node>(value: &N, file: bool) -> Result<Option<Interval>> {
    if !file && value.kind() != Kind::Null {
        return Err(Error::model(
            "simulate",
            "checkpoint_every needs checkpoint (the file to write)",
        ));
    }
    // (the number of seconds, and the value as the message quotes it: the number read from
    // a text, else the value given)
    let (seconds, shown) = match value.kind() {
        Kind::Null => return Ok(None),
        Kind::Str => {
            let text = value.text().unwrap_or_default();
            if let Some(n) = cycles_text(&text) {
                return Ok(Some(Interval::Cycles(n)));
            }
            match seconds_text(&text) {
                Some(x) => (Some(x), py_repr(x)),
                None => (None, value.repr()),
            }
        }
        Kind::Int | Kind::Float => (value.number(), value.repr()),
        _ => (None, value.repr()),
    };
    match seconds {
        Some(x) if x.is_finite() && (0.0..=MAX_EVERY_SECONDS).contains(&x) => {
            Ok(Some(Interval::Seconds(x)))
        }
        _ => Err(every_error(&shown)),
    }
}

/// The settings a resumed run is given (`keys`): only [`RUN_CONTROL`] may change, a
/// `ModelError` names the others.
pub fn check_resumed<S: AsRef<str>>(keys: &[S]) -> Result<()> {
    let mut changed: Vec<&str> = keys
        .iter()
        .map(AsRef::as_ref)
        .filter(|k| !RUN_CONTROL.contains(k))
        .collect();
    if changed.is_empty() {
        return Ok(());
    }
    changed.sort_unstable();
    changed.dedup();
    Err(Error::model(
        "resume",
        format!(
            "{} cannot change in a resumed run (it continues with the checkpoint's model and \
             settings)",
            changed.join(", ")
        ),
    ))
}

fn every_error(shown: &str) -> Error {
    let shown: String = shown.chars().take(80).collect();
    Error::model(
        "simulate",
        format!(
            "checkpoint_every must be seconds of wall time (a number from 0 to {}) or \
             'N cycles' (N from 1 to 10**12), got {shown}",
            py_g(MAX_EVERY_SECONDS)
        ),
    )
}

/// `"N cycles"` (or `"1 cycle"`): N of 1 to 12 digits, at least 1.
fn cycles_text(text: &str) -> Option<u64> {
    let (digits, unit) = number_and_unit(text, |c| c.is_ascii_digit())?;
    let n: u64 = digits.parse().ok()?;
    (digits.len() <= 12 && n >= 1 && matches!(unit, "cycle" | "cycles")).then_some(n)
}

/// `"90 s"`, `"1.5 sec"`, `"600 seconds"`: the number (not checked for its range here).
fn seconds_text(text: &str) -> Option<f64> {
    let (number, unit) = number_and_unit(text, |c| c.is_ascii_digit() || c == '.')?;
    matches!(unit, "s" | "sec" | "second" | "seconds")
        .then(|| number.parse().ok())
        .flatten()
}

/// The leading run of `part` characters (at least one) and the word after it, spaces around
/// either allowed.
fn number_and_unit(text: &str, part: impl Fn(char) -> bool) -> Option<(&str, &str)> {
    let text = text.trim();
    let end = text.find(|c: char| !part(c)).unwrap_or(text.len());
    (end > 0).then(|| (&text[..end], text[end..].trim_start()))
}

/// What a field must be: (field, test, what it must be).
type FieldRule<N> = (&'static str, fn(&N) -> bool, &'static str);

fn is_count<N: Node>(x: &N) -> bool {
    x.kind() == Kind::Int && x.integer().is_some_and(|n| n >= 0)
}

fn is_real<N: Node>(x: &N) -> bool {
    matches!(x.kind(), Kind::Int | Kind::Float) && x.number().is_some_and(f64::is_finite)
}

fn meta_fields<N: Node>() -> [FieldRule<N>; 4] {
    [
        ("model", N::is_map, "a mapping (the model)"),
        ("settings", N::is_map, "a mapping (the run settings)"),
        ("state", N::is_map, "a mapping (the run state's numbers)"),
        (
            "checkpoint_every",
            |x| matches!(x.kind(), Kind::Null | Kind::Str) || is_real(x),
            "seconds, 'N cycles' or null",
        ),
    ]
}

fn state_fields<N: Node>() -> [FieldRule<N>; 4] {
    [
        ("cycles_run", is_count::<N>, "an integer >= 0"),
        ("steps", is_count::<N>, "an integer >= 0"),
        (
            "dt",
            |x| is_real(x) && x.number().is_some_and(|dt| dt > 0.0),
            "a finite number > 0",
        ),
        (
            "periodic_error",
            |x| matches!(x.kind(), Kind::Null | Kind::Int | Kind::Float),
            "a number",
        ),
    ]
}

/// One array of a checkpoint file: its name, number of dimensions and dtype (as the front
/// end writes it: `float64`).
pub type ArrayShape = (String, usize, String);

/// Every field of a checkpoint's metadata `meta` present and of its type, the versions of the
/// file layout and of the run state this core reads, and every array of the file
/// (`arrays`) one-dimensional float64 and not also a number of the state, before any field
/// is used. An error names `file` and the field (`state/dt`) and quotes the value.
pub fn check<N: Node>(meta: &N, file: &str, arrays: &[ArrayShape]) -> Result<()> {
    let bad = |message: String| Err(Error::model(file, message));
    let format = meta.get("format").and_then(|f| f.text());
    if !meta.is_map() || format.as_deref() != Some(FORMAT) {
        return bad(format!(
            "not an oxyline checkpoint (field 'format' is not '{FORMAT}')"
        ));
    }
    let version = meta.get("version");
    if version
        .as_ref()
        .and_then(|v| v.integer().filter(|_| v.kind() == Kind::Int))
        != Some(FILE_VERSION)
    {
        return bad(format!(
            "checkpoint file version {}, this oxyline ({}) reads version {FILE_VERSION}",
            version.map_or_else(|| "None".into(), |v| v.repr()),
            env!("CARGO_PKG_VERSION")
        ));
    }
    fields(meta, "", &meta_fields()).map_err(|m| Error::model(file, m))?;
    if let Some(state) = meta.get("state") {
        fields(&state, "state/", &state_fields()).map_err(|m| Error::model(file, m))?;
        let v = state.get("version");
        let same = v.as_ref().is_some_and(|v| {
            matches!(v.kind(), Kind::Int | Kind::Float)
                && v.number() == Some(CHECKPOINT_VERSION.into())
        });
        if !same {
            return bad(format!(
                "run state version {}, this oxyline ({}) reads version {CHECKPOINT_VERSION}",
                v.map_or_else(|| "None".into(), |v| v.repr()),
                env!("CARGO_PKG_VERSION")
            ));
        }
        for (key, ndim, dtype) in arrays {
            if dtype != "float64" || *ndim != 1 {
                return bad(format!(
                    "field '{key}' must be a 1-D float64 array, got {ndim}-D {dtype}"
                ));
            }
            if state.has(key) {
                return bad(format!("field '{key}' is both a number and an array"));
            }
        }
    }
    Ok(())
}

/// Each field of `rules` present in `record` and passing its test (`place`: the record's
/// prefix in the messages).
fn fields<N: Node>(
    record: &N,
    place: &str,
    rules: &[FieldRule<N>],
) -> std::result::Result<(), String> {
    for (key, ok, what) in rules {
        let Some(value) = record.get(key) else {
            return Err(format!("field '{place}{key}' is missing"));
        };
        if !ok(&value) {
            let shown: String = value.repr().chars().take(80).collect();
            return Err(format!("field '{place}{key}' must be {what}, got {shown}"));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::{Value, json};

    fn every(v: Value) -> std::result::Result<Option<Interval>, String> {
        parse_every(&v, true).map_err(|e| e.to_string())
    }

    #[test]
    fn checkpoint_every_reads_seconds_or_cycles() {
        assert_eq!(every(json!(null)), Ok(None));
        assert_eq!(every(json!(600)), Ok(Some(Interval::Seconds(600.0))));
        assert_eq!(every(json!(0.0)), Ok(Some(Interval::Seconds(0.0))));
        assert_eq!(every(json!(" 90 s ")), Ok(Some(Interval::Seconds(90.0))));
        assert_eq!(every(json!("1.5sec")), Ok(Some(Interval::Seconds(1.5))));
        assert_eq!(every(json!(".5 seconds")), Ok(Some(Interval::Seconds(0.5))));
        assert_eq!(every(json!("1 cycle")), Ok(Some(Interval::Cycles(1))));
        assert_eq!(
            every(json!("999999999999 cycles")),
            Ok(Some(Interval::Cycles(MAX_EVERY_CYCLES)))
        );
    }

    #[test]
    fn a_bad_checkpoint_every_is_a_model_error_naming_the_setting_and_value() {
        let head = "simulate: checkpoint_every must be seconds of wall time (a number from 0 to \
                    1e+09) or 'N cycles' (N from 1 to 10**12), got ";
        for (value, shown) in [
            (json!("often"), "'often'"),
            (json!("0 cycles"), "'0 cycles'"),
            (json!("1000000000000 cycles"), "'1000000000000 cycles'"),
            (json!("1.2.3 s"), "'1.2.3 s'"),
            (json!(". s"), "'. s'"),
            (json!("2e3 s"), "'2e3 s'"),
            (json!(-1), "-1"),
            (json!(-0.5), "-0.5"),
            (json!(2e9), "2000000000.0"),
            (json!("9999999999 s"), "9999999999.0"),
            (json!(true), "True"),
            (json!([1]), "[1]"),
        ] {
            assert_eq!(
                every(value.clone()),
                Err(format!("{head}{shown}")),
                "{value}"
            );
        }
        // a long value is quoted to 80 characters
        let long = every(json!("x".repeat(200))).unwrap_err();
        assert_eq!(long.len(), head.len() + 80);
    }

    #[test]
    fn checkpoint_every_needs_a_file_and_a_resumed_run_changes_only_run_control() {
        assert_eq!(parse_every(&json!(null), false), Ok(None));
        assert_eq!(
            parse_every(&json!(10), false).unwrap_err().to_string(),
            "simulate: checkpoint_every needs checkpoint (the file to write)"
        );
        assert_eq!(
            check_resumed(&["progress", "threads", "checkpoint"]),
            Ok(())
        );
        assert_eq!(
            check_resumed(&["dt", "progress", "cycles", "dt"])
                .unwrap_err()
                .to_string(),
            "resume: cycles, dt cannot change in a resumed run (it continues with the \
             checkpoint's model and settings)"
        );
    }

    fn good() -> Value {
        json!({
            "format": FORMAT, "version": FILE_VERSION, "model": {}, "settings": {},
            "checkpoint_every": "2 cycles",
            "state": {"version": CHECKPOINT_VERSION, "cycles_run": 2, "steps": 2000,
                      "dt": 1e-3, "periodic_error": null}
        })
    }

    fn check_with(change: impl FnOnce(&mut Value)) -> std::result::Result<(), String> {
        let mut meta = good();
        change(&mut meta);
        check(&meta, "run.ckpt", &[]).map_err(|e| e.to_string())
    }

    #[test]
    fn checkpoint_metadata_of_this_layout_passes() {
        assert_eq!(check_with(|_| {}), Ok(()));
        assert_eq!(check_with(|m| m["checkpoint_every"] = json!(300.5)), Ok(()));
        assert_eq!(
            check_with(|m| m["state"]["periodic_error"] = json!(0.5)),
            Ok(())
        );
    }

    #[test]
    fn the_arrays_are_one_dimensional_float64_and_not_numbers_too() {
        let arrays = |list: &[(&str, usize, &str)]| -> Vec<ArrayShape> {
            list.iter()
                .map(|(k, n, d)| (k.to_string(), *n, d.to_string()))
                .collect()
        };
        let meta = good();
        assert_eq!(
            check(
                &meta,
                "f",
                &arrays(&[("y", 1, "float64"), ("data", 1, "float64")])
            ),
            Ok(())
        );
        let e = |list: &[(&str, usize, &str)]| {
            check(&meta, "f", &arrays(list)).unwrap_err().to_string()
        };
        assert_eq!(
            e(&[("y", 2, "float64")]),
            "f: field 'y' must be a 1-D float64 array, got 2-D float64"
        );
        assert_eq!(
            e(&[("y", 1, "int64")]),
            "f: field 'y' must be a 1-D float64 array, got 1-D int64"
        );
        assert_eq!(
            e(&[("dt", 1, "float64")]),
            "f: field 'dt' is both a number and an array"
        );
    }

    #[test]
    fn a_bad_field_is_named_with_the_file_and_its_value() {
        let e = |change: fn(&mut Value)| check_with(change).unwrap_err();
        assert_eq!(
            e(|m| m["format"] = json!("zip")),
            "run.ckpt: not an oxyline checkpoint (field 'format' is not 'oxyline-checkpoint')"
        );
        assert!(
            check(&json!([1, 2]), "f", &[])
                .unwrap_err()
                .to_string()
                .contains("field 'format'")
        );
        let version = e(|m| m["version"] = json!("1"));
        assert!(
            version.starts_with("run.ckpt: checkpoint file version '1', this oxyline (")
                && version.ends_with(") reads version 1"),
            "{version}"
        );
        assert!(e(|m| m["version"] = json!(99)).contains("file version 99"));
        assert_eq!(
            e(|m| drop(m.as_object_mut().unwrap().remove("model"))),
            "run.ckpt: field 'model' is missing"
        );
        assert_eq!(
            e(|m| m["settings"] = json!([1, 2])),
            "run.ckpt: field 'settings' must be a mapping (the run settings), got [1, 2]"
        );
        assert_eq!(
            e(|m| m["checkpoint_every"] = json!({"s": 1})),
            "run.ckpt: field 'checkpoint_every' must be seconds, 'N cycles' or null, got {'s': 1}"
        );
        assert_eq!(
            e(|m| m["state"]["dt"] = json!("0.001")),
            "run.ckpt: field 'state/dt' must be a finite number > 0, got '0.001'"
        );
        assert_eq!(
            e(|m| m["state"]["dt"] = json!(-1.0)),
            "run.ckpt: field 'state/dt' must be a finite number > 0, got -1.0"
        );
        assert_eq!(
            e(|m| m["state"]["cycles_run"] = json!(1.5)),
            "run.ckpt: field 'state/cycles_run' must be an integer >= 0, got 1.5"
        );
        assert_eq!(
            e(|m| m["state"]["steps"] = json!(true)),
            "run.ckpt: field 'state/steps' must be an integer >= 0, got True"
        );
        assert_eq!(
            e(|m| drop(m["state"].as_object_mut().unwrap().remove("steps"))),
            "run.ckpt: field 'state/steps' is missing"
        );
        assert_eq!(
            e(|m| m["state"]["periodic_error"] = json!(false)),
            "run.ckpt: field 'state/periodic_error' must be a number, got False"
        );
        let state = e(|m| m["state"]["version"] = json!(7));
        assert!(state.starts_with("run.ckpt: run state version 7, this oxyline ("));
        assert!(
            e(|m| m["state"]["version"] = json!(true)).contains("run state version True"),
            "a bool is no version"
        );
    }
}
