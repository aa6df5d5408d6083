//! The growth against independent truths: the count of an explicit enumeration of the growth
//! rule and of the symmetric tree's 2^(d+1) − 2, the steady resistance of the grown vessels
//! summed series/parallel vessel by vessel, and Z(0) of the assembled tree.

use super::*;
use crate::impedance::input_impedances;
use crate::model::{BoundarySpec, parse};
use crate::waveform::WaveformSpec;
use std::collections::HashMap;

const MU: f64 = 3.5e-3;

/// Vessels below a node of radius r, by the growth rule written out recursively.
fn enumerate(alpha: f64, beta: f64, r: f64, rmin: f64) -> usize {
    [alpha, beta]
        .iter()
        .filter(|&&k| k * r >= rmin)
        .map(|&k| 1 + enumerate(alpha, beta, k * r, rmin))
        .sum()
}

fn input(alpha: f64, beta: f64, rmin: f64) -> TreeInput {
    TreeInput {
        alpha: Some(alpha),
        beta: Some(beta),
        min_radius: Some(rmin),
        stiffness: Some(Stiffness::Modulus {
            youngs_modulus: 1.5e6,
            thickness_ratio: 0.1,
        }),
        ..TreeInput::default()
    }
}

#[test]
fn count_matches_the_enumeration_and_the_symmetric_closed_form() {
    for (a, b, rmin) in [
        (0.9, 0.6, 4e-4),
        (0.9, 0.6, 1e-4),
        (0.8, 0.3, 2e-5),
        (0.7, 0.7, 1e-4),
    ] {
        let n = vessel_count(a, b, 1e-3, rmin);
        assert!(n.exact);
        assert_eq!(n.n, enumerate(a, b, 1e-3, rmin) as u128, "{a} {b} {rmin}");
    }
    // α = β = 1/2, r_min = r0/2^d (exact in binary): levels 1..d, 2^(d+1) − 2 vessels
    for d in 1..=16 {
        let n = vessel_count(0.5, 0.5, 1.0, 0.5f64.powi(d));
        assert_eq!(n.n, (1u128 << (d + 1)) - 2);
    }
    // a tree far above the default guard: counted, not grown (the value is Σ C(i+j, i) in
    // Python's exact integers)
    let huge = vessel_count(0.9, 0.6, 1e-3, 1e-7);
    assert!(huge.exact);
    assert_eq!(huge.n, 137_512_188_294);
    // beyond u128: reported as a lower bound
    assert!(!vessel_count(0.9, 0.6, 1e-3, 1e-20).exact);
}

#[test]
fn growth_names_order_radii_and_leaves() {
    let tree = Tree::new("out", &input(0.9, 0.6, 4e-4), Root::Given(1e-3), Units::SI).unwrap();
    let g = tree.grow().unwrap();
    assert_eq!(g.vessels.len(), 18);
    assert_eq!(tree.count, 18);
    let names: Vec<&str> = g.vessels.iter().map(|v| v.name.as_str()).collect();
    assert_eq!(&names[..3], ["out/st/a", "out/st/aa", "out/st/aaa"]);
    let by_name: HashMap<&str, &VesselSpec> = g.vessels.iter().map(|v| (&*v.name, v)).collect();
    let sources: std::collections::HashSet<&str> =
        g.vessels.iter().map(|v| v.from.as_str()).collect();
    for v in &g.vessels {
        let path = v.name.strip_prefix("out/st/").unwrap();
        let (i, j) = path.chars().fold((0, 0), |(i, j), c| match c {
            'a' => (i + 1, j),
            _ => (i, j + 1),
        });
        let geo = v.geometry.as_ref().unwrap();
        let r = 0.9f64.powi(i) * 0.6f64.powi(j) * 1e-3;
        assert!((geo.radius_in / r - 1.0).abs() < 1e-14);
        assert!((geo.length / (50.0 * geo.radius_in) - 1.0).abs() < 1e-15);
        assert_eq!(v.to, v.name);
        let parent = &path[..path.len() - 1];
        let from = if parent.is_empty() {
            "out".to_string()
        } else {
            format!("out/st/{parent}")
        };
        assert_eq!(v.from, from);
        assert!(parent.is_empty() || by_name.contains_key(&*from));
        let e_h = geo.youngs_modulus.unwrap() * geo.wall_thickness.unwrap();
        assert!((e_h / (1.5e6 * 0.1 * r) - 1.0).abs() < 1e-14);
        assert_eq!(g.leaves.contains(&v.name), !sources.contains(&*v.name));
    }
}

