//! A serde `Deserializer` over Python objects: the core's serde types (`VesselSpec`,
//! `BoundarySpec`, `NetworkSpec`, ...) read a model's dicts in place, as they read its JSON
//! text, with no text written in between. Types are taken as Python has them, strictly: a
//! number is an `int` or `float` (never a `bool`), a string a `str`, a list a `list` or
//! `tuple`, a mapping a `dict`. A message names the key path inside the element and the value
//! as Python writes it (`'geometry.length' must be a number, got '1'`).

use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use serde::de::{self, DeserializeSeed, Deserializer, IntoDeserializer, Visitor};
use std::fmt;

/// A value that does not read, with the key path to it (outermost first).
#[derive(Debug)]
pub(crate) struct DeError {
    path: Vec<String>,
    message: String,
}

impl DeError {
    fn at(mut self, key: String) -> Self {
        self.path.insert(0, key);
        self
    }
}

impl fmt::Display for DeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.path.is_empty() {
            return f.write_str(&self.message);
        }
        let mut path = String::new();
        for (i, k) in self.path.iter().enumerate() {
            if i > 0 && !k.starts_with('[') {
                path.push('.');
            }
            path.push_str(k);
        }
        // "'key' must be ..." reads as the schema's messages do; anything else after a colon
        let sep = if self.message.starts_with("must be") {
            " "
        } else {
            ": "
        };
        write!(f, "'{path}'{sep}{}", self.message)
    }
}

impl std::error::Error for DeError {}

impl de::Error for DeError {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        DeError {
            path: Vec::new(),
            message: msg.to_string(),
        }
    }
    fn invalid_type(unexp: de::Unexpected<'_>, exp: &dyn de::Expected) -> Self {
        Self::custom(format_args!("must be {}, got {unexp}", expected(exp)))
    }
    fn invalid_value(unexp: de::Unexpected<'_>, exp: &dyn de::Expected) -> Self {
        Self::custom(format_args!("must be {}, got {unexp}", expected(exp)))
    }
}

type Res<T> = Result<T, DeError>;

/// serde's name of an expected primitive in the schema's words (a value read from serde's
/// buffer of a tagged variant is checked by serde's own visitors).
fn expected(exp: &dyn de::Expected) -> String {
    let name = exp.to_string();
    match name.as_str() {
        "f64" | "f32" => "a number".into(),
        "u8" | "u16" | "u32" | "u64" | "usize" => "an integer >= 0".into(),
        "i8" | "i16" | "i32" | "i64" | "isize" => "an integer".into(),
        "a boolean" => "a bool".into(),
        _ => name,
    }
}

/// Python's `repr` of a value (for messages).
fn repr(o: &Bound<'_, PyAny>) -> String {
    o.repr()
        .map(|s| s.to_string())
        .unwrap_or_else(|_| "<?>".into())
}

fn must(what: &str, o: &Bound<'_, PyAny>) -> DeError {
    de::Error::custom(format_args!("must be {what}, got {}", repr(o)))
}

/// One Python value to be read by a serde type.
pub(crate) struct PyDe<'a, 'py>(pub &'a Bound<'py, PyAny>);

impl<'py> PyDe<'_, 'py> {
    /// An `int` or `float`, not a `bool`, as f64.
    fn number(&self) -> Res<f64> {
        let o = self.0;
        if let Ok(f) = o.cast::<PyFloat>() {
            return Ok(f.value());
        }
        if o.is_instance_of::<PyInt>() && !o.is_instance_of::<PyBool>() {
            return o.extract::<f64>().map_err(|_| must("a number", o));
        }
        Err(must("a number", o))
    }

    /// An `int`, not a `bool`.
    fn int(&self) -> Option<&Bound<'py, PyAny>> {
        let o = self.0;
        (o.is_instance_of::<PyInt>() && !o.is_instance_of::<PyBool>()).then_some(o)
    }

    fn unsigned(&self) -> Res<u64> {
        let o = self.int().ok_or_else(|| must("an integer >= 0", self.0))?;
        o.extract::<u64>().map_err(|_| must("an integer >= 0", o))
    }

    fn signed(&self) -> Res<i64> {
        let o = self.int().ok_or_else(|| must("an integer", self.0))?;
        o.extract::<i64>().map_err(|_| must("an integer", o))
    }

    fn text(&self) -> Res<&Bound<'py, PyString>> {
        self.0
            .cast::<PyString>()
            .map_err(|_| must("a string", self.0))
    }

    fn sequence<'de, V: Visitor<'de>>(&self, v: V) -> Res<V::Value> {
        let o = self.0;
        let items: Vec<Bound<'py, PyAny>> = if let Ok(l) = o.cast::<PyList>() {
            l.iter().collect()
        } else if let Ok(t) = o.cast::<PyTuple>() {
            t.iter().collect()
        } else {
            return Err(must("a list", o));
        };
        v.visit_seq(Seq {
            items: items.into_iter(),
            index: 0,
        })
    }

    fn mapping<'de, V: Visitor<'de>>(&self, v: V) -> Res<V::Value> {
        let d = self
            .0
            .cast::<PyDict>()
            .map_err(|_| must("a mapping", self.0))?;
        v.visit_map(Map {
            items: d.iter(),
            entry: None,
        })
    }
}

