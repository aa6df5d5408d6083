"""Cost of exact sensitivities and of calibration with them (docs/calibration.md, "Cost").

1. Gradient cost: on adan56 (31 RCR outlets), the wall time of the sensitivities with 1, 5, 20
   and 100 parameters (outlet R and C, vessel lengths and stiffnesses), relative to the same
   call with none (the forward run to the periodic state, same step and tolerance), and per
   parameter: (t_p / t_0 − 1) / p. Best of 3 (forward) and 2 (tangents) in the same process.
2. Stenoses (nonlinear: the tangents refactorise once per step along the cycle): adan56 with
   a lumped stenosed segment (R, S) inserted before 1, 3 and 6 RCR outlets, the sensitivities
   to their stenosis coefficients relative to the same call with none, per parameter.
3. Adjoint: the same outputs' gradients by ``mode="adjoint"`` (one backward sweep per output,
   whatever the parameter count) for 1, 10, 100 parameters (and all the model has), relative
   to the forward run alone, against the forward tangents' time.
4. Heart chambers and valves: a left heart (tanh valves, an elastance-inductor chamber)
   into a Windkessel, its nine chamber/valve parameters by forward tangents and by the adjoint
   (three outputs), relative to the forward run alone (best of 3 in the same process).
5. Calibration: the bifurcation's two outlet resistances and the parent's stiffness fitted to
   synthetic targets from known values, by ``least_squares`` (trf) with the core's Jacobian and
   with scipy's forward differences ("2-point"): wall time, evaluations, final cost.

    python benches/bench_calibrate.py
    python benches/bench_calibrate.py --counts 1 5 --steps 200 --tol 1e-10
"""

from __future__ import annotations

import argparse
import time

import oxyline
from oxyline.calibrate import _base_value, native_model


def _parameters(model: oxyline.Model, count: int) -> list[str]:
    """``count`` differentiable parameters of ``model``: outlet R/C first, then vessel lengths
    and stiffnesses."""
    paths = []
    for node, bc in model.source["boundary_conditions"].items():
        if bc.get("type") == "rcr":
            paths += [f"boundary_conditions.{node}.{k}"
                      for k in ("distal_resistance", "capacitance", "proximal_resistance")]
    for v in model.source["vessels"]:
        if "length" in v:
            paths.append(f"vessels.{v['name']}.length")
        if "youngs_modulus" in v:
            paths.append(f"vessels.{v['name']}.youngs_modulus")
    if len(paths) < count:
        raise SystemExit(f"{model.name} has only {len(paths)} parameters")
    return paths[:count]


def _timed(fn, repeat: int = 1) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def gradient_cost(name: str, counts: list[int], steps: int, tol: float) -> None:
    model = oxyline.load_model(name)
    outputs = [f"{model.vessel_names[0]}.pressure_in.mean"]
    kw = {"steps_per_cycle": steps, "tol": tol}
    t0, s0 = _timed(lambda: oxyline.sensitivities(model, [], outputs, **kw), 3)
    print(f"\n{name}: forward run to the periodic state (tol {tol:g}) {t0 * 1e3:.0f} ms "
          f"({s0.cycles} cycles of {steps} steps)")
    print(f"{'parameters':>10} {'tangent cycles':>15} {'time (ms)':>10} {'x forward':>10} "
          f"{'x forward per param':>20}")
    for n in counts:
        params = _parameters(model, n)
        t, s = _timed(lambda p=params: oxyline.sensitivities(model, p, outputs, **kw), 2)
        print(f"{n:>10} {s.tangent_cycles:>15} {t * 1e3:>10.0f} {t / t0:>10.2f} "
              f"{(t / t0 - 1) / n:>20.3f}")


def _with_stenoses(model: oxyline.Model, count: int) -> tuple[dict, list[str]]:
    """``model``'s native dict with a lumped stenosed segment inserted before each of its
    first ``count`` RCR outlets (R 1e7 Pa s/m³, S 1e12 Pa s²/m⁶: at a terminal's mean flow of
    ~5e-6 m³/s a drop of ~75 Pa, a few per cent of the outlet's), and their coefficients'
    paths."""
    import copy

    data = copy.deepcopy(model.source)
    bcs = data["boundary_conditions"]
    outlets = [n for n, bc in bcs.items() if bc.get("type") == "rcr"][:count]
    paths = []
    for node in outlets:
        name = f"stenosis_{node}"
        for v in data["vessels"]:
            if str(v["to"]) == node:
                v["to"] = f"{node}_in"
        data["vessels"].append({"name": name, "from": f"{node}_in", "to": node,
                                "lumped": {"resistance": 1e7, "stenosis_coefficient": 1e12}})
        paths.append(f"vessels.{name}.lumped.stenosis_coefficient")
    return data, paths


