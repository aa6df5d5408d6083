"""oxyline vs svZeroDSolver (svzerod 3.2): wall time, peak memory and accuracy on the chain and
tree models of ``docs/peers.md`` §4 (generators in ``benches/networks.py``).

Every measurement runs in a fresh Python subprocess that builds the model dict, imports the
solver and pandas (not timed), then times one end-to-end call including the results:

* ``svzerod``: ``svzerod.simulate(cfg)`` -> DataFrame;
* ``oxyline``: ``oxyline.svzerod.simulate(cfg)`` -> DataFrame (the drop-in);
* ``native``: ``oxyline.load_model(cfg)`` + ``oxyline.simulate(model)`` -> numpy arrays (the
  drop-in converter keeps the file's CGS numbers);
  the time of a subsequent ``Result.to_pandas()`` is reported separately.

Peak RSS is the child's ``ru_maxrss`` read right after the timed call (so it covers the
interpreter, the imports, the model dict and the run); "base" is the RSS just before the call.

Accuracy: each solution is compared with a svzerod run with 5x smaller steps
(``5 (pts - 1) + 1`` points per cycle, ``output_interval = 5``, so the output times coincide);
the error of a column is max |x - x_ref| / (max x_ref - min x_ref) over all vessels and times.

Run ``python benches/bench_svzerod.py --help``; results also go to ``benches/results.md``.
"""

from __future__ import annotations

import argparse
import datetime
import gc
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import networks

COLUMNS = ("flow_in", "flow_out", "pressure_in", "pressure_out")
IMPLS = ("svzerod", "oxyline", "native")
# options of oxyline.simulate for the native path (the svzerod settings come with the model)
NATIVE_OPTIONS: dict[str, Any] = {"segments": False}
MARK = "@@BENCH@@"


# ----------------------------------------------------------------------------- child side


def _rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux


def _frame_to_array(df: Any, names: list[str]) -> tuple[Any, Any]:
    """(4, vessel, time) array in ``COLUMNS`` order and the time vector, from a long table."""
    import numpy as np
    import pandas as pd

    codes = pd.Categorical(df["name"], categories=names).codes
    if (codes < 0).any():
        raise ValueError("result has rows of unknown vessels")
    order = np.lexsort((df["time"].to_numpy(), codes))
    nv = len(names)
    nt = len(df) // nv
    if nt * nv != len(df):
        raise ValueError(f"{len(df)} rows is not a multiple of {nv} vessels")
    out = np.stack([df[c].to_numpy()[order].reshape(nv, nt) for c in COLUMNS])
    return out, df["time"].to_numpy()[order][:nt]


def child(spec: dict[str, Any]) -> dict[str, Any]:
    import numpy as np
    import pandas  # noqa: F401 - imported untimed in every child, see the module docstring

    impl, topo, n = spec["impl"], spec["topology"], spec["n"]
    pts = spec["pts"]
    cfg = networks.build(topo, n, spec["cycles"], pts)
    if spec.get("output_interval"):
        cfg["simulation_parameters"]["output_interval"] = spec["output_interval"]
    names = [v["vessel_name"] for v in cfg["vessels"]]
    rec: dict[str, Any] = {}
    if impl == "svzerod":
        import svzerod

        run = svzerod.simulate
    elif impl == "oxyline":
        import oxyline.svzerod

        run = oxyline.svzerod.simulate
    elif impl == "native":
        import oxyline
    else:
        raise ValueError(impl)
    gc.collect()
    rec["base_mb"] = _rss_mb()
    c0 = time.process_time()
    t0 = time.perf_counter()
    if impl == "native":
        try:
            model = oxyline.load_model(cfg)
            rec["loader"] = "oxyline.load_model"
        except oxyline.ModelError:  # load_model does not route this dict to the converter
            import oxyline.svzerod

            model = oxyline.svzerod.to_model(cfg)
            rec["loader"] = "oxyline.svzerod.to_model"
        t1 = time.perf_counter()
        res = oxyline.simulate(model, **NATIVE_OPTIONS)
        t2 = time.perf_counter()
        rec.update(wall_s=t2 - t0, cpu_s=time.process_time() - c0, load_s=t1 - t0,
                   simulate_s=t2 - t1, peak_mb=_peak_mb(),
                   method=res.settings.get("method"), dt=res.settings.get("dt"),
                   cycles_run=res.settings.get("cycles_run"))
        t3 = time.perf_counter()
        df = res.to_pandas()
        rec.update(to_pandas_s=time.perf_counter() - t3, peak_with_pandas_mb=_peak_mb(),
                   rows=len(df))
        del df
        if spec.get("save"):
            idx = [res.vessels.index(v) for v in names]
            # the native model is SI; svzerod's frame has the file's (cgs) numbers
            import oxyline.svzerod

            to_file = {"pressure": 10.0, "flow": 1e6} \
                if oxyline.svzerod.file_units(cfg) == "cgs" else {"pressure": 1.0, "flow": 1.0}
            arr = np.stack([getattr(res, c)[:, idx].T * to_file[c.split("_")[0]]
                            for c in COLUMNS])
            np.savez(spec["save"], data=arr, time=np.asarray(res.time))
    else:
        df = run(cfg)
        rec.update(wall_s=time.perf_counter() - t0, cpu_s=time.process_time() - c0,
                   peak_mb=_peak_mb(), rows=len(df))
        if spec.get("save"):
            arr, tt = _frame_to_array(df, names)
            np.savez(spec["save"], data=arr, time=tt)
    rec["loadavg"] = os.getloadavg()[0]
    return rec


