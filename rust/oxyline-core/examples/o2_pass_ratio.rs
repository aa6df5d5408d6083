//! Same-process, interleaved timing of the main pass's steps: flow only (the first model's
//! network) and flow + species for each model given (canonical SI JSON of the same tree with
//! different walls, e.g. constant k and the default closure), alternated `reps` times; prints
//! the best CPU ns per segment-step of each and its ratio to flow. One cycle of
//! generalized-α at dt = 1 ms (or RK4 stopped at `stop` s), vessel-level output every 10 ms.
//!
//!     cargo run --release -p oxyline-core --example o2_pass_ratio -- REPS ga|rk4 STOP a.json b.json ...
//!
//! Only the main pass is timed (a closure's flow-only first pass is left out, as in
//! `benches/bench_scale.py`): the CPU time between the main pass's first and last progress
//! checks (every 256 steps), read in ns from /proc/self/schedstat.
//!
//! Counters of the main pass alone (load-independent instruction counts): with
//! `O2_PASS_ONLY=flow|species` one run of that kind per model, and with `O2_PASS_CTL=FIFO`
//! `enable`/`disable` written to `perf stat -D -1 --control fifo:FIFO` around the main pass's
//! steps (from its first progress check to the cycle's end; the 125-step first pass has no
//! check before it ends).

mod common;

use common::{Model, load};
use oxyline_core::genalpha::NewtonControl;
use oxyline_core::{Method, RunSettings, Start, Transport, simulate_with_transport};

/// CPU ns this process has run (/proc/self/schedstat, first field).
fn cpu_ns() -> f64 {
    let s = std::fs::read_to_string("/proc/self/schedstat").expect("/proc/self/schedstat");
    s.split_whitespace()
        .next()
        .expect("field")
        .parse()
        .expect("ns")
}

fn main() {
    let mut args = std::env::args().skip(1);
    let usage = "usage: o2_pass_ratio REPS ga|rk4 STOP MODEL.json...";
    let reps: usize = args.next().expect(usage).parse().expect("reps");
    let method = match args.next().as_deref() {
        Some("rk4") => Method::Rk4,
        _ => Method::GeneralizedAlpha { rho_inf: 0.5 },
    };
    let stop: f64 = args.next().expect(usage).parse().expect("stop time");
    let paths: Vec<String> = args.collect();
    let models: Vec<Model> = paths.iter().map(|p| load(p)).collect();
    let (a0, dae0) = (&models[0].assembled, &models[0].dae);
    let nseg = a0.circuit.segments.len() as f64;
    let settings = |m: &Model| {
        let columns = m.vessel_columns();
        RunSettings {
            method,
            dt: matches!(method, Method::GeneralizedAlpha { .. }).then_some(1e-3),
            period: 1.0,
            cycles: 1,
            until_periodic: None,
            max_cycles: 1,
            output_every: 1e-2,
            output_all_cycles: false,
            keep_current_cycle: true,
            start: Start::Steady,
            newton: NewtonControl::default(),
            probes: m.assembled.probes.vessel_unknowns.clone(),
            species_columns: Some(columns),
            tolerances: None,
            svzerod: Default::default(),
        }
    };
    let only = std::env::var("O2_PASS_ONLY").ok();
    let ctl = std::env::var("O2_PASS_CTL").ok();
    let perf = |cmd: &str| {
        if let Some(path) = &ctl {
            std::fs::write(path, format!("{cmd}\n")).expect("perf control fifo");
        }
    };
    // ns per step of the main pass: marks (t, cpu) restart when t goes back (a second pass)
    let timed = |dae: &oxyline_core::Dae, run: Option<&mut Transport>, s: &RunSettings| {
        let mut marks: Vec<(f64, f64)> = Vec::new();
        let (mut counting, mut stopped) = (false, false);
        let mut progress = |t: f64, _: f64| {
            // (an interrupted run reports its cycle count once more: not a new pass)
            if stopped {
                return false;
            }
            if marks.last().is_some_and(|m| t < m.0) {
                marks.clear();
            }
            if !counting && t < 1.0 - 1e-9 {
                perf("enable");
                counting = true;
            } else if counting && (t >= 1.0 - 1e-9 || t >= stop) {
                perf("disable");
                counting = false;
            }
            // (the check at the cycle's end comes after fewer than 256 steps: not a mark)
            if t < 1.0 - 1e-9 {
                marks.push((t, cpu_ns()));
            }
            stopped = t >= stop && marks.len() >= 2;
            !stopped
        };
        match simulate_with_transport(dae, run, s, &mut progress) {
            Ok(_) | Err(oxyline_core::Error::Interrupted { .. }) => {}
            Err(e) => panic!("run failed: {e}"),
        }
        let (first, last) = (marks[0], marks[marks.len() - 1]);
        // progress checks every 256 steps
        (last.1 - first.1) / (256.0 * (marks.len() - 1) as f64)
    };
    let mut best = vec![f64::INFINITY; models.len() + 1];
    for _ in 0..reps {
        let s = settings(&models[0]);
        if only.as_deref() != Some("species") {
            best[0] = best[0].min(timed(dae0, None, &s));
        }
        if only.as_deref() == Some("flow") {
            continue;
        }
        for (k, m) in models.iter().enumerate() {
            let s = settings(m);
            let mut run = m.transport.new_run();
            best[k + 1] = best[k + 1].min(timed(&m.dae, Some(&mut run), &s));
        }
    }
    println!("segments {nseg}: flow {:.1} ns/seg-step", best[0] / nseg);
    for (k, p) in paths.iter().enumerate() {
        println!(
            "  {p}: {:.1} ns/seg-step, ratio {:.3}",
            best[k + 1] / nseg,
            best[k + 1] / best[0]
        );
    }
}
