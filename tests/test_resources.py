"""Resource exhaustion: a model or an output too large for the memory allowed
is refused with a typed ResourceError (estimate + the setting to change) before anything is
allocated; large buffers in the core are allocated fallibly; large outputs are announced.

Every refusal runs in a child process whose address space is capped (RLIMIT_AS), so that a
regression fails the test instead of taking the machine's memory."""

from __future__ import annotations

import json
import os
import sys
import textwrap

import pytest
from conftest import run_child

import oxyline
from oxyline import memory

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_AS and /proc: Linux")

CAP = 4 * 2**30  # bytes of address space for the child (Python, numpy and the core need ~1 GB)


def _capped() -> None:
    import resource
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)
    resource.setrlimit(resource.RLIMIT_AS, (CAP, CAP))


def _child(code: str) -> list[str]:
    """Run ``code`` (after ``import oxyline``) in a capped child; its stdout lines."""
    done = run_child([sys.executable, "-c", "import oxyline, warnings\n" + textwrap.dedent(code)],
                     timeout=300, preexec_fn=_capped)
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout.splitlines()


REFUSE = """
    def refused(what, f):
        try:
            f()
            print(what, "ran")
        except oxyline.ResourceError as exc:
            print(what, "ResourceError", exc)
        except oxyline.ModelError as exc:
            print(what, "ModelError", exc)
    def tube(**extra):
        v = {"name": "tube", "from": "in", "to": "out", "length": 0.1, "radius": 0.003}
        d = {"vessels": [v], "boundary_conditions": {
            "in": {"type": "flow", "flow": 1e-6}, "out": {"type": "resistance",
                                                          "resistance": 1e8}}}
        v.update(extra.pop("vessel", {}))
        d.update(extra)
        return d
"""


def test_huge_models_and_outputs_are_refused_before_allocating() -> None:
    lines = _child(REFUSE + """
    refused("segments", lambda: oxyline.load_model(tube(vessel={"segments": 10**9})))
    refused("max_length", lambda: oxyline.load_model(tube(segmentation={"max_length": 1e-9})))
    refused("whole-body", lambda: oxyline.simulate("whole-body-140", cycles=2000,
                                                   output_cycles="all"))
    refused("whole-body-all", lambda: oxyline.simulate("whole-body-140", cycles=2000,
                                                       until_periodic=None, output_cycles="all"))
    refused("output_every", lambda: oxyline.simulate("bifurcation", output_every=1e-7))
    # the limit is a setting: a model file's, or simulate()'s
    refused("file-limit", lambda: oxyline.load_model(tube(
        vessel={"segments": 10000}, simulation={"max_memory": "1 MB"})))
    refused("run-limit", lambda: oxyline.simulate("bifurcation", cycles=2, output_cycles="all",
                                                  max_memory=1e5))
    """)
    out = {line.split(" ", 1)[0]: line.split(" ", 1)[1] for line in lines}
    limit = "above max_memory = "
    assert out["segments"].startswith("ResourceError model 'network' (1000000000 segments): "
                                      "needs about 752.000 GB of memory (estimate), " + limit)
    assert "segmentation max_length" in out["segments"] and "OXYLINE_MAX_MEMORY" in out["segments"]
    # 0.1 m / 1 nm = 1e8 segments
    assert out["max_length"].startswith("ResourceError model 'network' (100000000 segments)")
    # as the issue wrote it, the call is refused by its settings (max_cycles 200 < 2000 cycles)
    assert out["whole-body"].startswith("ModelError simulation: max_cycles (200) is less than")
    assert out["whole-body-all"].startswith("ResourceError simulate: the output (2000001 rows x ")
    assert "output_cycles='last'" in out["whole-body-all"] and "max_memory" in out["whole-body-all"]
    assert out["output_every"].startswith("ResourceError simulate: the output (10000001 rows x ")
    assert out["file-limit"].endswith("") and "max_memory = 1.000 MB" in out["file-limit"]
    assert out["run-limit"].startswith("ResourceError simulate: the output (2001 rows")
    assert "max_memory = 100.000 kB" in out["run-limit"]


def test_a_failed_large_allocation_in_the_core_is_a_resource_error() -> None:
    """With no limit set, the circuit's tables (1e8 segments, ~10 GB) do not fit the capped
    address space: the core's fallible allocation reports it instead of aborting."""
    lines = _child(REFUSE + """
    refused("alloc", lambda: oxyline.load_model(tube(vessel={"segments": 10**8},
                                                     simulation={"max_memory": "none"})))
    """)
    assert lines[0].startswith("alloc ResourceError circuit "), lines
    assert "cannot allocate" in lines[0] and "out of memory" in lines[0]


def test_a_large_streamed_output_is_announced_before_the_run(tmp_path: object) -> None:
    lines = _child(f"""
    warnings.simplefilter("error", oxyline.OutputSizeWarning)
    try:
        oxyline.simulate_to_zarr("bifurcation", {str(tmp_path)!r} + "/big.zarr",
                                 output_every=1e-7)
    except oxyline.OutputSizeWarning as w:
        print("warned", w)
    """)
    assert lines[0].startswith("warned ") and "big.zarr: the output (10000001 rows x " in lines[0]
    assert "GB on disk" in lines[0]