def stenosis_cost(name: str, counts: list[int], steps: int, tol: float) -> None:
    base = oxyline.load_model(name)
    outputs = [f"{base.vessel_names[0]}.pressure_in.mean"]
    kw = {"steps_per_cycle": steps, "tol": tol}
    print(f"\n{name} with stenoses (Newton steps; tol {tol:g}):")
    print(f"{'stenoses':>9} {'forward (ms)':>13} {'cycles':>7} {'parameters':>11} "
          f"{'tangent cycles':>15} {'time (ms)':>10} {'x forward per param':>20}")
    for n in counts:
        data, paths = _with_stenoses(base, n)
        model = oxyline.load_model(data)
        t0, s0 = _timed(lambda m=model: oxyline.sensitivities(m, [], outputs, **kw), 2)
        t, s = _timed(lambda m=model, p=paths: oxyline.sensitivities(m, p, outputs, **kw), 2)
        print(f"{n:>9} {t0 * 1e3:>13.0f} {s0.cycles:>7} {len(paths):>11} "
              f"{s.tangent_cycles:>15} {t * 1e3:>10.0f} {(t / t0 - 1) / n:>20.3f}")


def adjoint_cost(name: str, counts: list[int], steps: int, tol: float) -> None:
    model = oxyline.load_model(name)
    outputs = [f"{model.vessel_names[0]}.pressure_in.mean"]
    kw = {"steps_per_cycle": steps, "tol": tol}
    t0, s0 = _timed(lambda: oxyline.sensitivities(model, [], outputs, **kw), 3)
    print(f"\n{name}: adjoint of 1 output (forward run alone {t0 * 1e3:.0f} ms, "
          f"{s0.cycles} cycles)")
    print(f"{'parameters':>10} {'adjoint (ms)':>13} {'x forward':>10} {'backward cycles':>16} "
          f"{'tangents (ms)':>14} {'x forward':>10}")
    for n in counts:
        params = _parameters(model, n)
        ta, sa = _timed(lambda p=params: oxyline.sensitivities(model, p, outputs, mode="adjoint",
                                                              **kw), 2)
        tt, _ = _timed(lambda p=params: oxyline.sensitivities(model, p, outputs, **kw), 1)
        print(f"{n:>10} {ta * 1e3:>13.0f} {ta / t0:>10.2f} {sa.tangent_cycles:>16} "
              f"{tt * 1e3:>14.0f} {tt / t0:>10.2f}")


#: the left heart of tests/test_sensitivity_heart.py (SI)
_VALVE = {"law": "tanh", "min_resistance": 3e6, "max_resistance": 1e10, "steepness": 5e-3}
HEART = {
    "name": "left-heart", "units": "SI", "period": 0.8,
    "vessels": [
        {"name": "mitral", "from": "ven", "to": "mv_out", "valve": dict(_VALVE)},
        {"name": "lv", "from": "mv_out", "to": "lv_out", "chamber": {
            "law": "elastance-inductor", "max_elastance": 3.0e8, "min_elastance": 1.3e7,
            "rest_volume_diastole": 2e-5, "rest_volume_systole": 1e-5, "period": 0.8,
            "inductance": 1e5, "initial_volume": 1.2e-4,
            "activation": {"kind": "half-cosine", "t_active": 0.1, "t_twitch": 0.35}}},
        {"name": "aortic", "from": "lv_out", "to": "ao", "valve": dict(_VALVE)},
        {"name": "aorta", "from": "ao", "to": "out",
         "lumped": {"resistance": 5e6, "inductance": 1e5, "capacitance": 3e-9}},
    ],
    "boundary_conditions": {
        "ven": {"type": "pressure", "value": 1200.0},
        "out": {"type": "rcr", "proximal_resistance": 1e7, "capacitance": 1.2e-8,
                "distal_resistance": 1.3e8},
    },
}
HEART_PARAMETERS = [
    "vessels.lv.chamber.max_elastance", "vessels.lv.chamber.min_elastance",
    "vessels.lv.chamber.rest_volume_diastole", "vessels.lv.chamber.rest_volume_systole",
    "vessels.lv.chamber.activation.t_active", "vessels.lv.chamber.activation.t_twitch",
    "vessels.aortic.valve.min_resistance", "vessels.aortic.valve.max_resistance",
    "vessels.mitral.valve.min_resistance"]


