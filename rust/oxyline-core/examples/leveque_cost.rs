//! Where the default Lévêque closure's extra cost goes: same-process CPU times of one tree
//! (canonical SI JSON of the constant-k and the Lévêque variant of the same network, see
//! `transport_memory`), one cycle, vessel-level output every 10 ms, alternated `reps` times:
//!
//! * `flow`      — flow only at the run's step (the O2/flow denominator);
//! * `setup`     — flow only, one step per cycle: steady solve, plan, factorisation, consistent
//!   start (what a pass costs before its steps);
//! * `pass1`     — flow only at the first pass's settings (no probes; an implicit pass at
//!   period/125 for dt = 1 ms, period/2000 for RK4): the first pass with its own set-up;
//! * `o2-k`      — flow + O2, constant k (no first pass);
//! * `o2-lev`    — flow + O2, Lévêque (first pass + coupled run);
//! * `steady`    — the steady solve alone (shared by both passes, inside `setup`);
//! * `lev-1row`  — the Lévêque run with one output row per cycle: `o2-lev` minus this is the
//!   cost of the output rows (mostly the species observation at 100 rows).
//!
//! The best CPU time of each is printed, and the Lévêque run's excess over constant k split
//! into the first pass and the rest.
//!
//!     cargo run --release -p oxyline-core --example leveque_cost -- k.json leveque.json [reps] [rk4]

mod common;

use common::{cpu, load};
use oxyline_core::genalpha::NewtonControl;
use oxyline_core::integrate::steady::steady_state;
use oxyline_core::{Method, RunSettings, Start, simulate_with_transport};

fn main() {
    let mut args = std::env::args().skip(1);
    let usage = "usage: leveque_cost K.json LEVEQUE.json [reps] [rk4]";
    let (k_path, lev_path) = (args.next().expect(usage), args.next().expect(usage));
    let reps: usize = args.next().map_or(3, |r| r.parse().expect("reps"));
    let rk4 = args.next().as_deref() == Some("rk4");
    let k = load(&k_path);
    let (dae, k_tr, columns) = (&k.dae, &k.transport, k.vessel_columns());
    let probes = k.assembled.probes.vessel_unknowns.clone();
    let lev_tr = load(&lev_path).transport;
    let s = RunSettings {
        method: if rk4 {
            Method::Rk4
        } else {
            Method::GeneralizedAlpha { rho_inf: 0.5 }
        },
        dt: (!rk4).then_some(1e-3),
        period: 1.0, // the bench trees (`benches/bench_scale.py`) beat once a second
        cycles: 1,
        until_periodic: None,
        max_cycles: 1,
        output_every: 1e-2,
        output_all_cycles: false,
        keep_current_cycle: true,
        start: Start::Steady,
        newton: NewtonControl::default(),
        probes,
        species_columns: Some(columns),
        tolerances: None,
        svzerod: Default::default(),
    };
    // the first pass's own settings (see run/two_pass.rs `mean_flow_pass`)
    let pass1 = RunSettings {
        method: Method::GeneralizedAlpha { rho_inf: 0.5 },
        dt: Some(if rk4 { 1.0 / 2000.0 } else { 1.0 / 125.0 }),
        probes: Vec::new(),
        ..s.clone()
    };
    let setup = RunSettings {
        method: Method::GeneralizedAlpha { rho_inf: 0.5 },
        dt: Some(1.0),
        output_every: 1.0,
        probes: Vec::new(),
        ..s.clone()
    };
    let one_row = RunSettings {
        output_every: 1.0,
        ..s.clone()
    };
    let names = [
        "flow", "setup", "pass1", "o2-k", "o2-lev", "steady", "lev-1row",
    ];
    let mut best = [f64::INFINITY; 7];
    for _ in 0..reps {
        for (i, b) in best.iter_mut().enumerate() {
            let t0 = cpu();
            match i {
                0 => simulate_with_transport(dae, None, &s, &mut |_, _| true).map(Some),
                1 => simulate_with_transport(dae, None, &setup, &mut |_, _| true).map(Some),
                2 => simulate_with_transport(dae, None, &pass1, &mut |_, _| true).map(Some),
                3 => simulate_with_transport(dae, Some(&mut k_tr.new_run()), &s, &mut |_, _| true)
                    .map(Some),
                4 => {
                    simulate_with_transport(dae, Some(&mut lev_tr.new_run()), &s, &mut |_, _| true)
                        .map(Some)
                }
                5 => steady_state(dae).map(|_| None),
                _ => {
                    let mut tr = lev_tr.new_run();
                    simulate_with_transport(dae, Some(&mut tr), &one_row, &mut |_, _| true)
                        .map(Some)
                }
            }
            .map(drop)
            .expect("run");
            *b = b.min(cpu() - t0);
        }
    }
    let f = best[0];
    println!("unknowns {}, best of {reps} (CPU s, ÷ flow):", dae.n);
    for (n, b) in names.iter().zip(best) {
        println!("  {n:<7} {b:8.3}  {:6.3}", b / f);
    }
    let excess = best[4] - best[3];
    println!(
        "  Lévêque − constant k {:.3} s = {:.3} flow: first pass (with its set-up) {:.3}, rest {:.3}",
        excess,
        excess / f,
        best[2] / f,
        (excess - best[2]) / f
    );
    println!(
        "  Lévêque run = first pass {:.3} + coupled steps and set-up {:.3} + output rows {:.3} flow",
        best[2] / f,
        (best[6] - best[2]) / f,
        (best[4] - best[6]) / f
    );
}