# ---------------------------------------------------------------------------- parent side


def _size(text: str) -> int:
    return int(float(text))


def run_child(spec: dict[str, Any], timeout: float | None,
              mem_limit_mb: float | None = None) -> dict[str, Any]:
    def limit() -> None:
        if mem_limit_mb:
            b = int(mem_limit_mb * 2**20)
            resource.setrlimit(resource.RLIMIT_AS, (b, b))

    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", json.dumps(spec)]
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, check=False, capture_output=True, text=True, timeout=timeout,
                           preexec_fn=limit if mem_limit_mb else None)
    except subprocess.TimeoutExpired:
        return {"error": f"timeout after {timeout:.0f} s"}
    for line in p.stdout.splitlines():
        if line.startswith(MARK):
            out = json.loads(line[len(MARK):])
            out["process_s"] = time.perf_counter() - t0
            return out
    err = (p.stderr.strip().splitlines() or [f"exit code {p.returncode}"])[-1]
    if p.returncode < 0:
        err = f"killed by signal {-p.returncode}; {err}"
    return {"error": err[:200]}


def measure(spec: dict[str, Any], repeat: int, timeout: float | None,
            mem_limit_mb: float | None = None) -> dict[str, Any]:
    """Best wall time of ``repeat`` fresh processes; memory figures are the largest seen."""
    runs = []
    for i in range(repeat):
        s = dict(spec)
        if i > 0:
            s.pop("save", None)
        r = run_child(s, timeout, mem_limit_mb)
        if "error" in r:
            return r
        runs.append(r)
    best = min(runs, key=lambda r: r["wall_s"])
    best = dict(best)
    for k in ("peak_mb", "peak_with_pandas_mb"):
        if k in best:
            best[k] = max(r[k] for r in runs)
    best["cpu_s"] = min(r["cpu_s"] for r in runs)
    best["walls"] = [r["wall_s"] for r in runs]
    return best


def oxyline_available() -> str | None:
    p = subprocess.run([sys.executable, "-c", "import oxyline.svzerod"], check=False,
                       capture_output=True, text=True)
    if p.returncode == 0:
        return None
    return (p.stderr.strip().splitlines() or ["import failed"])[-1]


def accuracy(files: dict[str, str]) -> dict[str, Any]:
    import numpy as np

    ref = np.load(files["ref"])
    out: dict[str, Any] = {}
    for impl in IMPLS:
        if impl not in files or not Path(files[impl]).exists():
            continue
        d = np.load(files[impl])
        if d["data"].shape != ref["data"].shape:
            out[impl] = {"error": f"shape {d['data'].shape} != reference {ref['data'].shape}"}
            continue
        if np.max(np.abs(d["time"] - ref["time"])) > 1e-9:
            out[impl] = {"error": "output times differ from the reference"}
            continue
        cols = {}
        for i, c in enumerate(COLUMNS):
            r = ref["data"][i]
            cols[c] = float(np.max(np.abs(d["data"][i] - r)) / (r.max() - r.min()))
        out[impl] = {"max": max(cols.values()), "columns": cols}
    if all(k in files and Path(files[k]).exists() for k in ("svzerod", "oxyline")):
        a, b = np.load(files["oxyline"])["data"], np.load(files["svzerod"])["data"]
        if a.shape == b.shape:
            out["agreement"] = max(float(np.max(np.abs(a[i] - b[i])) / np.ptp(b[i]))
                                   for i in range(len(COLUMNS)))
    return out


