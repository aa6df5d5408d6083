//! The one resolver of a dotted path into a native model: `vessels.<name>.<key>`,
//! `vessels.<name>.lumped.<key>`, `boundary_conditions.<node>.<key>`, `blood.<key>`,
//! `oxygen.<key>`, `oxygen.wall.<key>`, `transport.<key>`, `period`, `scale.<key>`, and a
//! heart element's `vessels.<name>.<chamber|valve|…>.<key>` (by its law).
//!
//! It knows the schema's addressable keys by [`Scope`] (the lists the schema reader itself
//! checks a model against: `super::native`, `super::species`), splits a table column's path
//! and a parameter path into their keys (a vessel or node name may hold dots: [`column_keys`],
//! [`parameter_keys`]), and words a key its scope does not have in one way
//! ([`unknown_key`]: the scope, its keys, the nearest of them). The ensemble's patch merge
//! (`super::patch`, and through it the calibration's parameter paths in
//! `super::parameters`) and the sensitivities' SI parameters
//! (`crate::sensitivity::parameter::Parameter::parse`) read paths through it, so a typo is
//! reported the same way wherever it is made; each caller puts the path in front (`variant k:
//! <path>` or `parameter '<path>'`).

use super::native::boundary::BC_KEYS;
use super::native::vessel::{
    LUMPED_KEYS, VESSEL_KEYS, activation_keys, heart_key_paths, heart_keys,
};
use super::species::{OXYGEN_KEYS, TRANSPORT_KEYS, WALL_KEYS};
use crate::error::Error;

#[cfg(test)]
mod tests;

/// The sections a patch may have.
pub const SECTIONS: &[&str] = &[
    "vessels",
    "boundary_conditions",
    "blood",
    "oxygen",
    "transport",
    "period",
    "scale",
];
pub const BLOOD_KEYS: &[&str] = &["density", "viscosity"];
/// The keys of a patch's `scale` section.
pub const SCALE_KEYS: &[&str] = &["resistance", "compliance", "vessels"];
/// The sections a flow parameter path starts with (an `oxygen.` path is the species
/// sensitivities' own: `crate::sensitivity::species`).
pub const PARAMETER_SECTIONS: &[&str] = &["vessels", "boundary_conditions", "scale"];
/// The factors a parameter path names under `scale`: the patch's two and the inflow's (a
/// factor on every flow condition's waveform, `super::parameters`).
pub const PARAMETER_SCALES: &[&str] = &["resistance", "compliance", "inflow"];
/// A vessel's keys a path may not change: its name and ends are the network's topology.
const TOPOLOGY: &[&str] = &["name", "from", "to"];

