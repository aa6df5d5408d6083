use super::*;

fn transport(json: &str) -> TransportSpec {
    serde_json::from_str(json).unwrap()
}

/// Rows of one vessel 'v' (two segments): end-face and segment concentrations, a balance
/// whose residual is `leak` per row.
struct Run {
    time: Vec<f64>,
    ends: Vec<f64>,
    segments: Vec<f64>,
    balance: Vec<f64>,
}

fn run(values: &[f64], leak: f64) -> Run {
    let n = values.len();
    let time = (0..n).map(|i| 0.1 * i as f64).collect();
    let ends = values.iter().flat_map(|&v| [v]).collect();
    let segments = values.iter().flat_map(|&v| [v, 0.5 * (v + 0.48)]).collect();
    // stored, inflow, outflow, wall uptake, decay: inflow 1 per row, outflow 1 − leak
    let balance = (0..n)
        .flat_map(|i| {
            let i = i as f64;
            [0.0, i, i * (1.0 - leak), 0.0, 0.0]
        })
        .collect();
    Run {
        time,
        ends,
        segments,
        balance,
    }
}

fn feed(m: &mut Monitor, r: &Run, rows: std::ops::Range<usize>, vessels: &[String]) {
    let ends = RowMajor {
        data: &r.ends[rows.clone()],
        columns: 1,
    };
    let segments = RowMajor {
        data: &r.segments[2 * rows.start..2 * rows.end],
        columns: 2,
    };
    let balance = RowMajor {
        data: &r.balance[5 * rows.start..5 * rows.end],
        columns: 5,
    };
    m.update(&Chunk {
        time: &r.time[rows],
        vessels,
        segment_count: &[2],
        species: vec![SpeciesRows {
            name: "oxygen",
            ends: vec![&ends],
            segments: Some(&segments),
            tl_resistance: None,
            balance: &balance,
            initial_stored: 0.0,
            po2_per_concentration: Some(100.0),
        }],
        flows: None,
        oxygen: Some("oxygen"),
    });
}

const LINE: &str = r#"{"species": [{"name": "oxygen", "inlet": {"kind": "constant", "value": 0.85},
    "wall": {"model": "graetz", "wall_concentration": 0.48}}]}"#;

#[test]
fn a_line_between_inlet_and_wall_values_is_silent() {
    // c(x) = c_w + (c_in − c_w) e^{−x/λ} stays in [c_w, c_in]: nothing to report
    let values: Vec<f64> = (0..20)
        .map(|i| 0.48 + 0.37 * (-(i as f64) / 5.0).exp())
        .collect();
    let mut m = Monitor::new(Some(&transport(LINE))).unwrap();
    feed(&mut m, &run(&values, 0.0), 0..20, &["v".into()]);
    assert_eq!(m.bounds("oxygen"), Some((0.48, 0.85)));
    assert!(m.messages().is_empty(), "{:?}", m.messages());
}

#[test]
fn a_value_above_the_inlet_is_reported_with_its_vessel_time_and_po2() {
    let mut values = vec![0.6; 10];
    values[3] = 0.974; // 97.4 mmHg above an 85 mmHg inlet
    let mut m = Monitor::new(Some(&transport(LINE))).unwrap();
    feed(&mut m, &run(&values, 0.0), 0..10, &["coronary".into()]);
    assert_eq!(
        m.messages(),
        [
            "species 'oxygen': vessel 'coronary' at t = 0.3 s has 97.4 mmHg, outside the physical \
          range [48, 85] mmHg of its inlet, initial and wall values (maximum principle, \
          tolerance 1e-06 of the range)"
        ]
    );
}

#[test]
fn fed_in_chunks_the_monitor_finds_what_it_finds_fed_whole() {
    let values: Vec<f64> = (0..30)
        .map(|i| 0.7 + 0.2 * (i as f64 * 0.7).sin())
        .collect();
    let r = run(&values, 1e-3);
    let vessels = ["v".to_string()];
    let mut whole = Monitor::new(Some(&transport(LINE))).unwrap();
    feed(&mut whole, &r, 0..30, &vessels);
    let mut chunked = Monitor::new(Some(&transport(LINE))).unwrap();
    for start in (0..30).step_by(7) {
        feed(&mut chunked, &r, start..(start + 7).min(30), &vessels);
    }
    let found = whole.messages();
    assert_eq!(found.len(), 2, "{found:?}"); // above 0.85, and the leak
    assert!(found[1].contains("the mass balance is off by 0.001 of the throughput"));
    assert_eq!(chunked.messages(), found);
}

#[test]
fn tl_quasisteady_reports_the_first_reversal_then_storage() {
    let tl = r#"{"formulation": "tl-quasisteady", "species": []}"#;
    let vessels = ["a".to_string(), "b".to_string()];
    let time = [0.0, 0.5, 1.0];
    // vessel a: forward flow that stops at t = 1 (mean > 0: a zero row is a low row);
    // vessel b: forward, storing 2 % of its flow
    let qi = [1e-6, 2e-6, 2e-6, 2e-6, 0.0, 2e-6];
    let qo = [1e-6, 1.96e-6, 2e-6, 1.96e-6, 0.0, 1.96e-6];
    let chunk = |flows| Chunk {
        time: &time,
        vessels: &vessels,
        segment_count: &[0, 0],
        species: vec![],
        flows,
        oxygen: None,
    };
    let (qi, qo) = (
        RowMajor {
            data: &qi,
            columns: 2,
        },
        RowMajor {
            data: &qo,
            columns: 2,
        },
    );
    let mut m = Monitor::new(Some(&transport(tl))).unwrap();
    m.update(&chunk(Some((&qi, &qo))));
    let found = m.messages();
    assert_eq!(found.len(), 1);
    assert!(
        found[0].contains("criterion 1 (forward flow): vessel 'a' has flow 0 → 0 m^3/s at t = 1 s"),
        "{found:?}"
    );
    // without the reversal: the storage |Q_in − Q_out|/|Q| = 0.02 of vessel b
    let qi2 = [1e-6, 2e-6, 2e-6, 2e-6, 1e-6, 2e-6];
    let qo2 = [1e-6, 1.96e-6, 2e-6, 1.96e-6, 1e-6, 1.96e-6];
    let (qi2, qo2) = (
        RowMajor {
            data: &qi2,
            columns: 2,
        },
        RowMajor {
            data: &qo2,
            columns: 2,
        },
    );
    let mut m = Monitor::new(Some(&transport(tl))).unwrap();
    m.update(&chunk(Some((&qi2, &qo2))));
    assert!(m.messages()[0].contains("criterion 2 (no storage): vessel 'b' stores |Q_in − Q_out|/|Q| = 0.02 of its flow at t = 0 s (> 0.001;"), "{:?}", m.messages());
}
