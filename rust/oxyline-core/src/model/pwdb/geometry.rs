//! PWDB's geometry changes of a subject: the radii of the large arteries scaled by the
//! subject's large-artery diameter factor, the lengths of the proximal aorta by its aortic
//! length factor (Charlton et al. 2019; docs/populations.md). Segments are numbered from 1 in
//! the order of the table.

use super::Segment;
use std::collections::BTreeSet;

/// The segments whose length PWDB's aortic length changes.
pub const PROXIMAL_AORTA: [usize; 2] = [1, 2];

/// The mean radius [m] from which a segment is a "large artery" (PWDB's 3.462 mm, with the
/// geometry's radii × √1.5).
pub fn large_artery_radius() -> f64 {
    0.003462 * 1.5f64.sqrt()
}

/// (large arteries, segments whose inlet radius scales): the segments of mean radius ≥
/// [`large_artery_radius`], and those with the segments fed by them.
pub fn large_arteries(base: &[Segment]) -> (BTreeSet<usize>, BTreeSet<usize>) {
    let limit = large_artery_radius();
    let big: BTreeSet<usize> = (1..=base.len())
        .filter(|&s| base[s - 1].mean_radius() >= limit)
        .collect();
    let fed: BTreeSet<usize> = big.iter().map(|&s| base[s - 1].outlet).collect();
    let inlets = (1..=base.len())
        .filter(|&s| big.contains(&s) || fed.contains(&base[s - 1].inlet))
        .collect();
    (big, inlets)
}

/// The segments with a radius that the large-artery diameter changes.
pub fn diameter_segments(base: &[Segment]) -> BTreeSet<usize> {
    let (big, inlets) = large_arteries(base);
    big.union(&inlets).copied().collect()
}

/// The subject's segments: outlet radii of the large arteries and inlet radii of the
/// segments of [`large_arteries`] × `dia`, lengths of the [`PROXIMAL_AORTA`] × `length`.
pub fn subject_geometry(base: &[Segment], dia: f64, length: f64) -> Vec<Segment> {
    let (big, inlets) = large_arteries(base);
    base.iter()
        .enumerate()
        .map(|(i, g)| {
            let s = i + 1;
            let mut g = *g;
            if big.contains(&s) {
                g.radius_out *= dia;
            }
            if inlets.contains(&s) {
                g.radius_in *= dia;
            }
            if PROXIMAL_AORTA.contains(&s) {
                g.length *= length;
            }
            g
        })
        .collect()
}
