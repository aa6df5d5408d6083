//! Input impedance over many frequencies in O(n) each: the frequency-domain matrix iωE + F has
//! the pattern of the time stepping's iteration matrices, so it gets the same elimination
//! (`sparse::SparseLu`: leaves-to-root on a tree, faer sparse LU where there are loops),
//! analysed once and refactorised per frequency. The dense `frequency::input_impedance` stays
//! as the independent check of small circuits.

use crate::circuit::Dae;
use crate::error::{Error, Result};
use crate::sparse::SparseLu;
use faer::c64;

const ELEMENT: &str = "input_impedance";

/// Z(ω) = P_node / Q_injected (Pa·s/m³) for a unit flow injected at unknown `node`, boundary
/// pressures held at zero, at each angular frequency of `omegas` (rad/s, finite, >= 0).
pub fn input_impedances(dae: &Dae, node: usize, omegas: &[f64]) -> Result<Vec<c64>> {
    let n = dae.n;
    if node >= n {
        return Err(Error::model(ELEMENT, format!("unknown {node} out of {n}")));
    }
    if let Some(w) = omegas.iter().find(|w| !(w.is_finite() && **w >= 0.0)) {
        return Err(Error::model(
            ELEMENT,
            format!("angular frequency {w} must be finite and >= 0"),
        ));
    }
    let mut system = FrequencySystem::new(dae);
    // at ω = 0 capacitor rows have no pivot and the elimination falls back to faer's LU for
    // good, so zero frequency gets its own solver and the others keep the O(n) one
    let mut lu_ac = SparseLu::<c64>::analyse(n, &system.stamps)?;
    let mut lu_dc = match omegas.contains(&0.0) {
        true => Some(SparseLu::<c64>::analyse(n, &system.stamps)?),
        false => None,
    };
    let mut rhs = vec![c64::new(0.0, 0.0); n];
    omegas
        .iter()
        .map(|&omega| {
            system.set_frequency(dae, omega);
            let singular = |why: String| {
                Error::solver(
                    0.0,
                    format!("frequency-domain system at ω = {omega}: {why}"),
                )
            };
            let lu = match lu_dc.as_mut() {
                Some(dc) if omega == 0.0 => dc,
                _ => &mut lu_ac,
            };
            lu.factor(&system.vals).map_err(singular)?;
            rhs.iter_mut().for_each(|x| *x = c64::new(0.0, 0.0));
            rhs[node] = c64::new(1.0, 0.0);
            if !lu.solve_in_place(&mut rhs) {
                return Err(singular("singular matrix".into()));
            }
            Ok(rhs[node])
        })
        .collect()
}

/// The frequency-domain matrix iωE + F in the stamp form `SparseLu` takes: F's entries, then
/// one diagonal stamp per row for iωE (duplicates are summed). Shared by the input impedance
/// and the periodic start (`integrate::periodic`), which solve the same system per frequency.
pub(crate) struct FrequencySystem {
    /// (row, column) of every value, in `vals` order
    pub stamps: Vec<(usize, usize)>,
    /// F's values, then the diagonal iωE of the frequency last set
    pub vals: Vec<c64>,
    nnz: usize,
}

impl FrequencySystem {
    pub fn new(dae: &Dae) -> Self {
        let n = dae.n;
        let nnz = dae.f.ptr[n];
        let mut stamps: Vec<(usize, usize)> = Vec::with_capacity(nnz + n);
        for i in 0..n {
            for k in dae.f.ptr[i]..dae.f.ptr[i + 1] {
                stamps.push((i, dae.f.col[k] as usize));
            }
        }
        stamps.extend((0..n).map(|i| (i, i)));
        let mut vals: Vec<c64> = dae.f.val[..nnz].iter().map(|&v| c64::new(v, 0.0)).collect();
        vals.resize(nnz + n, c64::new(0.0, 0.0));
        FrequencySystem { stamps, vals, nnz }
    }

    /// Sets the diagonal stamps to iωE (ω in rad/s).
    pub fn set_frequency(&mut self, dae: &Dae, omega: f64) {
        for (v, &e) in self.vals[self.nnz..].iter_mut().zip(&dae.e) {
            *v = c64::new(0.0, omega * e);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::parse;

    /// A bifurcation with a loop-free tree and the same with a loop: the O(n) elimination and
    /// faer's LU must reproduce the dense solve of `frequency::input_impedance`.
    #[test]
    fn matches_the_dense_solve() {
        let vessel = |name: &str, a: &str, b: &str, r: f64| {
            format!(
                r#"{{"name":"{name}","from":"{a}","to":"{b}","segments":5,"geometry":
                {{"length":0.05,"radius_in":{r},"radius_out":{r},"wall_thickness":2e-4,
                "youngs_modulus":1e6}}}}"#
            )
        };
        let bc = r#""in":{"type":"flow","flow":{"kind":"constant","value":1e-6}},
            "o1":{"type":"resistance","resistance":1e9,"pressure":{"kind":"constant","value":0}},
            "o2":{"type":"rcr","proximal_resistance":1e8,"capacitance":1e-10,
                  "distal_resistance":1e9,"pressure":{"kind":"constant","value":0}}"#;
        for looped in [false, true] {
            let mut vs = vec![
                vessel("p", "in", "j", 2e-3),
                vessel("d1", "j", "o1", 1.5e-3),
                vessel("d2", "j", "k", 1.2e-3),
                vessel("d3", "k", "o2", 1.2e-3),
            ];
            if looped {
                vs.push(vessel("x", "j", "k", 1e-3));
            }
            let json = format!(
                r#"{{"name":"t","blood":{{"density":1050,"viscosity":0.0035}},
                "vessels":[{}],"boundary_conditions":{{{bc}}}}}"#,
                vs.join(",")
            );
            let assembled = parse(&json).unwrap().assemble().unwrap();
            let dae = assembled.circuit.assemble().unwrap();
            let circuit = &assembled.circuit;
            let node = (0..circuit.nodes.len())
                .position(|i| circuit.names.node(i) == "in")
                .unwrap();
            let omegas = [0.0, 2.0, 30.0, 120.0];
            let z = input_impedances(&dae, node, &omegas).unwrap();
            for (&w, zs) in omegas.iter().zip(&z) {
                let zd = crate::frequency::input_impedance(&dae, node, w).unwrap();
                // two LU factorisations (no pivoting vs partial pivoting) of a ~100-unknown
                // system with entries over ~20 decades: agree to rounding times conditioning
                assert!(
                    (zs - zd).norm() <= 1e-9 * zd.norm(),
                    "{looped} {w}: {zs} vs {zd}"
                );
            }
        }
    }

    #[test]
    fn bad_frequencies_are_model_errors() {
        let dae_json = r#"{"name":"t","blood":{"density":1050,"viscosity":0.0035},
            "vessels":[{"name":"v","from":"a","to":"b","geometry":{"length":0.1,
            "radius_in":0.003,"radius_out":0.003}}],
            "boundary_conditions":{"a":{"type":"flow","flow":{"kind":"constant","value":1e-6}},
            "b":{"type":"resistance","resistance":1e9,"pressure":{"kind":"constant","value":0}}}}"#;
        let assembled = parse(dae_json).unwrap().assemble().unwrap();
        let dae = assembled.circuit.assemble().unwrap();
        assert!(input_impedances(&dae, 0, &[1.0, f64::NAN]).is_err());
        assert!(input_impedances(&dae, 0, &[-1.0]).is_err());
        assert!(input_impedances(&dae, dae.n, &[1.0]).is_err());
    }
}