/// Where a path's key is looked up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scope<'a> {
    /// The top level of a patch ([`SECTIONS`]).
    PatchSection,
    /// The top level of a flow parameter path ([`PARAMETER_SECTIONS`]).
    ParameterSection,
    /// A vessel's properties, its name and ends aside.
    Vessel,
    /// A lumped vessel's `lumped` values.
    Lumped,
    /// A boundary condition of the given type (lower case; an unknown type has no keys).
    Condition(&'a str),
    Blood,
    /// A patch's `scale` section.
    Scale,
    /// A parameter path's `scale.<key>` ([`PARAMETER_SCALES`]).
    ParameterScale,
    Oxygen,
    Transport,
    /// An `oxygen.wall` of the given closure (`model`).
    Wall(&'a str),
    /// A heart element's section: its kind (`chamber`, `valve`, `chamber_sphere`,
    /// `heart_pulmonary`, `coronary_bed`, `through_rc`) and law (a chamber's or valve's).
    Heart(&'a str, &'a str),
    /// A chamber's `activation` of the given kind.
    Activation(&'a str),
}

/// The vessel keys that hold a heart element's section ([`Scope::Heart`]).
pub const HEART_SECTIONS: &[&str] = &[
    "chamber",
    "valve",
    "chamber_sphere",
    "heart_pulmonary",
    "coronary_bed",
    "through_rc",
];

impl Scope<'_> {
    /// The keys the scope has, as the schema lists them (None: a wall closure the schema
    /// does not know, whose keys the schema reader checks when it names the closure).
    pub fn keys(self) -> Option<Vec<&'static str>> {
        let keys: Vec<&'static str> = match self {
            Scope::PatchSection => SECTIONS.to_vec(),
            Scope::ParameterSection => PARAMETER_SECTIONS.to_vec(),
            Scope::Vessel => VESSEL_KEYS
                .iter()
                .copied()
                .filter(|k| !TOPOLOGY.contains(k))
                .collect(),
            Scope::Lumped => LUMPED_KEYS.to_vec(),
            Scope::Condition(kind) => BC_KEYS
                .iter()
                .find(|(name, _)| *name == kind)
                .map_or_else(Vec::new, |(_, keys)| keys.to_vec()),
            Scope::Blood => BLOOD_KEYS.to_vec(),
            Scope::Scale => SCALE_KEYS.to_vec(),
            Scope::ParameterScale => PARAMETER_SCALES.to_vec(),
            Scope::Oxygen => OXYGEN_KEYS.to_vec(),
            Scope::Transport => TRANSPORT_KEYS.to_vec(),
            Scope::Wall(model) => WALL_KEYS
                .iter()
                .find(|(name, _)| *name == model)?
                .1
                .to_vec(),
            Scope::Heart(kind, law) => heart_keys(kind, law)?,
            Scope::Activation(kind) => activation_keys(kind)?,
        };
        Some(keys)
    }

    /// What a key of the scope is, as the messages name it.
    fn what(self) -> String {
        match self {
            Scope::PatchSection => "patch section".to_owned(),
            Scope::ParameterSection => "parameter section".to_owned(),
            Scope::Vessel => "vessel property".to_owned(),
            Scope::Lumped => "lumped property".to_owned(),
            Scope::Condition(kind) => format!("property of a {kind} condition"),
            Scope::Blood => "blood property".to_owned(),
            Scope::Scale | Scope::ParameterScale => "scale key".to_owned(),
            Scope::Oxygen => "oxygen property".to_owned(),
            Scope::Transport => "transport property".to_owned(),
            Scope::Wall(model) => format!("property of a {model} wall"),
            Scope::Heart(kind @ ("chamber" | "valve"), law) => {
                format!("property of a {law} {kind}")
            }
            Scope::Heart(kind, _) => format!("{kind} property"),
            Scope::Activation(kind) => format!("property of a {kind} activation"),
        }
    }

    /// `Err(`[`unknown_key`]`)` if the scope does not have `key`.
    pub fn check(self, key: &str) -> Result<(), String> {
        match self.keys() {
            Some(keys) if !keys.contains(&key) => Err(unknown_key(self, key)),
            _ => Ok(()),
        }
    }
}

/// The one wording of a key its scope does not have: `unknown <what> (allowed: <keys>;
/// nearest: <keys>)`, the keys sorted, the nearest those a typo away ([`nearest`]; the
/// clause left out when none is).
pub fn unknown_key(scope: Scope<'_>, key: &str) -> String {
    let mut allowed = scope.keys().unwrap_or_default();
    allowed.sort_unstable();
    let near = nearest(key, &allowed);
    let hint = if near.is_empty() {
        String::new()
    } else {
        format!("; nearest: {}", near.join(", "))
    };
    format!(
        "unknown {} (allowed: {}{hint})",
        scope.what(),
        allowed.join(", ")
    )
}

