"""The ``oxyline`` command line: run, plot, validate, impedance, convert, models, info.

Exit codes: 0 ok, 2 bad input (the message names the file, vessel or node, and key; also a
model or output above max_memory), 130 interrupted by Ctrl-C (SIGINT) and 143 stopped by SIGTERM
(a partial result is still written in both cases), 1 solver failure (the partial result up to
the failure is written), 3 the output could not be written (disk full, permission; the message
says what was kept).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from oxyline.units import MMHG

RESULT_SUFFIXES = (".nc", ".zarr", ".csv")
SUMMARY_SUFFIXES = (".csv", ".tsv", ".parquet")


class InputError(Exception):
    """Bad command-line input (exit code 2)."""


def _load(source: str) -> Any:
    from oxyline.io import read_model

    return read_model(source)


def _check_writable_dir(path: str, parent: Path) -> None:
    """``parent`` exists and a file can be created in it (also true for root on a read-only
    file system, which ``os.access`` would not tell)."""
    import tempfile

    if not parent.is_dir():
        raise InputError(f"{path}: directory '{parent}' does not exist (create it first)")
    try:
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as exc:
        raise InputError(f"{path}: cannot write into '{parent}': {exc.strerror or exc}") from None


def _check_outputs(args: argparse.Namespace) -> None:
    """Check every output path before the run, so that a bad one fails in a second, not after
    the run: no two roles for one file, suffix, an existing directory that can be written,
    and no existing Zarr store unless --overwrite (a .nc/.csv file is replaced only once the
    new one is complete)."""
    _check_clashes(args)
    if getattr(args, "checkpoint", None):
        ckpt = Path(args.checkpoint)
        if ckpt.is_dir():
            raise InputError(f"{args.checkpoint}: --checkpoint is a directory")
        _check_writable_dir(args.checkpoint, ckpt.parent)
    if args.output:
        out = Path(args.output)
        if out.suffix.lower() not in RESULT_SUFFIXES:
            raise InputError(f"{args.output}: output must end in .nc, .zarr or .csv")
        _check_writable_dir(args.output, out.parent)
        if out.suffix.lower() == ".zarr" and out.exists() and not args.overwrite:
            raise InputError(f"{args.output}: already exists; use --overwrite to replace it")
        if out.is_dir() and out.suffix.lower() != ".zarr":
            raise InputError(f"{args.output}: is a directory")
    if args.summary:
        if Path(args.summary).suffix.lower() not in SUMMARY_SUFFIXES:
            raise InputError(f"{args.summary}: summary must end in .csv, .tsv or .parquet")
        _check_writable_dir(args.summary, Path(args.summary).parent)
    if args.plot:  # the figure directory itself may be new, its parent must exist
        plot_dir = Path(args.plot)
        _check_writable_dir(args.plot, plot_dir if plot_dir.is_dir() else plot_dir.parent)


class _Stop:
    """SIGINT (Ctrl-C) and SIGTERM (a batch scheduler's stop) in ``oxyline run``. Before the
    run starts they stop at once (nothing computed, nothing to keep). From the start of the
    run on they only set the run's cancel event and are remembered: the run stops at its next
    check (within 0.1 s) with its partial result, a run that has already ended keeps its
    whole result, and that result is written before the exit code (130 or 143) tells what
    stopped it. A second signal changes nothing: the file being written is finished."""

    def __init__(self) -> None:
        import threading

        self.signum: int | None = None
        self.event = threading.Event()
        self.armed = False

    def __call__(self, signum: int, frame: object) -> None:
        import signal

        if self.signum is None:
            self.signum = signum
        if not self.armed:
            if signum == signal.SIGTERM:
                from oxyline.errors import SimulationTerminated

                raise SimulationTerminated("run terminated (SIGTERM)")
            raise KeyboardInterrupt
        self.event.set()

    @property
    def terminated(self) -> bool:
        import signal

        return self.signum == signal.SIGTERM


def _check_clashes(args: argparse.Namespace) -> None:
    """Refuse two roles for one file: the input model (or resumed checkpoint), the result,
    the checkpoint and the summary must all be different files."""
    from oxyline.io.atomic import same_file

    model = getattr(args, "model", None)
    roles = [(role, value) for role, value in (
        ("the input model", model if model and Path(model).exists() else None),
        ("the resumed checkpoint", getattr(args, "resume", None)),
        ("-o", getattr(args, "output", None)), ("--checkpoint", getattr(args, "checkpoint", None)),
        ("--summary", getattr(args, "summary", None))) if value]
    for i, (role_a, a) in enumerate(roles):
        for role_b, b in roles[i + 1:]:
            if role_b == "--checkpoint" and role_a == "the resumed checkpoint":
                continue  # a resumed run goes on checkpointing into its file
            if same_file(a, b):
                raise InputError(f"{b}: {role_b} names the same file as {role_a} ({a}); it "
                                 "would be overwritten: give another file")


def _tolerance_or_none(text: str) -> float | str:
    """``--until-periodic``: a number, or ``none`` (run exactly ``--cycles``)."""
    if text.strip().lower() == "none":
        return "none"
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a number or 'none', got {text!r}") from None


def _time_error_line(s: Mapping[str, Any]) -> str:
    """The summary's line on the accumulated-error estimate: the worst vessel of each kind
    and how it was measured."""
    kinds = [k.removeprefix("time_error_vessel_") for k in s if k.startswith("time_error_vessel_")]
    worst = ", ".join(f"{k} {s['time_error_vessel_' + k]}" for k in kinds)
    local = ", ".join(f"{k.removeprefix('local_error_estimate_')} {float(v):.1e}"
                      for k, v in s.items() if k.startswith("local_error_estimate_"))
    return (f"time error: worst vessel {worst}; measured by the {s['time_error_from']} "
            f"({s['time_error_steps']} steps); the step control's local estimate {local}")


#: the `run` options passed to simulate() as they are (when given), and the flags that ask for
#: an estimate; a resumed run keeps its checkpoint's settings, so takes none of them
_RUN_SETTINGS = ("cycles", "dt", "until_periodic", "max_cycles", "rtol", "output_every",
                 "method")
_RUN_FLAGS = ("estimate_space_error", "estimate_time_error")


def _run_options(args: argparse.Namespace) -> dict[str, object]:
    """The simulate() options of the command line (checkpoints included)."""
    overrides: dict[str, object] = {"progress": not args.quiet}
    overrides.update({k: getattr(args, k) for k in _RUN_SETTINGS
                      if getattr(args, k) is not None})
    if overrides.get("until_periodic") == "none":
        overrides["until_periodic"] = None
    overrides.update({k: True for k in _RUN_FLAGS if getattr(args, k, False)})
    if args.resume and len(overrides) > 1:
        raise InputError(f"{args.resume}: a resumed run keeps its checkpoint's settings (no "
                         "--cycles, --dt, --rtol, --until-periodic, --max-cycles, --output-every, "
                         "--estimate-space-error, --estimate-time-error or --method)")
    if args.threads is not None:
        overrides["threads"] = args.threads
    if args.checkpoint:
        overrides["checkpoint"] = args.checkpoint
    if args.checkpoint_every is not None:
        if not (args.checkpoint or args.resume):
            raise InputError("--checkpoint-every needs --checkpoint FILE")
        every = args.checkpoint_every.strip()
        try:
            overrides["checkpoint_every"] = float(every)
        except ValueError:
            overrides["checkpoint_every"] = every
    return overrides


def _is_closed_loop(name: str | None) -> bool:
    """A built-in of :mod:`oxyline.closed_loop` (not a flow network: no file of that name)."""
    from oxyline import closed_loop

    return name in closed_loop.BUILTINS and not Path(name).exists()


#: the `run` options a closed-loop O2 built-in takes (its O2 step is `--dt`)
_CLOSED_LOOP_OPTIONS = ("output", "dt", "quiet")


def _run_closed_loop(args: argparse.Namespace) -> int:
    """`oxyline run closed-loop-o2[-tree]`: O2 around the closed loop to its periodic steady
    state (:func:`oxyline.closed_loop.simulate_o2`); prints its summary, ``-o x.json`` writes
    it (docs/oxygen.md "Oxygen around a closed loop")."""
    from oxyline import closed_loop

    used = [k for k, v in vars(args).items() if v not in (None, False)
            and k not in ("command", "func", "model", *_CLOSED_LOOP_OPTIONS)]
    if used:
        raise InputError(f"{args.model}: a closed-loop O2 built-in takes -o FILE.json, --dt and "
                         f"--quiet only, not --{used[0].replace('_', '-')}")
    if args.output and Path(args.output).suffix.lower() != ".json":
        raise InputError(f"{args.output}: the summary of {args.model} is written as .json")
    p = closed_loop.load(args.model)
    if args.dt is not None:
        p["dt"] = args.dt
    s = closed_loop.simulate_o2(p).summary()
    if args.output:
        Path(args.output).write_text(json.dumps(s, indent=1) + "\n")
    if not args.quiet:
        print(f"{args.model}: cardiac output {s['cardiac_output']:.2f} L/min, "
              f"SaO2 {s['SaO2']:.1%}, SvO2 {s['SvO2']:.1%}, PaO2 {s['PaO2']:.1f} mmHg, "
              f"PvO2 {s['PvO2']:.1f} mmHg, VO2 {s['VO2']:.1f} mL/min")
        print("VO2 per organ (mL/min): " + ", ".join(f"{k} {v:.1f}"
                                                    for k, v in s["VO2_organs"].items()))
        print(f"Fick residual {s['fick_residual']:.1e}, O2 balance per step "
              f"{s['mass_balance_residual']:.1e}, {s['cycles']} O2 cycles")
        if args.output:
            print(f"summary written to {args.output}")
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    import signal

    stop = _Stop()
    handlers = {s: signal.signal(s, stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        return _run_and_write(args, stop)
    finally:
        for s, h in handlers.items():
            signal.signal(s, h)


def _run_and_write(args: argparse.Namespace, stop: _Stop) -> int:
    import oxyline

    if _is_closed_loop(args.model):
        return _run_closed_loop(args)
    _check_outputs(args)
    overrides = _run_options(args)
    if args.resume:
        from oxyline import checkpoint

        model = oxyline.load_model(checkpoint.read(args.resume)[0]["model"])
        args.model = args.resume
    else:
        model = _load(args.model)
    # a .zarr output is written during the run (memory bounded by one chunk); --plot then
    # reads the finished store back (oxyline.open_result) instead of keeping a second copy
    stream = bool(args.output) and Path(args.output).suffix.lower() == ".zarr"
    for what, asked in (("--estimate-space-error", overrides.get("estimate_space_error")),
                        ("--estimate-time-error", overrides.get("estimate_time_error")),
                        ("a resumed run", args.resume)):
        if stream and asked:
            raise InputError(f"{args.output}: {what} writes .nc or .csv, not a streamed .zarr "
                             "store")
    # from here on a signal cancels the run and its result is still written
    overrides["cancel"] = stop.event
    stop.armed = True
    if stop.signum is not None:
        stop.event.set()
    res = _simulate(args, model, overrides, stream, stop)
    if isinstance(res, int):  # interrupted: the partial result is written
        return res
    return _write_and_report(args, model, res, stream, stop)


def _simulate(args: argparse.Namespace, model: Any, overrides: dict[str, Any], stream: bool,
              stop: _Stop) -> Any:
    """The run's result, or the exit status of a run a signal stopped (its partial result
    written to ``--output``); a failed run's rows up to the failure are written too."""
    import oxyline

    try:
        if args.resume:
            return oxyline.resume(args.resume, **overrides)
        if stream:
            return oxyline.simulate_to_zarr(model, args.output, overwrite=args.overwrite,
                                            **overrides)
        return oxyline.simulate(model, **overrides)
    except oxyline.ModelError as exc:  # run settings (e.g. an unstable dt): name the model
        msg = str(exc)
        if msg.startswith(args.model):
            raise
        raise type(exc)(f"{args.model}: {msg}") from None
    except oxyline.SimulationInterrupted as exc:
        terminated = stop.terminated or isinstance(exc, oxyline.SimulationTerminated)
        if args.output and exc.result is not None:
            if not stream:
                _write(exc.result, args.output, args.overwrite)
            print(f"{'terminated' if terminated else 'interrupted'}; partial result written "
                  f"to {args.output}", file=sys.stderr)
        return 143 if terminated else 130
    except (oxyline.OutputError, oxyline.SolverError) as exc:
        # the rows up to the failure are kept (an output failure, e.g. a checkpoint the full
        # disk refused, keeps a whole Result written to -o, never into a streamed store)
        result = getattr(exc, "result", None)
        if isinstance(exc, oxyline.OutputError) and (
                stream or not isinstance(result, oxyline.Result)):
            raise
        if args.output and result is not None:
            if not stream:
                _write(result, args.output, args.overwrite)
            print(f"partial result (up to the failure) written to {args.output}",
                  file=sys.stderr)
        raise


