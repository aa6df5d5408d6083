"""benches/bench_step_ratio.py runs: its smallest tree (16 k segments) for
one interleaved block per configuration. No timing is asserted (speed lives in the bench).
Independent truth: species are passive in the flow (one-way coupling, docs/oxygen.md: the
transport reads the flow, never writes it), so the O2 runs' flows equal the flow-only run's."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from conftest import REPO

import oxyline

sys.path.insert(0, str(REPO / "benches"))
import bench_step_ratio

CONFIGS = ["flow", "o2-k", "o2-default"]  # o2-default: a first pass before the main one


@pytest.fixture(scope="module")
def lanes() -> tuple[int, list[bench_step_ratio.Lane]]:
    # one warm-up and one timed block of 256 steps each
    return bench_step_ratio.measure(12, "generalized-alpha", CONFIGS, rounds=1, warmup=1,
                                    checks=1)


def test_every_configuration_is_timed_in_its_main_pass(lanes):
    segments, ls = lanes
    assert segments == (2 ** 12 - 1) * 4
    for ln in ls:
        assert ln.error is None, (ln.config, ln.error)
        assert len(ln.blocks) == 1, ln.config
        t0, t1, cpu = ln.blocks[0]
        # the timed block follows the warm-up block in the main pass (from step 512 at 1 ms)
        # and lasts at least 256 steps, a whole number of progress checks (longer only if
        # the binding held back a check, at most one per 100 ms reaches Python)
        assert t0 >= 0.512 - 1e-9 and t1 - t0 >= 0.256 - 1e-9, ln.config
        steps = bench_step_ratio.steps_of(ln, ln.blocks[0])
        assert steps >= 256 and steps % 256 == 0, (ln.config, steps)
        assert cpu > 0
    assert [bool(ln.result.species) for ln in ls] == [False, True, True]
    table = bench_step_ratio.rows(segments, "generalized-alpha", ls)
    assert len(table) == len(CONFIGS) and not any("failed" in r for r in table)


def test_oxygen_runs_leave_the_flow_unchanged() -> None:
    """The bench's trees run whole (the lanes above stop at different cycles: a fast lane
    overshoots by a block when the binding holds back a progress check, so their rows are not
    comparable): the same cycles of flow only and of each O2 configuration."""
    kw = {"cycles": 1, "dt": bench_step_ratio.GA_DT, "output_every": 0.01, "segments": False,
          "method": "generalized-alpha"}
    runs = {c: oxyline.simulate(bench_step_ratio.tree(10, 4, c), **kw) for c in CONFIGS}
    flow = runs["flow"]
    q = flow.flow_in
    assert len(flow.time) > 50  # every 10 ms over a cycle
    scale = np.abs(q).max()
    for config in CONFIGS[1:]:
        res = runs[config]
        np.testing.assert_allclose(res.time, flow.time, rtol=0, atol=1e-12)
        # the same Newton on the same circuit: round-off only (1e-12 of the peak flow)
        np.testing.assert_allclose(res.flow_in, q, rtol=0, atol=1e-12 * scale, err_msg=config)
