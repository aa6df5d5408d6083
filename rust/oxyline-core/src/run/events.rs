//! Valve events of the error-controlled runs (docs/physics.md §10.5): after a step the error
//! control accepts, every valve's switching function is evaluated on the step's continuous
//! extension; where one changed sign the first root is found on the interpolant (Illinois),
//! the step is taken again to end on it, and the valve's status switches there, so that no
//! step straddles an opening or a closing.
//!
//! * **Switching functions.** A valve of the pressure rule (a `valve` element: open while the
//!   pressure behind exceeds the pressure in front) switches where ΔP = P_behind − P_front
//!   changes sign. An on/off valve (the heart block's) open while ΔP > 0 or Q > 0 closes where
//!   max(ΔP, R Q) reaches 0 (the flow's reversal after the pressure's), and once closed only
//!   ΔP reopens it (its held flow is not read; a generalized-α iterate leaves a closed
//!   valve's flow at the size of a Newton correction). A forward flow within the valve's
//!   flow tolerance says the closing is due; the root is the flow's reversal itself, and a
//!   flow still falling toward it at the step's end waits for the next step.
//! * **Root.** The function g(θ) of the interpolated state on θ ∈ [0, 1], g(0) > 0 ≥ g(1): the
//!   Illinois variant of regula falsi (superlinear, the bracket always kept) until the bracket
//!   is narrower than rtol·h (the time error of the event then sits below the step's own error
//!   in the state, g'·rtol·h against rtol·|y|).
//! * **Switch.** At the event an on/off valve that closes has its flow and its rate set to
//!   zero (its law's held state); the integrators restart there: the explicit pair with a new
//!   first stage, generalized-α with its error history cleared (its extrapolation would
//!   straddle the kink).

use crate::circuit::Dae;
use crate::element::Switch;
use crate::integrate::adaptive::Tolerances;

/// The most bisection-free iterations of the root finder (Illinois converges in ~10 for a
/// smooth g; the bracket test stops it first).
const MAX_ITERATIONS: usize = 60;

/// One valve's status change.
#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    /// Run time (s).
    pub time: f64,
    /// The valve's name (as its status output: the valve vessel, or `<heart>:<valve>`).
    pub valve: String,
    /// True for an opening, false for a closing.
    pub opened: bool,
}

/// A located event within the step just taken: θ of the root, and which switch.
#[derive(Debug, Clone, Copy)]
pub(super) struct Located {
    pub theta: f64,
    pub switch: usize,
}

/// Re-locations of one event at most (each on a step shorter than the one before).
const MAX_CUTS: u8 = 4;

/// The share of the step that straddled an event a step is held to when its cut fell short
/// of the event (the interpolant's root was late): the next step straddles it by a tenth,
/// where an interpolant across the kink errs a hundredth as much (second order in the step).
const APPROACH: f64 = 0.1;

/// A step taken again to end on an event: its length, the step the controller had proposed
/// before, the length of the step that straddled the event, and how many cuts so far.
#[derive(Debug, Clone, Copy)]
pub(super) struct Cut {
    pub h: f64,
    pub proposed: f64,
    pub straddle: f64,
    pub tries: u8,
}

/// What follows an accepted step (see [`decide`]).
pub(super) enum Next {
    /// Take the step again, shorter, to end on the event.
    Redo(Cut),
    /// Switch the valve at the step's end; the controller goes on from the step it proposed.
    Switch(usize, f64),
    /// A cut fell short of its event: the next step is at most this long.
    Approach(f64),
    /// No event.
    Go,
}

/// The decision after a step of `h` accepted by the error control: an event `found` within
/// the step is cut to unless it lies within `tol`·h of its end (or a cut would be below
/// `h_min`, or the event was cut to `MAX_CUTS` times); a cut step is itself searched again,
/// so an interpolant's root across the kink is refined on shorter steps.
pub(super) fn decide(
    found: Option<Located>,
    (h, h_min, tol): (f64, f64, f64),
    proposed: f64,
    cut: Option<Cut>,
) -> Next {
    let proposed = cut.map_or(proposed, |c| c.proposed);
    let tries = cut.map_or(0, |c| c.tries);
    match found {
        Some(loc) if loc.theta * h > h_min && loc.theta < 1.0 - tol && tries < MAX_CUTS => {
            Next::Redo(Cut {
                h: loc.theta * h,
                proposed,
                straddle: h,
                tries: tries + 1,
            })
        }
        Some(loc) => Next::Switch(loc.switch, proposed),
        None => match cut {
            Some(c) => Next::Approach(APPROACH * c.straddle),
            None => Next::Go,
        },
    }
}

