use super::*;
use crate::model::parse;
use std::sync::atomic::AtomicUsize;

/// Constant inflow through a lumped resistance into a resistance outlet: at steady state the
/// inlet pressure is Q (R_vessel + R_outlet) (Ohm's law), whatever the patch.
const MODEL: &str = r#"{
    "vessels": [{"name": "v", "from": "in", "to": "out", "lumped": {"resistance": 2e8}}],
    "boundary_conditions": {
        "in": {"type": "flow", "flow": {"kind": "constant", "value": 1e-6}},
        "out": {"type": "resistance", "resistance": 1e9}}
}"#;

fn inlet_pressure(m: &Member) -> f64 {
    let y = crate::simulate::steady_state(&m.dae).unwrap();
    let circuit = &m.assembled.circuit;
    let idx = (0..circuit.nodes.len())
        .position(|i| circuit.names.node(i) == "in")
        .unwrap();
    y[idx]
}

#[test]
fn a_patch_replaces_the_elements_it_names() {
    let base = parse(MODEL).unwrap();
    let p0 = inlet_pressure(&Member::of_patch(&base, None).unwrap());
    // 1e-6 m³/s through 1.2e9 Pa s/m³; tolerance: one steady linear solve
    assert!((p0 - 1.2e3).abs() <= 1e-9 * 1.2e3, "{p0}");
    let patch = r#"{"vessels": {"0": {"name": "v", "from": "in", "to": "out",
                        "lumped": {"resistance": 5e8}}},
                    "boundary_conditions": {"out": {"type": "resistance", "resistance": 3e9}}}"#;
    let p1 = inlet_pressure(&Member::of_patch(&base, Some(patch)).unwrap());
    assert!((p1 - 3.5e3).abs() <= 1e-9 * 3.5e3, "{p1}");
    // the base is untouched
    assert!((inlet_pressure(&Member::of_patch(&base, None).unwrap()) - p0).abs() == 0.0);
}

