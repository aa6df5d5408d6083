//! Frequency response of the linear circuit: input impedance seen from a node, by solving
//! (iωE + F) y = e_node with boundary pressures held at zero.

use crate::circuit::Dae;
use crate::error::{Error, Result};
use nalgebra::{Complex, DMatrix, DVector};

/// Z(ω) = P_node / Q_injected for a unit flow injected at `node` (dense solve; small circuits).
pub fn input_impedance(dae: &Dae, node: usize, omega: f64) -> Result<Complex<f64>> {
    let n = dae.n;
    if n > 5000 {
        return Err(Error::model(
            "input_impedance",
            format!("circuit too large for the dense solve ({n} unknowns)"),
        ));
    }
    let mut a = DMatrix::<Complex<f64>>::zeros(n, n);
    for i in 0..n {
        for k in dae.f.row(i) {
            a[(i, dae.f.col[k] as usize)] += Complex::new(dae.f.val[k], 0.0);
        }
        a[(i, i)] += Complex::new(0.0, omega * dae.e[i]);
    }
    let mut b = DVector::<Complex<f64>>::zeros(n);
    b[node] = Complex::new(1.0, 0.0);
    let y = a
        .lu()
        .solve(&b)
        .ok_or_else(|| Error::solver(0.0, "singular frequency-domain system"))?;
    Ok(y[node])
}
