//! Sparse LU (faer) with the symbolic analysis done once and numeric refactorisation on demand.
//! A fill-reducing ordering makes tree-structured circuits factor without fill-in, so both
//! factorisation and solves are linear in the network size.

use crate::error::{Error, Result};
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Lu, SymbolicLu};
use faer::sparse::{Argsort, Pair, SparseColMat, SymbolicSparseColMat};

pub struct SparseLu {
    n: usize,
    sym: SymbolicSparseColMat<usize>,
    order: Argsort<usize>,
    sym_lu: SymbolicLu<usize>,
    lu: Option<Lu<usize, f64>>,
}

impl SparseLu {
    /// `stamps` are the (row, col) positions of the values later passed to `factor`, in order;
    /// duplicates are summed.
    pub fn analyse(n: usize, stamps: &[(usize, usize)]) -> Result<Self> {
        let pairs: Vec<Pair<usize, usize>> = stamps.iter().map(|&(r, c)| Pair::new(r, c)).collect();
        let (sym, order) = SymbolicSparseColMat::try_new_from_indices(n, n, &pairs)
            .map_err(|e| Error::solver(0.0, format!("sparse pattern: {e:?}")))?;
        let sym_lu = SymbolicLu::try_new(sym.as_ref())
            .map_err(|e| Error::solver(0.0, format!("symbolic LU: {e:?}")))?;
        Ok(SparseLu { n, sym, order, sym_lu, lu: None })
    }

    pub fn factor(&mut self, vals: &[f64]) -> std::result::Result<(), String> {
        let a = SparseColMat::new_from_argsort(self.sym.clone(), &self.order, vals)
            .map_err(|e| format!("{e:?}"))?;
        let lu = Lu::try_new_with_symbolic(self.sym_lu.clone(), a.as_ref())
            .map_err(|e| format!("{e:?}"))?;
        self.lu = Some(lu);
        Ok(())
    }

    /// Solve in place; returns false if the solution is not finite (singular matrix).
    pub fn solve_in_place(&self, rhs: &mut [f64]) -> bool {
        debug_assert_eq!(rhs.len(), self.n);
        let lu = self.lu.as_ref().expect("factor before solve");
        lu.solve_in_place(faer::ColMut::from_slice_mut(rhs));
        rhs.iter().all(|x| x.is_finite())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_small_system_and_reuses_the_pattern() {
        // [[4,1,0],[1,3,1],[0,1,2]]
        let stamps = [(0, 0), (0, 1), (1, 0), (1, 1), (1, 2), (2, 1), (2, 2)];
        let mut lu = SparseLu::analyse(3, &stamps).unwrap();
        lu.factor(&[4.0, 1.0, 1.0, 3.0, 1.0, 1.0, 2.0]).unwrap();
        let mut b = [5.0, 5.0, 3.0];
        assert!(lu.solve_in_place(&mut b));
        for (x, e) in b.iter().zip([1.0, 1.0, 1.0]) {
            assert!((x - e).abs() < 1e-14);
        }
        lu.factor(&[8.0, 2.0, 2.0, 6.0, 2.0, 2.0, 4.0]).unwrap();
        let mut b = [5.0, 5.0, 3.0];
        lu.solve_in_place(&mut b);
        assert!((b[0] - 0.5).abs() < 1e-14);
    }
}