def _write_and_report(args: argparse.Namespace, model: Any, res: Any, stream: bool,
                      stop: _Stop) -> int:
    """Write a finished run's result, summary and figures and print what was written."""
    import oxyline

    if args.output and not stream:
        _write(res, args.output, args.overwrite)
    if args.summary:  # per-vessel, of a Result or of a streamed store's dataset
        from oxyline.io import results

        parquet = Path(args.summary).suffix.lower() == ".parquet"
        (results.to_parquet if parquet else results.to_csv)(res, args.summary)
    if stop.signum is not None:  # stopped once the run had ended: its whole result is kept
        print(f"{'terminated' if stop.terminated else 'interrupted'} after the run"
              + (f"; result written to {args.output}" if args.output else ""), file=sys.stderr)
        return 143 if stop.terminated else 130
    figures = []
    if args.plot:
        from oxyline import plot

        figures = plot.save_figures(oxyline.open_result(args.output) if stream else res, model,
                                    args.plot)
    if not args.quiet:
        _print_table(model, res, stream)
        if args.output:
            print(f"results written to {args.output}")
        if args.summary:
            print(f"summary written to {args.summary}")
        if figures:
            print(f"{len(figures)} figures written to {args.plot}")
    return 0


def _print_table(model: Any, res: Any, stream: bool, rows: int = 20) -> None:
    """The run's facts and the mean inlet pressure and flow of the first ``rows`` vessels that
    are arteries (internal branches, e.g. whole-body-140's '.wall' branches, are left out)."""
    from oxyline.plot import internal_vessels

    if stream:  # the store opened lazily: read the run facts and the vessels shown only
        s = {k[len("solver_"):]: v for k, v in res.attrs.items() if k.startswith("solver_")}
        vessels = [str(v) for v in res["vessel"].values]
    else:
        s, vessels = res.settings, res.vessels
    internal = internal_vessels(model)
    shown = [i for i, v in enumerate(vessels) if v not in internal][:rows]
    p_in, q_in = (res[k].isel(vessel=shown).mean("time").values if stream
                  else getattr(res, k)[:, shown].mean(axis=0) for k in ("pressure_in", "flow_in"))
    print(f"{model.name}: {len(vessels)} vessels, method {s['method']}, dt {s['dt']:.3e} s, "
          f"{s['cycles_run']} cycles, cycle-to-cycle change {s['periodic_error']:.2e}")
    if s.get("steps") is not None:
        est = ", ".join(f"{k.removeprefix('error_estimate_')} {v:.1e}" for k, v in s.items()
                        if k.startswith("error_estimate_") and k != "error_estimate_space")
        what = "accumulated error (worst vessel)" if s.get("time_error_from") is not None \
            else "estimated error"
        print(f"error control: rtol {s['rtol']:g}, {s['steps']} steps ({s['rejected_steps']} "
              f"rejected), dt {s['dt_min']:.2e} to {s['dt_max']:.2e} s; {what} {est}")
        if s.get("time_error_from") is not None:
            print(_time_error_line(s))
    elif s.get("step_control") is not None:
        print(f"step control: {s['step_control']}: no error estimate")
    if s.get("segments_total") is not None:
        print(_segmentation_line(s))
    if s.get("error_estimate_space") is not None:
        print(f"space: the inlet impedance moves {float(s['error_estimate_space']):.1e} "
              "(relative) when every vessel's segments are doubled")
    if s.get("periodic_reached") in (False, 0):
        print(f"not periodic: the change is above until_periodic = {s['until_periodic']:g} "
              "after max_cycles")
    width = max([24] + [len(vessels[i]) + 2 for i in shown])
    print(f"{'vessel':<{width}}{'mean P_in [mmHg]':>18}{'mean Q_in [mL/s]':>18}")
    for i, p, q in zip(shown, p_in, q_in):
        print(f"{vessels[i]:<{width}}{p / MMHG:>18.3f}{q * 1e6:>18.4f}")
    hidden = sum(v in internal for v in vessels)
    more = len(vessels) - len(shown) - hidden
    if more > 0 or hidden:
        print(f"... {more} more vessels" + (f" and {hidden} internal branches (e.g. wall "
                                             "viscosity) not shown" if hidden else ""))


