//! Resident memory after each stage of building and running a canonical JSON model (a
//! profiling aid for the scale targets): `cargo run --release --example mem_stages -- model.json`.

use oxyline_core::genalpha::NewtonControl;
use oxyline_core::model::parse;
use oxyline_core::output::Selection;
use oxyline_core::{Method, RunSettings, Start, Transport};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
use std::time::Instant;

/// The system allocator, counting live heap bytes and their high-water mark: the stage table
/// gives exact heap bytes per segment (RSS also holds freed pages the allocator keeps).
struct Counting;
static LIVE: AtomicUsize = AtomicUsize::new(0);
static HIGH: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        let now = LIVE.fetch_add(l.size(), Relaxed) + l.size();
        HIGH.fetch_max(now, Relaxed);
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        LIVE.fetch_sub(l.size(), Relaxed);
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        if new > l.size() {
            let now = LIVE.fetch_add(new - l.size(), Relaxed) + new - l.size();
            HIGH.fetch_max(now, Relaxed);
        } else {
            LIVE.fetch_sub(l.size() - new, Relaxed);
        }
        unsafe { System.realloc(p, l, new) }
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

/// Live heap bytes now and their peak since the last call (which resets the peak).
fn heap() -> (f64, f64) {
    let live = LIVE.load(Relaxed);
    (live as f64, HIGH.swap(live, Relaxed) as f64)
}

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

/// Heap bytes of a vector (its capacity).
fn cap<T>(v: &[T], capacity: usize) -> usize {
    let _ = v;
    capacity * std::mem::size_of::<T>()
}

/// Heap bytes of a waveform's tables.
fn wave_heap(w: &oxyline_core::waveform::Waveform) -> usize {
    use oxyline_core::waveform::Waveform;
    match w {
        Waveform::Constant(_) => 0,
        Waveform::Table { t, v, m, .. } => {
            8 * (t.capacity() + v.capacity() + m.as_ref().map_or(0, Vec::capacity))
        }
        Waveform::Fourier { cos, sin, .. } => 8 * (cos.capacity() + sin.capacity()),
    }
}

/// Heap bytes per segment of the circuit, the segment table, the probes and the DAE, by field.
fn report(a: &oxyline_core::assemble::Assembled, dae: &oxyline_core::circuit::Dae, segs: f64) {
    let c = &a.circuit;
    let p = &a.probes;
    let rows = [
        ("circuit.nodes", cap(&c.nodes, c.nodes.capacity())),
        ("circuit.branches", cap(&c.branches, c.branches.capacity())),
        ("circuit.segments", cap(&c.segments, c.segments.capacity())),
        ("circuit.names", c.names.heap_bytes()),
        (
            "circuit.conditions",
            cap(&c.sources, c.sources.capacity())
                + cap(&c.fixed_pressures, c.fixed_pressures.capacity())
                + cap(&c.branch_sources, c.branch_sources.capacity())
                + c.fixed_pressures
                    .iter()
                    .chain(&c.sources)
                    .map(|(_, w)| wave_heap(w))
                    .sum::<usize>(),
        ),
        (
            "circuit.boundaries",
            cap(&c.boundaries, c.boundaries.capacity())
                + c.boundaries
                    .iter()
                    .map(|b| b.name.capacity())
                    .sum::<usize>()
                + cap(&c.source_boundary, c.source_boundary.capacity()),
        ),
        (
            "circuit.end_capacitors",
            cap(&c.end_capacitors, c.end_capacitors.capacity()),
        ),
        (
            "circuit.start_values",
            cap(&c.start_values, c.start_values.capacity()),
        ),
        (
            "arrangements",
            cap(&a.arrangements, a.arrangements.capacity()),
        ),
        ("segment table", a.segments.heap_bytes()),
        (
            "probes",
            cap(&p.vessel_unknowns, p.vessel_unknowns.capacity())
                + cap(&p.segment_count, p.segment_count.capacity())
                + cap(&p.segment_unknowns, p.segment_unknowns.capacity())
                + cap(&p.segment_position, p.segment_position.capacity())
                + p.vessels.iter().map(|v| v.capacity() + 24).sum::<usize>(),
        ),
        (
            "vessel names",
            c.vessel_names
                .iter()
                .map(|v| v.capacity() + 24)
                .sum::<usize>(),
        ),
        (
            "dae.e + windkessel",
            cap(&dae.e, dae.e.capacity()) + dae.windkessel.capacity(),
        ),
        (
            "dae.f (csr)",
            cap(&dae.f.ptr, dae.f.ptr.capacity())
                + cap(&dae.f.col, dae.f.col.capacity())
                + cap(&dae.f.val, dae.f.val.capacity()),
        ),
    ];
    for (name, bytes) in rows {
        println!("  {name:>20}: {:6.1} B/segment", bytes as f64 / segs);
    }
}

fn main() {
    let path = std::env::args().nth(1).expect("model.json");
    let run = std::env::args().nth(2).is_none_or(|a| a != "--no-run");
    let t0 = Instant::now();
    let mark = |stage: &str, segs: f64| {
        let (now, peak) = rss();
        let (live, high) = heap();
        println!(
            "| {stage} | {:.2} | {:.2} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} |",
            t0.elapsed().as_secs_f64(),
            cpu(),
            now / 1e6,
            now / segs,
            peak / 1e6,
            peak / segs,
            live / segs,
            high / segs
        );
    };
    let json = std::fs::read_to_string(&path).unwrap();
    println!(
        "| stage | wall s | CPU s | rss MB | B/seg | peak MB | peak B/seg | heap B/seg | stage heap peak B/seg |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|"
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
    report(&assembled, &dae, segs);
    let transport = spec
        .transport
        .as_ref()
        .map(|t| Transport::build(t, &assembled.circuit, &dae, &assembled.probes).unwrap());
    mark("transport plan", segs);
    // as `ensemble::Member::build` (the binding's network): the plan has its own copy
    let mut assembled = assembled;
    assembled.circuit.segments = Vec::new();
    mark("circuit segments released", segs);
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
        tolerances: None,
        svzerod: Default::default(),
        finer_last_cycle: None,
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