/// The keys of `allowed` nearest `key`: those at the least edit distance (insertions,
/// deletions, substitutions of one character), if it is at most a third of the key's length
/// (at least 1); else those the key begins (a key cut short). At most three, in `allowed`'s
/// order.
pub fn nearest<'k>(key: &str, allowed: &[&'k str]) -> Vec<&'k str> {
    let reach = (key.chars().count() / 3).max(1);
    let scored: Vec<(usize, &'k str)> = allowed.iter().map(|k| (edits(key, k), *k)).collect();
    let best = scored.iter().map(|(d, _)| *d).min().unwrap_or(usize::MAX);
    let mut near: Vec<&'k str> = if best <= reach {
        scored
            .into_iter()
            .filter(|(d, _)| *d == best)
            .map(|p| p.1)
            .collect()
    } else if key.len() >= 3 {
        allowed
            .iter()
            .copied()
            .filter(|k| k.starts_with(key))
            .collect()
    } else {
        Vec::new()
    };
    near.truncate(3);
    near
}

/// The edit (Levenshtein) distance between `a` and `b`, by characters.
fn edits(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diagonal = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let above = row[j + 1];
            row[j + 1] = (above + 1)
                .min(row[j] + 1)
                .min(diagonal + usize::from(ca != *cb));
            diagonal = above;
        }
    }
    row[b.len()]
}

/// Why a flow parameter path (`parts`, its dot-separated pieces) has the wrong shape: a
/// model section that holds no flow parameter, an unknown section, an unknown scale key, or
/// a vessel or condition path without a property.
pub fn parameter_shape(parts: &[&str]) -> String {
    match parts {
        [section, ..] if SECTIONS.contains(section) && !PARAMETER_SECTIONS.contains(section) => {
            format!(
                "a {section} value is not a flow parameter (flow parameters: \
                 vessels.NAME.PROPERTY, boundary_conditions.NODE.PROPERTY, scale.<{}>)",
                PARAMETER_SCALES.join("|")
            )
        }
        [section, ..] if !PARAMETER_SECTIONS.contains(section) => {
            unknown_key(Scope::ParameterSection, section)
        }
        ["scale", key] => unknown_key(Scope::ParameterScale, key),
        ["scale", ..] => format!("expected scale.<{}>", PARAMETER_SCALES.join("|")),
        [section, ..] => format!("expected {section}.NAME.PROPERTY"),
        [] => "empty path".to_owned(),
    }
}

/// The keys of a parameter path (`vessels.a.b.radius` -> `vessels`, `a.b`, `radius`): its
/// dot-separated pieces, except that a vessel or node name may itself hold dots: under
/// `vessels` / `boundary_conditions` (`names`: the model's vessel names and nodes) the
/// longest known name the pieces after the section start with is one key, at least one piece
/// left for the property. A path that starts with no known name is split at every dot (its
/// reader then names the first piece as unknown, with [`nearest_name`]).
pub fn parameter_keys<'p>(path: &'p str, names: &[(&str, &[String])]) -> Vec<&'p str> {
    let plain = || path.split('.').collect();
    let Some((section, rest)) = path.split_once('.') else {
        return plain();
    };
    let Some(known) = names.iter().find(|(s, _)| *s == section).map(|(_, n)| *n) else {
        return plain();
    };
    // the last dot that ends a known name: the longest name
    let cut = rest
        .rmatch_indices('.')
        .map(|(i, _)| i)
        .find(|&i| known.iter().any(|n| *n == rest[..i]));
    match cut {
        Some(i) => {
            let mut keys = vec![section, &rest[..i]];
            keys.extend(rest[i + 1..].split('.'));
            keys
        }
        None => plain(),
    }
}

/// The names of `known` nearest the name a path's pieces after its section (`rest`) start
/// with, when they start with none: the longest start that has near names wins (a dotted
/// name's typo, `a.c.radius` -> `a.b`; else the first piece's, `rv.chamber.max_elastance`
/// -> `lv`). Empty when no start is a typo away ([`nearest`]).
pub fn nearest_name<'k>(rest: &[&str], known: &'k [String]) -> Vec<&'k str> {
    let known: Vec<&'k str> = known.iter().map(String::as_str).collect();
    let longest = rest.len().saturating_sub(1).max(1).min(rest.len());
    (1..=longest)
        .rev()
        .map(|cut| nearest(&rest[..cut].join("."), &known))
        .find(|near| !near.is_empty())
        .unwrap_or_default()
}