/// Steady resistance below `node` summed over the grown vessels (series/parallel, each vessel's
/// own Poiseuille law 8 μ l/(π r⁴) written out), leaves at `r_leaf`.
fn summed(vessels: &[VesselSpec], node: &str, r_leaf: f64) -> f64 {
    let g: f64 = vessels
        .iter()
        .filter(|v| v.from == node)
        .map(|v| {
            let geo = v.geometry.as_ref().unwrap();
            let own = 8.0 * MU * geo.length / (std::f64::consts::PI * geo.radius_in.powi(4));
            1.0 / (own + summed(vessels, &v.name, r_leaf))
        })
        .sum();
    if g == 0.0 { r_leaf } else { 1.0 / g }
}

#[test]
fn class_resistance_equals_the_sum_over_the_grown_vessels() {
    for (rmin, leaf) in [(4e-4, 0.0), (2e-4, 3e11)] {
        let tree = Tree::new("n", &input(0.9, 0.6, rmin), Root::Given(1e-3), Units::SI).unwrap();
        let g = tree.grow().unwrap();
        let shape = Shape {
            alpha: 0.9,
            beta: 0.6,
            length_ratio: 50.0,
            root_radius: 1e-3,
            viscosity: MU,
        };
        let exact = summed(&g.vessels, "n", leaf);
        // the same sums in another order, radii as powers or products: rounding only
        assert!((shape.resistance(rmin, 0.0 + leaf) / exact - 1.0).abs() < 1e-12);
    }
}

#[test]
fn matched_tree_has_the_asked_resistance() {
    let shape = Shape {
        alpha: 0.9,
        beta: 0.6,
        length_ratio: 50.0,
        root_radius: 1e-3,
        viscosity: MU,
    };
    let total = 5.0 * shape.resistance(3e-4, 0.0);
    let (rmin, leaf) = shape.matched("n", total, 3e-4, 0.9).unwrap();
    assert_eq!(rmin, 3e-4); // the tree alone has 20 % < 90 %: not raised
    let tree = Tree::new("n", &input(0.9, 0.6, rmin), Root::Given(1e-3), Units::SI).unwrap();
    assert!((summed(&tree.grow().unwrap().vessels, "n", leaf) / total - 1.0).abs() < 1e-12);
    // a tree alone above the fraction is cut at a larger radius
    let (raised, _) = shape
        .matched("n", 1.05 * shape.resistance(3e-4, 0.0), 3e-4, 0.9)
        .unwrap();
    assert!(
        raised > 3e-4 && shape.resistance(raised, 0.0) <= 0.9 * 1.05 * shape.resistance(3e-4, 0.0)
    );
    let e = shape.matched("n", -1.0, 3e-4, 0.9).unwrap_err().to_string();
    assert!(
        e.contains("boundary condition 'n' (structured-tree): the resistance to match is -1 Pa")
    );
}

