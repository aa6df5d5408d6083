//! Index-2 algebraic unknowns and their values consistent with the constraint
//! (docs/physics.md §10, "Index-2 unknowns").
//!
//! An algebraic unknown (E_jj = 0) that no algebraic row holds is fixed only through the rates
//! of the differential rows it appears in: a flow between a capacitance and a node whose
//! pressure an algebraic row sets (the veins' capacitance on a heart chamber's pressure-set
//! node). Generalized-α meets that flow's rows at the α_f level through the α_m-level rate of
//! the constrained pressure, an alternating sum of the carried rates (−ρ∞ per step): a kink of
//! the pressure's rate (a valve's opening) rings through it, and the step-end value, the α_f
//! level's extrapolation by 1/α_f, rings the more. The other unknowns do not see it (the flow
//! enters their rows at the α_f level only).
//!
//! The value reported for such an unknown is instead the one its balance row gives with the
//! constrained unknown's rate taken from the step's α_f-level values, which lie on the
//! constraint (the circuit's algebraic rows hold there): the slope of the line (two points)
//! or quadratic (three) through the last levels, with the step's start standing for a level
//! before the first since a restart. The run's own state is never changed.

use crate::circuit::Dae;

/// An index-2 unknown and the differential row that fixes it:
/// e ẏ_rate + coefficient · y_unknown + Σ F_k y_k = 0.
#[derive(Debug, Clone)]
pub struct Balance {
    pub unknown: usize,
    /// The row's own differential unknown (its E entry).
    pub rate_unknown: usize,
    e: f64,
    coefficient: f64,
    /// (k, F_rk) of the row's other unknowns.
    terms: Vec<(usize, f64)>,
}

impl Balance {
    /// The unknown's value with the row's rate `rate` and its other unknowns `y`.
    #[inline]
    pub fn value(&self, rate: f64, y: impl Fn(usize) -> f64) -> f64 {
        let others: f64 = self.terms.iter().map(|&(k, f)| f * y(k)).sum();
        -(self.e * rate + others) / self.coefficient
    }
}

/// The index-2 unknowns of a circuit with a balance row each, sorted by unknown.
#[derive(Debug, Clone, Default)]
pub struct Index2 {
    pub balances: Vec<Balance>,
}