def _segmentation_line(s: Mapping[str, Any]) -> str:
    """How many segments and how they were chosen (run settings or a model summary)."""
    total, auto = int(s["segments_total"]), int(s["segments_auto"])
    if auto == 0:
        return f"segments: {total}, as the model states them"
    rule = f"by the auto rule (rtol {float(s['segmentation_rtol']):g})"
    if auto == total:
        return f"segments: {total}, all {rule}"
    return f"segments: {total}, {auto} {rule}, {total - auto} as the model states them"


def _cmd_plot(args: argparse.Namespace) -> int:
    import oxyline
    from oxyline import plot

    if not Path(args.result).exists():
        raise InputError(f"{args.result}: file not found")
    res = oxyline.open_result(args.result)
    if args.model is not None:
        model = _load(args.model)
    elif res.model_json is not None:  # the file holds the model it was run from
        model = oxyline.load_model(json.loads(res.model_json))
    else:
        # a file without its model (a whole tree, or an older file): a built-in one can be
        # found from its name alone
        try:
            model = oxyline.catalogue.load(res.model_name)
        except oxyline.ModelError:
            raise InputError(f"{args.result}: model '{res.model_name}' is not a built-in model "
                             "and the file does not hold it; give the model file it was run "
                             "from with --model") from None
    missing = [v for v in res.vessels if v not in set(model.vessel_names)]
    if missing:
        raise InputError(f"{args.result}: vessel '{missing[0]}' is not in model "
                         f"'{model.name}' (is --model the model the result was run from?)")
    figures = plot.save_figures(res, model, args.plot)
    if not args.quiet:
        state = "" if res.complete else " (partial result: the run was interrupted)"
        print(f"{len(figures)} figures written to {args.plot}{state}")
    return 0


