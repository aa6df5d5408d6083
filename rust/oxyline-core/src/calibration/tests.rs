//! The calibration rows against three independent truths: the assembled DAE of the same RCL
//! vessel (its stamps, with the interior pressure set from the R branch), central differences
//! of the residual (the rows are at most bilinear in α, so the quotient is exact up to
//! rounding, ~1e-16 × |row| / h), and data made to satisfy the rows exactly.

use super::*;
use crate::model::parse;

const VESSEL: [usize; 4] = [0, 1, 2, 3];

fn vessel() -> Vec<Block> {
    vec![
        Block::Vessel {
            name: "v".into(),
            vars: VESSEL,
            params: [0, 1, 2, 3],
        },
        Block::Branch {
            name: "j:v2".into(),
            vars: [2, 4, 5],
            params: [4, 5, 6],
        },
    ]
}

/// Six variables (P_in, Q, P_out, Q_out, P_b, Q_b) at three observations, with flows of both
/// signs (the stenosis term's |Q| and its kink).
fn data() -> (Vec<f64>, Vec<f64>) {
    let y = [
        [1.3e4, 1.1e4, 0.9e4],
        [12.0, -3.0, 40.0],
        [1.2e4, 1.05e4, 0.95e4],
        [10.0, -1.0, 30.0],
        [1.1e4, 1.0e4, 0.92e4],
        [4.0, -2.0, 9.0],
    ];
    let dy = [
        [3e4, -2e4, 1e4],
        [200.0, -150.0, 90.0],
        [2e4, -1e4, 5e3],
        [120.0, -60.0, 30.0],
        [1e4, 2e3, -4e3],
        [50.0, -20.0, 10.0],
    ];
    (y.concat(), dy.concat())
}

const ALPHA: [f64; 7] = [80.0, 2e-4, 1.5, -0.7, 30.0, 0.8, 0.2];

#[test]
fn jacobian_matches_central_differences() {
    let (y, dy) = data();
    let obs = Observations {
        y: &y,
        dy: &dy,
        n_obs: 3,
    };
    let (r0, triplets) = residual(&vessel(), &obs, &ALPHA).unwrap();
    let mut jac = vec![vec![0.0; ALPHA.len()]; r0.len()];
    for (i, p, v) in triplets {
        jac[i][p] += v;
    }
    for p in 0..ALPHA.len() {
        let h = 1e-4 * ALPHA[p].abs();
        let mut up = ALPHA;
        let mut down = ALPHA;
        up[p] += h;
        down[p] -= h;
        let (ru, _) = residual(&vessel(), &obs, &up).unwrap();
        let (rd, _) = residual(&vessel(), &obs, &down).unwrap();
        for i in 0..r0.len() {
            let fd = (ru[i] - rd[i]) / (2.0 * h);
            let scale = jac.iter().map(|row| row[p].abs()).fold(1e-300, f64::max);
            assert!(
                (fd - jac[i][p]).abs() <= 1e-8 * scale,
                "row {i} slot {p}: {fd} vs {}",
                jac[i][p]
            );
        }
    }
}

#[test]
fn normal_equations_are_jt_r_and_jt_j() {
    let (y, dy) = data();
    let obs = Observations {
        y: &y,
        dy: &dy,
        n_obs: 3,
    };
    let (r, triplets) = residual(&vessel(), &obs, &ALPHA).unwrap();
    let ne = normal_equations(&vessel(), &obs, &ALPHA).unwrap();
    let mut jac = vec![vec![0.0; ALPHA.len()]; r.len()];
    for (i, p, v) in triplets {
        jac[i][p] += v;
    }
    let cost: f64 = r.iter().map(|x| x * x).sum();
    assert!((ne.cost - cost).abs() <= 1e-12 * cost);
    for (p, &mine) in ne.gradient.iter().enumerate() {
        let g: f64 = jac.iter().zip(&r).map(|(row, ri)| row[p] * ri).sum();
        assert!((mine - g).abs() <= 1e-12 * g.abs().max(1.0));
    }
    // the vessel's 4×4 block, then the branch's 3×3
    let mut k = 0;
    for slots in [&[0, 1, 2, 3][..], &[4, 5, 6][..]] {
        for &a in slots {
            for &b in slots {
                let h: f64 = (0..r.len()).map(|i| jac[i][a] * jac[i][b]).sum();
                assert!((ne.gram[k] - h).abs() <= 1e-12 * h.abs().max(1e-300));
                k += 1;
            }
        }
    }
}

