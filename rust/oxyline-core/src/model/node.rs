//! A model value as the front end holds it: what the schema reader (`model::native`) asks of
//! it. The binding implements [`Node`] over Python objects (so a model dict crosses into the
//! core once, read in place); `serde_json::Value` implements it here for JSON text and tests.
//! Messages quote values the way the front end writes them ([`Node::repr`]) and numbers the
//! way Python formats them ([`py_repr`], [`py_g`]), so a user reads the same text whichever
//! side checked the model.

use serde_json::Value;

/// The type of a value, in the front end's terms (a Python `bool` is not an `int`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Null,
    Bool,
    Int,
    Float,
    Str,
    /// A list or tuple.
    List,
    Map,
    /// Anything else (an array, a callable, ...).
    Other,
}

/// A value of a model description.
pub trait Node: Sized {
    fn kind(&self) -> Kind;
    /// An `Int` or `Float` as f64 (None for every other kind).
    fn number(&self) -> Option<f64>;
    /// An `Int` that fits i64.
    fn integer(&self) -> Option<i64>;
    /// A `Str`'s text.
    fn text(&self) -> Option<String>;
    /// The value under `key` of a `Map` (None when missing or not a map).
    fn get(&self, key: &str) -> Option<Self>;
    /// A `Map`'s keys (as text) and values, in order.
    fn entries(&self) -> Vec<(String, Self)>;
    /// The items of a `List` or of an array-like value (None for anything else).
    fn items(&self) -> Option<Vec<Self>>;
    /// The value as the front end quotes it (Python's `repr`).
    fn repr(&self) -> String;
    /// The value as text (Python's `str`).
    fn show(&self) -> String;
    /// The front end's name of the value's type (Python's `type(x).__name__`).
    fn type_name(&self) -> String;
    /// Truth value (Python's `bool(x)`).
    fn truthy(&self) -> bool;

    fn is_map(&self) -> bool {
        self.kind() == Kind::Map
    }
    /// A function of time the front end can call (a wall flux f(t) given as a callable).
    fn callable(&self) -> bool {
        false
    }
    /// The value of a callable at `t` (its failure as text).
    fn call(&self, _t: f64) -> Result<Self, String> {
        Err(format!("{} is not callable", self.repr()))
    }
    fn has(&self, key: &str) -> bool {
        self.get(key).is_some()
    }
}

/// A mapping whose entries are read once: every `get` then scans them instead of asking the
/// front end again (a vessel's ~25 lookups cost one pass over its keys, not 25 calls into
/// Python). Any other value is passed through as it is.
#[derive(Clone)]
pub struct Fields<N> {
    node: N,
    entries: Option<Vec<(String, N)>>,
}

impl<N: Node + Clone> Fields<N> {
    pub fn new(node: N) -> Self {
        let entries = node.is_map().then(|| node.entries());
        Fields { node, entries }
    }
}

impl<N: Node + Clone> Node for Fields<N> {
    fn kind(&self) -> Kind {
        self.node.kind()
    }
    fn number(&self) -> Option<f64> {
        self.node.number()
    }
    fn integer(&self) -> Option<i64> {
        self.node.integer()
    }
    fn text(&self) -> Option<String> {
        self.node.text()
    }
    fn get(&self, key: &str) -> Option<Self> {
        match &self.entries {
            Some(e) => e
                .iter()
                .find(|(k, _)| k == key)
                .map(|(_, v)| Fields::new(v.clone())),
            None => None,
        }
    }
    fn entries(&self) -> Vec<(String, Self)> {
        self.entries
            .iter()
            .flatten()
            .map(|(k, v)| (k.clone(), Fields::new(v.clone())))
            .collect()
    }
    fn items(&self) -> Option<Vec<Self>> {
        Some(self.node.items()?.into_iter().map(Fields::new).collect())
    }
    fn repr(&self) -> String {
        self.node.repr()
    }
    fn show(&self) -> String {
        self.node.show()
    }
    fn type_name(&self) -> String {
        self.node.type_name()
    }
    fn truthy(&self) -> bool {
        self.node.truthy()
    }
    fn has(&self, key: &str) -> bool {
        self.entries.iter().flatten().any(|(k, _)| k == key)
    }
    fn callable(&self) -> bool {
        self.node.callable()
    }
    fn call(&self, t: f64) -> Result<Self, String> {
        self.node.call(t).map(Fields::new)
    }
}

