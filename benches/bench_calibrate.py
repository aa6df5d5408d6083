"""Cost of exact sensitivities and of calibration with them (docs/calibration.md, "Cost").

1. Gradient cost: on adan56 (31 RCR outlets), the process CPU time of the sensitivities with 1, 5, 20
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
   with scipy's forward differences ("2-point"): CPU time, evaluations, final cost.

Every time is the process CPU time (the machine may be shared: wall time is not telling).

    python benches/bench_calibrate.py
    python benches/bench_calibrate.py --counts 1 5 --steps 200 --tol 1e-10
"""

from __future__ import annotations

import argparse
import time

import numpy as np

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
    """The least process CPU time of ``repeat`` calls of ``fn`` and its (last) result."""
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t0)
    return best, out


def gradient_cost(name: str, counts: list[int], steps: int, tol: float) -> None:
    model = oxyline.load_model(name)
    outputs = [f"{model.vessel_names[0]}.pressure_in.mean"]
    kw = {"steps_per_cycle": steps, "tol": tol}
    t0, s0 = _timed(lambda: oxyline.sensitivities(model, [], outputs, **kw), 3)
    print(f"\n{name}: forward run to the periodic state (tol {tol:g}) {t0 * 1e3:.0f} ms "
          f"({s0.cycles} cycles of {steps} steps)")
    print(f"{'parameters':>10} {'tangent cycles':>15} {'CPU (ms)':>10} {'x forward':>10} "
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
          f"{'tangent cycles':>15} {'CPU (ms)':>10} {'x forward per param':>20}")
    for n in counts:
        data, paths = _with_stenoses(base, n)
        model = oxyline.load_model(data)
        t0, s0 = _timed(lambda m=model: oxyline.sensitivities(m, [], outputs, **kw), 2)
        t, s = _timed(lambda m=model, p=paths: oxyline.sensitivities(m, p, outputs, **kw), 2)
        print(f"{n:>9} {t0 * 1e3:>13.0f} {s0.cycles:>7} {len(paths):>11} "
              f"{s.tangent_cycles:>15} {t * 1e3:>10.0f} {(t / t0 - 1) / n:>20.3f}")


def tree(depth: int) -> dict:
    """A symmetric binary tree of ``depth`` generations (2^depth − 1 vessels of two segments,
    radius × 0.8 per generation, RCR outlets sized for ~100/70 mmHg): a model with more than
    a thousand parameters for the adjoint's cost."""
    import math

    vessels, bcs = [], {}
    n_out = 2 ** (depth - 1)
    r_total = 1.3e8  # Pa s/m^3: 90 mmHg mean over 5.5 l/min
    for k in range(1, 2 ** depth):
        gen = int(math.log2(k))
        r = 0.012 * 0.8 ** gen
        vessels.append({"name": f"v{k}", "from": f"n{k // 2}" if k > 1 else "in",
                        "to": f"n{k}", "segments": 2, "length": 0.05, "radius": r,
                        "wall_thickness": 0.1 * r, "youngs_modulus": 4e5})
        if gen == depth - 1:
            bcs[f"n{k}"] = {"type": "rcr", "proximal_resistance": 0.1 * r_total * n_out,
                            "distal_resistance": 0.9 * r_total * n_out,
                            "capacitance": 1e-8 / n_out}
    bcs["in"] = {"type": "flow", "fourier": {"period": 1.0, "mean": 9e-5,
                                             "cos": [-4e-5, -4e-5, 1e-5],
                                             "sin": [1.2e-4, -2e-5, -2e-5]}}
    return {"name": f"tree{depth}", "units": "SI", "period": 1.0, "vessels": vessels,
            "boundary_conditions": bcs}


def adjoint_cost(name: str, counts: list[int], steps: int, tol: float,
                 tangent_max: int) -> None:
    """The gradient of one output by the adjoint and by the forward tangents, relative to
    the forward run alone (best of 2 and 1), for each parameter count; tangents above
    ``tangent_max`` parameters are not run (their cost per parameter is the table above)."""
    model = oxyline.load_model(tree(10) if name == "tree" else name)
    outputs = [f"{model.vessel_names[0]}.pressure_in.mean"]
    kw = {"steps_per_cycle": steps, "tol": tol}
    t0, s0 = _timed(lambda: oxyline.sensitivities(model, [], outputs, **kw), 3)
    print(f"\n{model.name}: adjoint of 1 output (forward run alone {t0 * 1e3:.0f} ms, "
          f"{s0.cycles} cycles; {len(model.vessel_names)} vessels)")
    print(f"{'parameters':>10} {'adjoint (ms)':>13} {'x forward':>10} {'backward cycles':>16} "
          f"{'tangents (ms)':>14} {'x forward':>10}")
    for n in counts:
        params = _parameters(model, n)
        ta, sa = _timed(lambda p=params: oxyline.sensitivities(model, p, outputs, mode="adjoint",
                                                              **kw), 2)
        if n <= tangent_max:
            tt, _ = _timed(lambda p=params: oxyline.sensitivities(model, p, outputs, **kw), 1)
            tcol = f"{tt * 1e3:>14.0f} {tt / t0:>10.2f}"
        else:
            tcol = f"{'not run':>14} {'':>10}"
        print(f"{n:>10} {ta * 1e3:>13.0f} {ta / t0:>10.2f} {sa.tangent_cycles:>16} {tcol}")