#[test]
fn data_that_satisfy_the_rows_leave_no_residual() {
    // choose P_in, Q and their rates; Q_out from the capacitor row, P_out from the momentum
    // row with dQ_out/dt = 0 (a steady outflow at each sample)
    let (r, c, l, s): (f64, f64, f64, f64) = (80.0, 2e-4, 1.5, -0.7);
    let (p_in, q, dp_in, dq): ([f64; 2], [f64; 2], [f64; 2], [f64; 2]) =
        ([1.3e4, 1.1e4], [12.0, -3.0], [3e4, -2e4], [200.0, -150.0]);
    let q_out: Vec<f64> = (0..2)
        .map(|k| q[k] - c * (dp_in[k] - (r + 2.0 * s * q[k].abs()) * dq[k]))
        .collect();
    let p_out: Vec<f64> = (0..2)
        .map(|k| p_in[k] - (r + s * q[k].abs()) * q[k])
        .collect();
    let y = [p_in.to_vec(), q.to_vec(), p_out, q_out].concat();
    let dy = [dp_in.to_vec(), dq.to_vec(), vec![0.0; 4]].concat();
    let obs = Observations {
        y: &y,
        dy: &dy,
        n_obs: 2,
    };
    let blocks = &vessel()[..1];
    let ne = normal_equations(blocks, &obs, &[r, c, l, s]).unwrap();
    assert!(ne.cost < 1e-20, "cost {}", ne.cost);
}

/// The same RCL vessel (svZeroDSolver's form) assembled by the core: its capacitor-node row
/// in chain-rule form and its L branch row, at the DAE state made from the observations, equal
/// the calibration rows (up to each row's sign).
#[test]
fn rows_are_the_assembled_vessel_stamps() {
    let (r, c, l, s) = (ALPHA[0], ALPHA[1], ALPHA[2], ALPHA[3]);
    let model = format!(
        r#"{{"name": "m", "vessels": [{{"name": "v", "from": "in", "to": "out",
            "arrangement": "RCL", "lumped": {{"resistance": {r}, "capacitance": {c},
            "inductance": {l}, "stenosis_coefficient": {s}, "stenosis_form": "svzerod"}}}}],
          "boundary_conditions": {{"in": {{"type": "flow", "flow": {{"kind": "constant", "value": 1.0}}}},
                                   "out": {{"type": "resistance", "resistance": 1.0}}}}}}"#
    );
    let spec = parse(&model).unwrap();
    let dae = spec.assemble().unwrap().circuit.assemble().unwrap();
    let names = dae.names.unknowns();
    let find = |what: &str| {
        names
            .iter()
            .position(|n| n.contains(what))
            .unwrap_or_else(|| panic!("no unknown '{what}' in {names:?}"))
    };
    let cap = dae.chain_rule[0];
    let (p_in, p_c, flow) = (cap.inlet, cap.node, cap.flow);
    let p_out = find("pressure at out");
    let q_out = (0..dae.n)
        .find(|&i| i >= dae.n_nodes && i != flow && dae.e[i] == l)
        .expect("the L branch's flow");
    let (y, dy) = data();
    let obs = Observations {
        y: &y,
        dy: &dy,
        n_obs: 3,
    };
    let (rows, _) = residual(&vessel()[..1], &obs, &ALPHA).unwrap();
    for k in 0..3 {
        let at = |v: usize| (y[v * 3 + k], dy[v * 3 + k]);
        let mut state = vec![0.0; dae.n];
        let mut rate = vec![0.0; dae.n];
        for (unknown, v) in [(p_in, 0), (flow, 1), (p_out, 2), (q_out, 3)] {
            (state[unknown], rate[unknown]) = at(v);
        }
        state[p_c] = state[p_in] - (r + s * state[flow].abs()) * state[flow];
        // E ẏ + F y + c(y) row by row, the capacitor row in chain-rule form
        let row = |i: usize| {
            let mut x = dae.f.row_dot(i, &state) + dae.e[i] * rate[i];
            for &(j, sj) in &dae.stenosis {
                if j == i {
                    x += sj * state[j].abs() * state[j];
                }
            }
            x
        };
        let slope = cap.resistance + 2.0 * cap.stenosis * state[flow].abs();
        let capacitor =
            row(p_c) - dae.e[p_c] * rate[p_c] + cap.capacitance * (rate[p_in] - slope * rate[flow]);
        for (mine, theirs) in [(rows[2 * k], row(q_out)), (rows[2 * k + 1], capacitor)] {
            let scale = mine.abs().max(theirs.abs()).max(1.0);
            assert!(
                (mine - theirs).abs() <= 1e-12 * scale || (mine + theirs).abs() <= 1e-12 * scale,
                "observation {k}: {mine} vs {theirs}"
            );
        }
    }
}