#[test]
fn zero_frequency_impedance_of_the_assembled_tree_is_the_class_resistance() {
    let tree = Tree::new("out", &input(0.9, 0.6, 3e-4), Root::Given(1e-3), Units::SI).unwrap();
    let g = tree.grow().unwrap();
    let mut spec = parse(
        r#"{"name":"st","blood":{"density":1050,"viscosity":0.0035},"vessels":[],
        "boundary_conditions":{}}"#,
    )
    .unwrap();
    let mut feed = VesselSpec::blank();
    (feed.name, feed.from, feed.to) = ("feed".into(), "in".into(), "out".into());
    feed.geometry = g.vessels[0].geometry.clone();
    spec.vessels = vec![feed];
    spec.vessels.extend(g.vessels);
    for leaf in g.leaves {
        let p = Some(WaveformSpec::Constant { value: 0.0 });
        spec.boundary_conditions.insert(
            leaf,
            BoundarySpec::Resistance {
                resistance: 0.0,
                pressure: p,
            },
        );
    }
    let flow = WaveformSpec::Constant { value: 1e-7 };
    spec.boundary_conditions
        .insert("in".into(), BoundarySpec::Flow { flow });
    let assembled = spec.assemble().unwrap();
    let dae = assembled.circuit.assemble().unwrap();
    let node = (0..assembled.circuit.nodes.len())
        .position(|i| assembled.circuit.names.node(i) == "out")
        .unwrap();
    let z = input_impedances(&dae, node, &[0.0]).unwrap()[0];
    let shape = Shape {
        alpha: 0.9,
        beta: 0.6,
        length_ratio: 50.0,
        root_radius: 1e-3,
        viscosity: MU,
    };
    let exact = shape.resistance(3e-4, 0.0);
    // one sparse LU solve of a few hundred unknowns: rounding far below 1e-9
    assert!((z.re / exact - 1.0).abs() < 1e-9, "{} vs {exact}", z.re);
    assert!(z.im.abs() < 1e-9 * exact);
}

#[test]
fn errors_name_the_node_key_and_value_as_written() {
    let msg = |i: TreeInput| {
        Tree::new("out", &i, Root::Given(1e-3), Units::SI)
            .unwrap_err()
            .to_string()
    };
    let base = input(0.9, 0.6, 4e-4);
    let pre = "boundary condition 'out' (structured-tree): ";
    assert_eq!(
        msg(TreeInput {
            alpha: Some(1.0),
            ..base.clone()
        }),
        format!("{pre}'alpha' must be in (0, 1), got 1")
    );
    assert_eq!(
        msg(TreeInput {
            min_radius: Some(-1e-4),
            ..base.clone()
        }),
        format!("{pre}'min_radius' must be in (0, inf), got -0.0001")
    );
    assert_eq!(
        msg(TreeInput {
            max_vessels: Some(10.0),
            ..base.clone()
        }),
        format!(
            "{pre}the tree has 18 vessels, more than max_vessels = 10 (alpha = 0.9, beta = 0.6; raise min_radius = 0.0004 m or max_vessels)"
        )
    );
    assert!(
        msg(TreeInput {
            min_radius: Some(1e-6),
            max_vessels: None,
            ..base.clone()
        })
        .contains("more than max_vessels = 2e+06")
    );
    assert!(
        msg(TreeInput {
            min_radius: Some(2e-3),
            ..base.clone()
        })
        .contains("no daughter reaches min_radius = 0.002 m (root radius 0.001 m, alpha = 0.9)")
    );
    assert_eq!(
        msg(TreeInput {
            segments: Some(0),
            ..base.clone()
        }),
        format!("{pre}'segments' must be an integer >= 1, got 0")
    );
    let k = Stiffness::KLaw {
        k1: -1e7,
        k2: 0.0,
        k3: 0.0,
    };
    let e = Tree::new(
        "out",
        &TreeInput {
            stiffness: Some(k),
            ..base
        },
        Root::Given(1e-3),
        Units::SI,
    )
    .unwrap()
    .grow()
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("E·h/r = -1e+07 Pa <= 0 at radius 0.0009 m"),
        "{e}"
    );
}

#[test]
fn numbers_are_written_as_percent_g() {
    for (x, s) in [
        (1.0, "1"),
        (1.2, "1.2"),
        (0.0, "0"),
        (-1e-4, "-0.0001"),
        (2e6, "2e+06"),
        (-1e7, "-1e+07"),
        (123456.0, "123456"),
        (1234567.0, "1.23457e+06"),
        (1.5e-5, "1.5e-05"),
        (0.000123456789, "0.000123457"),
        (f64::INFINITY, "inf"),
        (1e100, "1e+100"),
    ] {
        assert_eq!(fmt_g(x), s);
    }
}

