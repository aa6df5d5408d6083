//! The path resolver: each expectation written out by hand from the documented rules (the
//! schema's key lists, the edit distance of a typo, the longest known name of a column),
//! never taken from the code's own output.

use super::{Scope, column_keys, nearest, parameter_shape, unknown_key};

/// One wording for every scope: the scope's keys sorted, the nearest of them named.
#[test]
fn an_unknown_key_names_its_scope_its_keys_and_the_nearest() {
    assert_eq!(
        unknown_key(Scope::Lumped, "inductanse"),
        "unknown lumped property (allowed: capacitance, inductance, resistance, \
         stenosis_coefficient, stenosis_form; nearest: inductance)"
    );
    assert_eq!(
        unknown_key(Scope::Blood, "colour"),
        "unknown blood property (allowed: density, viscosity)"
    );
    assert_eq!(
        unknown_key(Scope::Condition("resistance"), "resistanse"),
        "unknown property of a resistance condition (allowed: pressure, resistance, type; \
         nearest: resistance)"
    );
    assert_eq!(
        unknown_key(Scope::ParameterScale, "inflw"),
        "unknown scale key (allowed: compliance, inflow, resistance; nearest: inflow)"
    );
    // a vessel's topology is not offered
    let vessel = unknown_key(Scope::Vessel, "radiuss");
    assert!(
        vessel.starts_with("unknown vessel property (allowed: "),
        "{vessel}"
    );
    assert!(vessel.ends_with("; nearest: radius)"), "{vessel}");
    assert!(
        !vessel.contains(" from,") && !vessel.contains(" name,"),
        "{vessel}"
    );
    // the keys a scope has pass; a wall closure the schema does not know is its reader's
    assert_eq!(Scope::Lumped.check("resistance"), Ok(()));
    assert_eq!(Scope::Wall("no-such-closure").check("anything"), Ok(()));
    assert!(Scope::Wall("graetz").check("k").is_err());
}

/// The nearest keys: the least edit distance within a third of the key's length, ties all
/// named, else the keys a short key begins.
#[test]
fn the_nearest_keys_are_a_typo_away() {
    let keys = [
        "length",
        "radius",
        "radius_in",
        "radius_out",
        "youngs_modulus",
    ];
    assert_eq!(nearest("radis", &keys), ["radius"]); // one deletion
    assert_eq!(nearest("lenght", &keys), ["length"]); // two substitutions, 6 / 3 = 2
    assert_eq!(nearest("radius_ot", &keys), ["radius_out"]); // one insertion (radius_in: 2)
    assert_eq!(nearest("radius_ix", &keys), ["radius_in"]);
    assert_eq!(nearest("young", &keys), ["youngs_modulus"]); // cut short
    assert!(nearest("colour", &keys).is_empty());
    assert!(nearest("", &keys).is_empty());
}

/// A parameter path of the wrong shape names what it lacks.
#[test]
fn a_parameter_path_of_the_wrong_shape_is_named() {
    assert_eq!(
        parameter_shape(&["vesels", "a", "length"]),
        "unknown parameter section (allowed: boundary_conditions, scale, vessels; nearest: vessels)"
    );
    assert_eq!(
        parameter_shape(&["scale", "inflow", "x"]),
        "expected scale.<resistance|compliance|inflow>"
    );
    assert_eq!(
        parameter_shape(&["vessels", "a"]),
        "expected vessels.NAME.PROPERTY"
    );
    assert_eq!(
        parameter_shape(&["blood", "viscosity"]),
        "a blood value is not a flow parameter (flow parameters: vessels.NAME.PROPERTY, \
         boundary_conditions.NODE.PROPERTY, scale.<resistance|compliance|inflow>)"
    );
}