def test_max_memory_values_are_checked() -> None:
    assert memory.parse("8 GB", "x") == 8e9
    assert memory.parse("512MiB", "x") == 512 * 2**20
    assert memory.parse(1e9, "x") == 1e9
    assert memory.parse("none", "x") is None
    for bad in ("lots", -1, 0, True, float("nan")):
        with pytest.raises(oxyline.ModelError, match="x must be a number of bytes > 0"):
            memory.parse(bad, "x")
    with pytest.raises(oxyline.ModelError, match="simulate: max_memory must be"):
        oxyline.simulate("bifurcation", max_memory="lots")


MEASURE = """
import ctypes, json, sys, oxyline
from oxyline import memory
from oxyline.run import _output_size, _settings

def rss(key):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key):
                return float(line.split()[1]) * 1024

# imports and first-use allocations (of both the default error-controlled run and RK4's
# step estimate, whose dense scratch the paper's RK4 run needs)
oxyline.simulate("bifurcation", cycles=1)
oxyline.simulate("bifurcation", cycles=1, method="rk4")
# the warm-up's freed pages handed back and the high-water mark reset, so that the run's
# own allocations count (a run reusing them would understate the peak of a fresh process)
ctypes.CDLL(None).malloc_trim(0)
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")
base = rss("VmRSS:")
name, max_length, kw = json.loads(sys.argv[1])
d = oxyline.load_model(name).to_dict()
if max_length:
    d["segmentation"] = {"max_length": max_length}
    for v in d["vessels"]:
        v.pop("segments", None)
m = oxyline.load_model(d)
s = _settings(m, kw)
estimate = memory.run_estimate(m.network, s) + _output_size(m, s)[0]
oxyline.simulate(m, **kw)
print(json.dumps([estimate, rss("VmHWM:") - base]))
"""


@pytest.mark.parametrize("case", [
    # model-dominated: 8,931 segments, flow only
    ("adan56", 1e-3, {"cycles": 1, "segments": False, "method": "generalized-alpha"}),
    # oxygen (one species): 9,440 segments and cells
    # (the file asks for the paper's RK4, whose stable step at 20 µm segments is tiny)
    ("paper-bifurcated", 2e-5, {"cycles": 1, "segments": False,
                                "method": "generalized-alpha"}),
    # output-dominated: every row of 4 cycles, all vessels and segments
    ("whole-body-140", None, {"cycles": 4, "until_periodic": None, "output_cycles": "all"}),
])
def test_the_estimate_is_within_a_small_factor_of_the_measured_peak(case: tuple) -> None:
    """The estimate (the core's count of the run from its network's sizes + the output;
    these runs are error-controlled) against the measured peak resident memory the load and
    run add to a warmed-up process. Measured (load average ~12, two runs each): 1.02-1.04x
    (adan56, 12.1 vs 11.7-11.9 MB), 0.94-0.96x (oxygen, 13.6 vs 14.2-14.5 MB), 0.96x (output,
    133.5 vs 139.6 MB: the output is
    counted at its 8 bytes a value, the result's own objects come on top); from 131 k to
    10.5 M segments 1.05-1.23x (docs/performance.md). An estimate is meant to err high,
    never far below the real need. Factor stated: 0.9 <= estimate / peak <= 1.6."""
    done = run_child([sys.executable, "-c", MEASURE, json.dumps(case)], timeout=600,
                     env={**os.environ, "OXYLINE_MAX_MEMORY": "none"})
    assert done.returncode == 0, done.stderr[-3000:]
    estimate, peak = json.loads(done.stdout.splitlines()[-1])
    assert 0.9 <= estimate / peak <= 1.6, (estimate, peak)


def test_the_core_constants_are_exported() -> None:
    assert oxyline._core.FLOW_BYTES_PER_SEGMENT > 0
    assert oxyline._core.TRANSPORT_BYTES_PER_CELL > 0


@pytest.mark.parametrize(("segments", "vessels", "outlets", "peak"), [
    # depth 18, O2, one generalized-alpha cycle at 1 ms, 4 segments a vessel:
    # benches/profile_memory.py --depth 18 --config o2-k: peak 1 007 MiB (the steps' own; 1 109
    # MiB, the setup's, before RK4's index reduction of the consistent start kept flat work
    # lists, 1 183 MiB before the extension mapped its blocks of 1 MiB or more on their own,
    # 1 216 MiB before the fixed step's stamp map was dropped after its factorisation)
    (1_048_572, 262_143, 131_072, 1_007 * 2.0**20),
    # benches/bench_scale.py --depths 21 --per-vessel 5 --configs o2-k: peak 11 748 MB
    (10_485_755, 2_097_151, 1_048_576, 11_748e6),
])
def test_the_estimate_of_a_measured_large_tree_is_within_its_factor(
        segments: int, vessels: int, outlets: int, peak: float) -> None:
    """The model part of the estimate (without the output's ~5 %) of the binary trees with O2
    whose peaks were measured (docs/performance.md, one generalized-alpha cycle at 1 ms): at
    or above the peak, within 1.5x, and the 10.5 M-segment tree (14.4 GB) under the default
    limit of an idle 24 GB machine (80 % of ~22 GB available)."""
    elements = vessels + outlets + 1  # the vessels, an RCR per outlet, the inflow
    estimate = oxyline._core.model_bytes(segments, elements, 1.0, 1)
    assert 0.95 <= estimate / peak <= 1.5, (estimate, peak)
    assert estimate < 0.8 * 22e9
