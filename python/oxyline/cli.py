"""The ``oxyline`` command line: run, validate, models, info.

Exit codes: 0 ok, 2 bad input, 130 interrupted.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path


def _cmd_run(args: argparse.Namespace) -> int:
    import oxyline

    model = oxyline.load_model(args.model)
    overrides: dict[str, object] = {"progress": not args.quiet}
    if args.cycles is not None:
        overrides["cycles"] = args.cycles
    if args.dt is not None:
        overrides["dt"] = args.dt
    if args.until_periodic is not None:
        overrides["until_periodic"] = args.until_periodic
    if args.method is not None:
        overrides["method"] = args.method
    try:
        res = oxyline.simulate(model, **overrides)
    except oxyline.SimulationInterrupted as exc:
        if args.output and exc.result is not None:
            _write(exc.result, args.output)
            print(f"interrupted; partial result written to {args.output}", file=sys.stderr)
        return 130
    if args.output:
        _write(res, args.output)
    if not args.quiet:
        s = res.settings
        print(f"{model.name}: {len(res.vessels)} vessels, method {s['method']}, dt {s['dt']:.3e} s, "
              f"{s['cycles_run']} cycles, cycle-to-cycle change {s['periodic_error']:.2e}")
        print(f"{'vessel':<24}{'mean P_in [mmHg]':>18}{'mean Q_in [mL/s]':>18}")
        for name in res.vessels[:20]:
            v = res.vessel(name)
            print(f"{name:<24}{v.pressure_in.mean() / 133.322368:>18.3f}{v.flow_in.mean() * 1e6:>18.4f}")
        if len(res.vessels) > 20:
            print(f"... {len(res.vessels) - 20} more vessels")
        if args.output:
            print(f"results written to {args.output}")
    return 0


def _write(res: object, path: str) -> None:
    ds = res.to_xarray()  # type: ignore[attr-defined]
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    if p.suffix == ".zarr":
        ds.to_zarr(p, mode="w")
    elif p.suffix == ".csv":
        res.to_pandas().to_csv(p, index=False)  # type: ignore[attr-defined]
    else:
        ds.to_netcdf(p, engine="h5netcdf")


def _cmd_validate(args: argparse.Namespace) -> int:
    import oxyline

    s = oxyline.load_model(args.model).summary()
    print(f"model            {s['name']}")
    for key in ("vessels", "segments", "nodes", "junctions", "inlets", "outlets", "unknowns"):
        print(f"{key:<17}{s[key]}")
    print(f"total compliance {s['total_compliance']:.4e} m^3/Pa")
    print(f"total volume     {s['total_volume'] * 1e6:.4f} mL")
    print(f"period           {s['period']} s")
    print(f"rk4 stable dt    {s['rk4_dt_max']:.4e} s ({'exact' if s['rk4_limit_exact'] else 'estimate'},"
          f" set by {s['rk4_limiting_element']})")
    return 0


def _cmd_models(args: argparse.Namespace) -> int:
    from oxyline import examples

    for name in examples.names():
        print(name)
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    import os

    import oxyline
    from oxyline import _core

    print(f"oxyline {oxyline.__version__} ({_core.build_profile} build), threads: {os.cpu_count()}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="oxyline", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("run", help="run a model file or built-in example")
    p.add_argument("model")
    p.add_argument("-o", "--output", help="result file (.nc, .zarr or .csv)")
    p.add_argument("--cycles", type=int)
    p.add_argument("--dt", type=float)
    p.add_argument("--method", choices=["auto", "rk4", "generalized-alpha"])
    p.add_argument("--until-periodic", type=float)
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=_cmd_run)
    p = sub.add_parser("validate", help="check a model and print a summary")
    p.add_argument("model")
    p.set_defaults(func=_cmd_validate)
    sub.add_parser("models", help="list built-in models").set_defaults(func=_cmd_models)
    sub.add_parser("info", help="version and build").set_defaults(func=_cmd_info)
    args = parser.parse_args(argv)
    from oxyline.errors import ModelError

    try:
        return int(args.func(args))
    except ModelError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