def heart_cost(steps: int, tol: float) -> None:
    outputs = ["lv.pressure_in.max", "aortic.flow_in.mean", "aorta.pressure_out.pulse"]
    kw = {"steps_per_cycle": steps, "tol": tol}
    model = oxyline.load_model(HEART)
    t0, s0 = _timed(lambda: oxyline.sensitivities(model, [], outputs, **kw), 3)
    print(f"\nleft heart, {steps} steps a cycle: forward run alone {t0 * 1e3:.1f} ms "
          f"({s0.cycles} cycles)")
    print(f"{'mode':>8} {'parameters':>10} {'time (ms)':>10} {'x forward':>10} "
          f"{'x forward per parameter':>24}")
    for mode in ("forward", "adjoint"):
        for n in (1, len(HEART_PARAMETERS)):
            p = HEART_PARAMETERS[:n]
            t, _ = _timed(lambda p=p, m=mode: oxyline.sensitivities(model, p, outputs, mode=m,
                                                                    **kw), 3)
            print(f"{mode:>8} {n:>10} {t * 1e3:>10.1f} {t / t0:>10.2f} {t / t0 / n:>24.3f}")


def calibration_speedup() -> None:
    import scipy.optimize  # noqa: F401 — its import (~1 s) is not the fit's time

    params = ["boundary_conditions.ica_out.resistance", "boundary_conditions.eca_out.resistance",
              "vessels.parent.youngs_modulus"]
    source = oxyline.load_model("bifurcation").source
    true = [_base_value(source, p) * f for p, f in zip(params, (1.4, 0.8, 1.5), strict=True)]
    outputs = ["parent.pressure_in.max", "parent.pressure_in.min", "parent.pressure_in.mean",
               "flow_split.daughter1.parent", "daughter2.pressure_out.pulse"]
    values = oxyline.sensitivities(native_model(source, params, true), [], outputs).values
    targets = {o: {"value": v, "sigma": 0.01 * abs(v)} for o, v in zip(outputs, values,
                                                                          strict=True)}
    print("\nbifurcation, 3 parameters, 5 targets, trf:")
    print(f"{'Jacobian':>10} {'time (s)':>9} {'evaluations':>12} {'cost':>10} {'success':>8}")
    times = {}
    for jac in ("exact", "2-point"):
        t, res = _timed(lambda j=jac: oxyline.calibrate("bifurcation", targets, params,
                                                          method="trf", jacobian=j), 3)
        times[jac] = t
        print(f"{jac:>10} {t:>9.2f} {res.report['evaluations']:>12} {res.cost:>10.2e} "
              f"{res.success!s:>8}")
    print(f"speed-up of the exact Jacobian: {times['2-point'] / times['exact']:.1f}x")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default="adan56")
    ap.add_argument("--counts", type=int, nargs="*", default=[1, 5, 20, 100])
    ap.add_argument("--steps", type=int, default=400, help="steps per cycle")
    ap.add_argument("--tol", type=float, default=1e-8, help="periodic-state tolerance")
    ap.add_argument("--stenoses", type=int, nargs="*", default=[1, 3, 6])
    ap.add_argument("--adjoint", type=int, nargs="*", default=[1, 10, 100])
    ap.add_argument("--heart", type=int, default=400, help="steps per cycle of the heart "
                    "section (0: skip it)")
    ap.add_argument("--skip-calibration", action="store_true")
    args = ap.parse_args()
    if args.counts:
        gradient_cost(args.model, args.counts, args.steps, args.tol)
    if args.stenoses:
        stenosis_cost(args.model, args.stenoses, args.steps, args.tol)
    if args.adjoint:
        adjoint_cost(args.model, args.adjoint, args.steps, args.tol)
    if args.heart:
        heart_cost(args.heart, args.tol)
    if not args.skip_calibration:
        calibration_speedup()


if __name__ == "__main__":
    main()