fn with_str<'de, V: Visitor<'de>>(s: &Bound<'_, PyString>, v: V) -> Res<V::Value> {
    let text = s
        .to_str()
        .map_err(|_| de::Error::custom("must be text without lone surrogates"))?;
    v.visit_str(text)
}

impl<'de> Deserializer<'de> for PyDe<'_, '_> {
    type Error = DeError;

    fn deserialize_any<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        let o = self.0;
        if o.is_none() {
            v.visit_unit()
        } else if let Ok(b) = o.cast::<PyBool>() {
            v.visit_bool(b.is_true())
        } else if o.is_instance_of::<PyInt>() {
            match o.extract::<i64>() {
                Ok(i) => v.visit_i64(i),
                Err(_) => v.visit_u64(self.unsigned()?),
            }
        } else if let Ok(f) = o.cast::<PyFloat>() {
            v.visit_f64(f.value())
        } else if let Ok(s) = o.cast::<PyString>() {
            with_str(s, v)
        } else if o.is_instance_of::<PyList>() || o.is_instance_of::<PyTuple>() {
            self.sequence(v)
        } else if o.is_instance_of::<PyDict>() {
            self.mapping(v)
        } else {
            Err(de::Error::custom(format_args!(
                "must be a number, string, list or mapping, got {}",
                repr(o)
            )))
        }
    }

    fn deserialize_bool<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        match self.0.cast::<PyBool>() {
            Ok(b) => v.visit_bool(b.is_true()),
            Err(_) => Err(must("a bool", self.0)),
        }
    }

    fn deserialize_f64<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        v.visit_f64(self.number()?)
    }

    fn deserialize_f32<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        v.visit_f64(self.number()?)
    }

    fn deserialize_u64<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        v.visit_u64(self.unsigned()?)
    }

    fn deserialize_u32<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        v.visit_u64(self.unsigned()?)
    }

    fn deserialize_u8<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        v.visit_u64(self.unsigned()?)
    }

    fn deserialize_u16<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        v.visit_u64(self.unsigned()?)
    }

    fn deserialize_i64<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        v.visit_i64(self.signed()?)
    }

    fn deserialize_i32<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        v.visit_i64(self.signed()?)
    }

    fn deserialize_i16<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        v.visit_i64(self.signed()?)
    }

    fn deserialize_i8<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        v.visit_i64(self.signed()?)
    }

    fn deserialize_str<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        with_str(self.text()?, v)
    }

    fn deserialize_string<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        with_str(self.text()?, v)
    }

    fn deserialize_char<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        with_str(self.text()?, v)
    }

    fn deserialize_identifier<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        with_str(self.text()?, v)
    }

    fn deserialize_option<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        if self.0.is_none() {
            v.visit_none()
        } else {
            v.visit_some(self)
        }
    }

    fn deserialize_unit<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        if self.0.is_none() {
            v.visit_unit()
        } else {
            Err(must("None", self.0))
        }
    }

    fn deserialize_unit_struct<V: Visitor<'de>>(self, _: &'static str, v: V) -> Res<V::Value> {
        self.deserialize_unit(v)
    }

    fn deserialize_newtype_struct<V: Visitor<'de>>(self, _: &'static str, v: V) -> Res<V::Value> {
        v.visit_newtype_struct(self)
    }

    fn deserialize_seq<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        self.sequence(v)
    }

    fn deserialize_tuple<V: Visitor<'de>>(self, _: usize, v: V) -> Res<V::Value> {
        self.sequence(v)
    }

    fn deserialize_tuple_struct<V: Visitor<'de>>(
        self,
        _: &'static str,
        _: usize,
        v: V,
    ) -> Res<V::Value> {
        self.sequence(v)
    }

    fn deserialize_map<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        self.mapping(v)
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        _: &'static str,
        _: &'static [&'static str],
        v: V,
    ) -> Res<V::Value> {
        self.mapping(v)
    }

    /// A unit variant by its name (`"pi"`), a variant with content as a one-key mapping.
    fn deserialize_enum<V: Visitor<'de>>(
        self,
        _: &'static str,
        _: &'static [&'static str],
        v: V,
    ) -> Res<V::Value> {
        if let Ok(s) = self.0.cast::<PyString>() {
            let name = s
                .to_str()
                .map_err(|_| de::Error::custom("must be text without lone surrogates"))?;
            return v.visit_enum(name.into_deserializer());
        }
        let d = self
            .0
            .cast::<PyDict>()
            .map_err(|_| must("a name", self.0))?;
        let mut it = d.iter();
        match (it.next(), it.next()) {
            (Some((k, x)), None) => v.visit_enum(Variant { key: k, value: x }),
            _ => Err(must("a name or a mapping of one key", self.0)),
        }
    }

    fn deserialize_bytes<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        self.deserialize_any(v)
    }

    fn deserialize_byte_buf<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        self.deserialize_any(v)
    }

    fn deserialize_ignored_any<V: Visitor<'de>>(self, v: V) -> Res<V::Value> {
        v.visit_unit()
    }
}

