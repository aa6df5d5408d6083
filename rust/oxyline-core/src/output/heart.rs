//! The heart outputs of a run: each chamber's blood volume and each valve's status (1 open,
//! 0 closed), handed over as ordinary output columns beside the selected ones
//! (`Result.chamber_volume`, `Result.valve_status`; docs/physics.md §1.8, §1.10).
//!
//! A run records their unknowns after its selected columns (a chamber's volume; a valve's
//! pressure behind, pressure in front and flow); [`HeartColumns::split`] takes them out of the
//! recorded rows again and reads each valve's status off them, row after row, carrying each
//! valve's last status from one chunk of a streamed run to the next.

use super::Probes;

/// The chambers and valves of a run's heart outputs, and each valve's status after the
/// rows split so far.
#[derive(Debug, Clone, Default)]
pub struct HeartColumns {
    /// Chamber names (`Probes::chamber_volumes`' order).
    pub chambers: Vec<String>,
    /// Valve names (`Probes::valves`' order).
    pub valves: Vec<String>,
    /// The recorded unknowns: each chamber's volume, then each valve's [pressure behind,
    /// pressure in front, flow].
    unknowns: Vec<usize>,
    /// Each valve's rule: the heart block's on/off valve, else a `valve` element.
    on_off: Vec<bool>,
    /// Each valve's status after the last row split (closed before the first).
    open: Vec<bool>,
}

/// The heart outputs of some rows, one column per chamber and per valve.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct HeartRows {
    /// Each chamber's volume at every row (m³).
    pub volume: Vec<Vec<f64>>,
    /// Each valve's status at every row (1 open, 0 closed).
    pub status: Vec<Vec<i8>>,
}

impl HeartColumns {
    /// The chambers and valves of an assembled network (none: an empty set).
    pub fn of(p: &Probes) -> Self {
        let mut unknowns: Vec<usize> = p.chamber_volumes.iter().map(|&(_, u)| u).collect();
        unknowns.extend(p.valves.iter().flat_map(|v| v.unknowns));
        HeartColumns {
            chambers: p.chamber_volumes.iter().map(|(n, _)| n.clone()).collect(),
            valves: p.valves.iter().map(|v| v.name.clone()).collect(),
            unknowns,
            on_off: p.valves.iter().map(|v| v.on_off).collect(),
            open: vec![false; p.valves.len()],
        }
    }

    pub fn is_empty(&self) -> bool {
        self.unknowns.is_empty()
    }

    /// The unknowns to record after the selected ones (see [`HeartColumns`]).
    pub fn unknowns(&self) -> &[usize] {
        &self.unknowns
    }

    /// Recorded columns the heart outputs take.
    pub fn width(&self) -> usize {
        self.unknowns.len()
    }

    /// Take the heart columns (columns `at..at + width()` of rows `n_cols` wide, row-major)
    /// out of `data`, which keeps the other columns in their order, and return their chamber
    /// volumes and valve statuses. Each valve goes on from its status after the last call.
    pub fn split(&mut self, data: &mut Vec<f64>, n_cols: usize, at: usize) -> HeartRows {
        let w = self.width();
        let nt = data.len().checked_div(n_cols).unwrap_or(0);
        let column =
            |c: usize| -> Vec<f64> { (0..nt).map(|r| data[r * n_cols + at + c]).collect() };
        let nc = self.chambers.len();
        let volume = (0..nc).map(column).collect();
        let mut status = Vec::with_capacity(self.valves.len());
        for k in 0..self.valves.len() {
            let [behind, front, flow] = [0, 1, 2].map(|j| column(nc + 3 * k + j));
            let (s, last) = valve_status(self.on_off[k], &behind, &front, &flow, self.open[k]);
            self.open[k] = last;
            status.push(s);
        }
        if w > 0 {
            drop_columns(data, n_cols, at, w);
        }
        HeartRows { volume, status }
    }
}

/// Remove columns `at..at + w` of every row (`n_cols` wide) of row-major `data`, in place.
fn drop_columns(data: &mut Vec<f64>, n_cols: usize, at: usize, w: usize) {
    let nt = data.len() / n_cols;
    let kept = n_cols - w;
    for r in 0..nt {
        let (src, dst) = (r * n_cols, r * kept);
        // (dst <= src: the rows move left, each part into room already read)
        data.copy_within(src..src + at, dst);
        data.copy_within(src + at + w..src + n_cols, dst + at);
    }
    data.truncate(nt * kept);
}