/// Column keys: each expectation written out from the documented rule (the longest known
/// vessel or node name wins; a multi-level column's levels are the keys).
#[test]
fn column_keys_split_dotted_names_by_the_longest_known_name() {
    let vessels = vec!["a".to_owned(), "a.b".to_owned(), "c".to_owned()];
    let nodes = vec!["out.1".to_owned()];
    let names: [(&str, &[String]); 2] = [("vessels", &vessels), ("boundary_conditions", &nodes)];
    let keys = |label: &str| {
        let parts: Vec<String> = label.split('.').map(str::to_owned).collect();
        column_keys(&parts, true, &names, 3).map_err(|e| e.to_string())
    };
    assert_eq!(
        keys("vessels.a.b.radius").unwrap(),
        ["vessels", "a.b", "radius"]
    );
    assert_eq!(
        keys("vessels.a.radius").unwrap(),
        ["vessels", "a", "radius"]
    );
    assert_eq!(
        keys("vessels.a.b.lumped.resistance").unwrap(),
        ["vessels", "a.b", "lumped", "resistance"]
    );
    assert_eq!(
        keys("boundary_conditions.out.1.resistance").unwrap(),
        ["boundary_conditions", "out.1", "resistance"]
    );
    assert_eq!(keys("blood.viscosity").unwrap(), ["blood", "viscosity"]);
    assert_eq!(keys("oxygen.wall.po2").unwrap(), ["oxygen", "wall", "po2"]);
    let err = keys("vessels.zz.radius").unwrap_err();
    assert!(err.contains("variant 3: vessels.zz.radius"), "{err}");
    assert!(
        err.contains("no vessel or node of the model starts this path"),
        "{err}"
    );
    assert!(
        keys("vessels.c")
            .unwrap_err()
            .contains("expected vessels.NAME.PROPERTY")
    );
    // a known name then a key: the merge, not the column, judges the property
    assert_eq!(keys("vessels.a.b").unwrap(), ["vessels", "a", "b"]);
    assert!(
        keys("vessels.zz")
            .unwrap_err()
            .contains("expected vessels.NAME.PROPERTY")
    );
    assert!(
        keys("vessels.a.b.radius.")
            .unwrap_err()
            .contains("empty key")
    );
    assert!(keys("blood..viscosity").unwrap_err().contains("empty key"));
    // levels of a multi-level column: no splitting, trailing empty levels dropped
    let levels = ["vessels", "a.b", "radius", "", ""].map(str::to_owned);
    assert_eq!(
        column_keys(&levels, false, &names, 0).unwrap(),
        ["vessels", "a.b", "radius"]
    );
}

/// Parameter keys: the longest known vessel or node name wins, at least one piece left for
/// the property; a path that starts with no known name splits at every dot.
#[test]
fn parameter_keys_split_dotted_names_by_the_longest_known_name() {
    use super::{nearest_name, parameter_keys};
    let vessels = vec!["a".to_owned(), "a.b".to_owned(), "lv".to_owned()];
    let nodes = vec!["out.1".to_owned()];
    let names: [(&str, &[String]); 2] = [("vessels", &vessels), ("boundary_conditions", &nodes)];
    let keys = |path: &'static str| parameter_keys(path, &names);
    assert_eq!(keys("vessels.a.b.radius"), ["vessels", "a.b", "radius"]);
    assert_eq!(keys("vessels.a.radius"), ["vessels", "a", "radius"]);
    assert_eq!(
        keys("vessels.a.b.lumped.resistance"),
        ["vessels", "a.b", "lumped", "resistance"]
    );
    assert_eq!(
        keys("vessels.lv.chamber.activation.t_active"),
        ["vessels", "lv", "chamber", "activation", "t_active"]
    );
    assert_eq!(
        keys("boundary_conditions.out.1.resistance"),
        ["boundary_conditions", "out.1", "resistance"]
    );
    // a name alone is not a property: the name keeps one piece after it
    assert_eq!(keys("vessels.a.b"), ["vessels", "a", "b"]);
    assert_eq!(keys("vessels.zz.radius"), ["vessels", "zz", "radius"]);
    assert_eq!(keys("scale.resistance"), ["scale", "resistance"]);
    // the nearest names: a dotted name's typo, else the first piece's
    assert_eq!(nearest_name(&["a", "c", "radius"], &vessels), ["a.b"]);
    assert_eq!(
        nearest_name(&["rv", "chamber", "max_elastance"], &vessels),
        ["lv"]
    );
    assert!(nearest_name(&["zzz", "radius"], &vessels).is_empty());
    assert_eq!(nearest_name(&["out", "2", "resistance"], &nodes), ["out.1"]);
}