def _write(res: Any, path: str, overwrite: bool = False) -> None:
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".zarr":
        res.to_zarr(p, overwrite=overwrite)
    elif suffix == ".csv":
        from oxyline.errors import OutputError
        from oxyline.io.atomic import replace_atomically

        try:  # written whole, then renamed: a full disk or a signal leaves no half table
            replace_atomically(p, lambda tmp: res.to_pandas(units=True).to_csv(tmp, index=False))
        except OSError as exc:
            raise OutputError(f"{p}: cannot write the table: {exc.strerror or exc}; nothing "
                              "was written", res) from exc
    else:
        res.to_netcdf(p)


def _cmd_validate(args: argparse.Namespace) -> int:
    model = _load(args.model)
    s = model.summary()
    print(f"model            {s['name']}")
    for key in ("vessels", "segments", "nodes", "junctions", "inlets", "outlets", "unknowns"):
        print(f"{key:<17}{s[key]}")
    from oxyline.run import segmentation_facts

    print(f"{'':<17}{_segmentation_line(segmentation_facts(model))}")
    print(f"total compliance {s['total_compliance']:.4e} m^3/Pa")
    print(_volume_line(model, s["total_volume"]))
    print(f"period           {s['period']} s")
    print(f"rk4 stable dt    {s['rk4_dt_max']:.4e} s ({'exact' if s['rk4_limit_exact'] else 'Krylov, conservative'},"
          f" set by {s['rk4_limiting_element']})")
    sim = model.simulation or {}
    out = sim.get("output") or {}
    period = s["period"] or 1.0
    print(f"run settings     method {sim.get('method', 'auto')}, dt {sim.get('dt', 'auto')}, "
          f"cycles {sim.get('cycles', 10)}, output every {out.get('every', period / 1000):g} s "
          f"({out.get('cycles', 'last')} cycle{'s' if out.get('cycles') == 'all' else ''})")
    species = [str(x) for x in model.transport.get("species", [])]
    if species:
        oxygen = model.transport.get("oxygen")
        wall = (model.to_dict().get("oxygen") or {}).get("wall") or {}
        note = f" (oxygen: {oxygen}, wall {wall.get('model', 'none')})" if oxygen else ""
        print(f"species          {', '.join(species)}{note}")
    return 0


