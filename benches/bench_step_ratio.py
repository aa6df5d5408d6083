"""Per-step O2/flow cost, interleaved (O2 ≤ 1.6× flow per step, Hill ≤ 2×).

Single runs of the same build drift by ±30 % on this machine (docs/performance.md),
so a ratio of two separate runs cannot show a 1.6× bound. Here every configuration of one
tree and integrator runs at the same time, each a single ``oxyline.simulate`` call in its own
thread, built once (``load_model``; the steady start, RK4's step size and the closures' first
pass happen once per configuration, untimed), and the runs take turns: flow, o2-k, o2-leveque,
o2-hill-k, o2-default, flow, ... one block each, only one stepping at a time. A block is a
span of simulated time, the same for every run: ~1.7e7 segment-steps (1 s of a 16 k-segment
tree at 1 ms steps, 0.256 s at 65 k and above; never under 256 steps, the core's progress
check interval). Its cost is the thread CPU time (``time.thread_time``: the core steps on the
calling thread, the GIL released) between the run's resumption and the progress check that
ends the block; its steps are its simulated time over the run's step (RK4: each run's own
automatic step). Slow drift of the machine then lands on both sides of each ratio alike, and all
configurations advance in lockstep, so each round's blocks cover the same part of the cycle
(systole costs more Newton iterations than diastole).

What "per step" covers: the main (coupled) pass only — the flow step, the species step and
the output rows recorded during those steps (vessel-level every 10 ms, as in
``bench_scale.py``). Not included: loading, the steady start, RK4's stability probe and
the flow-only first pass of the Lévêque and default closures (with the default closure's
flow harmonics and backward wall strain), which are one-off per run and reported by
``bench_scale.py``'s whole-run column (``O2/flow run``).

Figures per configuration: ns per segment-step (median over the timed blocks), the ratio to
flow (median over rounds of the same round's O2 block / flow block; "min ratio" is
min O2 block / min flow block), the spread of the config's own blocks (max/min: drift plus the
cycle phase) and of its per-round ratios (max/min: what the interleaving leaves).

    python benches/bench_step_ratio.py                  # 16 k, 65 k, 262 k; gen-α and RK4
    python benches/bench_step_ratio.py --large          # ... and 1.05 M (gen-α)
    python benches/bench_step_ratio.py --depths 18 --rk4-max-depth 18   # 1.05 M, both
    python benches/bench_step_ratio.py --depths 12 --rounds 3 --methods rk4
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Any

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_scale import CONFIGS, PERIOD, tree

import oxyline

CHECK_STEPS = 256  # the core's progress check interval (run/cycle.rs)
FIRST_PASS = {"o2-leveque", "o2-default"}  # closures with a flow-only first pass
GA_DT = 1e-3
BLOCK_SEGMENT_STEPS = 65532 * CHECK_STEPS  # generalized-α step, as in bench_scale.py
WAIT_S = 3600.0  # a lane that does not answer in an hour is stuck


@dataclass
class Lane:
    """One configuration's run: its thread, its progress marks and its timed blocks."""

    config: str
    model: Any
    kw: dict[str, Any]
    cancel: threading.Event = field(default_factory=threading.Event)
    in_main: bool = False
    waiting: bool = False
    done: bool = False
    last_t: float = -1.0
    resumed: tuple[float, float] | None = None  # (t, thread CPU s) when last given the turn
    blocks: list[tuple[float, float, float]] = field(default_factory=list)  # (t0, t1, CPU s)
    result: Any = None
    error: str | None = None