/// The switches of a circuit and their statuses.
pub(super) struct Events {
    switches: Vec<Switch>,
    names: Vec<String>,
    open: Vec<bool>,
    /// Switched at the end of the step before: its event ended that step, so a state that
    /// still reads the old status at the new step's start is the root's tolerance, not an
    /// event (without this the status would chatter back at the same time).
    fresh: Vec<bool>,
    /// A flow at most atol + rtol·(the valve's largest flow so far) is no forward flow of an
    /// on/off valve (the error control's own flow tolerance): generalized-α leaves a valve it
    /// closed itself at a Newton correction's flow of either sign, which must not hold it
    /// open.
    flow_tol: (f64, f64),
    /// The run's tolerances: the flow atol above and the pressure atol below are their kinds'
    /// at the valves' largest flow and pressure so far (`Tolerances::kind_atol`: at most 0.3
    /// rtol of them, so that a model in small units has a band at its own scale), renewed as
    /// those grow.
    tol: Option<Tolerances>,
    peak: Vec<f64>,
    /// The pressure's absolute tolerance: with rtol·(the larger of the valve's two largest
    /// pressures so far) the band of ΔP an open on/off valve must leave downwards to close
    /// (the hysteresis of the module text).
    pressure_atol: f64,
    pressure_peak: Vec<f64>,
    /// The switch's function has left the band (above) since its last event: until then a
    /// switch back needs its function below minus the band (hysteresis: at an event ΔP = 0
    /// (and an opening on/off valve's Q = 0) within the root's tolerance, where the sign of ΔP
    /// is not resolved by the solution).
    armed: Vec<bool>,
    pub log: Vec<Event>,
}

/// The name inside an element's `kind 'name'`.
fn quoted(element: &str) -> &str {
    match (element.find('\''), element.rfind('\'')) {
        (Some(a), Some(b)) if b > a => &element[a + 1..b],
        _ => element,
    }
}

const HEART_VALVES: [&str; 4] = ["tricuspid", "pulmonary", "mitral", "aortic"];

impl Events {
    /// The circuit's switches (None without any), their statuses read at the start `y`.
    pub fn new(dae: &Dae, y: &[f64], tol: Tolerances) -> Option<Self> {
        let (mut switches, mut names) = (Vec::new(), Vec::new());
        for el in &dae.elements {
            let own = el.switches();
            let many = own.len() > 1;
            for (k, sw) in own.into_iter().enumerate() {
                let name = quoted(el.name());
                names.push(match (many, HEART_VALVES.get(k)) {
                    (true, Some(part)) => format!("{name}:{part}"),
                    (true, None) => format!("{name}:{k}"),
                    _ => name.to_owned(),
                });
                switches.push(sw);
            }
        }
        if switches.is_empty() {
            return None;
        }
        let open = switches
            .iter()
            .map(|sw| {
                let [b, f, q] = sw.unknowns;
                y[b] > y[f] || (sw.on_off && y[q] > 0.0)
            })
            .collect();
        let mut events = Events {
            fresh: vec![false; switches.len()],
            flow_tol: (tol.atol.flow, tol.rtol),
            tol: Some(tol),
            peak: switches.iter().map(|sw| y[sw.unknowns[2]].abs()).collect(),
            pressure_atol: tol.atol.pressure,
            pressure_peak: switches.iter().map(|sw| pressure_scale(sw, y)).collect(),
            armed: vec![true; switches.len()],
            switches,
            names,
            open,
            log: Vec::new(),
        };
        events.renew_atol();
        Some(events)
    }

    /// The flow and pressure atol of the valves' largest flow and pressure so far.
    fn renew_atol(&mut self) {
        if let Some(tol) = self.tol {
            let largest = |v: &[f64]| v.iter().fold(0.0f64, |m, &p| m.max(p));
            self.flow_tol.0 = tol.kind_atol(1, largest(&self.peak));
            self.pressure_atol = tol.kind_atol(0, largest(&self.pressure_peak));
        }
    }