/// ` (nearest: a, b)`, or nothing when `near` is empty: the hint an unknown name's message
/// ends with.
pub fn nearest_hint(near: &[&str]) -> String {
    if near.is_empty() {
        String::new()
    } else {
        format!(" (nearest: {})", near.join(", "))
    }
}

/// Why a heart element has no value `key` among the keys of `has` (the element's own, of
/// [`heart_paths`]): `(<has>; nearest: <keys>)`, the nearest clause left out when no key is a
/// typo away ([`nearest`]); ` (it has none)` for an element without any.
pub fn heart_key_hint(key: &str, has: &[&str]) -> String {
    if has.is_empty() {
        return " (it has none)".to_owned();
    }
    let near = nearest(key, has);
    let near = if near.is_empty() {
        String::new()
    } else {
        format!("; nearest: {}", near.join(", "))
    };
    format!(" (differentiable: {}{near})", has.join(", "))
}

/// The keys a parameter path may name after a heart element of `kind` (`chamber`, `valve`,
/// `chamber_sphere`, `heart_pulmonary`, …): every law's, a chamber's activation keys as
/// `activation.<key>`; the schema's lists (`super::native::vessel`).
pub fn heart_paths(kind: &str) -> Vec<String> {
    heart_key_paths(kind)
}

/// The prefix of a patch message: the variant and the patch path.
pub fn at(k: usize, path: &str) -> String {
    format!("variant {k}: {path}")
}

/// The keys of a table column's path (`vessels.CCA.radius` -> `vessels`, `CCA`, `radius`):
/// `parts` are its dot-separated pieces, or the levels of a multi-level column (`dotted`
/// false: each level is one key, trailing empty levels dropped). A vessel or node name may
/// itself hold dots: under `vessels` / `boundary_conditions` (`names`: the model's vessel
/// names and nodes) the longest known name wins. A column of variant `k` that names no vessel
/// or node, or has an empty key, is an error naming the variant and the column.
pub fn column_keys(
    parts: &[String],
    dotted: bool,
    names: &[(&str, &[String])],
    k: usize,
) -> std::result::Result<Vec<String>, Error> {
    let mut parts = parts;
    while !dotted && parts.len() > 1 && parts.last().is_some_and(String::is_empty) {
        parts = &parts[..parts.len() - 1];
    }
    let label = parts.join(".");
    let fail = |message: &str| Error::model(at(k, &label), message.to_owned());
    let Some((section, rest)) = parts.split_first() else {
        return Err(fail("empty key in the column's dotted path"));
    };
    let mut keys = vec![section.clone()];
    let known = names
        .iter()
        .find(|(s, _)| *s == section.as_str())
        .map(|(_, n)| *n);
    match known.filter(|_| dotted) {
        Some(known) => {
            let is_name = |cut: usize| known.iter().any(|n| *n == rest[..cut].join("."));
            let Some(cut) = (1..rest.len()).rev().find(|&cut| is_name(cut)) else {
                let no_property = rest.len() <= 1 || is_name(rest.len());
                return Err(fail(&if no_property {
                    format!("expected {section}.NAME.PROPERTY")
                } else {
                    "no vessel or node of the model starts this path".to_owned()
                }));
            };
            keys.push(rest[..cut].join("."));
            keys.extend(rest[cut..].iter().cloned());
        }
        None => keys.extend(rest.iter().cloned()),
    }
    if keys.iter().any(String::is_empty) {
        return Err(fail("empty key in the column's dotted path"));
    }
    Ok(keys)
}