#: adan56's regions, by the words of its vessels' names (the first that matches): the aorta
#: with its short trunk branches (alone, their stiffness moves no target measurably)
REGIONS = {"head_neck": ("carotid", "vertebral", "brachiocephalic"),
           "arms": ("subclavian", "axillary", "brachial", "radial", "ulnar", "interosseous"),
           "aorta_trunk": ("aort", "intercostal", "celiac", "hepatic", "splenic", "gastric",
                           "mesenteric", "renal"),
           "legs": ("iliac", "femor", "popliteal", "tibial", "tibiofibular")}


def adan56_problem() -> tuple[oxyline.Model, list[str], dict[str, list[str]], list[str]]:
    """adan56's calibration problem: every terminal R (distal) and C, the inflow scale and a
    wall-stiffness factor per region (parameters, groups), and its outputs: each terminal's
    mean and pulsatile outflow, the aortic root's systolic and diastolic pressure, a pressure
    pulse per region, the aortic PWV and the cardiac output."""
    model = oxyline.load_model("adan56")
    bcs = model.source["boundary_conditions"]
    outlets = [n for n, bc in bcs.items() if bc.get("type") == "rcr"]
    params = [f"boundary_conditions.{n}.{k}" for n in outlets
              for k in ("distal_resistance", "capacitance")] + ["scale.inflow"]
    groups: dict[str, list[str]] = {f"stiffness.{r}": [] for r in REGIONS}
    for v in model.source["vessels"]:
        region = next(r for r, words in REGIONS.items() if any(w in v["name"] for w in words))
        groups[f"stiffness.{region}"].append(f"vessels.{v['name']}.youngs_modulus")
    terminal = [str(v["name"]) for v in model.source["vessels"] if v["to"] in outlets]
    outputs = [f"{v}.flow_out.{s}" for v in terminal for s in ("mean", "pulse")]
    outputs += ["aortic_arch_I.pressure_in.max", "aortic_arch_I.pressure_in.min",
                "internal_carotid_R.pressure_out.pulse", "radial_R.pressure_out.pulse",
                "abdominal_aorta_V.pressure_out.pulse", "posterior_tibial_R.pressure_out.pulse",
                "pwv.aortic_arch_I.abdominal_aorta_V", "cardiac_output"]
    return model, params, groups, outputs