def machine() -> dict[str, Any]:
    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = "?"
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                mem = f"{int(line.split()[1]) / 2**20:.1f} GB"
    except OSError:
        pass
    from importlib.metadata import PackageNotFoundError, version

    vers = {}
    for pkg in ("svzerod", "oxyline", "pandas", "numpy"):
        try:
            vers[pkg] = version(pkg)
        except PackageNotFoundError:
            vers[pkg] = "?"
    try:
        commit = subprocess.run(["git", "-C", str(HERE), "rev-parse", "--short", "HEAD"],
                                check=False, capture_output=True, text=True).stdout.strip()
    except OSError:
        commit = "?"
    core = "?"
    try:
        import oxyline

        so = next(Path(oxyline.__file__).parent.glob("_core*.so"))
        core = datetime.datetime.fromtimestamp(so.stat().st_mtime, datetime.timezone.utc) \
            .strftime("%Y-%m-%d %H:%M UTC")
        dirty = subprocess.run(["git", "-C", str(HERE), "status", "--porcelain", "--", "../rust",
                                "../python"], check=False, capture_output=True, text=True).stdout
        if dirty.strip():
            commit += " + uncommitted changes in rust/ or python/"
    except (ImportError, StopIteration, OSError):
        pass
    return {"nproc": os.cpu_count(), "cpu": cpu, "mem": mem, "python": platform.python_version(),
            "versions": vers, "commit": commit, "core_built": core}


def _f(x: Any, fmt: str = ".3g") -> str:
    return "–" if x is None else format(x, fmt)


def _ratio(a: Any, b: Any) -> str:
    return "–" if a is None or b is None or not b else f"{a / b:.1f}x"