def _volume_line(model: Any, volume: float) -> str:
    """The blood volume line of `validate`: lumped elements and chambers have no geometric
    volume, so a model of those only has none to print (never a misleading 0 mL)."""
    vessels = model.canonical["vessels"]
    geometric = sum(1 for v in vessels if "geometry" in v)
    if geometric == 0:
        return "total volume     - (lumped elements and chambers only: no vessel geometry)"
    if geometric < len(vessels):
        return (f"total volume     {volume * 1e6:.4f} mL (the {geometric} geometric vessels; "
                f"{len(vessels) - geometric} lumped elements or chambers have no geometry)")
    return f"total volume     {volume * 1e6:.4f} mL"


def _cmd_impedance(args: argparse.Namespace) -> int:
    import numpy as np

    import oxyline

    if not args.fmax > 0 or not args.df > 0:
        raise InputError(f"--fmax and --df must be > 0, got {args.fmax:g} and {args.df:g}")
    model = _load(args.model)
    f = np.arange(0.0, args.fmax + 0.5 * args.df, args.df)
    z = oxyline.impedance(model, args.node, f, direction=args.direction)
    rows = ["frequency_Hz,modulus_Pa_s_m3,phase_rad,real_Pa_s_m3,imag_Pa_s_m3"]
    rows += [f"{fi:.6g},{abs(zi):.10e},{np.angle(zi):.10e},{zi.real:.10e},{zi.imag:.10e}"
             for fi, zi in zip(f, z)]
    if args.plot is None:
        print("\n".join(rows))
        return 0
    out = Path(args.plot)
    out.mkdir(parents=True, exist_ok=True)
    (out / "impedance.csv").write_text("\n".join(rows) + "\n")
    from oxyline import plot

    fig = plot.impedance(f, z, label=f"{model.name}: {args.node}")
    for suffix in (".png", ".svg"):
        fig.savefig(out / f"impedance{suffix}")
    if not args.quiet:
        print(f"impedance.csv and impedance.png/.svg written to {out}")
    return 0


