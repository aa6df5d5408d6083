"""Error control (docs/physics.md §10): generalized-α with a variable step meeting `rtol`,
checked against the closed-form periodic responses of single RC, RL and RLC lines under
sinusoidal forcing; the dense output between steps against the same closed forms; the output
interval never changing the solution; fixed-step runs unchanged; bad settings refused."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import oxyline

T = 1.0
W = 2 * np.pi / T
ATOL = {"pressure": 1.0, "flow": 1e-9}  # the core's SI defaults (Pa, m^3/s)
#: a kind's default atol is at most this share of rtol times the kind's largest magnitude
#: (docs/physics.md §10, "Settings": a model in small units is held to rtol of its own size)
SCALE_CAP = 0.3

Exact = Callable[[np.ndarray], dict[str, np.ndarray]]


def _line(name: str, lumped: dict[str, float], inlet: dict[str, Any],
          r_out: float) -> dict[str, Any]:
    return {"name": name, "arrangement": "L", "period": T,
            "vessels": [{"name": "v", "from": "in", "to": "out", "lumped": lumped}],
            "boundary_conditions": {"in": inlet,
                                    "out": {"type": "resistance", "resistance": r_out}}}


def rc() -> tuple[dict[str, Any], Exact]:
    """Sinusoidal inflow into R then C || R_out (time constant 0.16 s ~ 1/ω)."""
    r, r_out, c, q0, q1 = 1e6, 1e8, 1.6e-9, 5e-6, 4e-6
    model = _line("rc", {"resistance": r, "capacitance": c},
                  {"type": "flow", "fourier": {"period": T, "mean": q0, "sin": [q1]}}, r_out)

    def exact(t: np.ndarray) -> dict[str, np.ndarray]:
        z = r_out / (1 + 1j * W * r_out * c)
        q = q0 + q1 * np.sin(W * t)
        pc = q0 * r_out + np.imag(z * q1 * np.exp(1j * W * t))
        return {"flow_in": q, "pressure_out": pc, "pressure_in": pc + r * q}
    return model, exact


def rl() -> tuple[dict[str, Any], Exact]:
    """Sinusoidal pressure driving R + L into R_out."""
    r, ind, r_out, p0, p1 = 1e7, 2e6, 1e8, 1.2e4, 4e3
    model = _line("rl", {"resistance": r, "inductance": ind},
                  {"type": "pressure", "fourier": {"period": T, "mean": p0, "sin": [p1]}}, r_out)

    def exact(t: np.ndarray) -> dict[str, np.ndarray]:
        q = p0 / (r + r_out) + np.imag(p1 * np.exp(1j * W * t) / (r + r_out + 1j * W * ind))
        return {"flow_in": q, "pressure_out": q * r_out}
    return model, exact


def rlc() -> tuple[dict[str, Any], Exact]:
    """Sinusoidal pressure driving R + L into C || R_out (eigenvalues -5.6 ± 17.7i 1/s)."""
    r, ind, r_out, c, p0, p1 = 1e7, 2e6, 1e8, 1.6e-9, 1.2e4, 4e3
    model = _line("rlc", {"resistance": r, "inductance": ind, "capacitance": c},
                  {"type": "pressure", "fourier": {"period": T, "mean": p0, "sin": [p1]}}, r_out)

    def exact(t: np.ndarray) -> dict[str, np.ndarray]:
        zl = r_out / (1 + 1j * W * r_out * c)
        drive = p1 * np.exp(1j * W * t) / (r + 1j * W * ind + zl)
        q = p0 / (r + r_out) + np.imag(drive)
        return {"flow_in": q, "pressure_out": p0 * r_out / (r + r_out) + np.imag(drive * zl)}
    return model, exact


def achieved(res: oxyline.Result, exact: Exact, rtol: float) -> float:
    """The largest error of every closed-form variable at every output time, relative to
    atol/rtol + its peak magnitude (the norm the step control works in: the default atol of
    the kind's largest peak, at most SCALE_CAP·rtol of it)."""
    v, want = res.vessel("v"), exact(res.time)
    peaks = {k: float(np.max(np.abs(e))) for k, e in want.items()}
    worst = 0.0
    for key, e in want.items():
        kind = "pressure" if key.startswith("pressure") else "flow"
        largest = max(p for k, p in peaks.items() if k.startswith(kind))
        atol = min(ATOL[kind], SCALE_CAP * rtol * largest)
        worst = max(worst, float(np.max(np.abs(getattr(v, key) - e))
                                 / (atol / rtol + peaks[key])))
    return worst


def scaled(case: Callable[[], tuple[dict[str, Any], Exact]],
           factor: float) -> tuple[dict[str, Any], Exact]:
    """The line of `case` with its forcing (a pressure or a flow) times `factor`: R, L, C
    unchanged, every pressure and flow of the exact response times `factor`."""
    model, exact = case()
    fourier = model["boundary_conditions"]["in"]["fourier"]
    fourier["mean"] *= factor
    fourier["sin"] = [a * factor for a in fourier["sin"]]
    return model, lambda t: {k: factor * e for k, e in exact(t).items()}


def relative_error(res: oxyline.Result, exact: Exact) -> float:
    """The largest error of every closed-form variable over its own peak magnitude."""
    v, want = res.vessel("v"), exact(res.time)
    return max(float(np.max(np.abs(getattr(v, k) - e)) / np.max(np.abs(e)))
               for k, e in want.items())


@pytest.mark.parametrize("case", [rc, rl, rlc], ids=["rc", "rl", "rlc"])
def test_achieved_error_is_within_the_tolerance_and_not_far_below(case: Any) -> None:
    # from the exact periodic state, 3 cycles, output every 1 ms (mostly between steps);
    # honest: achieved <= 2 rtol (the estimate may be off by 2x), and >= rtol/100 (not
    # wastefully over-resolved; rtol 1e-2 hits the step ceiling T/32, hence 1/100)
    model, exact = case()
    for rtol in (1e-2, 1e-3, 1e-4, 1e-5, 1e-6):
        res = oxyline.simulate(model, rtol=rtol, cycles=3, start="periodic", output_every=1e-3,
                               method="generalized-alpha")
        err = achieved(res, exact, rtol)
        assert rtol / 100 <= err <= 2 * rtol, (rtol, err)
        est = res.error_estimate
        assert set(est) == {"pressure", "flow"}
        # the reported estimate is what the controller held: at most rtol, and not vacuous
        assert 0 < max(est.values()) <= rtol * (1 + 1e-9)
        assert res.settings["steps"] > 0 and res.settings["dt_min"] <= res.settings["dt_max"]


@pytest.mark.filterwarnings("ignore:boundary condition 'in'")  # 16 Pa, 16 mPa: small units
@pytest.mark.parametrize("case", [rc, rl, rlc], ids=["rc", "rl", "rlc"])
def test_a_model_in_small_units_meets_rtol_at_the_default_atol(case: Any) -> None:
    # every pressure and flow times 1e-3 (12-16 Pa, 1e-7 m^3/s) and 1e-6: within the SI
    # default atol of 1 Pa and 1e-9 m^3/s, which left the 1e-3 line 1.9-190 rtol off its
    # closed form over rtol 1e-2...1e-5. The default atol follows the model's own scale, so
    # each line meets rtol of its own peaks against its closed form (allowed 2 rtol: the
    # estimate may be off by 2x), and the two small ones, whose defaults are both capped at
    # 0.3 rtol of their own scale, are the same problem in other units: the same relative
    # error (measured: equal to 3 digits up to rtol 1e-4, within 7 % at 1e-5, where their
    # step sequences part by a few steps in 2,600; allowed 25 %). The unscaled
    # line differs from them by up to 2.1x (rl at 1e-4), where the SI flow default lies
    # below the cap and holds it tighter.
    for rtol in (1e-2, 1e-3, 1e-4, 1e-5):
        errs = []
        for factor in (1.0, 1e-3, 1e-6):
            model, exact = scaled(case, factor)
            res = oxyline.simulate(model, rtol=rtol, cycles=3, start="periodic",
                                   output_every=1e-3, method="generalized-alpha")
            errs.append(relative_error(res, exact))
        assert max(errs) <= 2 * rtol, (rtol, errs)
        _, small, smaller = errs
        assert abs(smaller - small) <= 0.25 * small, (rtol, errs)


def test_a_small_vessels_flow_meets_rtol_of_its_own_amplitude() -> None:
    # a large and a small R + L line from two sinusoidal pressures into one outlet: the small
    # one carries ~1e-8 m^3/s (3e-5 of the large one's flow, ten times the flow atol of
    # 1e-9 m^3/s, which holds it only through its share of the largest amplitude) at the 10th
    # harmonic, faster than the large one's: each flow within 2 rtol of its own amplitude,
    # against the circuit's closed-form (phasor) periodic response
    lines = {"large": (1e7, 2e6, 1), "small": (4e11, 6.4e9, 10)}  # R, L, forced harmonic
    r_out, p0, p1 = 1e8, 1.2e4, 4e3
    model = {"name": "two-sources", "arrangement": "L", "period": T,
             "vessels": [{"name": v, "from": v + "_in", "to": "j",
                          "lumped": {"resistance": rv, "inductance": lv}}
                         for v, (rv, lv, _) in lines.items()]
             + [{"name": "outlet", "from": "j", "to": "out",
                 "lumped": {"resistance": 0.5 * r_out}}],
             "boundary_conditions": {
                 **{v + "_in": {"type": "pressure", "fourier": {
                     "period": T, "mean": p0, "sin": [0.0] * (k - 1) + [p1]}}
                    for v, (_, _, k) in lines.items()},
                 "out": {"type": "resistance", "resistance": 0.5 * r_out}}}

    def flow(v: str, t: np.ndarray) -> np.ndarray:
        q = np.zeros_like(t)
        for k, part in ((0, np.real), *((k, np.imag) for _, _, k in lines.values())):
            z = {u: ru + 1j * k * W * lu for u, (ru, lu, _) in lines.items()}
            src = {u: (p0 if k == 0 else p1 * (ku == k)) for u, (_, _, ku) in lines.items()}
            pj = sum(src[u] / z[u] for u in z) / (sum(1 / z[u] for u in z) + 1 / r_out)
            q += part((src[v] - pj) / z[v] * np.exp(1j * k * W * t))
        return q

    for rtol in (1e-3, 1e-4):
        res = oxyline.simulate(model, rtol=rtol, cycles=3, start="periodic",
                               output_every=1e-3, method="generalized-alpha")
        for v in lines:
            q = flow(v, res.time)
            err = np.max(np.abs(res.vessel(v).flow_in - q)) / np.max(np.abs(q))
            assert err <= 2 * rtol, (v, rtol, err)


@pytest.mark.filterwarnings("ignore:boundary condition 'bed_in'")  # a venous-like 10-30 Pa
def test_a_low_pressure_beds_pressure_meets_rtol_of_its_own_scale() -> None:
    # a large R + L line (~1.5e-4 m^3/s, pressures ~1e4 Pa) and, joined to it through a
    # 1e14 Pa·s/m^3 link, a tiny bed (~3e-9 m^3/s, 2e-5 of the large flow) fed by its own
    # low pressure (20 ± 10 Pa at the 10th harmonic) through R into a compliant node k: the
    # pressure atol of 1 Pa is 3 % of that node's ~30 Pa, which let its error grow past
    # rtol. Against the circuit's phasor closed form (nodal analysis per harmonic), from the
    # exact periodic state: the bed's pressure within 2 rtol of its own peak, and its flow,
    # the difference of two pressures each held so, within 2 rtol times the pressure's peak
    # over the difference's (~9.5)
    k_bed = 10
    r_big, l_big, r_out = 1e7, 2e6, 1e8
    r_bed, c_bed, r_link = 1e9, 5e-12, 1e14
    big_src, bed_src = (1.2e4, 4e3, 1), (20.0, 10.0, k_bed)  # mean, amplitude, harmonic

    def source(mean: float, amp: float, k: int) -> dict[str, Any]:
        return {"type": "pressure", "fourier": {"period": T, "mean": mean,
                                                "sin": [0.0] * (k - 1) + [amp]}}

    model = {"name": "low-pressure-bed", "arrangement": "L", "period": T, "vessels": [
        {"name": "big", "from": "big_in", "to": "j",
         "lumped": {"resistance": r_big, "inductance": l_big}},
        {"name": "bed", "from": "bed_in", "to": "k",
         "lumped": {"resistance": r_bed, "capacitance": c_bed}},
        {"name": "link", "from": "k", "to": "j", "lumped": {"resistance": r_link}},
        {"name": "outlet", "from": "j", "to": "out", "lumped": {"resistance": 0.5 * r_out}}],
        "boundary_conditions": {"big_in": source(*big_src), "bed_in": source(*bed_src),
                                "out": {"type": "resistance", "resistance": 0.5 * r_out}}}

    def exact(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(P_k, Q_bed): the node pressures (k, j) per harmonic from the nodal equations."""
        p_k, q_bed = np.zeros_like(t), np.zeros_like(t)
        for k, p_big, p_bed in ((0, big_src[0], bed_src[0]), (1, big_src[1], 0.0),
                                (k_bed, 0.0, bed_src[1])):
            w = k * W
            y_big, y_bed, y_link = 1 / (r_big + 1j * w * l_big), 1 / r_bed, 1 / r_link
            a = np.array([[y_bed + 1j * w * c_bed + y_link, -y_link],
                          [-y_link, y_link + y_big + 1 / r_out]])
            pk = np.linalg.solve(a, np.array([p_bed * y_bed, p_big * y_big]))[0]
            q = (p_bed - pk) * y_bed
            part = np.real if k == 0 else np.imag
            p_k += part(pk * np.exp(1j * w * t))
            q_bed += part(q * np.exp(1j * w * t))
        return p_k, q_bed

    m = oxyline.load_model(model)
    for rtol in (1e-2, 1e-3, 1e-4):
        res = oxyline.simulate(m, rtol=rtol, cycles=3, start="periodic", output_every=1e-3,
                               method="generalized-alpha")
        p_k, q_bed = exact(res.time)
        bed = res.vessel("bed")
        err_p = np.max(np.abs(bed.pressure_out - p_k)) / np.max(np.abs(p_k))
        err_q = np.max(np.abs(bed.flow_in - q_bed)) / np.max(np.abs(q_bed))
        lever = np.max(np.abs(p_k)) / (r_bed * np.max(np.abs(q_bed)))
        assert err_p <= 2 * rtol, (rtol, err_p)
        assert err_q <= 2 * rtol * lever, (rtol, err_q, lever)


def test_a_start_up_transient_does_not_loosen_the_later_cycles() -> None:
    # R + L into C (no path for a mean flow: R_out 1e12) driven by 1.2e4 + 4e3 sin(wt) Pa
    # from the zero start: the charging of C rings through the line's flow at 6.75x its
    # periodic amplitude, decaying with R/2L = 2.5 1/s (by the last of 5 cycles to 5e-6 of
    # it). Each unknown's scale is its largest value over the previous cycle and the
    # current one (docs/physics.md §10, "The scale's window"): the last cycle is held to
    # rtol of its own periodic amplitude. Against the closed form (the periodic phasor
    # response plus the homogeneous solution from the zero state): within 2 rtol (measured
    # 1.6 and 1.7 rtol; the same run from the periodic start 0.9 and 2.2). With the scale
    # over the whole run the flow was 10.4 and 10.3 rtol off. (At rtol 1e-3 this circuit's
    # flow is 2.65 rtol off from either start: its capacitor's pressure, held to rtol of
    # its 1.2e4 Pa mean, moves the small flow by more.)
    r, ind, c, r_out, p0, p1 = 1e7, 2e6, 1.6e-9, 1e12, 1.2e4, 4e3
    model = _line("rlc-charging", {"resistance": r, "inductance": ind, "capacitance": c},
                  {"type": "pressure", "fourier": {"period": T, "mean": p0, "sin": [p1]}},
                  r_out)
    # x = (Q, P_C): L Q' = P_in - R Q - P_C, C P_C' = Q - P_C / R_out
    a = np.array([[-r / ind, -1 / ind], [1 / c, -1 / (r_out * c)]])

    def exact(t: np.ndarray) -> np.ndarray:
        mean = np.linalg.solve(-a, np.array([p0 / ind, 0.0]))
        wave = np.linalg.solve(1j * W * np.eye(2) - a, np.array([p1 / ind, 0.0]))
        periodic = mean[:, None] + np.imag(wave[:, None] * np.exp(1j * W * t)[None, :])
        lam, v = np.linalg.eig(a)
        k = np.linalg.solve(v, -(mean + np.imag(wave)))  # from the zero state
        return periodic + np.real(v @ (k[:, None] * np.exp(lam[:, None] * t[None, :])))

    cycles = 5
    for rtol in (1e-4, 1e-5):
        res = oxyline.simulate(model, rtol=rtol, cycles=cycles, start="zero",
                               until_periodic=None, output_cycles="all", output_every=1e-3,
                               method="generalized-alpha")
        q, p_c = exact(res.time)
        assert np.max(np.abs(q)) > 6 * np.max(np.abs(q[res.time >= cycles - 1]))
        last = res.time >= (cycles - 1) * T
        v = res.vessel("v")
        for got, want in ((v.flow_in, q), (v.pressure_out, p_c)):
            err = np.max(np.abs(got - want)[last]) / np.max(np.abs(want[last]))
            assert err <= 2 * rtol, (rtol, err / rtol)


def test_dense_output_between_steps_matches_the_closed_form() -> None:
    # 0.1 ms output: ~10-100 rows per step at rtol 1e-4; the interpolant keeps the error
    # within the same 2 rtol as the steps' ends
    model, exact = rlc()
    rtol = 1e-4
    res = oxyline.simulate(model, rtol=rtol, cycles=3, start="periodic", output_every=1e-4,
                           method="generalized-alpha")
    assert res.settings["steps"] < len(res.time) / 5  # most rows are between steps
    assert achieved(res, exact, rtol) <= 2 * rtol


def test_output_interval_never_changes_the_solution() -> None:
    # the rows every 20 ms of a run output every 1 ms and of one output every 20 ms are the
    # same numbers: the steps do not depend on the output times (bit for bit, same
    # arithmetic; the species outputs of an O2 model included)
    # (the model file asks for the paper's RK4: method auto picks generalized-α here)
    model = oxyline.load_model("paper-bifurcated")
    fine = oxyline.simulate(model, rtol=1e-3, cycles=2, output_every=1e-3, method="auto")
    coarse = oxyline.simulate(model, rtol=1e-3, cycles=2, output_every=2e-2, method="auto")
    assert fine.settings["steps"] == coarse.settings["steps"]
    assert np.array_equal(fine.pressure_in[::20], coarse.pressure_in)
    assert np.array_equal(fine.flow_out[-1], coarse.flow_out[-1])
    assert np.array_equal(fine.po2_out[-1], coarse.po2_out[-1])
    assert fine.error_estimate["species"] > 0


@pytest.mark.parametrize(("settings", "message"), [
    ({"rtol": 0.0}, "rtol must be a finite number > 0"),
    ({"rtol": -1e-3}, "rtol must be a finite number > 0"),
    ({"rtol": float("nan")}, "rtol must be a finite number > 0"),
    ({"rtol": 1.0}, "simulation: rtol must be > 0 and < 1, got 1"),
    ({"rtol": "1e-3"}, "rtol must be a number"),
    ({"rtol": 1e-3, "atol": 1.0}, "atol must be a mapping of kind"),
    ({"rtol": 1e-3, "atol": [1.0, 1e-9]}, "atol must be a mapping of kind"),
    ({"rtol": 1e-3, "atol": {"pressure": -1.0}}, "atol.pressure must be a finite number > 0"),
    ({"rtol": 1e-3, "atol": {"presure": 1.0}}, "atol has no kind 'presure'"),
    ({"atol": {"pressure": 1.0}, "dt": 1e-3}, "atol needs error control"),
    ({"atol": {"pressure": 1.0}, "method": "rk4"}, "atol needs error control"),
    ({"rtol": 1e-3, "dt": 1e-3}, "rtol (error control) and dt = 0.001"),
    ({"rtol": 1e-3, "method": "rk4"}, "method 'rk4' needs a fixed dt"),
])
def test_bad_error_control_settings_name_the_setting(settings: dict[str, Any],
                                                     message: str) -> None:
    with pytest.raises(oxyline.ModelError, match=message.replace("(", r"\(").replace(")", r"\)")):
        oxyline.simulate("bifurcation", cycles=1, **settings)


# Values of fixed-step runs (the automatic fixed step of the build before error control, given
# here as the dt it chose: generalized-α with O2, generalized-α on adan56)
# computed with the build before error control: equal to 1e-12 relative (the fixed-step path
# is untouched; the tolerance only allows another compiler's reassociation, the runs are
# bit-identical on one machine).
FIXED = {
    ('bifurcation', (('cycles', 1), ('dt', 0.05), ('method', 'generalized-alpha'), ('output_every', 0.05))): {
        (3, 0, 'pressure_in'): 15738.793561163195,
        (3, 2, 'pressure_in'): 15592.130589943503,
        (3, 0, 'flow_out'): 9.590191379507863e-06,
        (3, 2, 'flow_out'): 3.2766443715971856e-06,
        (20, 0, 'pressure_in'): 9301.54371544021,
        (20, 2, 'pressure_in'): 9213.841837958666,
        (20, 0, 'flow_out'): 5.5157159335522685e-06,
        (20, 2, 'flow_out'): 1.9373814929815092e-06,
    },
    ('paper-bifurcated', (('cycles', 1), ('dt', 0.001), ('method', 'generalized-alpha'), ('output_every', 0.05))): {
        (3, 0, 'pressure_in'): 15770.581073597947,
        (3, 2, 'pressure_in'): 15642.238739339215,
        (3, 0, 'flow_out'): 9.572106683213857e-06,
        (3, 2, 'flow_out'): 3.287986344370022e-06,
        (3, 0, 'po2_out'): 85.26519321630956,
        (3, 2, 'po2_out'): 85.24437535685497,
        (20, 0, 'pressure_in'): 9330.633841248671,
        (20, 2, 'pressure_in'): 9241.65877406065,
        (20, 0, 'flow_out'): 5.557227229064835e-06,
        (20, 2, 'flow_out'): 1.9429474760505923e-06,
        (20, 0, 'po2_out'): 85.17149919862352,
        (20, 2, 'po2_out'): 85.00166283148673,
    },
    ('adan56', (('cycles', 1), ('dt', 0.005), ('method', 'generalized-alpha'), ('output_every', 0.05))): {
        (3, 0, 'pressure_in'): 15120.373569108631,
        (3, 76, 'pressure_in'): 10310.68564775052,
        (3, 0, 'flow_out'): 0.0004780707733801279,
        (3, 76, 'flow_out'): 7.210377725860245e-07,
        (20, 0, 'pressure_in'): 11103.429551708097,
        (20, 76, 'pressure_in'): 12869.253310436552,
        (20, 0, 'flow_out'): 1.753781355090939e-05,
        (20, 76, 'flow_out'): 1.2722717823833713e-06,
    },
}


def test_fixed_step_runs_are_unchanged() -> None:
    for (model, kwargs), values in FIXED.items():
        res = oxyline.simulate(model, **dict(kwargs))
        for (row, vessel, key), want in values.items():
            got = float(getattr(res, key)[row, vessel])
            assert got == pytest.approx(want, rel=1e-12, abs=0.0), (model, key)


def test_cli_rtol_reports_the_estimate_in_the_summary_and_the_file(
        tmp_path: Any, capsys: pytest.CaptureFixture[str]) -> None:
    xr = pytest.importorskip("xarray")
    from oxyline.cli import main

    out = tmp_path / "r.nc"
    assert main(["run", "bifurcation", "--cycles", "1", "--rtol", "1e-3", "--output-every",
                 "0.01", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "error control: rtol 0.001" in text and "estimated error pressure" in text
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        assert ds.sizes["time"] == 101
        assert 0 < ds.attrs["solver_error_estimate_pressure"] <= 1e-3
        assert 0 < ds.attrs["solver_error_estimate_flow"] <= 1e-3
        assert ds.attrs["solver_rtol"] == 1e-3 and ds.attrs["solver_steps"] > 0


def test_the_default_run_is_error_controlled_and_says_so(tmp_path: Any,
                                                         capsys: pytest.CaptureFixture[str]
                                                         ) -> None:
    # no dt, no rtol: error control at rtol 1e-3 (default atol), whatever the output
    # interval; against the RLC line's closed form within the honesty bound of the tests
    # above (2 rtol), the rows every 20 ms the same numbers at 1 ms and 20 ms output
    model, exact = rlc()
    fine = oxyline.simulate(model, cycles=3, start="periodic", output_every=1e-3)
    coarse = oxyline.simulate(model, cycles=3, start="periodic", output_every=2e-2)
    for res in (fine, coarse):
        assert res.settings["rtol"] == 1e-3
        assert res.settings["step_control"] == "error control (rtol 0.001)"
        assert achieved(res, exact, 1e-3) <= 2e-3
        assert 0 < max(res.error_estimate.values()) <= 1e-3 * (1 + 1e-9)
    assert fine.settings["steps"] == coarse.settings["steps"]
    assert np.array_equal(fine.vessel("v").flow_in[::20], coarse.vessel("v").flow_in)
    # the NetCDF attributes and the command line's summary carry the estimate
    xr = pytest.importorskip("xarray")
    from oxyline.cli import main

    out = tmp_path / "d.nc"
    assert main(["run", "bifurcation", "--cycles", "1", "--output-every", "0.01", "-o",
                 str(out)]) == 0
    assert "error control: rtol 0.001" in capsys.readouterr().out
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        assert ds.attrs["solver_step_control"] == "error control (rtol 0.001)"
        assert 0 < ds.attrs["solver_error_estimate_pressure"] <= 1e-3


def test_a_fixed_step_says_why_and_atol_alone_joins_the_default_rtol() -> None:
    res = oxyline.simulate("bifurcation", cycles=1, dt=1e-3, method="generalized-alpha")
    assert res.settings["step_control"] == "fixed step (dt)" and res.error_estimate == {}
    res = oxyline.simulate("bifurcation", cycles=1, method="rk4", output_every=0.01)
    assert res.settings["step_control"].startswith("fixed step (method rk4")
    assert res.settings["method"] == "rk4" and "steps" not in res.settings
    res = oxyline.simulate("bifurcation", cycles=1, atol={"pressure": 0.5})
    assert res.settings["rtol"] == 1e-3 and res.settings["steps"] > 0


def test_a_checkpointed_default_run_takes_the_automatic_fixed_step(tmp_path: Any) -> None:
    # a checkpoint does not carry the controller's state: the default run falls back to the
    # automatic fixed step (generalized-α at the output interval here), says so, and its
    # resumed run is the same run
    ck = tmp_path / "run.ckpt"
    res = oxyline.simulate("bifurcation", cycles=2, output_every=0.01, checkpoint=ck,
                           checkpoint_every="1 cycle")
    assert res.settings["step_control"].startswith("fixed step (checkpoints")
    assert res.settings["rtol"] is None and res.settings["dt"] == pytest.approx(0.01)
    resumed = oxyline.resume(ck)
    assert resumed.settings["step_control"] == res.settings["step_control"]
    assert np.array_equal(resumed.data, res.data)
    # a tolerance asked for is not dropped: refused, naming the fixed step checkpoints need
    with pytest.raises(oxyline.ModelError, match="checkpoints need a fixed step"):
        oxyline.simulate("bifurcation", cycles=2, rtol=1e-3, checkpoint=tmp_path / "b.ckpt")


def test_the_default_run_reaches_a_tight_periodicity() -> None:
    # error control chooses each cycle's steps from the state it meets: without replaying the
    # steps of near-periodic cycles the cycle-to-cycle change stalled at ~rtol (6e-4 after 400
    # cycles here); replayed, it falls as a fixed step's. Truth: the circuit's periodic state
    # from its harmonics (start="periodic", RK4's fixed step: within 1e-6, see
    # test_periodic_start.py), within 2 rtol of the peak pressure
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parent))
    from test_periodic_start import rcr_bifurcation

    m, kw = rcr_bifurcation(), {"segments": False, "progress": False}
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", oxyline.PeriodicityWarning)
        res = oxyline.simulate(m, start="steady", until_periodic=1e-10, max_cycles=400, **kw)
    assert res.settings["periodic_reached"] and res.settings["cycles_run"] < 100
    truth = oxyline.simulate(m, start="periodic", cycles=1, method="rk4", **kw)
    p, want = res.pressure_in, truth.pressure_in
    assert np.max(np.abs(p - want)) <= 2e-3 * np.max(np.abs(want))


def _steady_tube() -> dict[str, Any]:
    """A rigid tube with a constant inflow carrying a decaying solute: its cumulative inflow
    of solute grows exactly linearly in time (Q·c_in·t)."""
    return {"period": 1.0,
            "vessels": [{"name": "tube", "from": "in", "to": "out", "segments": 5,
                         "length": 0.1, "radius": 3e-3}],
            "boundary_conditions": {"in": {"type": "flow", "value": 2e-6},
                                    "out": {"type": "resistance", "resistance": 1e8}},
            "species": [{"name": "drug", "decay": 0.5, "inlet": {"concentration": 1.0},
                         "initial": 1.0}],
            "simulation": {"cycles": 2, "output": {"every": 0.01}}}


@pytest.mark.parametrize("method", ["auto", "dopri5", "generalized-alpha"])
def test_species_rows_under_error_control(method: str) -> None:
    # one species row per output row, in order, from either controlled integrator (the
    # explicit pair once recorded each row behind the ones before it): the cumulative inflow
    # grows by Q·c_in·Δt between rows (1e-9: the sums' rounding), the balance closes
    res = oxyline.simulate(_steady_tube(), method=method, output_cycles="all",
                           output_every=0.25)
    assert res.settings["step_control"].startswith("error control")
    mb = res.species["drug"].mass_balance
    np.testing.assert_allclose(np.diff(mb["inflow"]), 2e-6 * 1.0 * np.diff(res.time),
                               rtol=1e-9)
    assert np.abs(mb["residual"]).max() <= 1e-12 * mb["inflow"][-1]
