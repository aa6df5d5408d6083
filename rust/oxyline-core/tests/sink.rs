//! Streaming output (`simulate_to_sink`): the chunks handed over, concatenated, are exactly the
//! output of the same run without a sink, no chunk is longer than asked, the driver never holds
//! more than one chunk, and a stopped run still hands over what it computed.

use oxyline_core::genalpha::NewtonControl;
use oxyline_core::network::parse;
use oxyline_core::{
    Dae, Error, Method, OutputSink, RunSettings, Start, Transport, simulate_to_sink,
    simulate_with_transport,
};

/// A compliant tube with a reversing inflow and one species with wall uptake.
const TUBE: &str = r#"{"vessels": [{"name": "tube", "from": "in", "to": "out", "segments": 8,
    "geometry": {"length": 0.2, "radius_in": 8e-3, "radius_out": 8e-3,
                 "wall_thickness": 2e-3, "youngs_modulus": 5.11e6}}],
  "boundary_conditions": {
    "in": {"type": "flow", "flow": {"kind": "fourier", "period": 1.0, "mean": 2e-5, "sin": [3e-5]}},
    "out": {"type": "resistance", "resistance": 1.15e7}},
  "transport": {"species": [{"name": "o2", "inlet": {"kind": "constant", "value": 0.119},
    "initial": 0.1, "wall": {"model": "mass-transfer", "k": 5e-6, "wall_concentration": 0.084}}]}}"#;

fn build() -> (Dae, Transport, Vec<usize>) {
    let spec = parse(TUBE).unwrap();
    let assembled = spec.assemble().unwrap();
    let dae = assembled.circuit.assemble().unwrap();
    let tr = Transport::build(
        spec.transport.as_ref().unwrap(),
        &assembled.circuit,
        &dae,
        &assembled.probes,
    )
    .unwrap();
    (dae, tr, assembled.probes.all())
}

fn settings(probes: Vec<usize>, all_cycles: bool, until_periodic: Option<f64>) -> RunSettings {
    RunSettings {
        method: Method::Rk4,
        dt: Some(1e-3),
        period: 1.0,
        cycles: 3,
        until_periodic,
        max_cycles: 4,
        output_every: 1e-2,
        output_all_cycles: all_cycles,
        keep_current_cycle: true,
        start: Start::Steady,
        newton: NewtonControl::default(),
        probes,
        species_columns: None,
        tolerances: None,
        svzerod: Default::default(),
    }
}

/// Chunks as (times, data, transport) and the concatenation of all of them.
#[derive(Default)]
struct Collected {
    rows: Vec<usize>,
    times: Vec<f64>,
    data: Vec<f64>,
    transport: Vec<f64>,
}

/// Run with a sink of `rows` rows that refuses the chunk number `refuse` (if any); `stop_at`
/// interrupts the run through the progress callback once t passes it.
fn streamed(
    s: &RunSettings,
    rows: usize,
    refuse: Option<usize>,
    stop_at: f64,
) -> (oxyline_core::Outcome, Collected) {
    let (dae, mut tr, _) = build();
    let mut got = Collected::default();
    let mut write = |c: oxyline_core::Chunk<'_>| {
        if refuse == Some(got.rows.len()) {
            return false;
        }
        got.rows.push(c.times.len());
        got.times.extend_from_slice(c.times);
        got.data.extend_from_slice(c.data);
        got.transport.extend_from_slice(c.transport);
        assert_eq!(c.initial_stored.len(), 1);
        true
    };
    let mut sink = OutputSink {
        rows,
        write: &mut write,
    };
    let out = simulate_to_sink(&dae, Some(&mut tr), s, &mut sink, &mut |t, _| t < stop_at).unwrap();
    (out, got)
}

fn in_memory(s: &RunSettings) -> oxyline_core::Outcome {
    let (dae, mut tr, _) = build();
    simulate_with_transport(&dae, Some(&mut tr), s, &mut |_, _| true).unwrap()
}

