//! CPU time and page faults of each core stage of loading a canonical JSON model (the scale targets
//! item 3, a profiling aid): `cargo run --release -p oxyline-core --example load_stages --
//! model.json [repeats]`. Stages: JSON parse, assemble (graph, segments, circuit, probes), the
//! DAE, the transport plan, and the steady state a run starts from. CPU is this thread's
//! run time (`/proc/thread-self/schedstat`, ns); system time and minor faults from
//! `/proc/self/stat` (10 ms ticks). Every repeat after the first reuses memory the allocator
//! kept, so the first row is the fresh-process figure.

use oxyline_core::Transport;
use oxyline_core::model::parse;

/// (thread CPU ns, system ticks, minor faults).
fn usage() -> (f64, f64, f64) {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").unwrap();
    let ns: f64 = s.split_whitespace().next().unwrap().parse().unwrap();
    let st = std::fs::read_to_string("/proc/self/stat").unwrap();
    let f: Vec<f64> = st[st.rfind(')').unwrap() + 2..]
        .split_whitespace()
        .map(|x| x.parse().unwrap_or(0.0))
        .collect();
    // fields after the command: state(0) ... minflt(7) ... utime(11) stime(12)
    (ns, f[12] / 100.0, f[7])
}

fn main() {
    let path = std::env::args()
        .nth(1)
        .expect("usage: load_stages model.json [repeats]");
    let repeats: usize = std::env::args()
        .nth(2)
        .map(|r| r.parse().unwrap())
        .unwrap_or(1);
    let json = std::fs::read_to_string(&path).unwrap();
    println!(
        "# B per element: vessel spec {}, segment row {}",
        std::mem::size_of::<oxyline_core::model::VesselSpec>(),
        std::mem::size_of::<oxyline_core::SegmentRow>()
    );
    let stages = ["parse", "assemble", "dae", "transport", "steady"];
    println!(
        "| run | segments | {} | total µs/seg | faults/kseg |",
        stages.join(" | ")
    );
    println!("|---:|---:|{}---:|---:|", "---:|".repeat(stages.len()));
    for run in 1..=repeats {
        let mut cells = Vec::new();
        let mut last = usage();
        let t0 = last;
        let mut mark = |cells: &mut Vec<(f64, f64, f64)>| {
            let now = usage();
            cells.push((now.0 - last.0, now.1 - last.1, now.2 - last.2));
            last = now;
        };
        let spec = parse(&json).unwrap();
        mark(&mut cells);
        let assembled = spec.assemble().unwrap();
        mark(&mut cells);
        let dae = assembled.circuit.assemble().unwrap();
        mark(&mut cells);
        let transport = spec
            .transport
            .as_ref()
            .map(|t| Transport::build(t, &assembled.circuit, &dae, &assembled.probes).unwrap());
        mark(&mut cells);
        let y = oxyline_core::simulate::steady_state(&dae).unwrap();
        mark(&mut cells);
        let n = assembled.segments.len() as f64;
        let end = usage();
        let row: Vec<String> = cells
            .iter()
            .map(|(ns, sys, _)| format!("{:.2} ({:.2})", ns / 1e3 / n, sys * 1e6 / n))
            .collect();
        println!(
            "| {run} | {n} | {} | {:.2} | {:.0} |",
            row.join(" | "),
            (end.0 - t0.0) / 1e3 / n,
            (end.2 - t0.2) / n * 1e3
        );
        drop((y, transport, dae, assembled, spec));
    }
}