class Interleave:
    """Round-robin turns between lanes: one lane steps while the others wait in their progress
    callback (a wait costs no CPU time, so each lane's thread CPU time is its own steps)."""

    def __init__(self, lanes: list[Lane], block_time: float) -> None:
        self.lanes = lanes
        self.block_time = block_time  # simulated s per block
        self.cond = threading.Condition()
        self.turn: Lane | None = None
        self.stop = False

    def callback(self, lane: Lane, t: float) -> None:
        cpu = time.thread_time()
        if self.stop:
            # the run's last report, after its cancel (the core reports the cycle end)
            lane.cancel.set()
            return
        if t < lane.last_t:
            # a new pass (the first pass ended): what was timed so far was not the main pass
            lane.blocks.clear()
            lane.resumed = None
            lane.in_main = True
        lane.last_t = t
        # a closure's first pass runs untimed without waiting for its turn; its main pass is
        # recognised by the time going back to 0, or, when the first pass was too short to
        # report progress, by the main pass's first check at 256 steps of the set step
        if not lane.in_main:
            dt = lane.kw.get("dt")
            first_check = dt is not None and abs(t - CHECK_STEPS * dt) < 1e-9 * PERIOD
            if lane.config in FIRST_PASS and not first_check:
                return
            lane.in_main = True
        # a block is a span of simulated time, the same for every lane (lockstep also when
        # their steps differ); it ends at the first progress check that reaches Python after
        # it (the binding passes at most one check per 100 ms wall to Python)
        if lane.resumed is not None and t < lane.resumed[0] + self.block_time * (1 - 1e-9):
            return  # the block goes on
        if lane.resumed is not None:
            lane.blocks.append((lane.resumed[0], t, cpu - lane.resumed[1]))
        with self.cond:
            lane.waiting = True
            self.cond.notify_all()
            self.cond.wait_for(lambda: self.stop or self.turn is lane)
            lane.waiting = False
            self.turn = None  # taken: the coordinator now waits for the next check
            self.cond.notify_all()
            if self.stop:
                lane.cancel.set()  # simulate() raises SimulationCancelled after this callback
                return
        lane.resumed = (t, time.thread_time())

    def run_lane(self, lane: Lane) -> None:
        try:
            lane.result = oxyline.simulate(
                lane.model, progress=lambda t, _t_end: self.callback(lane, t),
                cancel=lane.cancel, **lane.kw)
            lane.error = "the run ended before the blocks were timed (more cycles needed)"
        except oxyline.SimulationCancelled as exc:
            lane.result = exc.result
        except Exception as exc:  # noqa: BLE001  (reported in the table, the others go on)
            lane.error = f"{type(exc).__name__}: {exc}"
        finally:
            with self.cond:
                lane.done = True
                self.cond.notify_all()

    def rounds(self, n: int) -> None:
        """Start every lane, wait until all are in their main pass, then give each lane ``n``
        turns in round-robin order; stop them all."""
        threads = [threading.Thread(target=self.run_lane, args=(ln,), daemon=True)
                   for ln in self.lanes]
        for th in threads:
            th.start()
        try:
            with self.cond:
                ok = self.cond.wait_for(lambda: all(ln.waiting or ln.done for ln in self.lanes),
                                        timeout=WAIT_S)
                if not ok:
                    raise RuntimeError("a run did not reach its main pass")
                for _ in range(n):
                    for ln in self.lanes:
                        if ln.done:
                            continue
                        self.turn = ln
                        self.cond.notify_all()
                        # the lane takes the turn (clears it), steps, and waits again at its
                        # next check
                        if not self.cond.wait_for(
                                lambda ln=ln: ln.done or (self.turn is None and ln.waiting),
                                timeout=WAIT_S):
                            raise RuntimeError(f"{ln.config}: no progress check in an hour")
                        self.turn = None
        finally:
            with self.cond:
                self.stop = True
                self.cond.notify_all()
            for th in threads:
                th.join()


def measure(depth: int, method: str, configs: list[str], rounds: int, warmup: int = 1,
            per_vessel: int = 4, checks: int | None = None) -> tuple[int, list[Lane]]:
    """Time ``rounds`` interleaved blocks per configuration (after ``warmup`` untimed ones);
    (segments, lanes). Each lane's ``blocks`` are (t0, t1, CPU s) of its main pass.

    A block is ~1.7e7 segment-steps (~0.5 s of generalized-α flow, at least 256 steps), so
    that small trees are not timed in slivers of a few ms. The run gets enough cycles for the
    blocks, not more: a closure's first pass runs as many cycles as the run (until its mean
    flow settles), untimed but not free. ``checks``: progress checks per block instead."""
    models = [oxyline.load_model(tree(depth, per_vessel, c)) for c in configs]
    segments = int(models[0].network.summary()["segments"])
    kw: dict[str, Any] = {"output_every": 0.01, "segments": False, "method": method}
    if method == "generalized-alpha":
        kw["dt"] = dt = GA_DT
    else:
        # RK4's automatic step is at most half its stability limit (run/plan.rs; an O2 run's
        # may be smaller still: more steps per block, the same simulated time)
        dt = 0.5 * models[0].network.rk4_stability_limit()[0]
    if checks is None:
        checks = max(1, round(BLOCK_SEGMENT_STEPS / (segments * CHECK_STEPS)))
    block_time = checks * CHECK_STEPS * dt
    # + the first check, one block of overshoot (the binding's 100 ms check filter), a cycle
    kw["cycles"] = math.ceil((warmup + rounds + 2) * block_time / PERIOD) + 1
    lanes = [Lane(c, m, dict(kw)) for c, m in zip(configs, models)]
    Interleave(lanes, block_time).rounds(warmup + rounds)
    for ln in lanes:
        if ln.error is None and len(ln.blocks) > rounds:
            ln.blocks = ln.blocks[-rounds:]  # the warm-up blocks are left out
    return segments, lanes