def _cmd_convert(args: argparse.Namespace) -> int:
    from oxyline.io import formats

    model = formats.read_model(args.input, format=args.from_format)
    out = Path(args.output)
    fmt = args.to_format or formats.output_format(out)
    if fmt is None:
        raise InputError(f"{out}: cannot tell the output format from the suffix (use "
                         f"{', '.join(formats.WRITE_SUFFIXES)}, or --to)")
    options = {"units": args.units} if "units" in formats.FORMATS[fmt].write_options else {}
    written = formats.write_model(model, out, format=fmt, **options)
    print(f"{args.input} -> {fmt}: " + ", ".join(str(p) for p in written))
    return 0


def _cmd_models(args: argparse.Namespace) -> int:
    from oxyline import catalogue

    for name, description in catalogue.describe().items():
        print(f"{name:<24}{description}")
    from oxyline import closed_loop

    for name in closed_loop.BUILTINS:  # not flow networks: `run` prints their O2 summary
        print(f"{name:<24}closed-loop O2 (oxyline.closed_loop; `oxyline run {name}` prints "
              f"SaO2, SvO2, VO2 per organ)")
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    import oxyline
    from oxyline import _core

    print(f"oxyline {oxyline.__version__} ({_core.build_profile} build), threads: {os.cpu_count()}")
    if args.model is not None:  # `info MODEL`: the model's summary, as `validate` prints it
        return _cmd_validate(args)
    return 0


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from oxyline.calibrate import main_cli  # scipy is imported only for this command

    return main_cli(args.model, args.targets, args.output, args.quiet)