/// Python's `repr` of a float: the shortest text that reads back the same, in fixed notation
/// for exponents −4 ≤ e < 16 (with at least one decimal), else `d.dddde±XX`.
pub fn py_repr(x: f64) -> String {
    if x.is_nan() {
        return "nan".into();
    }
    if x.is_infinite() {
        return if x > 0.0 { "inf" } else { "-inf" }.into();
    }
    let (sign, digits, exp) = shortest(x);
    if (-4..16).contains(&exp) {
        fixed(sign, &digits, exp, true)
    } else {
        scientific(sign, &digits, exp)
    }
}

/// Python's `format(x, "g")`: six significant digits, trailing zeros dropped, exponent
/// notation below 1e-4 and from 1e6.
pub fn py_g(x: f64) -> String {
    py_g_digits(x, 6)
}

/// Python's `format(x, ".{digits}g")`: `digits` (≥ 1) significant digits, trailing zeros
/// dropped, exponent notation below 1e-4 and from 10^digits.
pub fn py_g_digits(x: f64, digits: usize) -> String {
    if x.is_nan() {
        return "nan".into();
    }
    if x.is_infinite() {
        return if x > 0.0 { "inf" } else { "-inf" }.into();
    }
    let p = digits.max(1);
    let s = format!("{:.*e}", p - 1, x.abs());
    let (mant, exp) = s.split_once('e').unwrap_or((&s, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    let digits: String = mant.chars().filter(|c| c.is_ascii_digit()).collect();
    let digits = digits.trim_end_matches('0');
    let digits = if digits.is_empty() { "0" } else { digits };
    let sign = if x.is_sign_negative() { "-" } else { "" };
    if (-4..p as i32).contains(&exp) {
        fixed(sign, digits, exp, false)
    } else {
        scientific(sign, digits, exp)
    }
}

/// Sign, shortest round-trip significant digits and decimal exponent of a finite `x`.
fn shortest(x: f64) -> (&'static str, String, i32) {
    let s = format!("{:e}", x.abs());
    let (mant, exp) = s.split_once('e').unwrap_or((&s, "0"));
    let digits: String = mant.chars().filter(|c| c.is_ascii_digit()).collect();
    let sign = if x.is_sign_negative() { "-" } else { "" };
    (sign, digits, exp.parse().unwrap_or(0))
}

/// `digits` (d.ddd × 10^exp) in fixed notation; `point`: keep ".0" on a whole number.
fn fixed(sign: &str, digits: &str, exp: i32, point: bool) -> String {
    let n = digits.len() as i32;
    let body = if exp < 0 {
        format!("0.{}{digits}", "0".repeat((-exp - 1) as usize))
    } else if exp + 1 >= n {
        let whole = format!("{digits}{}", "0".repeat((exp + 1 - n) as usize));
        if point { format!("{whole}.0") } else { whole }
    } else {
        let (a, b) = digits.split_at((exp + 1) as usize);
        format!("{a}.{b}")
    };
    format!("{sign}{body}")
}

fn scientific(sign: &str, digits: &str, exp: i32) -> String {
    let (a, b) = digits.split_at(1);
    let mant = if b.is_empty() {
        a.to_owned()
    } else {
        format!("{a}.{b}")
    };
    let esign = if exp < 0 { '-' } else { '+' };
    format!("{sign}{mant}e{esign}{:02}", exp.abs())
}

/// A Python-style quoted string: `'text'` (or `"text"` when it holds a single quote).
pub fn py_quote(s: &str) -> String {
    if s.contains('\'') && !s.contains('"') {
        format!("\"{s}\"")
    } else {
        format!("'{}'", s.replace('\\', "\\\\").replace('\'', "\\'"))
    }
}

/// A Python-style list of already formatted items: `[a, b]`.
pub fn py_list(items: impl Iterator<Item = String>) -> String {
    format!("[{}]", items.collect::<Vec<_>>().join(", "))
}

/// A Python-style dict of (key, formatted value) pairs: `{'k': v}`.
pub fn py_dict<'a>(items: impl Iterator<Item = (&'a String, String)>) -> String {
    let items: Vec<String> = items
        .map(|(k, v)| format!("{}: {}", py_quote(k), v))
        .collect();
    format!("{{{}}}", items.join(", "))
}