#[test]
fn bad_input_names_the_block() {
    let (mut y, dy) = data();
    y[4] = f64::NAN;
    let obs = Observations {
        y: &y,
        dy: &dy,
        n_obs: 3,
    };
    let e = normal_equations(&vessel(), &obs, &ALPHA).unwrap_err();
    assert!(e.to_string().starts_with("v:"), "{e}");
    let (y, dy) = data();
    let obs = Observations {
        y: &y,
        dy: &dy,
        n_obs: 3,
    };
    let mut alpha = ALPHA;
    alpha[5] = f64::INFINITY;
    let e = normal_equations(&vessel(), &obs, &alpha).unwrap_err();
    assert!(e.to_string().starts_with("j:v2:"), "{e}");
    let e = normal_equations(&vessel(), &obs, &ALPHA[..5]).unwrap_err();
    assert!(e.to_string().contains("out of range"), "{e}");
}

/// Observations made to satisfy the vessel rows exactly at `alpha` (several samples, flows of
/// both signs, a varying outflow so that L is determined).
fn exact_data(alpha: [f64; 4]) -> (Vec<f64>, Vec<f64>) {
    let [r, c, l, s] = alpha;
    let p_in: [f64; 6] = [1.3e4, 1.1e4, 0.9e4, 1.2e4, 1.0e4, 1.15e4];
    let q: [f64; 6] = [12.0, -3.0, 40.0, 25.0, 5.0, -8.0];
    let dp_in: [f64; 6] = [3e4, -2e4, 1e4, -5e3, 8e3, 2e4];
    let dq: [f64; 6] = [200.0, -150.0, 90.0, -40.0, 60.0, 10.0];
    let dq_out: [f64; 6] = [120.0, -60.0, 30.0, 15.0, -25.0, 70.0];
    let q_out: Vec<f64> = (0..6)
        .map(|k| q[k] - c * (dp_in[k] - (r + 2.0 * s * q[k].abs()) * dq[k]))
        .collect();
    let p_out: Vec<f64> = (0..6)
        .map(|k| p_in[k] - (r + s * q[k].abs()) * q[k] - l * dq_out[k])
        .collect();
    let y = [p_in.to_vec(), q.to_vec(), p_out, q_out].concat();
    let dy = [dp_in.to_vec(), dq.to_vec(), vec![0.0; 6], dq_out.to_vec()].concat();
    (y, dy)
}

const FIT: FitSettings = FitSettings {
    max_iterations: 200,
    initial_damping: 1.0,
    tolerance_gradient: 1e-12,
    tolerance_increment: 1e-14,
};

#[test]
fn fit_recovers_the_values_that_made_the_data() {
    let truth = [80.0, 2e-4, 1.5, -0.7];
    let (y, dy) = exact_data(truth);
    let obs = Observations {
        y: &y,
        dy: &dy,
        n_obs: 6,
    };
    let start = [104.0, 1.4e-4, 1.8, -0.56];
    let out = fit(&vessel()[..1], &obs, &start, &[true; 4], &FIT).unwrap();
    assert!(out.iterations > 1);
    for (got, want) in out.alpha.iter().zip(truth) {
        assert!((got / want - 1.0).abs() < 1e-8, "{got} vs {want} ({out:?})");
    }
    // a slot not fitted keeps its start value; the others still fit the data's values
    let start = [104.0, 1.4e-4, 1.5, -0.56];
    let out = fit(
        &vessel()[..1],
        &obs,
        &start,
        &[true, true, false, true],
        &FIT,
    )
    .unwrap();
    assert_eq!(out.alpha[2], 1.5);
    assert!((out.alpha[0] / 80.0 - 1.0).abs() < 1e-8, "{out:?}");
    // from the values themselves (a gradient of rounding only) the fit stays there
    let out = fit(&vessel()[..1], &obs, &truth, &[true; 4], &FIT).unwrap();
    for (got, want) in out.alpha.iter().zip(truth) {
        assert!((got / want - 1.0).abs() < 1e-8, "{got} vs {want} ({out:?})");
    }
}

#[test]
fn fit_stops_at_max_iterations_unconverged() {
    let (y, dy) = exact_data([80.0, 2e-4, 1.5, -0.7]);
    let obs = Observations {
        y: &y,
        dy: &dy,
        n_obs: 6,
    };
    let s = FitSettings {
        max_iterations: 1,
        ..FIT
    };
    let out = fit(
        &vessel()[..1],
        &obs,
        &[104.0, 1.4e-4, 1.8, -0.56],
        &[true; 4],
        &s,
    )
    .unwrap();
    assert_eq!((out.iterations, out.converged), (1, false));
}
