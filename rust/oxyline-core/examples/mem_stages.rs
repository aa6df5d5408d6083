//! Resident memory after each stage of building and running a canonical JSON model (a
//! profiling aid for issue 9, item 6): `cargo run --release --example mem_stages -- model.json`.

use oxyline_core::genalpha::NewtonControl;
use oxyline_core::output::Selection;
use oxyline_core::spec::parse;
use oxyline_core::{Method, RunSettings, Start, Transport};
use std::time::Instant;

fn rss() -> (f64, f64) {
    let s = std::fs::read_to_string("/proc/self/status").unwrap();
    let get = |k: &str| {
        s.lines()
            .find(|l| l.starts_with(k))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(0.0)
            * 1024.0
    };
    (get("VmRSS:"), get("VmHWM:"))
}

/// CPU seconds of this process (user + system, from /proc/self/stat; 10 ms ticks).
fn cpu() -> f64 {
    let s = std::fs::read_to_string("/proc/self/stat").unwrap();
    let rest = &s[s.rfind(')').unwrap() + 2..];
    let f: Vec<f64> = rest
        .split_whitespace()
        .skip(11)
        .take(2)
        .map(|x| x.parse().unwrap())
        .collect();
    (f[0] + f[1]) / 100.0
}

fn main() {
    let path = std::env::args().nth(1).expect("model.json");
    let run = std::env::args().nth(2).is_none_or(|a| a != "--no-run");
    let t0 = Instant::now();
    let mark = |stage: &str, segs: f64| {
        let (now, peak) = rss();
        println!(
            "| {stage} | {:.2} | {:.2} | {:.0} | {:.0} | {:.0} | {:.0} |",
            t0.elapsed().as_secs_f64(),
            cpu(),
            now / 1e6,
            now / segs,
            peak / 1e6,
            peak / segs
        );
    };
    let json = std::fs::read_to_string(&path).unwrap();
    println!(
        "| stage | wall s | CPU s | rss MB | B/seg | peak MB | peak B/seg |\n|---|---:|---:|---:|---:|---:|---:|"
    );
    let spec = parse(&json).unwrap();
    let segs = spec
        .vessels
        .iter()
        .map(|v| v.segments.unwrap_or(1))
        .sum::<usize>() as f64;
    mark("json text + parse", segs);
    drop(json);
    mark("json text dropped", segs);
    let assembled = spec.assemble().unwrap();
    mark("assemble", segs);
    let dae = assembled.circuit.assemble().unwrap();
    mark("dae", segs);
    let transport = spec
        .transport
        .as_ref()
        .map(|t| Transport::build(t, &assembled.circuit, &dae, &assembled.probes).unwrap());
    mark("transport plan", segs);
    drop(spec);
    mark("spec dropped", segs);
    if !run {
        return;
    }
    let sel =
        Selection::resolve(&assembled.probes, None, None, false, transport.is_some()).unwrap();
    let counts = transport
        .as_ref()
        .map(|t| t.out_segment_counts())
        .unwrap_or_default();
    let settings = RunSettings {
        method: Method::GeneralizedAlpha { rho_inf: 0.5 },
        dt: Some(1e-3),
        period: 1.0,
        cycles: 1,
        until_periodic: None,
        max_cycles: 100,
        output_every: 0.01,
        output_all_cycles: false,
        keep_current_cycle: true,
        start: Start::Steady,
        newton: NewtonControl::default(),
        probes: sel.flow_columns(&assembled.probes),
        species_columns: transport.as_ref().map(|_| sel.species_columns(&counts)),
    };
    let mut species = transport.as_ref().map(Transport::new_run);
    mark("settings + transport run copy", segs);
    let out =
        oxyline_core::simulate_with_transport(&dae, species.as_mut(), &settings, &mut |_, _| true)
            .unwrap();
    let out_bytes = 8 * (out.data.len() + out.transport.as_ref().map_or(0, |t| t.data.len()));
    mark("simulate (outcome kept)", segs);
    println!("output arrays: {:.0} MB", out_bytes as f64 / 1e6);
}