#[test]
fn poiseuille_closed_form_is_the_segment_resistance() {
    use crate::segment::{Blood, InertanceProfile, segment_rlc};
    let blood = Blood {
        density: 1050.0,
        viscosity: MU,
    };
    for (l, a, b) in [(0.05, 2e-3, 2e-3), (0.05, 4e-3, 2e-3), (0.2, 1e-3, 1.3e-3)] {
        let s = segment_rlc(l, a, b, blood, None, InertanceProfile::Flat).resistance;
        // the same integral in two closed forms: rounding (the taper form loses a few digits
        // to the difference r_in⁻³ − r_out⁻³)
        assert!((poiseuille_resistance(l, a, b, MU) / s - 1.0).abs() < 1e-13);
    }
}

#[test]
fn root_radius_is_the_vessel_end_at_the_node() {
    let mut a = VesselSpec::blank();
    (a.name, a.from, a.to) = ("a".into(), "in".into(), "out".into());
    a.geometry = Some(GeometrySpec {
        length: 0.1,
        radius_in: 2e-3,
        radius_out: 1e-3,
        wall_thickness: None,
        youngs_modulus: None,
        poisson_ratio: 0.5,
        wall_viscosity: 0.0,
    });
    let mut lumped = VesselSpec::blank();
    (lumped.name, lumped.from, lumped.to) = ("r".into(), "out".into(), "x".into());
    let vessels = [a, lumped];
    assert_eq!(root_radius("out", &vessels).unwrap(), 1e-3);
    assert_eq!(root_radius("in", &vessels).unwrap(), 2e-3);
    let e = root_radius("x", &vessels).unwrap_err().to_string();
    assert!(
        e.ends_with("vessel 'r' at this node has no radius: give 'root_radius'"),
        "{e}"
    );
    let e = root_radius("nowhere", &vessels).unwrap_err().to_string();
    assert!(e.ends_with("no vessel ends at this node"), "{e}");
    // the SI radius of the vessel is the root radius as given in SI
    let i = input(0.9, 0.6, 4e-4);
    let given = Tree::new("out", &i, Root::Given(1e-3), Units::SI).unwrap();
    assert_eq!(
        Tree::new("out", &i, Root::Vessel(1e-3), Units::SI).unwrap(),
        given
    );
}

#[test]
fn closed_form_bound_is_a_lower_bound_of_the_enumeration() {
    for (a, b, r0, rmin) in [
        (0.9, 0.6, 1e-3, 1e-4),
        (0.8, 0.8, 1e-3, 5e-5),
        (0.95, 0.3, 1.0, 0.01),
        (0.5, 0.5, 1.0, 0.5),
        (0.5, 0.5, 1.0, 0.4999),
        (0.7, 0.7, 1.0, 1e-3),
    ] {
        let n = enumerate(a, b, r0, rmin) as f64;
        let bound = vessel_count_bound(a, b, r0, rmin);
        assert!(bound <= n, "{a} {b} {r0} {rmin}: {bound} > {n}");
        if a == b && n > 10.0 {
            // a full binary tree: the bound is within one level of it
            assert!(bound >= n / 4.0, "{a} {rmin}: {bound} vs {n}");
        }
    }
}

#[test]
fn trees_near_one_and_guards_out_of_range_are_refused_before_counting() {
    let msg = |i: TreeInput| {
        Tree::new("out", &i, Root::Given(1e-3), Units::SI)
            .unwrap_err()
            .to_string()
    };
    // ~10^(10^6) vessels: refused by the closed-form bound, not by a count
    let near = msg(TreeInput {
        beta: Some(0.999999),
        ..input(0.999999, 0.6, 1e-5)
    });
    assert!(
        near.contains("at least inf vessels") && near.contains("alpha = 0.999999"),
        "{near}"
    );
    for bad in [0.0, 6e9, f64::NAN, f64::INFINITY] {
        let m = msg(TreeInput {
            max_vessels: Some(bad),
            ..input(0.9, 0.6, 4e-4)
        });
        assert!(
            m.contains("'max_vessels' must be a number from 1 to 1e+08"),
            "{m}"
        );
    }
}

