//! The root of a tree at an outlet, and a Windkessel outlet replaced by a structured tree of
//! the same steady resistance (docs/structured-tree.md "Whole trees").

use super::{Shape, err};
use crate::error::Result;

/// A vessel's ends as a tree's root looks at them: its nodes (None: not given) and end radii
/// (None: the vessel has no radius there, e.g. a lumped element).
#[derive(Debug, Clone, Copy)]
pub struct VesselEnds<'a> {
    pub name: &'a str,
    pub from: Option<&'a str>,
    pub to: Option<&'a str>,
    pub radius_in: Option<f64>,
    pub radius_out: Option<f64>,
}

/// The radius of the first vessel end at `node` (a vessel's distal end is looked at before its
/// proximal one), in the vessels' units: the default root radius of a tree there.
pub fn end_radius<'a>(
    node: &str,
    vessels: impl IntoIterator<Item = VesselEnds<'a>>,
) -> Result<f64> {
    for v in vessels {
        for (end, radius) in [(v.to, v.radius_out), (v.from, v.radius_in)] {
            if end != Some(node) {
                continue;
            }
            return radius.ok_or_else(|| {
                err(
                    node,
                    format!(
                        "vessel '{}' at this node has no radius: give 'root_radius'",
                        v.name
                    ),
                )
            });
        }
    }
    Err(err(node, "no vessel ends at this node"))
}

/// (min_radius, terminal resistance) of the structured tree at `node` that replaces an RCR
/// outlet of resistances `proximal` and `distal` (SI): the tree and its leaves' terminal
/// resistance together have the Windkessel's steady resistance R_p + R_d (`Shape::matched`).
pub fn windkessel_tree(
    node: &str,
    proximal: f64,
    distal: f64,
    shape: &Shape,
    min_radius: f64,
    tree_fraction: f64,
) -> Result<(f64, f64)> {
    shape.matched(node, proximal + distal, min_radius, tree_fraction)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ends<'a>(name: &'a str, from: &'a str, to: &'a str, r: Option<f64>) -> VesselEnds<'a> {
        VesselEnds {
            name,
            from: Some(from),
            to: Some(to),
            radius_in: r.map(|r| 2.0 * r),
            radius_out: r,
        }
    }

    #[test]
    fn the_first_vessel_at_the_node_gives_its_end_radius() {
        let v = [
            ends("a", "in", "out", Some(1e-3)),
            ends("r", "out", "x", None),
        ];
        assert_eq!(end_radius("out", v).unwrap(), 1e-3);
        assert_eq!(end_radius("in", v).unwrap(), 2e-3);
        let e = end_radius("x", v).unwrap_err().to_string();
        assert!(
            e.ends_with("vessel 'r' at this node has no radius: give 'root_radius'"),
            "{e}"
        );
        let e = end_radius("nowhere", v).unwrap_err().to_string();
        assert!(e.ends_with("no vessel ends at this node"), "{e}");
    }

    /// The matched tree's steady resistance (its radius classes in closed form, leaves at the
    /// terminal resistance) is the Windkessel's R_p + R_d.
    #[test]
    fn the_tree_keeps_the_windkessels_steady_resistance() {
        let shape = Shape {
            alpha: 0.9,
            beta: 0.6,
            length_ratio: 50.0,
            root_radius: 2e-3,
            viscosity: 3.5e-3,
        };
        let (rp, rd) = (2.0e7, 1.5e9);
        let (rmin, leaf) = windkessel_tree("n", rp, rd, &shape, 1e-4, 0.9).unwrap();
        let r = shape.resistance(rmin, leaf);
        assert!((r / (rp + rd) - 1.0).abs() < 1e-9, "{r}");
        assert!(windkessel_tree("n", 0.0, 0.0, &shape, 1e-4, 0.9).is_err());
    }
}