/// A valve's status at each recorded row (1 open, 0 closed) from its pressure behind, its
/// pressure in front and its flow there (docs/physics.md §1.8, §1.10). A `valve` element
/// (`on_off` false) is open while the pressure behind exceeds the pressure in front. The heart
/// block's valve (`on_off`) also stays open while its flow is still forward after the pressure
/// difference reversed (the inertial end of ejection), until the flow reverses; once closed,
/// only the pressure difference reopens it: with generalized-α a closed valve keeps the small
/// flow of the last Newton correction (~1e-3 of the peak, of either sign; svZeroDSolver's
/// reset), which must not read as open (with RK4 a closed valve's flow is exactly zero).
/// `open`: the on/off valve's status before the first row (a chunk of a streamed run goes on
/// from the last chunk's). Returns the statuses and the status after the last row.
pub fn valve_status(
    on_off: bool,
    behind: &[f64],
    front: &[f64],
    flow: &[f64],
    mut open: bool,
) -> (Vec<i8>, bool) {
    let rows = behind.iter().zip(front).zip(flow);
    let status = rows
        .map(|((&up, &down), &q)| {
            let pushed = up > down;
            // a sequence, not an elementwise rule: the on/off valve's hysteresis
            open = pushed || (on_off && open && q > 0.0);
            i8::from(open)
        })
        .collect();
    (status, open)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::ValveProbe;

    #[test]
    fn a_heart_valve_stays_open_while_its_flow_is_forward_and_reopens_only_when_pushed() {
        // rows: pushed open; pressure reversed with forward flow (inertial end of ejection);
        // flow reversed (closes); a small forward flow while closed (a Newton residue); pushed
        let behind = [2.0, 1.0, 1.0, 1.0, 3.0];
        let front = [1.0, 2.0, 2.0, 2.0, 1.0];
        let flow = [5.0, 1.0, -0.1, 1e-3, 4.0];
        let (heart, last) = valve_status(true, &behind, &front, &flow, false);
        assert_eq!(heart, vec![1, 1, 0, 0, 1]);
        assert!(last);
        // a `valve` element reads the pressures alone
        let (element, _) = valve_status(false, &behind, &front, &flow, false);
        assert_eq!(element, vec![1, 0, 0, 0, 1]);
        // a chunk goes on from the last one's status: open and flow forward stays open
        let (cont, last) = valve_status(true, &[1.0], &[2.0], &[0.5], true);
        assert_eq!((cont, last), (vec![1], true));
        let (fresh, _) = valve_status(true, &[1.0], &[2.0], &[0.5], false);
        assert_eq!(fresh, vec![0]);
    }

    /// One chamber (unknown 7) and one heart valve (behind 4, front 5, flow 6).
    fn heart() -> HeartColumns {
        HeartColumns::of(&Probes {
            chamber_volumes: vec![("lv".into(), 7)],
            valves: vec![ValveProbe {
                name: "aortic".into(),
                unknowns: [4, 5, 6],
                on_off: true,
                law: None,
            }],
            ..Probes::default()
        })
    }

    /// Rows of two selected columns, the four heart columns, then one more (a derived
    /// column): the split keeps the selected and derived columns in order, and the heart
    /// columns read as written by hand.
    #[test]
    fn the_heart_columns_leave_the_rows_as_volumes_and_statuses() {
        let mut h = heart();
        assert_eq!(h.unknowns(), &[7, 4, 5, 6]);
        // (a, b, V, behind, front, flow, d) per row: pushed open; reversed, flow forward
        let mut data = vec![
            1.0, 2.0, 1e-4, 2.0, 1.0, 5.0, 9.0, //
            3.0, 4.0, 2e-4, 1.0, 2.0, 1.0, 8.0,
        ];
        let rows = h.split(&mut data, 7, 2);
        assert_eq!(data, vec![1.0, 2.0, 9.0, 3.0, 4.0, 8.0]);
        assert_eq!(rows.volume, vec![vec![1e-4, 2e-4]]);
        assert_eq!(rows.status, vec![vec![1, 1]]);
    }

    /// A streamed run's chunks give the statuses of the whole run: the second chunk goes on
    /// from the first one's open valve (reversed pressure, forward flow: still open).
    #[test]
    fn a_valve_status_carries_from_chunk_to_chunk() {
        let (mut whole, mut chunked) = (heart(), heart());
        let rows = [
            [1e-4, 2.0, 1.0, 5.0],
            [1e-4, 1.0, 2.0, 1.0],
            [1e-4, 1.0, 2.0, -1.0],
        ];
        let mut all: Vec<f64> = rows.concat();
        let want = whole.split(&mut all, 4, 0).status;
        assert_eq!(want, vec![vec![1, 1, 0]]);
        let mut got = Vec::new();
        for r in rows {
            let mut one = r.to_vec();
            got.extend(chunked.split(&mut one, 4, 0).status[0].clone());
            assert!(one.is_empty());
        }
        assert_eq!(got, want[0]);
    }
}