def tables(results: list[dict[str, Any]]) -> str:
    def get(r: dict[str, Any], impl: str, key: str) -> Any:
        v = r.get(impl) or {}
        return v.get(key)

    lines = [
        ("| topology | N | svzerod s | oxyline s | native s | speed-up oxyline | speed-up native "
         "| svzerod MB | oxyline MB | native MB | memory ratio oxyline | memory ratio native |"),
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    notes = []
    for r in results:
        row = [r["topology"], f"{r['n']:,}".replace(",", " ")]
        for impl in IMPLS:
            v = r.get(impl)
            if v is None:
                row.append("not run")
            elif "error" in v:
                row.append("failed")
                notes.append(f"* {r['topology']} {r['n']} {impl}: {v['error']}")
            else:
                row.append(_f(v["wall_s"]))
        sv = get(r, "svzerod", "wall_s")
        row += [_ratio(sv, get(r, "oxyline", "wall_s")), _ratio(sv, get(r, "native", "wall_s"))]
        for impl in IMPLS:
            row.append(_f(get(r, impl, "peak_mb"), ".0f"))
        sm = get(r, "svzerod", "peak_mb")
        row += [_ratio(sm, get(r, "oxyline", "peak_mb")), _ratio(sm, get(r, "native", "peak_mb"))]
        lines.append("| " + " | ".join(row) + " |")
    out = ["### Wall time (end-to-end, best of repeats) and peak RSS", "", *lines, ""]
    out += [("Speed-up and memory ratio = svzerod / oxyline (targets at 1e3 and 1e4: "
             "speed-up >= 20x, memory ratio >= 10x)."), ""]
    # CPU time: less sensitive than wall time to other processes on a shared machine
    out += ["### CPU time of the timed call (user + system, s)", "",
            ("| topology | N | svzerod | oxyline | native | speed-up oxyline | speed-up native "
             "| load avg |"),
            "|---|---|---|---|---|---|---|---|"]
    for r in results:
        row = [r["topology"], str(r["n"])]
        row += [_f(get(r, impl, "cpu_s")) for impl in IMPLS]
        sc = get(r, "svzerod", "cpu_s")
        row += [_ratio(sc, get(r, "oxyline", "cpu_s")), _ratio(sc, get(r, "native", "cpu_s"))]
        loads = [get(r, impl, "loadavg") for impl in IMPLS if get(r, impl, "loadavg") is not None]
        row.append(" / ".join(f"{x:.1f}" for x in loads) or "–")
        out.append("| " + " | ".join(row) + " |")
    out.append("")
    # memory above the pre-run baseline
    out += ["### Memory above the pre-run baseline (peak - RSS before the call), MB", "",
            ("| topology | N | svzerod base | svzerod +run | oxyline base | oxyline +run "
             "| native base | native +run | ratio (+run) oxyline | ratio (+run) native |"),
            "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        row = [r["topology"], str(r["n"])]
        inc = {}
        for impl in IMPLS:
            b, p = get(r, impl, "base_mb"), get(r, impl, "peak_mb")
            inc[impl] = None if b is None or p is None else p - b
            row += [_f(b, ".0f"), _f(inc[impl], ".0f")]
        row += [_ratio(inc["svzerod"], inc["oxyline"]), _ratio(inc["svzerod"], inc["native"])]
        out.append("| " + " | ".join(row) + " |")
    out.append("")
    # native breakdown
    out += ["### oxyline native path: breakdown (s)", "",
            ("| topology | N | load_model | simulate | to_pandas | peak MB with to_pandas "
             "| rows | method | dt | load avg |"),
            "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        v = r.get("native") or {}
        if "wall_s" not in v:
            continue
        out.append(f"| {r['topology']} | {r['n']} | {_f(v['load_s'])} | {_f(v['simulate_s'])} | "
                   f"{_f(v['to_pandas_s'])} | {_f(v['peak_with_pandas_mb'], '.0f')} | "
                   f"{v['rows']} | {v['method']} | {_f(v['dt'])} | {v['loadavg']:.2f} |")
    out.append("")
    acc = [r for r in results if r.get("accuracy")]
    if acc:
        out += ["### Accuracy against a run with 5x smaller steps", "",
                ("max over the 4 columns of max|x - x_ref| / range(x_ref); reference at "
                 "5 (pts - 1) + 1 points per cycle, output every 5th step."), "",
                ("| topology | N | svzerod | oxyline | native | worst column (oxyline) "
                 "| oxyline vs svzerod | reference solver | reference s |"),
                "|---|---|---|---|---|---|---|---|---|"]
        for r in acc:
            a = r["accuracy"]
            if "error" in a:
                out.append(f"| {r['topology']} | {r['n']} | {a['error']} | | | | | | |")
                continue
            row = [r["topology"], str(r["n"])]
            for impl in IMPLS:
                v = a.get(impl)
                row.append("–" if v is None else v.get("error") or f"{v['max']:.2e}")
            ox = a.get("oxyline") or a.get("native") or {}
            cols = ox.get("columns") or {}
            row.append(max(cols, key=cols.get) if cols else "–")
            ref = r.get("reference") or {}
            agree = a.get("agreement")
            row += ["–" if agree is None else f"{agree:.1e}", ref.get("impl", "–"),
                    _f(ref.get("wall_s"))]
            out.append("| " + " | ".join(row) + " |")
        out.append("")
    if notes:
        out += ["Failures:", "", *notes, ""]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="1e2,1e3,1e4,1e5",
                    help="comma-separated vessel counts (default 1e2,1e3,1e4,1e5)")
    ap.add_argument("--topologies", default="chain,tree", help="chain,tree (default both)")
    ap.add_argument("--repeat", type=int, default=1,
                    help="fresh processes per measurement; the best time is kept (default 1)")
    ap.add_argument("--quick", action="store_true", help="only N = 1e2 and 1e3")
    ap.add_argument("--with-svzerod-1e5", action="store_true",
                    help="also run svzerod at N >= 1e5 (expected to exceed time/memory)")
    ap.add_argument("--svzerod-timeout", type=float, default=900.0,
                    help="timeout (s) of a svzerod run at N >= 1e5 (default 900)")
    ap.add_argument("--timeout", type=float, default=3600.0, help="timeout (s) of any other run")
    ap.add_argument("--accuracy-sizes", default="1e2,1e3",
                    help="sizes with the accuracy check (default 1e2,1e3; '' for none)")
    ap.add_argument("--reference", choices=("svzerod", "oxyline"), default="svzerod",
                    help="solver of the 5x finer reference run (default svzerod; oxyline runs "
                         "the same scheme, see the accuracy table at N = 1e2, 1e3)")
    ap.add_argument("--impls", default=",".join(IMPLS),
                    help="subset of svzerod,oxyline,native (default all)")
    ap.add_argument("--cycles", type=int, default=networks.CYCLES)
    ap.add_argument("--pts", type=int, default=networks.PTS_PER_CYCLE,
                    help="time points per cycle (default 1000)")
    ap.add_argument("--output", default=str(HERE / "results.md"),
                    help="Markdown file to write ('' for none)")
    ap.add_argument("--append", action="store_true",
                    help="append to the output file instead of replacing it")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)

    if args.child:
        rec = child(json.loads(args.child))
        print(MARK + json.dumps(rec), flush=True)
        return 0

    sizes = [_size(s) for s in args.sizes.split(",") if s.strip()]
    if args.quick:
        sizes = [s for s in sizes if s <= 1000] or [100, 1000]
    topologies = [t.strip() for t in args.topologies.split(",") if t.strip()]
    impls = [i.strip() for i in args.impls.split(",") if i.strip()]
    acc_sizes = {_size(s) for s in args.accuracy_sizes.split(",") if s.strip()}
    for t in topologies:
        if t not in networks.GENERATORS:
            ap.error(f"unknown topology {t!r}")
    for i in impls:
        if i not in IMPLS:
            ap.error(f"unknown implementation {i!r}")
    missing = oxyline_available()
    if missing and ("oxyline" in impls or "native" in impls):
        print(f"oxyline.svzerod is not importable ({missing}); oxyline runs skipped",
              file=sys.stderr)
        impls = [i for i in impls if i == "svzerod"]

    info = machine()
    load0 = os.getloadavg()
    started = datetime.datetime.now(datetime.timezone.utc)
    print(f"# {started:%Y-%m-%d %H:%M} UTC, {info['nproc']} x {info['cpu']}, load {load0[0]:.2f}",
          file=sys.stderr)
    tmp = tempfile.TemporaryDirectory(prefix="oxyline-bench-")
    results = []
    for n in sizes:
        for topo in topologies:
            r: dict[str, Any] = {"topology": topo, "n": n}
            check = n in acc_sizes
            files = {}
            base = {"topology": topo, "n": n, "cycles": args.cycles, "pts": args.pts}
            for impl in impls:
                big = n >= 100_000 and impl == "svzerod"
                if big and not args.with_svzerod_1e5:
                    continue
                spec = dict(base, impl=impl)
                if check:
                    files[impl] = spec["save"] = os.path.join(tmp.name, f"{topo}{n}-{impl}.npz")
                print(f"  {topo} {n} {impl} ...", end="", file=sys.stderr, flush=True)
                mem_limit = None
                if n >= 100_000:  # keep a runaway run from exhausting a shared machine
                    mem_limit = 0.8 * os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") \
                        / 2**20
                r[impl] = measure(spec, args.repeat,
                                  args.svzerod_timeout if big else args.timeout, mem_limit)
                v = r[impl]
                print(f" {v['error']}" if "error" in v else
                      f" {v['wall_s']:.3f} s, {v['peak_mb']:.0f} MB (load {v['loadavg']:.2f})",
                      file=sys.stderr)
            if check and files:
                ref = dict(base, impl=args.reference, pts=5 * (args.pts - 1) + 1, output_interval=5,
                           save=os.path.join(tmp.name, f"{topo}{n}-ref.npz"))
                print(f"  {topo} {n} reference ...", end="", file=sys.stderr, flush=True)
                v = run_child(ref, args.timeout)
                if "error" in v:
                    r["accuracy"] = {"error": f"reference failed: {v['error']}"}
                    print(f" {v['error']}", file=sys.stderr)
                else:
                    files["ref"] = ref["save"]
                    r["accuracy"] = accuracy(files)
                    r["reference"] = {"impl": args.reference, "wall_s": v["wall_s"]}
                    print(" " + ", ".join(f"{k} {a.get('max', a.get('error'))}"
                                          for k, a in r["accuracy"].items()
                                          if isinstance(a, dict)), file=sys.stderr)
                for f in files.values():
                    Path(f).unlink(missing_ok=True)
            results.append(r)
    tmp.cleanup()
    load1 = os.getloadavg()
    header = [
        f"## svzerod vs oxyline, {started:%Y-%m-%d %H:%M} UTC",
        "",
        f"Machine: {info['nproc']} CPUs ({info['cpu']}), {info['mem']} RAM; Python "
        f"{info['python']}; " + ", ".join(f"{k} {v}" for k, v in info["versions"].items())
        + f"; oxyline commit {info['commit']}; core library built {info['core_built']}.",
        (f"Load average (1 min) at start {load0[0]:.2f}, at end {load1[0]:.2f} (other "
         "processes share the machine; see the per-run load in the breakdown table)."),
        f"Models: benches/networks.py, {args.cycles} cycles x {args.pts} points per cycle, "
        "svzerod defaults. Command: `python benches/bench_svzerod.py "
        + " ".join(sys.argv[1:] if argv is None else argv) + "`",
        "",
        "",
    ]
    text = "\n".join(header) + tables(results)
    print(text)
    if args.output:
        out = Path(args.output)
        if args.append and out.exists():
            out.write_text(out.read_text().rstrip("\n") + "\n\n" + text)
        else:
            out.write_text("# Benchmark results\n\n" + text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