#: shared arguments of the subcommands, by name
_MODEL = (("model",), {"help": "built-in name, or a model file (any supported format)"})
_QUIET = (("--quiet",), {"action": "store_true", "help": "print nothing but errors"})
#: the options of ``oxyline run``: (flags, add_argument keywords)
_RUN_ARGUMENTS: tuple[tuple[tuple[str, ...], dict[str, Any]], ...] = (
    (("model",), {"nargs": "?", "help": "built-in name, or a .yaml/.json/.csv model (native, "
                  "svZeroDSolver, openBF, tables); omitted with --resume"}),
    (("-o", "--output"), {"help": "result file: .nc (NetCDF), .zarr (written during the run, "
                          "memory bounded), or .csv (waveforms)"}),
    (("--summary",), {"help": "per-vessel mean/min/max table: .csv, .tsv or .parquet"}),
    (("--plot",), {"metavar": "DIR", "help": "write waveform, profile and map figures (PNG + "
                   "SVG) into DIR"}),
    (("--overwrite",), {"action": "store_true", "help": "replace an existing .zarr store (a "
                        ".nc/.csv file is always replaced, once the new one is complete)"}),
    (("--cycles",), {"type": int, "help": "cardiac cycles to run (default: the model's "
                     "simulation.cycles, else 10)"}),
    (("--dt",), {"type": float, "help": "a fixed time step in s (default: the model's, else "
                 "error control at --rtol)"}),
    (("--method",), {"choices": ["auto", "rk4", "generalized-alpha", "dopri5"],
                     "help": "time integrator (default: the model's, else auto)"}),
    (("--until-periodic",), {"type": _tolerance_or_none, "metavar": "TOL", "help": "run until "
                             "the cycle-to-cycle change is below TOL (relative), at least "
                             "--cycles and at most --max-cycles cycles; 'none' runs exactly "
                             "--cycles even if the model asks for periodicity"}),
    (("--threads",), {"type": int, "metavar": "N", "help": "threads of the run (default: every "
                      "core; 1: serial); the results are the same on any number of threads"}),
    (("--rtol",), {"type": float, "metavar": "TOL", "help": "error control: a variable step "
                   "keeping the estimated error of every unknown within TOL (relative; default "
                   "1e-3 where no dt is given); excludes --dt"}),
    (("--estimate-space-error",), {"action": "store_true", "help": "also estimate the spatial "
                                   "error: the inlet impedance's change over the forcing's "
                                   "significant harmonics when every vessel's segments are "
                                   "doubled (in the summary and the result's attributes)"}),
    (("--estimate-time-error",), {"action": "store_true", "help": "also estimate the "
                                  "accumulated time-integration error of every vessel (the "
                                  "last cycle again at rtol/4; in the summary and the result's "
                                  "attributes)"}),
    (("--max-cycles",), {"type": int, "metavar": "N", "help": "most cycles a run "
                         "--until-periodic takes (default: the model's, else max(cycles, "
                         "100))"}),
    (("--output-every",), {"type": float, "metavar": "SECONDS", "help": "output interval in s "
                           "(default: the model's, else period/1000)"}),
    (("--checkpoint",), {"metavar": "FILE", "help": "write the run's state to FILE at cycle "
                         "ends (atomically), to continue it later with --resume FILE"}),
    (("--checkpoint-every",), {"metavar": "EVERY", "help": "how often to checkpoint: seconds "
                               "of wall time (e.g. 600) or 'N cycles' (default 300 s)"}),
    (("--resume",), {"metavar": "FILE", "help": "continue the run of checkpoint FILE (its "
                     "model and settings; results bit-identical to an uninterrupted run); it "
                     "goes on checkpointing into FILE"}),
    (("--quiet",), {"action": "store_true", "help": "no progress bar and no table"}),
)
#: the subcommands: name -> (handler, add_parser keywords, arguments)
_COMMANDS: dict[str, tuple[Any, dict[str, str], tuple[Any, ...]]] = {
    "run": (_cmd_run, {"help": "run a model file or built-in model"}, _RUN_ARGUMENTS),
    "plot": (_cmd_plot, {
        "help": "write the figures of a saved result (.nc/.zarr)",
        "description": "Write the figures of `run --plot` (PNG + SVG) from a result file "
                       "written by `run -o` or Result.to_netcdf/to_zarr."}, (
        (("result",), {"metavar": "RESULT", "help": "result file: .nc (NetCDF) or .zarr"}),
        (("--plot", "-o"), {"dest": "plot", "metavar": "DIR", "required": True,
                            "help": "directory for the figures (PNG + SVG)"}),
        (("--model",), {"help": "the model the result was run from (built-in name or model "
                        "file; default: the built-in model the file names)"}),
        (("--quiet",), {"action": "store_true", "help": "print nothing"}))),
    "validate": (_cmd_validate, {"help": "check a model and print a summary"}, (_MODEL,)),
    "impedance": (_cmd_impedance, {
        "help": "input impedance Z(f) seen from a node",
        "description": "Write Z(f) = P/Q (Pa s/m^3) seen from NODE into the network downstream "
                       "of it, for f = 0, df, ..., fmax: a CSV on stdout, or with --plot a CSV "
                       "and a modulus/phase figure in DIR."}, (
        _MODEL,
        (("--node",), {"required": True, "help": "graph node (e.g. the inlet)"}),
        (("--fmax",), {"type": float, "default": 20.0, "help": "highest frequency, Hz (20)"}),
        (("--df",), {"type": float, "default": 0.25, "help": "frequency step, Hz (0.25)"}),
        (("--direction",), {"choices": ("downstream", "upstream", "both"),
                            "default": "downstream", "help": "the side of NODE to look into "
                            "(downstream; both: every branch)"}),
        (("--plot",), {"metavar": "DIR", "help": "write impedance.csv and impedance.png/.svg"}),
        _QUIET)),
    "convert": (_cmd_convert, {
        "help": "convert a model between formats",
        "description": "Convert IN to OUT. Formats: native (.yaml/.yml/.json), svzerod "
                       "(svZeroDSolver JSON; read when detected, write with --to svzerod), "
                       "tables (.csv/.tsv vessel table + <stem>_bcs table), openbf (read "
                       "only)."}, (
        (("input",), {"metavar": "IN", "help": "model file or built-in name"}),
        (("output",), {"metavar": "OUT", "help": "file to write"}),
        (("--from",), {"dest": "from_format", "choices": ["native", "svzerod", "tables", "openbf"],
                       "help": "input format (default: detected)"}),
        (("--to",), {"dest": "to_format", "choices": ["native", "svzerod", "tables"],
                     "help": "output format (default: from the suffix)"}),
        (("--units",), {"choices": ["cgs", "SI"], "default": "cgs", "help": "units of an "
                        "svZeroDSolver output file (default cgs: cm, dyn/cm^2, mL/s)"}))),
    "models": (_cmd_models, {"help": "list built-in models"}, ()),
    "calibrate": (_cmd_calibrate, {"help": "fit model parameters to targets "
                                   "(docs/calibration.md)"}, (
        _MODEL,
        (("targets",), {"help": "YAML/JSON file: parameters, targets, method"}),
        (("-o", "--output"), {"required": True, "help": "calibrated model file (.yaml/.json)"}),
        _QUIET)),
    "info": (_cmd_info, {"help": "version and build; with MODEL, the model's summary"}, (
        (("model",), {"nargs": "?", "help": "built-in name, or a model file (any format)"}),)),
}


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="oxyline", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    from oxyline import __version__

    parser.add_argument("--version", action="version", version=f"oxyline {__version__}")
    parser.add_argument("--no-plausibility", action="store_true",
                        help="do not warn about model values outside their physiological "
                             "ranges (PlausibilityWarning: likely unit mix-ups)")
    sub = parser.add_subparsers(dest="command", required=True)
    for name, (func, about, arguments) in _COMMANDS.items():
        p = sub.add_parser(name, **about)
        for flags, options in arguments:
            p.add_argument(*flags, **options)
        p.set_defaults(func=func)
    return parser