def adan56_identifiability(steps: int, tol: float, fd: bool, noises: list[float],
                           fd_noise: float, ftol: float = 1e-8, repeat: int = 3,
                           reference: bool = True) -> None:
    """Synthetic data from known values (each factor drawn in [0.7, 1.4]), without and with
    2 % noise: the fit's time, evaluations and the recovery (largest relative error; how
    many true values lie inside the reported 95 % intervals); then the same noisy fit with
    scipy's forward differences (same optimiser, trf, every variable bounded to a factor of 4
    of its start) for the speed-up. Wall and process CPU time: the machine is shared; the
    exact fits best of ``repeat`` in the same run. ``ftol``: least_squares' tolerance on the
    cost's decrease; ``reference``: the noisy fit once more with 1e-12, and how far the
    parameters moved after the ``ftol`` stop, in half-widths of their 95 % intervals."""
    model, params, groups, outputs = adan56_problem()
    names = params + list(groups)
    rng = np.random.default_rng(2026)
    factors = rng.uniform(0.7, 1.4, len(names))
    paths = params + [q for g in groups.values() for q in g]
    base = np.array([1.0 if p.startswith("scale.") else _base_value(model.source, p)
                     for p in paths])
    fpath = np.concatenate([factors[:len(params)]] +
                           [np.full(len(g), f) for g, f in zip(groups.values(),
                                                               factors[len(params):],
                                                               strict=True)])
    truth = native_model(model.source, paths, base * fpath)
    kw = {"steps_per_cycle": steps, "tol": tol}
    values = oxyline.sensitivities(truth, [], outputs, **kw).values
    true = dict(zip(names, [*(base[:len(params)] * factors[:len(params)]),
                            *factors[len(params):]], strict=True))
    print(f"\nadan56: {len(names)} parameters ({len(params)} terminal R/C and inflow scale, "
          f"{len(groups)} regional stiffness factors over {len(paths) - len(params)} vessels), "
          f"{len(outputs)} targets, trf")
    # every variable within a factor of 4 of its start (the truth is within 0.7-1.4)
    bounds = {p: (x / 4, x * 4) for p, x in zip(
        names, [*base[:len(params)], *np.ones(len(groups))], strict=True)}
    print(f"{'data':>10} {'Jacobian':>9} {'ftol':>6} {'wall (s)':>9} {'CPU (s)':>8} {'iters':>6} {'runs':>6} "
          f"{'cost':>9} {'max rel err':>12} {'in 95 % CI':>11} {'success':>8}")
    runs = [("exact", n, ftol) for n in noises] + ([("2-point", fd_noise, ftol)] if fd else [])
    noisy = [n for n in noises if n > 0]
    if reference and noisy:
        runs.append(("exact", noisy[0], 1e-12))
    times, fits = {}, {}
    for jac, noise, ft in runs:
        sigma = 0.02 * np.abs(values)
        data = values + noise / 0.02 * sigma * np.random.default_rng(5).standard_normal(
            len(values))
        targets = {o: {"value": float(d), "sigma": float(s)}
                   for o, d, s in zip(outputs, data, sigma, strict=True)}
        rounds = repeat if jac == "exact" and ft == ftol else 1
        t, cpu = float("inf"), float("inf")
        for _ in range(rounds):
            c0, w0 = time.process_time(), time.perf_counter()
            fit = oxyline.calibrate(model, targets, params, groups=groups, method="trf",
                                    bounds=bounds, jacobian=jac, max_evaluations=200,
                                    ftol=ft, **kw)
            cpu = min(cpu, time.process_time() - c0)
            t = min(t, time.perf_counter() - w0)
        times[(jac, noise)] = cpu
        fits[(jac, noise, ft)] = fit
        err = max(abs(fit.parameters[p] / v - 1) for p, v in true.items())
        inside = sum(fit.intervals[p][0] <= v <= fit.intervals[p][1] for p, v in true.items())
        print(f"{f'{noise:.0%} noise':>10} {jac:>9} {ft:>6.0e} {t:>9.1f} {cpu:>8.1f} "
              f"{fit.report.get('nfev', 0):>6} {fit.report['evaluations']:>6} "
              f"{fit.cost:>9.2e} {err:>12.2e} {f'{inside}/{len(true)}':>11} "
              f"{fit.success!s:>8}  ({fit.report['gradient']})")
    if reference and noisy:
        a, b = fits[("exact", noisy[0], ftol)], fits[("exact", noisy[0], 1e-12)]
        moved = max(abs(a.parameters[p] - b.parameters[p])
                    / ((b.intervals[p][1] - b.intervals[p][0]) / 2) for p in true)
        print(f"{noisy[0]:.0%} noise: stopping at ftol {ftol:g} instead of 1e-12 leaves every "
              f"parameter within {moved:.1e} of its 95 % half-width of the 1e-12 fit")
    if fd:
        exact = times.get(("exact", fd_noise))
        if exact:
            print(f"speed-up of the exact Jacobian at {fd_noise:.0%} noise (CPU time): "
                  f"{times[('2-point', fd_noise)] / exact:.1f}x")


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
    print(f"{'mode':>8} {'parameters':>10} {'CPU (ms)':>10} {'x forward':>10} "
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
    print(f"{'Jacobian':>10} {'CPU (s)':>9} {'evaluations':>12} {'cost':>10} {'success':>8}")
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
    ap.add_argument("--tree", type=int, nargs="*", default=[1, 10, 100, 1000],
                    help="adjoint cost on a 1023-vessel tree for these parameter counts")
    ap.add_argument("--tangent-max", type=int, default=100,
                    help="run the forward tangents up to this many parameters")
    ap.add_argument("--identify", action=argparse.BooleanOptionalAction, default=True,
                    help="adan56 identifiability (68 parameters)")
    ap.add_argument("--fd", action=argparse.BooleanOptionalAction, default=True,
                    help="also the finite-difference fit of adan56")
    ap.add_argument("--noise", type=float, nargs="*", default=[0.0, 0.02],
                    help="noise levels of the exact adan56 fits (relative SD)")
    ap.add_argument("--fd-noise", type=float, default=0.0,
                    help="noise level of the finite-difference adan56 fit")
    ap.add_argument("--ftol", type=float, default=1e-8,
                    help="least_squares' ftol of the adan56 fits (cost's relative decrease)")
    ap.add_argument("--repeat", type=int, default=3, help="rounds of each exact adan56 fit")
    ap.add_argument("--reference", action=argparse.BooleanOptionalAction, default=True,
                    help="the noisy adan56 fit also at ftol 1e-12, for the parameters' move")
    args = ap.parse_args()
    if args.counts:
        gradient_cost(args.model, args.counts, args.steps, args.tol)
    if args.stenoses:
        stenosis_cost(args.model, args.stenoses, args.steps, args.tol)
    if args.adjoint:
        adjoint_cost(args.model, args.adjoint, args.steps, args.tol, args.tangent_max)
    if args.tree:
        adjoint_cost("tree", args.tree, args.steps, args.tol, args.tangent_max)
    if args.identify:
        adan56_identifiability(args.steps, args.tol, args.fd, args.noise, args.fd_noise,
                               args.ftol, args.repeat, args.reference)
    if args.heart:
        heart_cost(args.heart, args.tol)
    if not args.skip_calibration:
        calibration_speedup()


if __name__ == "__main__":
    main()