#[test]
fn chunks_concatenate_to_the_in_memory_output() {
    let probes = build().2;
    for (all_cycles, until_periodic) in [(true, None), (false, None), (false, Some(1e-30))] {
        let s = settings(probes.clone(), all_cycles, until_periodic);
        let full = in_memory(&s);
        assert!(full.error.is_none());
        let n = full.times.len();
        let rows = 8; // divides neither 101 nor 301 rows
        assert!(n % rows != 0);
        let (out, got) = streamed(&s, rows, None, f64::INFINITY);
        assert!(out.error.is_none());
        assert_eq!(got.times, full.times, "{all_cycles} {until_periodic:?}");
        assert_eq!(got.data, full.data);
        let ft = full.transport.as_ref().unwrap();
        assert_eq!(got.transport, ft.data);
        assert_eq!(got.rows.len(), n.div_ceil(rows));
        assert!(got.rows.iter().all(|&r| r == rows || r == n % rows));
        // nothing left behind; the driver held at most one chunk of all-cycles output, and at
        // most one cycle of last-cycle output (the rows of a cycle are kept until it is known
        // whether it is the output, as without a sink: an interrupted run returns them)
        assert!(out.times.is_empty() && out.data.is_empty());
        assert!(out.transport.as_ref().unwrap().data.is_empty());
        let bound = if all_cycles { rows } else { 101 };
        assert!(out.max_buffered_rows <= bound, "{}", out.max_buffered_rows);
        assert_eq!(full.max_buffered_rows, n);
        assert_eq!(out.final_state, full.final_state);
    }
}

#[test]
fn an_interrupted_run_hands_over_everything_it_computed() {
    let probes = build().2;
    let s = settings(probes.clone(), true, None);
    let full = in_memory(&s);
    let (out, got) = streamed(&s, 16, None, 1.5);
    assert!(matches!(out.error, Some(Error::Interrupted { .. })));
    let n = got.times.len();
    assert!(n > 16 && n < full.times.len(), "{n}");
    assert_eq!(got.times, full.times[..n]);
    assert_eq!(got.data, full.data[..n * probes.len()]);
    let cols = full.transport.as_ref().unwrap().data.len() / full.times.len();
    assert_eq!(
        got.transport,
        full.transport.as_ref().unwrap().data[..n * cols]
    );
}

#[test]
fn a_refusing_sink_stops_the_run_and_is_not_called_again() {
    let probes = build().2;
    let s = settings(probes, true, None);
    let (out, got) = streamed(&s, 10, Some(2), f64::INFINITY);
    assert!(matches!(out.error, Some(Error::Interrupted { .. })));
    assert_eq!(got.rows, vec![10, 10]);
    assert!(out.cycles_run < 3);
}

#[test]
fn interrupted_last_cycle_output_keeps_species_rows_aligned() {
    // in memory, stopped in the first of three cycles of last-cycle output, whose species
    // outputs are not computed: the flow rows so far come with NaN species rows, one per time
    let (dae, mut tr, probes) = build();
    let s = settings(probes, false, None);
    let mut progress = |t: f64, _: f64| t < 0.5;
    let out = simulate_with_transport(&dae, Some(&mut tr), &s, &mut progress).unwrap();
    assert!(out.error.is_some());
    let n = out.times.len();
    assert!(n > 1);
    let species = out.transport.unwrap().data;
    let cols = species.len() / n;
    assert_eq!(species.len(), n * cols);
    assert!(species[cols..].iter().all(|v| v.is_nan()));
    assert!(species[..cols].iter().all(|v| v.is_finite()));
}

#[test]
fn without_keep_current_cycle_nothing_before_the_last_cycle_is_recorded() {
    // last-cycle output streamed with keep_current_cycle off: the earlier cycles are not
    // recorded at all, so the driver holds at most one chunk, and a run stopped before the
    // last cycle hands over nothing
    let probes = build().2;
    let s = RunSettings {
        keep_current_cycle: false,
        ..settings(probes, false, None)
    };
    let (out, got) = streamed(&s, 8, None, f64::INFINITY);
    assert!(out.error.is_none());
    assert!(out.max_buffered_rows <= 8, "{}", out.max_buffered_rows);
    assert_eq!(got.times, in_memory(&s).times);
    let (out, got) = streamed(&s, 8, None, 1.5);
    assert!(matches!(out.error, Some(Error::Interrupted { .. })));
    assert!(got.times.is_empty());
}