    /// Switch `k`'s function at the state `v` (an unknown's value by index), positive while
    /// it keeps its status.
    fn keep(&self, k: usize, v: &impl Fn(usize) -> f64) -> f64 {
        self.keep_with(k, v, self.closing_flow(k))
    }

    /// [`Self::keep`] with an open on/off valve closing at the flow `q_close`.
    fn keep_with(&self, k: usize, v: &impl Fn(usize) -> f64, q_close: f64) -> f64 {
        let band = if self.armed[k] { 0.0 } else { self.band(k) };
        self.rule(k, v, q_close) + band
    }

    /// The flow below which an open on/off valve is due to close: its flow tolerance
    /// atol + rtol·(the valve's largest flow so far), so that a Newton correction's flow
    /// does not hold it open. (Where it closes is the flow's reversal: [`Self::locate`].)
    fn closing_flow(&self, k: usize) -> f64 {
        self.flow_tol.0 + self.flow_tol.1 * self.peak[k]
    }

    /// An open on/off valve (its closing is its flow's reversal, not its tolerance).
    fn closes_at_reversal(&self, k: usize) -> bool {
        self.open[k] && self.switches[k].on_off
    }

    /// The band of ΔP within which a sign is not resolved: the error control's pressure
    /// tolerance at the larger of the valve's two largest pressures so far.
    fn band(&self, k: usize) -> f64 {
        self.pressure_atol + self.flow_tol.1 * self.pressure_peak[k]
    }

    /// Switch `k`'s rule at the state `v`, without the band.
    fn rule(&self, k: usize, v: &impl Fn(usize) -> f64, q_close: f64) -> f64 {
        let sw = &self.switches[k];
        let [b, f, q] = sw.unknowns;
        let dp = v(b) - v(f);
        match (self.open[k], sw.on_off) {
            (true, true) => dp.max(sw.resistance * (v(q) - q_close)),
            (true, false) => dp,
            // a closed valve reopens where ΔP turns positive (ΔP = 0 keeps the piecewise
            // law's R_max)
            (false, _) => -dp,
        }
    }

    /// The first switch within the step whose state at θ ∈ [0, 1) is `at(θ)` and whose end
    /// state is `end`, to within `tol_theta`. None when every valve keeps its status at the
    /// step's end; θ = 0 for a switch already due at its start.
    pub fn locate<E, F, V>(&self, end: &E, at: F, tol_theta: f64) -> Option<Located>
    where
        E: Fn(usize) -> f64,
        F: Fn(f64) -> V,
        V: Fn(usize) -> f64,
    {
        let due = self.due_at(end);
        if due.is_empty() {
            return None;
        }
        let start = at(0.0);
        let mut first: Option<Located> = None;
        for k in due {
            let g0 = self.keep(k, &start);
            let theta = if g0 > 0.0 {
                // an open on/off valve closes where its flow reverses (the law's own rule:
                // its flow tolerance only says the closing is due; the flow through it
                // until the reversal is the ejection's end)
                let q_close = if self.closes_at_reversal(k) {
                    0.0
                } else {
                    self.closing_flow(k)
                };
                let g1 = self.keep_with(k, end, q_close);
                if g1 > 0.0 {
                    // still forward at the step's end, within its tolerance
                    if self.reversal_after_end(k, end, &at, tol_theta) {
                        continue;
                    }
                    1.0
                } else {
                    let g0 = self.keep_with(k, &start, q_close);
                    let g = |th: f64| {
                        if th >= 1.0 {
                            g1
                        } else {
                            self.keep_with(k, &at(th), q_close)
                        }
                    };
                    illinois(g, (0.0, g0), (1.0, g1), tol_theta)
                }
            } else if self.fresh[k] {
                // switched at the start and back by its end: a new event there
                1.0
            } else {
                0.0
            };
            if first.is_none_or(|f| theta < f.theta) {
                first = Some(Located { theta, switch: k });
            }
        }
        first
    }