/// The items of a list or tuple; an item's error names its index.
struct Seq<'py> {
    items: std::vec::IntoIter<Bound<'py, PyAny>>,
    index: usize,
}

impl<'de> de::SeqAccess<'de> for Seq<'_> {
    type Error = DeError;

    fn next_element_seed<T: DeserializeSeed<'de>>(&mut self, seed: T) -> Res<Option<T::Value>> {
        let Some(item) = self.items.next() else {
            return Ok(None);
        };
        let i = self.index;
        self.index += 1;
        seed.deserialize(PyDe(&item))
            .map(Some)
            .map_err(|e| e.at(format!("[{i}]")))
    }

    fn size_hint(&self) -> Option<usize> {
        Some(self.items.len())
    }
}

/// The entries of a dict in order; a value's error names its key.
struct Map<'py> {
    items: pyo3::types::iter::BoundDictIterator<'py>,
    entry: Option<(Bound<'py, PyAny>, Bound<'py, PyAny>)>,
}

impl<'de> de::MapAccess<'de> for Map<'_> {
    type Error = DeError;

    fn next_key_seed<K: DeserializeSeed<'de>>(&mut self, seed: K) -> Res<Option<K::Value>> {
        let Some(entry) = self.items.next() else {
            return Ok(None);
        };
        let key = seed.deserialize(PyDe(&entry.0)).map(Some);
        self.entry = Some(entry);
        key
    }

    fn next_value_seed<V: DeserializeSeed<'de>>(&mut self, seed: V) -> Res<V::Value> {
        let (k, x) = self
            .entry
            .take()
            .ok_or_else(|| de::Error::custom("a value without its key"))?;
        // the key's text only for a message (no allocation per entry read)
        seed.deserialize(PyDe(&x)).map_err(|e| {
            e.at(match k.cast::<PyString>() {
                Ok(s) => s.to_string(),
                Err(_) => repr(&k),
            })
        })
    }
}

/// A variant given as `{name: content}`.
struct Variant<'py> {
    key: Bound<'py, PyAny>,
    value: Bound<'py, PyAny>,
}

impl<'de, 'py> de::EnumAccess<'de> for Variant<'py> {
    type Error = DeError;
    type Variant = VariantContent<'py>;

    fn variant_seed<T: DeserializeSeed<'de>>(self, seed: T) -> Res<(T::Value, Self::Variant)> {
        let tag = seed.deserialize(PyDe(&self.key))?;
        Ok((tag, VariantContent(self.value)))
    }
}

struct VariantContent<'py>(Bound<'py, PyAny>);

impl<'de> de::VariantAccess<'de> for VariantContent<'_> {
    type Error = DeError;

    fn unit_variant(self) -> Res<()> {
        de::Deserialize::deserialize(PyDe(&self.0))
    }

    fn newtype_variant_seed<T: DeserializeSeed<'de>>(self, seed: T) -> Res<T::Value> {
        seed.deserialize(PyDe(&self.0))
    }

    fn tuple_variant<V: Visitor<'de>>(self, _: usize, v: V) -> Res<V::Value> {
        PyDe(&self.0).sequence(v)
    }

    fn struct_variant<V: Visitor<'de>>(self, _: &'static [&'static str], v: V) -> Res<V::Value> {
        PyDe(&self.0).mapping(v)
    }
}

/// `T` read from the Python value `o`; an error names `element` (`vessel 'a'`).
pub(crate) fn read<T: de::DeserializeOwned>(
    o: &Bound<'_, PyAny>,
    element: impl FnOnce() -> String,
) -> Result<T, oxyline_core::Error> {
    T::deserialize(PyDe(o)).map_err(|e| oxyline_core::Error::model(element(), e.to_string()))
}