#[test]
fn an_overflowing_wall_law_is_refused_naming_the_node() {
    let k = Stiffness::KLaw {
        k1: 1.0,
        k2: 1e300,
        k3: 0.0,
    };
    let tree = Tree::new(
        "out",
        &TreeInput {
            stiffness: Some(k),
            ..input(0.9, 0.6, 5e-4)
        },
        Root::Given(1e-3),
        Units::SI,
    )
    .unwrap();
    let e = tree.grow().unwrap_err().to_string();
    assert!(
        e.starts_with("boundary condition 'out' (structured-tree): stiffness gives E·h/r = inf"),
        "{e}"
    );
}

#[test]
fn memory_is_estimated_from_the_count_before_growing() {
    let tree = Tree::new("out", &input(0.9, 0.6, 5e-5), Root::Given(1e-3), Units::SI).unwrap();
    let n = enumerate(0.9, 0.6, 1e-3, 5e-5) as f64;
    // one segment per vessel: each vessel's element and segment bytes
    let need = n * (memory::BYTES_PER_ELEMENT + memory::FLOW_BYTES_PER_SEGMENT);
    assert!(tree.check_memory(Some(need * 1.001)).is_ok());
    assert!(tree.check_memory(None).is_ok());
    let e = tree.check_memory(Some(need * 0.999)).unwrap_err();
    assert!(matches!(e, Error::Resource { .. }), "{e}");
    assert!(e.to_string().contains("boundary condition 'out'"), "{e}");
}

#[test]
fn matching_a_tree_near_one_is_refused_before_its_class_table() {
    let shape = Shape {
        alpha: 0.999999,
        beta: 0.999999,
        length_ratio: 50.0,
        root_radius: 1e-3,
        viscosity: MU,
    };
    let e = shape
        .matched("out", 1e9, 1e-5, 0.9)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("radius classes") && e.contains("alpha = 0.999999"),
        "{e}"
    );
    let one = Shape {
        alpha: 1.0,
        ..shape
    };
    let e = one.matched("out", 1e9, 1e-5, 0.9).unwrap_err().to_string();
    assert!(e.contains("'alpha' must be in (0, 1), got 1"), "{e}");
}

/// Olufsen's rule written out recursively: below a node above `rmin` both daughters exist.
fn enumerate_olufsen(alpha: f64, beta: f64, r: f64, rmin: f64) -> usize {
    if r <= rmin {
        return 0;
    }
    [alpha, beta]
        .iter()
        .map(|&k| 1 + enumerate_olufsen(alpha, beta, k * r, rmin))
        .sum()
}

#[test]
fn olufsen_stopping_counts_grows_and_ends_at_the_first_vessel_at_or_below_min_radius() {
    for (a, b, rmin) in [(0.9, 0.6, 4e-4), (0.9, 0.6, 1e-4), (0.8, 0.3, 2e-5)] {
        let tree_input = TreeInput {
            stopping: Some(Stopping::Olufsen),
            ..input(a, b, rmin)
        };
        let tree = Tree::new("out", &tree_input, Root::Given(1e-3), Units::SI).unwrap();
        let expected = enumerate_olufsen(a, b, 1e-3, rmin);
        assert_eq!(tree.count as usize, expected, "{a} {b} {rmin}");
        let grown = tree.grow().unwrap();
        assert_eq!(grown.vessels.len(), expected);
        let radius = |name: &String| {
            let v = grown.vessels.iter().find(|v| &v.name == name).unwrap();
            v.geometry.as_ref().unwrap().radius_in
        };
        // every leaf at or below min_radius, every other vessel above it
        assert!(grown.leaves.iter().all(|l| radius(l) <= rmin));
        let leaves: std::collections::HashSet<&String> = grown.leaves.iter().collect();
        for v in &grown.vessels {
            let r = v.geometry.as_ref().unwrap().radius_in;
            assert_eq!(leaves.contains(&v.name), r <= rmin, "{}", v.name);
        }
        // a superset of today's tree
        let today = Tree::new("out", &input(a, b, rmin), Root::Given(1e-3), Units::SI).unwrap();
        assert!(tree.count > today.count);
    }
}

mod terminal_compartments {
    use super::super::terminal::{self, End, Link};

    fn link(name: &str, from: &str, to: &str, r: Option<f64>) -> Link {
        Link {
            name: name.into(),
            from: from.into(),
            to: to.into(),
            lumped_resistance: r,
        }
    }

