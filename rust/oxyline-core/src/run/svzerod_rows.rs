//! svZeroDSolver's output rows of a run extended by its cycle-to-cycle rule
//! (`use_cycle_to_cycle_error` without RCR, [`super::CycleMeanStop`]): which of the run's
//! recorded steps svZeroDSolver writes, and at which times. Its output counter runs on through
//! the extra cycles, whose times restart at Δt each cycle; with last-cycle output only the
//! file's last cycle is kept, plus, for a 2-cycle file, each extra cycle's step at the index
//! where the last cycle started (svZeroDSolver compares the cycle-local step with that global
//! index).

/// (global step indices, output times in units of Δt) for `cycles` requested cycles of
/// `steps` steps, `extra` cycles run beyond them, output every `interval`-th step
/// (`interval` ≥ 1) and all cycles or the last one only.
pub fn svzerod_output_rows(
    cycles: usize,
    steps: usize,
    extra: usize,
    interval: usize,
    all_cycles: bool,
) -> (Vec<usize>, Vec<f64>) {
    let total = steps * cycles + 1;
    // the step at which the last requested cycle starts (none for a single point)
    let start_last = total.checked_sub(steps + 1);
    let (mut rows, mut times) = (Vec::new(), Vec::new());
    if all_cycles || start_last.is_none_or(|s| s == 0) {
        rows.push(0);
        times.push(0.0);
    }
    let interval = interval.max(1);
    let mut counter = 0;
    let mut visit = |i: usize, row: usize, time: usize| {
        counter += 1;
        if counter == interval || (!all_cycles && Some(i) == start_last) {
            if all_cycles || start_last.is_none_or(|s| i >= s) {
                rows.push(row);
                times.push(time as f64);
            }
            counter = 0;
        }
    };
    for i in 1..total {
        visit(i, i, i);
    }
    for c in 0..extra {
        for i in 1..=steps {
            visit(i, total - 1 + c * steps + i, i);
        }
    }
    if let (false, Some(&t0)) = (all_cycles, times.first()) {
        times.iter_mut().for_each(|t| *t -= t0);
    }
    (rows, times)
}

#[cfg(test)]
mod tests {
    use super::svzerod_output_rows;

    /// Without extra cycles the rows are svZeroDSolver's plain rule: every `interval`-th step
    /// of all cycles, or the last cycle from its start (its start always written).
    #[test]
    fn plain_rule_without_extra_cycles() {
        let (rows, t) = svzerod_output_rows(3, 4, 0, 2, true);
        assert_eq!(rows, [0, 2, 4, 6, 8, 10, 12]);
        assert_eq!(t, [0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0]);
        // the last cycle's start (step 8) resets the counter
        let (rows, t) = svzerod_output_rows(3, 4, 0, 3, false);
        assert_eq!(rows, [8, 11]);
        assert_eq!(t, [0.0, 3.0]);
    }

    /// Extra cycles go on counting; their times restart at Δt, and a 2-cycle file's last-cycle
    /// output adds each extra cycle's step at the last cycle's start index (here 4).
    #[test]
    fn extra_cycles_restart_their_times() {
        let (rows, t) = svzerod_output_rows(2, 4, 1, 1, true);
        assert_eq!(rows, (0..=12).collect::<Vec<_>>());
        assert_eq!(&t[9..], [1.0, 2.0, 3.0, 4.0]);
        let (rows, t) = svzerod_output_rows(2, 4, 2, 4, false);
        assert_eq!(rows, [4, 8, 12, 16]);
        assert_eq!(t, [0.0, 4.0, 0.0, 0.0]);
        // a single requested cycle: its start is written, the extra cycles counted on
        let (rows, t) = svzerod_output_rows(1, 4, 2, 3, false);
        assert_eq!(rows, [0, 3, 6, 9, 12]);
        assert_eq!(t, [0.0, 3.0, 2.0, 1.0, 4.0]);
    }
}