    /// An open on/off valve due to close whose flow at the step's end is still forward
    /// (within its tolerance): true when the flow, falling at its rate there, reverses
    /// later than `tol_theta` of the step after its end — a flow that ends ejection, whose
    /// reversal the next step meets (closing it here, at a flow of its tolerance, closed the
    /// heart block's valves ~1 ms early at rtol 1e-3, the cardiac output then 4.6 rtol off).
    /// False for a flow that does not fall (not the open law's: a Newton correction's flow
    /// through a valve the step closed) or reverses within the root's tolerance: the valve
    /// closes at the step's end.
    fn reversal_after_end<F, V>(
        &self,
        k: usize,
        end: &impl Fn(usize) -> f64,
        at: &F,
        tol_theta: f64,
    ) -> bool
    where
        F: Fn(f64) -> V,
        V: Fn(usize) -> f64,
    {
        // the interpolant's slope over the step's last share (per unit θ)
        const SHARE: f64 = 1e-3;
        let q = self.switches[k].unknowns[2];
        let q_end = end(q);
        let slope = (q_end - at(1.0 - SHARE)(q)) / SHARE;
        slope < 0.0 && q_end > -slope * tol_theta
    }

    /// Switch `k`'s status at `time`, logged; a closing on/off valve's flow and rate are
    /// set to zero in (y, ẏ). True when the state changed.
    pub fn switch(&mut self, k: usize, time: f64, y: &mut [f64], yd: &mut [f64]) -> bool {
        self.open[k] = !self.open[k];
        self.fresh[k] = true;
        self.armed[k] = false;
        self.log.push(Event {
            time,
            valve: self.names[k].clone(),
            opened: self.open[k],
        });
        let sw = &self.switches[k];
        if sw.on_off && !self.open[k] {
            let q = sw.unknowns[2];
            y[q] = 0.0;
            yd[q] = 0.0;
            return true;
        }
        false
    }

    /// The step just accepted ends in (y, ẏ): every on/off valve closed through it whose
    /// pressure difference there does not open it has its flow and rate set to zero, its
    /// closed law's held state (generalized-α leaves a closed valve's flow at its last Newton
    /// correction and its rate at ΔP/L, which the dense output between steps would read as
    /// a flow of either sign through the closed valve).
    pub fn hold_closed(&self, y: &mut [f64], yd: &mut [f64]) {
        for (sw, &open) in self.switches.iter().zip(&self.open) {
            let [b, f, q] = sw.unknowns;
            if sw.on_off && !open && y[b] <= y[f] {
                y[q] = 0.0;
                yd[q] = 0.0;
            }
        }
    }

    /// A step without events was accepted, ending in `y`: no switch is fresh any more; the
    /// valves' largest flows so far.
    pub fn settle(&mut self, y: &[f64]) {
        self.fresh.fill(false);
        for (k, sw) in self.switches.iter().enumerate() {
            self.peak[k] = self.peak[k].max(y[sw.unknowns[2]].abs());
            self.pressure_peak[k] = self.pressure_peak[k].max(pressure_scale(sw, y));
        }
        self.renew_atol();
        for k in 0..self.switches.len() {
            let q_close = self.closing_flow(k);
            // an open on/off valve's flow that left its tolerance upwards arms it too: its
            // closing is the flow's reversal, resolved as the flow state is (a valve with a
            // small R·Q — the mitral's — had its ΔP and R·Q inside the band for a whole
            // cycle and stayed open to the events, its closings left to the Newton
            // iteration within a step: the heart block's cardiac output 12 % off at rtol
            // 1e-2 after 20 cycles)
            let forward =
                self.closes_at_reversal(k) && y[self.switches[k].unknowns[2]] > 2.0 * q_close;
            self.armed[k] |= forward || self.rule(k, &|i| y[i], q_close) > self.band(k);
        }
    }

    /// The switches whose function at the state `v` says they changed.
    pub fn due_at(&self, v: &impl Fn(usize) -> f64) -> Vec<usize> {
        (0..self.switches.len())
            .filter(|&k| self.keep(k, v) <= 0.0)
            .collect()
    }
}

/// The larger magnitude of a switch's two pressures at `y`.
fn pressure_scale(sw: &Switch, y: &[f64]) -> f64 {
    y[sw.unknowns[0]].abs().max(y[sw.unknowns[1]].abs())
}