impl Node for Value {
    fn kind(&self) -> Kind {
        match self {
            Value::Null => Kind::Null,
            Value::Bool(_) => Kind::Bool,
            Value::Number(n) if n.is_f64() => Kind::Float,
            Value::Number(_) => Kind::Int,
            Value::String(_) => Kind::Str,
            Value::Array(_) => Kind::List,
            Value::Object(_) => Kind::Map,
        }
    }
    fn number(&self) -> Option<f64> {
        match self {
            Value::Number(n) => n.as_f64(),
            _ => None,
        }
    }
    fn integer(&self) -> Option<i64> {
        match self {
            Value::Number(n) => n.as_i64(),
            _ => None,
        }
    }
    fn text(&self) -> Option<String> {
        self.as_str().map(str::to_owned)
    }
    fn get(&self, key: &str) -> Option<Self> {
        self.as_object()?.get(key).cloned()
    }
    fn entries(&self) -> Vec<(String, Self)> {
        self.as_object()
            .map(|m| m.iter().map(|(k, v)| (k.clone(), v.clone())).collect())
            .unwrap_or_default()
    }
    fn items(&self) -> Option<Vec<Self>> {
        self.as_array().cloned()
    }
    fn repr(&self) -> String {
        match self {
            Value::Null => "None".into(),
            Value::Bool(b) => if *b { "True" } else { "False" }.into(),
            Value::Number(n) if n.is_f64() => py_repr(n.as_f64().unwrap_or(f64::NAN)),
            Value::Number(n) => n.to_string(),
            Value::String(s) => py_quote(s),
            Value::Array(a) => py_list(a.iter().map(Node::repr)),
            Value::Object(m) => py_dict(m.iter().map(|(k, v)| (k, v.repr()))),
        }
    }
    fn show(&self) -> String {
        match self {
            Value::String(s) => s.clone(),
            other => other.repr(),
        }
    }
    fn type_name(&self) -> String {
        match self {
            Value::Null => "NoneType",
            Value::Bool(_) => "bool",
            Value::Number(n) if n.is_f64() => "float",
            Value::Number(_) => "int",
            Value::String(_) => "str",
            Value::Array(_) => "list",
            Value::Object(_) => "dict",
        }
        .into()
    }
    fn truthy(&self) -> bool {
        match self {
            Value::Null => false,
            Value::Bool(b) => *b,
            Value::Number(n) => n.as_f64() != Some(0.0),
            Value::String(s) => !s.is_empty(),
            Value::Array(a) => !a.is_empty(),
            Value::Object(m) => !m.is_empty(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Python 3's own output for the same numbers (`repr(x)`, `format(x, "g")`).
    #[test]
    fn floats_read_as_python_writes_them() {
        let cases = [
            (1.0, "1.0", "1"),
            (-0.001, "-0.001", "-0.001"),
            (1e-5, "1e-05", "1e-05"),
            (0.0001, "0.0001", "0.0001"),
            (1e16, "1e+16", "1e+16"),
            (1234567.0, "1234567.0", "1.23457e+06"),
            (3e9, "3000000000.0", "3e+09"),
            (-1e-12, "-1e-12", "-1e-12"),
            (0.1 + 0.2, "0.30000000000000004", "0.3"),
            (0.0, "0.0", "0"),
            (123456.0, "123456.0", "123456"),
            (2.5, "2.5", "2.5"),
            (1.5e300, "1.5e+300", "1.5e+300"),
        ];
        for (x, repr, g) in cases {
            assert_eq!(py_repr(x), repr, "repr of {x}");
            assert_eq!(py_g(x), g, "g of {x}");
        }
        // `format(x, ".4g")`
        for (x, g4) in [
            (-9.995e6, "-9.995e+06"),
            (12346.0, "1.235e+04"),
            (0.0, "0"),
            (1013.25, "1013"),
            (2.5e-5, "2.5e-05"),
            (-0.5, "-0.5"),
        ] {
            assert_eq!(py_g_digits(x, 4), g4, "{x}");
        }
        assert_eq!(py_repr(f64::NAN), "nan");
        assert_eq!(py_g(f64::NEG_INFINITY), "-inf");
    }
}