#[test]
fn a_patch_cannot_change_the_topology() {
    let base = parse(MODEL).unwrap();
    let err = |p: &str| Member::of_patch(&base, Some(p)).err().unwrap().to_string();
    let v = r#"{"vessels": {"3": {"name": "v", "from": "in", "to": "out", "lumped": {"resistance": 1}}}}"#;
    assert!(err(v).contains("vessel #3"), "{}", err(v));
    let v = r#"{"vessels": {"0": {"name": "w", "from": "in", "to": "out", "lumped": {"resistance": 1}}}}"#;
    assert!(err(v).contains("vessel 'v'"), "{}", err(v));
    let b = r#"{"boundary_conditions": {"nowhere": {"type": "resistance", "resistance": 1}}}"#;
    assert!(err(b).contains("'nowhere'"), "{}", err(b));
    assert!(err(r#"{"period": 1}"#).contains("variant patch"));
    // invalid values are the assembler's usual errors
    let neg = r#"{"vessels": {"0": {"name": "v", "from": "in", "to": "out", "lumped": {"resistance": -1}}}}"#;
    assert!(err(neg).contains("vessel 'v'"), "{}", err(neg));
}

/// A feed of `0..n` (input i for job i).
fn counter(n: usize) -> impl FnMut() -> Option<(usize, usize)> {
    let mut next = 0;
    move || {
        (next < n).then(|| {
            next += 1;
            (next - 1, next - 1)
        })
    }
}

#[test]
fn every_job_is_handed_over_once_whatever_the_workers() {
    for workers in [1, 2, 3] {
        let mut seen = vec![0usize; 50];
        let mut order = Vec::new();
        let job = |i: usize, input: usize, _: &AtomicBool| (i, input * input);
        run_fed(workers, &job, &mut counter(50), &mut |item| {
            if let Some((i, (j, sq))) = item {
                assert_eq!((j, sq), (i, i * i));
                seen[i] += 1;
                order.push(i);
            }
            true
        })
        .unwrap();
        assert!(seen.iter().all(|&n| n == 1), "{workers}: {seen:?}");
        if workers == 1 {
            assert!(
                order.windows(2).all(|w| w[0] < w[1]),
                "one worker: in feed order"
            );
        }
    }
}

#[test]
fn cancelling_stops_the_feed_and_skips_the_queued_jobs() {
    let started = AtomicUsize::new(0);
    let job = |_: usize, _: usize, cancelled: &AtomicBool| {
        started.fetch_add(1, Ordering::SeqCst);
        // a running job sees the cancellation (a run's progress callback checks it)
        while !cancelled.load(Ordering::Relaxed) {
            std::thread::yield_now();
        }
        true
    };
    let mut fed = 0;
    let mut feed = counter(1000);
    let mut finished = 0;
    run_fed(
        2,
        &job,
        &mut || {
            fed += 1;
            feed()
        },
        &mut |item| {
            finished += usize::from(item.is_some());
            false // cancel at the first wake-up
        },
    )
    .unwrap();
    let started = started.load(Ordering::SeqCst);
    assert_eq!(finished, started);
    assert!(
        started <= 2,
        "{started} jobs started after the cancellation"
    );
    assert!(fed <= 2 * AHEAD_PER_WORKER, "{fed} inputs fed");
}

#[test]
fn worker_count_reads_the_argument_first() {
    assert_eq!(worker_count(Some(3)).unwrap(), 3);
    assert!(worker_count(Some(0)).is_err());
}

/// Against closed forms: the trapezoidal rule is exact for a piecewise-linear signal (its time
/// average over [0, T] is the area of the polyline over T), min/max are the extreme samples,
/// NaN propagates, and there is no time average without two distinct times.
#[test]
fn column_stats_against_closed_forms() {
    // column 0: 1 + 2t on uneven times; column 1: a tent 0 -> 4 -> 0 over [0, 2]
    let times = [0.0, 0.5, 1.0, 2.0];
    let data = [1.0, 0.0, 2.0, 2.0, 3.0, 4.0, 5.0, 0.0];
    let s = column_stats(&times, &data, 2).unwrap();
    // mean of 1 + 2t over [0, 2] = 3; tent area 4 over 2 s = 2
    assert!((s.mean[0] - 3.0).abs() < 1e-15 && (s.mean[1] - 2.0).abs() < 1e-15);
    assert_eq!(
        (s.min.clone(), s.max.clone()),
        (vec![1.0, 0.0], vec![5.0, 4.0])
    );
    let with_nan = [1.0, 0.0, f64::NAN, 2.0, 3.0, 4.0, 5.0, 0.0];
    let s = column_stats(&times, &with_nan, 2).unwrap();
    assert!(s.mean[0].is_nan() && s.min[0].is_nan() && s.max[0].is_nan());
    assert_eq!(s.max[1], 4.0);
    assert!(column_stats(&[0.0], &[1.0, 2.0], 2).is_none());
    assert!(column_stats(&[1.0, 1.0], &[1.0, 2.0, 3.0, 4.0], 2).is_none());
    assert!(column_stats(&times, &data[..6], 2).is_none());
}

/// The streamed statistics equal the closed forms above and, bit for bit, those of the whole
/// table, whatever the chunk sizes (the terms are the same and added in the same order).
#[test]
fn stats_fold_over_chunks_is_the_whole_table() {
    let times = [0.0, 0.5, 1.0, 2.0];
    let data = [1.0, 0.0, 2.0, 2.0, 3.0, 4.0, 5.0, 0.0];
    let mut fold = StatsFold::new(2);
    fold.push(&times[..1], &data[..2]);
    fold.push(&times[1..], &data[2..]);
    let s = fold.finish().unwrap();
    assert!((s.mean[0] - 3.0).abs() < 1e-15 && (s.mean[1] - 2.0).abs() < 1e-15);
    // uneven times and values of mixed magnitude, where a changed order of additions shows
    let (nt, nc) = (97, 5);
    let mut x = 0x2545_f491_4f6c_dd1d_u64;
    let mut next = || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut times = vec![0.0];
    for _ in 1..nt {
        let t = times[times.len() - 1] + 1e-3 * (0.5 + next());
        times.push(t);
    }
    let data: Vec<f64> = (0..nt * nc)
        .map(|k| (next() - 0.3) * 10f64.powi(k as i32 % 7))
        .collect();
    let whole = column_stats(&times, &data, nc).unwrap();
    for chunk in [1, 2, 3, 7, 96, 200] {
        let mut fold = StatsFold::new(nc);
        for (t, d) in times.chunks(chunk).zip(data.chunks(chunk * nc)) {
            fold.push(t, d);
        }
        let s = fold.finish().unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&s.mean), bits(&whole.mean), "chunk {chunk}");
        assert_eq!(
            (bits(&s.min), bits(&s.max)),
            (bits(&whole.min), bits(&whole.max))
        );
    }
    assert!(StatsFold::new(2).finish().is_none());
}