def _show_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                  file: Any = None, line: str | None = None) -> None:
    """A warning as one line, ``warning: <message>``, like the errors (not Python's file and
    line of the library code)."""
    print(f"warning: {message}", file=sys.stderr if file is None else file)


def main(argv: Sequence[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if args.command == "run" and (args.model is None) == (args.resume is None):
        parser.error("run: give a model to run, or --resume CHECKPOINT (not both)")
    from oxyline.errors import ModelError, OutputError, SolverError

    try:
        with warnings.catch_warnings():  # restores the caller's display after the command
            warnings.showwarning = _show_warning
            if args.no_plausibility:
                from oxyline.errors import PlausibilityWarning

                warnings.simplefilter("ignore", PlausibilityWarning)
            return int(args.func(args))
    except OutputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 3
    except (ModelError, InputError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into e.g. `head`
        sys.stdout = open(os.devnull, "w")  # noqa: SIM115
        return 0
    except (KeyError, ValueError, ImportError, OSError) as exc:
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        print(f"error: {msg}", file=sys.stderr)
        return 2
    except SolverError as exc:
        msg = str(exc)
        print(f"error: {msg if msg.lower().startswith('solver failed') else 'solver failed: ' + msg}",
              file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:
        from oxyline.errors import SimulationTerminated

        terminated = isinstance(exc, SimulationTerminated)
        print("terminated" if terminated else "interrupted", file=sys.stderr)
        return 143 if terminated else 130


if __name__ == "__main__":
    sys.exit(main())