/// The root of g on [a, b] with g(a) > 0 ≥ g(b) by the Illinois method, to a bracket of
/// `tol`: the right end of the final bracket (where g ≤ 0: the event has happened).
fn illinois(g: impl Fn(f64) -> f64, a: (f64, f64), b: (f64, f64), tol: f64) -> f64 {
    let ((mut xa, mut ga), (mut xb, mut gb)) = (a, b);
    // the side kept twice in a row has its value halved (Illinois)
    let mut side = 0i8;
    for _ in 0..MAX_ITERATIONS {
        if xb - xa <= tol {
            break;
        }
        // a state the continuous extension could not give (its algebraic unknowns not
        // solved there) reads as switched with a NaN function value: the secant through it
        // is no point, and the bracket is halved instead
        let secant = xb - gb * (xb - xa) / (gb - ga);
        let x = if secant.is_finite() {
            secant.clamp(xa, xb)
        } else {
            0.5 * (xa + xb)
        };
        // a secant point on a bracket end (round-off) is moved in by the tolerance
        let x = x.clamp(xa + 0.5 * tol, xb - 0.5 * tol);
        let gx = g(x);
        if gx > 0.0 {
            (xa, ga) = (x, gx);
            if side == 1 {
                gb *= 0.5;
            }
            side = 1;
        } else {
            (xb, gb) = (x, gx);
            if side == -1 {
                ga *= 0.5;
            }
            side = -1;
        }
    }
    xb
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The events of `switches` (named a, b, …), every valve open and armed, no tolerances.
    fn open_events(switches: Vec<Switch>) -> Events {
        let n = switches.len();
        Events {
            switches,
            names: (b'a'..)
                .take(n)
                .map(|c| char::from(c).to_string())
                .collect(),
            open: vec![true; n],
            fresh: vec![false; n],
            flow_tol: (0.0, 0.0),
            tol: None,
            peak: vec![0.0; n],
            pressure_atol: 0.0,
            pressure_peak: vec![0.0; n],
            armed: vec![true; n],
            log: Vec::new(),
        }
    }

    #[test]
    fn illinois_brackets_the_root_to_the_tolerance() {
        // g = cos(3θ) − 0.2: root at acos(0.2)/3 = 0.45667...
        let root = 0.2f64.acos() / 3.0;
        let g = |x: f64| (3.0 * x).cos() - 0.2;
        for tol in [1e-3, 1e-6, 1e-10] {
            let x = illinois(g, (0.0, g(0.0)), (1.0, g(1.0)), tol);
            assert!(x >= root && x - root <= tol, "{tol}: {x} vs {root}");
        }
    }

    #[test]
    fn illinois_bisects_where_the_function_has_no_value() {
        // g = 0.5 − θ, but no state (NaN, read as switched) beyond θ = 0.7: the root is
        // still bracketed to the tolerance, never a NaN
        let g = |x: f64| if x > 0.7 { f64::NAN } else { 0.5 - x };
        for tol in [1e-3, 1e-8] {
            let x = illinois(g, (0.0, g(0.0)), (1.0, g(1.0)), tol);
            assert!(x >= 0.5 && x - 0.5 <= tol, "{tol}: {x}");
        }
    }

    #[test]
    fn switching_functions_follow_the_valve_rules() {
        let pressure = Switch {
            unknowns: [0, 1, 2],
            on_off: false,
            resistance: 1.0,
        };
        let on_off = Switch {
            on_off: true,
            ..pressure
        };
        let mut ev = open_events(vec![pressure, on_off]);
        // ΔP < 0 with forward flow: the pressure rule closes, the on/off rule stays open
        let y = [1.0, 2.0, 3.0];
        let v = |i: usize| y[i];
        assert!(ev.keep(0, &v) < 0.0 && ev.keep(1, &v) > 0.0);
        // closing the on/off valve clamps its flow and rate
        let (mut y, mut yd) = ([1.0, 2.0, 3.0], [0.0, 0.0, 5.0]);
        assert!(ev.switch(1, 0.5, &mut y, &mut yd));
        assert_eq!((y[2], yd[2]), (0.0, 0.0));
        // closed: a small positive flow does not reopen it, a positive ΔP does
        let y = [1.0, 2.0, 1e-9];
        assert!(ev.keep(1, &|i| y[i]) > 0.0);
        let y = [2.5, 2.0, 0.0];
        assert!(ev.keep(1, &|i| y[i]) < 0.0);
        assert_eq!(ev.log[0].valve, "b");
        assert!(!ev.log[0].opened);
    }

    #[test]
    fn a_switch_back_within_the_pressure_band_is_no_event() {
        // a pressure-rule valve with a 2 Pa band (atol 1 Pa + rtol 0.1 × peak 10 Pa)
        let sw = Switch {
            unknowns: [0, 1, 2],
            on_off: false,
            resistance: 1.0,
        };
        let mut ev = Events {
            switches: vec![sw],
            names: vec!["a".into()],
            open: vec![false],
            fresh: vec![false],
            flow_tol: (0.0, 0.1),
            tol: None,
            peak: vec![0.0],
            pressure_atol: 1.0,
            pressure_peak: vec![10.0],
            armed: vec![true],
            log: Vec::new(),
        };
        let (mut y, mut yd) = ([10.0, 10.0, 0.0], [0.0; 3]);
        ev.switch(0, 0.0, &mut y, &mut yd); // opened at ΔP = 0
        // ΔP = −1 Pa after the opening: within the band, not a closing
        let y = [9.0, 10.0, 0.0];
        assert!(ev.due_at(&|i| y[i]).is_empty());
        // below the band: a closing
        let y = [7.5, 10.0, 0.0];
        assert_eq!(ev.due_at(&|i| y[i]), vec![0]);
        // once ΔP has left the band upwards, any ΔP ≤ 0 closes it again
        ev.settle(&[13.0, 10.0, 0.0]);
        let y = [9.9, 10.0, 0.0];
        assert_eq!(ev.due_at(&|i| y[i]), vec![0]);
    }

    #[test]
    fn the_first_root_of_several_is_located() {
        let sw = |b, f| Switch {
            unknowns: [b, f, 0],
            on_off: false,
            resistance: 1.0,
        };
        let ev = open_events(vec![sw(1, 2), sw(3, 4)]);
        // ΔP_a = 1 − 2θ (root 0.5), ΔP_b = 1 − 4θ (root 0.25)
        let at = |th: f64| move |i: usize| [0.0, 1.0 - 2.0 * th, 0.0, 1.0 - 4.0 * th, 0.0][i];
        let found = ev.locate(&at(1.0), at, 1e-9).expect("an event");
        assert_eq!(found.switch, 1);
        assert!((found.theta - 0.25).abs() < 1e-9);
    }

    #[test]
    fn an_on_off_valve_closes_where_its_flow_reverses() {
        // ΔP = −1 throughout; flow Q(θ) = 0.5 − θ: reverses at θ = 0.5, while the flow
        // tolerance 0.2 (rtol 0.1 × peak 2) is reached at θ = 0.3
        let sw = Switch {
            unknowns: [0, 1, 2],
            on_off: true,
            resistance: 1.0,
        };
        let mut ev = open_events(vec![sw]);
        ev.flow_tol = (0.0, 0.1);
        ev.peak = vec![2.0];
        let at = |th: f64| move |i: usize| [0.0, 1.0, 0.5 - th][i];
        let found = ev.locate(&at(1.0), at, 1e-9).expect("a closing");
        assert!((found.theta - 0.5).abs() < 1e-6, "{}", found.theta);
        // a step ending at θ = 0.4 (Q = 0.1, within the tolerance, still falling): no event
        // yet, the reversal is the next step's
        let short = |th: f64| move |i: usize| [0.0, 1.0, 0.5 - 0.4 * th][i];
        assert!(ev.locate(&short(1.0), short, 1e-9).is_none());
        // a flow that ends within its tolerance rising (not the open law's: a Newton
        // correction's flow through a valve the step closed): the valve closes at the end
        let rising = |th: f64| move |i: usize| [0.0, 1.0, 0.3 - 0.5 * th + 0.3 * th * th][i];
        let found = ev.locate(&rising(1.0), rising, 1e-9).expect("a closing");
        assert_eq!(found.theta, 1.0);
    }
}