impl Index2 {
    /// The circuit's index-2 unknowns that a linear, unforced differential row fixes (none:
    /// empty). An unknown is index 2 when it is algebraic and no algebraic row holds it (in F,
    /// an element's pattern, a stenosis or a time-varying resistance); its balance row is a
    /// differential row of F that holds it with no element, stenosis, time-varying term,
    /// chain-rule capacitor, wall or forcing, and no other index-2 unknown.
    pub fn find(dae: &Dae) -> Self {
        let n = dae.n;
        let algebraic = |i: usize| dae.e[i] == 0.0;
        // rows whose terms are not F's alone
        let mut special = vec![false; n];
        let mut held = vec![false; n];
        for el in &dae.elements {
            for &r in el.rows() {
                special[r] = true;
            }
            for &(r, c) in el.pattern() {
                held[c] |= algebraic(r);
            }
        }
        for &(i, _) in &dae.stenosis {
            special[i] = true;
            held[i] |= algebraic(i);
        }
        for (i, _) in &dae.varying {
            special[*i] = true;
            held[*i] |= algebraic(*i);
        }
        for c in &dae.chain_rule {
            special[c.node] = true;
        }
        for &(node, u) in &dae.walls {
            special[node] = true;
            special[u] = true;
        }
        for (row, _) in &dae.forcing {
            special[*row] = true;
        }
        // a row of F alone tying two algebraic unknowns (a capacitance-free node between two
        // wires: Q_a = Q_b) holds neither: it passes one's value to the other
        let entries = |r: usize| entries(dae, r);
        let ties: Vec<[(usize, f64); 2]> = (0..n)
            .filter(|&r| algebraic(r) && !special[r])
            .filter_map(|r| {
                let row: Vec<(usize, f64)> = entries(r).collect();
                is_tie(&row, &algebraic).then(|| [row[0], row[1]])
            })
            .collect();
        for r in (0..n).filter(|&r| algebraic(r)) {
            if !special[r] && is_tie(&entries(r).collect::<Vec<_>>(), &algebraic) {
                continue;
            }
            for (c, _) in entries(r) {
                held[c] = true;
            }
        }
        let index2: Vec<bool> = (0..n).map(|j| algebraic(j) && !held[j]).collect();
        if !index2.contains(&true) {
            return Index2::default();
        }
        // the rows holding each index-2 unknown
        let mut rows_of: Vec<Vec<usize>> = vec![Vec::new(); n];
        for r in (0..n).filter(|&r| !algebraic(r) && !special[r]) {
            for k in dae.f.row(r) {
                let c = dae.f.col[k] as usize;
                if index2[c] && dae.f.val[k] != 0.0 {
                    rows_of[c].push(r);
                }
            }
        }
        let balance = |j: usize, r: usize| {
            let mut b = Balance {
                unknown: j,
                rate_unknown: r,
                e: dae.e[r],
                coefficient: 0.0,
                terms: Vec::new(),
            };
            for k in dae.f.row(r) {
                let (c, v) = (dae.f.col[k] as usize, dae.f.val[k]);
                if c == j {
                    b.coefficient += v;
                } else if index2[c] && v != 0.0 {
                    return None;
                } else {
                    b.terms.push((c, v));
                }
            }
            Some(b)
        };
        let mut found: Vec<Option<Balance>> = vec![None; n];
        for j in (0..n).filter(|&j| index2[j]) {
            found[j] = rows_of[j].iter().find_map(|&r| balance(j, r));
        }
        // an index-2 unknown tied to one with a balance: a·y_j + b·y_m = 0, so y_j is the
        // same balance's value times −b/a (along a chain of ties, one link a pass)
        for _ in 0..ties.len() {
            let mut linked = false;
            for &[(j, a), (m, b)] in &ties {
                for ((j, a), (m, b)) in [((j, a), (m, b)), ((m, b), (j, a))] {
                    if !index2[j] || found[j].is_some() {
                        continue;
                    }
                    if let Some(bm) = found[m].clone() {
                        let factor = -b / a;
                        found[j] = Some(Balance {
                            unknown: j,
                            coefficient: bm.coefficient / factor,
                            ..bm
                        });
                        linked = true;
                    }
                }
            }
            if !linked {
                break;
            }
        }
        Index2 {
            balances: found.into_iter().flatten().collect(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.balances.is_empty()
    }

    /// The balance of unknown `i` and its position, if it is one of the index-2 unknowns.
    #[inline]
    pub fn balance_at(&self, i: usize) -> Option<(usize, &Balance)> {
        if self.balances.is_empty() {
            return None;
        }
        let k = self.balances.binary_search_by_key(&i, |b| b.unknown);
        k.ok().map(|k| (k, &self.balances[k]))
    }

    /// The balance of unknown `i`, if it is one of the index-2 unknowns.
    #[inline]
    pub fn balance(&self, i: usize) -> Option<&Balance> {
        self.balance_at(i).map(|(_, b)| b)
    }

    pub fn contains(&self, i: usize) -> bool {
        self.balance(i).is_some()
    }
}

/// Row `r`'s nonzero entries of F, (column, value).
fn entries(dae: &Dae, r: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
    let f = &dae.f;
    f.row(r)
        .filter(move |&k| f.val[k] != 0.0)
        .map(move |k| (f.col[k] as usize, f.val[k]))
}

/// Whether a row's nonzero entries of F, `row`, tie exactly two algebraic unknowns.
fn is_tie(row: &[(usize, f64)], algebraic: &impl Fn(usize) -> bool) -> bool {
    matches!(row, [a, b] if algebraic(a.0) && algebraic(b.0))
}

/// Values per balance in a checkpoint (see [`StepEnds::carried`]).
const CARRIED_PER_BALANCE: usize = 8;

/// The slope at `t` of the line through two points or the quadratic through three (t, v),
/// distinct in t; 0 with fewer.
pub fn slope_at(points: &[(f64, f64)], t: f64) -> f64 {
    match *points {
        [(a, ya), (b, yb)] => (yb - ya) / (b - a),
        [(a, ya), (b, yb), (c, yc)] => {
            let la = ((t - b) + (t - c)) / ((a - b) * (a - c));
            let lb = ((t - a) + (t - c)) / ((b - a) * (b - c));
            let lc = ((t - a) + (t - b)) / ((c - a) * (c - b));
            la * ya + lb * yb + lc * yc
        }
        [p0, p1, p2, p3] => {
            // the quadratic's slope through the last three plus the cubic term's
            let (b, c, d) = (p1.0, p2.0, p3.0);
            let dd = |(s, u): (f64, f64), (t, v): (f64, f64)| (v - u) / (t - s);
            let (ab, bc, cd) = (dd(p0, p1), dd(p1, p2), dd(p2, p3));
            let third = ((cd - bc) / (d - b) - (bc - ab) / (c - p0.0)) / (d - p0.0);
            let w = (t - c) * (t - d) + (t - b) * (t - d) + (t - b) * (t - c);
            slope_at(&points[1..], t) + third * w
        }
        _ => 0.0,
    }
}

/// The error, over a step of `h` (0 ≤ x ≤ h from its start), of the slope the quadratic
/// through the last three of four points (t, v) gives, distinct in t, oldest first: the slope
/// of the cubic through all four less the quadratic's, the cubic term
/// f[t₀, t₁, t₂, t₃]·(x − t₁)(x − t₂)(x − t₃) differentiated, at the larger of its values at
/// the step's ends (the derivative of that product is a quadratic in x whose extreme over the
/// step lies at an end unless its vertex falls within; the vertex is taken too).
pub fn quadratic_slope_error(points: &[(f64, f64); 4], h: f64) -> f64 {
    let [(a, ya), (b, yb), (c, yc), (d, yd)] = *points;
    let f1 = |(s, u): (f64, f64), (t, v): (f64, f64)| (v - u) / (t - s);
    let (ab, bc, cd) = (
        f1((a, ya), (b, yb)),
        f1((b, yb), (c, yc)),
        f1((c, yc), (d, yd)),
    );
    let (abc, bcd) = ((bc - ab) / (c - a), (cd - bc) / (d - b));
    let third = (bcd - abc) / (d - a);
    // d/dx (x − b)(x − c)(x − d) = 3x² − 2(b + c + d)x + (bc + bd + cd)
    let (s1, s2) = (b + c + d, b * c + b * d + c * d);
    let w = |x: f64| 3.0 * x * x - 2.0 * s1 * x + s2;
    let vertex = (s1 / 3.0).clamp(0.0, h);
    let worst = w(0.0).abs().max(w(h).abs()).max(w(vertex).abs());
    third.abs() * worst
}

/// The α_f-level values of each index-2 balance's rate unknown over the last three accepted
/// steps of an error-controlled run, oldest first, at times from the current step's start:
/// with the step's own level, the four points [`quadratic_slope_error`] judges the step's
/// consistent values by.
#[derive(Debug, Clone, Default)]
pub struct Levels {
    points: Vec<[(f64, f64); 3]>,
}

impl Levels {
    /// A step of `h` from `y0` to `y` was accepted: its levels join, the times move to the
    /// next step's start.
    pub fn accepted(&mut self, index2: &Index2, alpha_f: f64, h: f64, y0: &[f64], y: &[f64]) {
        self.points.resize(index2.balances.len(), [(0.0, 0.0); 3]);
        for (b, pts) in index2.balances.iter().zip(&mut self.points) {
            let r = b.rate_unknown;
            let level = y0[r] + alpha_f * (y[r] - y0[r]);
            *pts = [
                (pts[1].0 - h, pts[1].1),
                (pts[2].0 - h, pts[2].1),
                ((alpha_f - 1.0) * h, level),
            ];
        }
    }

    /// The four points of balance `k` for the step of `h` from `y0` to `y` (its level last):
    /// valid once three steps were accepted since the last restart.
    pub fn with_step(
        &self,
        k: usize,
        r: usize,
        alpha_f: f64,
        h: f64,
        y0: &[f64],
        y: &[f64],
    ) -> [(f64, f64); 4] {
        let p = self.points[k];
        [
            p[0],
            p[1],
            p[2],
            (alpha_f * h, y0[r] + alpha_f * (y[r] - y0[r])),
        ]
    }
}

/// The consistent values of a fixed-step run's index-2 unknowns at its step ends: per
/// balance, the last (up to three) points its rate is taken from (the α_f levels of the
/// steps, after the state a restart began from).
#[derive(Debug, Clone)]
pub struct StepEnds {
    index2: Index2,
    alpha_f: f64,
    /// Per balance, the rate unknown's value at the last step end.
    last: Vec<f64>,
    /// Per balance, up to three (time, value) points, oldest first.
    points: Vec<Vec<(f64, f64)>>,
    /// The index-2 unknowns' own values while a row is recorded with the consistent ones.
    saved: Vec<f64>,
}

impl StepEnds {
    /// None for a circuit without index-2 unknowns or an integrator that meets its algebraic
    /// rows at the step's end (α_f = 1).
    pub fn new(dae: &Dae, alpha_f: f64) -> Option<Self> {
        let index2 = Index2::find(dae);
        if index2.is_empty() || alpha_f >= 1.0 {
            return None;
        }
        let m = index2.balances.len();
        Some(StepEnds {
            index2,
            alpha_f,
            last: vec![0.0; m],
            points: vec![Vec::with_capacity(4); m],
            saved: Vec::new(),
        })
    }

    /// The run (re)starts at `t` from `y`.
    pub fn start(&mut self, t: f64, y: &[f64]) {
        for ((b, last), pts) in self
            .index2
            .balances
            .iter()
            .zip(&mut self.last)
            .zip(&mut self.points)
        {
            *last = y[b.rate_unknown];
            pts.clear();
            pts.push((t, *last));
        }
    }

    /// Whether [`StepEnds::start`] was called.
    pub fn started(&self) -> bool {
        self.points.first().is_some_and(|p| !p.is_empty())
    }

    /// A step of `h` from `t` ended in `y`.
    pub fn stepped(&mut self, t: f64, h: f64, y: &[f64]) {
        let af = self.alpha_f;
        for ((b, last), pts) in self
            .index2
            .balances
            .iter()
            .zip(&mut self.last)
            .zip(&mut self.points)
        {
            let end = y[b.rate_unknown];
            if pts.len() == 3 {
                pts.remove(0);
            }
            pts.push((t + af * h, *last + af * (end - *last)));
            *last = end;
        }
    }

    /// `y` at the step end `t` with its index-2 unknowns' consistent values; `restore` puts
    /// the run's own back.
    pub fn substitute(&mut self, t: f64, y: &mut [f64]) {
        self.saved.clear();
        for (b, pts) in self.index2.balances.iter().zip(&self.points) {
            self.saved.push(y[b.unknown]);
            if pts.len() < 2 {
                continue;
            }
            let v = b.value(slope_at(pts, t), |k| y[k]);
            y[b.unknown] = v;
        }
    }

    /// What a checkpoint carries so that a resumed run reports the same rows: per balance,
    /// the rate unknown's last step-end value, the number of points and the points (padded
    /// to three).
    pub fn carried(&self) -> Vec<f64> {
        let mut out = Vec::with_capacity(CARRIED_PER_BALANCE * self.points.len());
        for (last, pts) in self.last.iter().zip(&self.points) {
            out.extend([*last, pts.len() as f64]);
            for k in 0..3 {
                let (t, v) = pts.get(k).copied().unwrap_or((0.0, 0.0));
                out.extend([t, v]);
            }
        }
        out
    }

    /// Continue from a checkpoint's [`StepEnds::carried`]; false when it is not of this
    /// circuit's balances (another count).
    pub fn restore_carried(&mut self, carried: &[f64]) -> bool {
        if carried.len() != CARRIED_PER_BALANCE * self.points.len() {
            return false;
        }
        let chunks = carried.chunks_exact(CARRIED_PER_BALANCE);
        for ((c, last), pts) in chunks.zip(&mut self.last).zip(&mut self.points) {
            *last = c[0];
            pts.clear();
            let n = (c[1] as usize).min(3);
            pts.extend((0..n).map(|k| (c[2 + 2 * k], c[3 + 2 * k])));
        }
        true
    }

    /// The run's own values of the index-2 unknowns back into `y` (after `substitute`).
    pub fn restore(&self, y: &mut [f64]) {
        for (b, &v) in self.index2.balances.iter().zip(&self.saved) {
            y[b.unknown] = v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::circuit::Circuit;
    use crate::waveform::Waveform;

    #[test]
    fn the_slope_of_a_quadratic_is_exact_and_of_a_line_its_chord() {
        let q = |t: f64| 1.0 - 2.0 * t + 3.0 * t * t;
        let pts = [(0.1, q(0.1)), (0.4, q(0.4)), (0.65, q(0.65))];
        for t in [0.0, 0.5, 0.9] {
            assert!((slope_at(&pts, t) - (-2.0 + 6.0 * t)).abs() < 1e-12);
        }
        assert!((slope_at(&pts[..2], 7.0) - (q(0.4) - q(0.1)) / 0.3).abs() < 1e-12);
    }

    /// The quadratic's slope error is the cubic's slope less the quadratic's, exactly for a
    /// cubic and at its worst over the step; the four-point slope is the cubic's.
    #[test]
    fn the_slope_error_of_the_quadratic_is_its_miss_of_a_cubic() {
        let y = |t: f64| 0.3 - t + 2.0 * t * t - 5.0 * t * t * t;
        let dy = |t: f64| -1.0 + 4.0 * t - 15.0 * t * t;
        // levels at uneven spacing, the last inside the step [0, h]
        let h = 0.2;
        let ts = [-0.55, -0.3, -0.12, 0.13];
        let pts = ts.map(|t| (t, y(t)));
        let mut worst = 0.0f64;
        for k in 0..=200 {
            let x = h * k as f64 / 200.0;
            assert!((slope_at(&pts, x) - dy(x)).abs() < 1e-12);
            worst = worst.max((slope_at(&pts[1..], x) - dy(x)).abs());
        }
        let est = quadratic_slope_error(&pts, h);
        // (the samples may miss an interior extreme by a little)
        assert!(
            est >= worst * (1.0 - 1e-12) && est <= worst * (1.0 + 1e-4),
            "{est} vs {worst}"
        );
        // a quadratic has none
        let q = |t: f64| 1.0 + t - 3.0 * t * t;
        assert!(quadratic_slope_error(&ts.map(|t| (t, q(t))), h) < 1e-12);
    }

    /// The levels of three accepted steps, with the step's own, at times from its start.
    #[test]
    fn the_levels_move_with_the_accepted_steps() {
        let index2 = Index2 {
            balances: vec![Balance {
                unknown: 1,
                rate_unknown: 0,
                e: 2.0,
                coefficient: -1.0,
                terms: Vec::new(),
            }],
        };
        let af = 2.0 / 3.0;
        let (mut levels, mut t) = (Levels::default(), 0.0);
        let p = |t: f64| [t * t, f64::NAN];
        for h in [0.3, 0.6, 0.15] {
            levels.accepted(&index2, af, h, &p(t), &p(t + h));
            t += h;
        }
        let h = 0.45;
        let pts = levels.with_step(0, 0, af, h, &p(t), &p(t + h));
        // each level at its step's α_f time, relative to the step's start t = 1.05
        let want = [
            (-1.05 + 0.2, 0.0, 0.3),
            (-0.75 + 0.4, 0.3, 0.9),
            (-0.15 + 0.1, 0.9, 1.05),
        ];
        for (k, (x, a, b)) in want.into_iter().enumerate() {
            let level = a * a + af * (b * b - a * a);
            assert!((pts[k].0 - x).abs() < 1e-12 && (pts[k].1 - level).abs() < 1e-12);
        }
        assert!((pts[3].0 - af * h).abs() < 1e-15);
    }

    /// Two capacitors tied by a wire (its flow is index 2: only the two nodes' balances hold
    /// it), fed by a source, drained by a resistor.
    #[test]
    fn a_wire_between_two_capacitors_is_index_2_and_a_resistor_is_not() {
        for (r, index2) in [(0.0, true), (1e6, false)] {
            let mut k = Circuit::default();
            let a = k.add_node("a", 1e-9, 0.0);
            let b = k.add_node("b", 2e-9, 0.0);
            let out = k.add_node("out", 0.0, 0.0);
            let w = k.add_branch("wire", a, b, r, 0.0, 0.0);
            k.add_branch("drain", b, out, 1e8, 0.0, 0.0);
            k.sources.push((a, Waveform::constant(1e-6)));
            k.fixed_pressures.push((out, Waveform::constant(0.0)));
            let dae = k.assemble().unwrap();
            // (a branch's flow is the unknown after the nodes' pressures)
            let w = dae.n_nodes + w;
            let found = Index2::find(&dae);
            assert_eq!(found.contains(w), index2, "R = {r}");
            if index2 {
                // the unforced node b: C_b ẏ_b − Q_wire + Q_drain = 0 (the source's node a
                // is forced)
                let bal = found.balance(w).unwrap();
                assert_eq!(bal.rate_unknown, b);
                let (qd, rate) = (3e-7, 50.0);
                let y = |i: usize| if i == w { f64::NAN } else { qd };
                let q = bal.value(rate, y);
                assert!((q - (2e-9 * rate + qd)).abs() < 1e-18, "{q}");
            }
        }
    }

    /// A rigid tube between a `flow` and a `resistance` condition: its pressures follow the
    /// inflow's rate (index 2). A checkpoint's carried points give a resumed run the same
    /// consistent values as the run that wrote it, and another circuit's are refused.
    #[test]
    fn the_carried_points_give_the_same_rows_after_a_resume() {
        // (the file as a user writes it, through the native reader's canonical form)
        let file: serde_json::Value = serde_json::from_str(
            r#"{"period": 1.0,
                "vessels": [{"name": "tube", "from": "in", "to": "out", "segments": 10,
                             "length": 0.1, "radius": 0.01}],
                "boundary_conditions": {
                  "in": {"type": "flow", "fourier": {"period": 1.0, "mean": 1e-5,
                                                     "cos": [0.0], "sin": [3e-5]}},
                  "out": {"type": "resistance", "resistance": 1e7}}}"#,
        )
        .unwrap();
        let (canonical, _) = crate::model::native::canonical::canonical(&file).unwrap();
        let spec = crate::model::parse(&canonical.to_string()).unwrap();
        let dae = spec.assemble().unwrap().circuit.assemble().unwrap();
        let mut ends = StepEnds::new(&dae, 0.6).expect("the rigid tube's pressures are index 2");
        let state = |t: f64| -> Vec<f64> {
            (0..dae.n)
                .map(|i| (i as f64 + 1.0) * (1.0 + t * t))
                .collect()
        };
        ends.start(0.0, &state(0.0));
        for k in 0..4 {
            let t = k as f64 * 1e-3;
            ends.stepped(t, 1e-3, &state(t + 1e-3));
        }
        let mut resumed = StepEnds::new(&dae, 0.6).unwrap();
        assert!(resumed.restore_carried(&ends.carried()));
        let (mut a, mut b) = (state(4e-3), state(4e-3));
        ends.substitute(4e-3, &mut a);
        resumed.substitute(4e-3, &mut b);
        assert_eq!(a, b);
        assert_ne!(
            a,
            state(4e-3),
            "the consistent values differ from the state's"
        );
        assert!(!resumed.restore_carried(&[0.0; 3]));
    }
}