    #[test]
    fn two_level_walk_is_series_then_parallel_by_hand() {
        // t (R 1) → j; j feeds a (R 2) → o1 and b (R 6) → k; k feeds c (R 3) → o2 and a
        // wall branch w (R 5) → dead end: R = 1 + 1/(1/2 + 1/(6 + 3)) = 1 + 18/11
        let links = vec![
            link("p", "in", "s", None),
            link("t", "s", "j", Some(1.0)),
            link("a", "j", "o1", Some(2.0)),
            link("b", "j", "k", Some(6.0)),
            link("c", "k", "o2", Some(3.0)),
            link("w", "k", "dead", Some(5.0)),
        ];
        let ends = |n: &str| match n {
            "o1" | "o2" => End::Pressure(100.0),
            "dead" => End::ZeroFlow,
            _ => End::Open,
        };
        let c = terminal::compartment("t", &links, &ends).unwrap();
        assert!((c.resistance - (1.0 + 18.0 / 11.0)).abs() < 1e-15);
        assert_eq!(c.pressure, 100.0);
        assert_eq!(c.vessels.len(), 5);
        assert!(c.nodes.contains("dead") && !c.nodes.contains("s"));
        // a geometric vessel inside, two outlet pressures, an unknown condition: refused
        let mut bad = links.clone();
        bad[4].lumped_resistance = None;
        let e = terminal::compartment("t", &bad, &ends).unwrap_err();
        assert!(e.to_string().contains("'c' is not a lumped element"), "{e}");
        let two = |n: &str| match n {
            "o1" => End::Pressure(0.0),
            "o2" => End::Pressure(1.0),
            "dead" => End::ZeroFlow,
            _ => End::Open,
        };
        let e = terminal::compartment("t", &links, &two).unwrap_err();
        assert!(e.to_string().contains("outlet pressures [0, 1]"), "{e}");
        let other = |n: &str| match n {
            "o1" => End::Other("{'type': 'rcr'}".into()),
            _ => ends(n),
        };
        let e = terminal::compartment("t", &links, &other).unwrap_err();
        assert!(
            e.to_string()
                .contains("node 'o1' has condition {'type': 'rcr'}"),
            "{e}"
        );
        assert!(terminal::compartment("nope", &links, &ends).is_err());
    }

    #[test]
    fn murray_radii_of_a_split_keep_the_parent_r_cubed() {
        // flow ∝ r³: daughters carrying 30 % and 70 % have r1³ + r2³ = r_parent³
        let rp = 2e-3;
        let r1 = terminal::murray_radius("t1", "p", rp, 3e-6, 1e-5).unwrap();
        let r2 = terminal::murray_radius("t2", "p", rp, 7e-6, 1e-5).unwrap();
        assert!(((r1.powi(3) + r2.powi(3)) / rp.powi(3) - 1.0).abs() < 1e-14);
        let e = terminal::murray_radius("t", "p", rp, -1e-7, 1e-6).unwrap_err();
        assert!(
            e.to_string()
                .contains("steady flow share -0.1 of parent 'p'"),
            "{e}"
        );
    }

    #[test]
    fn root_vessel_is_olufsens_with_poiseuilles_resistance() {
        let r0 = 1e-3;
        let v = terminal::root_vessel("t", r0, 50.0, None, Some(0.01), 3.5e-3).unwrap();
        assert_eq!(v.length, 50.0 * r0);
        assert_eq!(v.segments, Some(5));
        let pi = std::f64::consts::PI;
        // 8 μ l / (π r⁴)
        assert!((v.resistance / (8.0 * 3.5e-3 * 0.05 / (pi * 1e-12)) - 1.0).abs() < 1e-14);
        // Olufsen's E h / r = 2e6 e^(−2253 r) + 8.65e4 Pa
        let ehr = 2.0e6 * (-2253.0f64 * r0).exp() + 8.65e4;
        assert!((v.youngs_modulus * v.wall_thickness / r0 / ehr - 1.0).abs() < 1e-14);
        assert!(terminal::root_vessel("t", 0.0, 50.0, None, None, 3.5e-3).is_err());
    }
}