def steps_of(lane: Lane, block: tuple[float, float, float]) -> int:
    """Steps in a block, from the simulated time it covered and the run's step."""
    return round((block[1] - block[0]) / float(lane.result.settings["dt"]))


def per_step(lane: Lane) -> list[float]:
    """CPU s per step of each timed block."""
    return [b[2] / steps_of(lane, b) for b in lane.blocks]


def rows(segments: int, method: str, lanes: list[Lane]) -> list[str]:
    """Table rows of one tree and integrator (ratios to the flow lane of the same rounds)."""
    flow = next((ln for ln in lanes if ln.config == "flow" and ln.error is None), None)
    out = []
    fs = per_step(flow) if flow and flow.blocks else []
    for ln in lanes:
        if ln.error is not None or not ln.blocks:
            out.append(f"| {segments} | {method} | {ln.config} | failed: "
                       f"{ln.error or 'no timed block'} |")
            continue
        ps = per_step(ln)
        ns = 1e9 * statistics.median(ps) / segments
        spread = max(ps) / min(ps)
        ratio = ratio_min = ratio_spread = "–"
        if ln is not flow and fs:
            per_round = [a / b for a, b in zip(ps, fs)]
            ratio = f"**{statistics.median(per_round):.2f}**"
            ratio_min = f"{min(ps) / min(fs):.2f}"
            ratio_spread = f"{max(per_round) / min(per_round):.2f}"
        steps = sum(steps_of(ln, b) for b in ln.blocks)
        out.append(f"| {segments} | {method} | {ln.config} | {ln.result.settings['dt']:.3g} | "
                   f"{len(ln.blocks)} × {steps // len(ln.blocks)} | {ns:.1f} | {ratio} | "
                   f"{ratio_min} | {spread:.2f} | {ratio_spread} |")
    return out


HEADER = ("| segments | method | config | dt s | blocks × steps | ns/seg-step (median) "
          "| O2/flow per step (median of rounds) | O2/flow (min/min) | block spread max/min "
          "| ratio spread max/min |\n|---:|---|---|---:|---:|---:|---:|---:|---:|---:|")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--depths", type=int, nargs="+", default=[12, 14, 16],
                    help="tree depths (2^depth - 1 vessels × 4 segments: 12 → 16 k, 14 → 65 k, "
                         "16 → 262 k, 18 → 1.05 M)")
    ap.add_argument("--large", action="store_true", help="also depth 18 (1.05 M segments, "
                    "generalized-α; ~12 GB for the five configurations)")
    ap.add_argument("--methods", nargs="+", default=["generalized-alpha", "rk4"],
                    choices=["generalized-alpha", "rk4"])
    ap.add_argument("--rk4-max-depth", type=int, default=14,
                    help="largest tree run with RK4 (its closures' first pass is 2 000 "
                         "generalized-α steps per cycle, ~1 min per configuration at 262 k; "
                         "18 with --large: 1.05 M segments, ~12 GB)")
    ap.add_argument("--configs", nargs="+", default=CONFIGS, choices=CONFIGS)
    ap.add_argument("--rounds", type=int, default=6, help="timed blocks per configuration")
    ap.add_argument("--warmup", type=int, default=1, help="untimed blocks first")
    a = ap.parse_args()
    configs = ["flow", *[c for c in a.configs if c != "flow"]]
    depths = a.depths + ([18] if a.large and 18 not in a.depths else [])
    print(f"# interleaved blocks of ~{BLOCK_SEGMENT_STEPS:.2g} segment-steps (>= {CHECK_STEPS} "
          f"steps), {a.rounds} timed (+{a.warmup} warm-up) per configuration, main pass only; "
          f"thread CPU time; binary trees, 4 segments per "
          f"vessel, vessel output every 10 ms; {os.cpu_count()} CPUs, load average "
          f"{os.getloadavg()[0]:.1f}")
    print(HEADER)
    skipped = []
    t0 = time.perf_counter()
    for method in a.methods:
        for depth in depths:
            if method == "rk4" and depth > a.rk4_max_depth:
                skipped.append(f"{method} depth {depth}")
                continue
            segments, lanes = measure(depth, method, configs, a.rounds, a.warmup)
            print("\n".join(rows(segments, method, lanes)), flush=True)
    print(f"\n{time.perf_counter() - t0:.0f} s wall; load average {os.getloadavg()[0]:.1f}"
          + (f"; not run: {', '.join(skipped)} (--rk4-max-depth)" if skipped else ""))


if __name__ == "__main__":
    main()
