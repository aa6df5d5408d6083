"""A large network drops its circuit's node and branch tables once the run's matrices and the
transport plan are built (docs/performance.md, "The circuit's tables off a large run's
peak"): a run reads only those, and the circuit's diagnostics and the impedance assemble the
model anew. Here the drop is asked for on small networks (``keep_circuit=False``), which a
large model gets by default.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

import oxyline
from oxyline import _core


def tree(depth: int) -> dict[str, Any]:
    """A symmetric binary tree of 2^depth - 1 elastic vessels (Murray radii from 5 mm), one
    RCR per leaf, a half-sine inflow and O2 with a constant-k wall."""
    vessels, bcs = [], {}
    n_leaves = 2 ** (depth - 1)
    for i in range(2 ** depth - 1):
        level = int(math.log2(i + 1))
        r = 5e-3 * 2.0 ** (-level / 3.0)
        vessels.append({"name": f"v{i}", "from": "in" if i == 0 else f"n{(i - 1) // 2}",
                        "to": f"n{i}", "length": 10 * r, "radius": r,
                        "wall_thickness": 0.1 * r, "youngs_modulus": 4e5, "segments": 3})
        if level == depth - 1:
            bcs[f"n{i}"] = {"type": "rcr", "proximal_resistance": 1.3e7 * n_leaves,
                            "capacitance": 1e-8 / n_leaves, "distal_resistance": 1.2e8 * n_leaves}
    bcs["in"] = {"type": "flow", "fourier": {"period": 1.0, "mean": 5e-5, "sin": [4e-5]}}
    return {"name": "tree", "period": 1.0, "vessels": vessels, "boundary_conditions": bcs,
            "oxygen": {"inlet": {"po2": 95.0}, "reference_pressure": 85.0, "hemoglobin": "none",
                       "wall": {"model": "mass-transfer", "k": 1e-5, "po2": 60.0}}}


def released(model: dict[str, Any]) -> oxyline.Model:
    """``model`` loaded with its network's circuit tables dropped, as a large model's are."""
    m = oxyline.load_model(model)
    m._network = _core.Network(m.canonical, None, False)
    return m


def test_a_run_reads_none_of_the_released_tables() -> None:
    """The run of a released network: the O2 mass balance closes (a conservation law the run
    does not impose), and its outputs are the kept network's bits (the same matrices and
    plan on the same solver path: exact equality is the claim)."""
    model = tree(3)
    kept = oxyline.load_model(model)
    drop = released(model)
    assert kept.network.circuit_kept() and not drop.network.circuit_kept()
    kw = {"method": "generalized-alpha", "dt": 1e-3, "cycles": 2, "output_every": 0.02}
    a, b = oxyline.simulate(kept, **kw), oxyline.simulate(drop, **kw)
    mb = b.o2_mass_balance
    # (the balance's rounding: 1e-9 of the cycle's inflow)
    assert abs(mb["residual"][-1]) <= 1e-9 * abs(mb["inflow"][-1])
    for name in ("pressure_in", "flow_out", "po2_out"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_the_released_circuit_is_a_model_error_and_the_impedance_assembles_anew() -> None:
    """``circuit()`` of a released network is a typed error saying why; the impedance of such a
    model assembles the model anew: Z(0) seen from the inlet is the steady resistance, the
    root vessel's Poiseuille resistance in series with the leaves' parallel paths (computed
    here, to 1e-9: the elimination's rounding on a ~100-unknown circuit)."""
    model = tree(2)
    m = released(model)
    with pytest.raises(oxyline.ModelError, match="not kept for a model this large"):
        m.network.circuit()
    mu = oxyline.load_model(model).canonical.get("blood", {}).get("viscosity", 4e-3)

    def poiseuille(v: dict[str, Any]) -> float:
        return 8.0 * mu * v["length"] / (math.pi * v["radius"] ** 4)

    vs = model["vessels"]
    leaf = [poiseuille(v) + 1.3e7 * 2 + 1.2e8 * 2 for v in vs[1:]]
    want = poiseuille(vs[0]) + 1.0 / sum(1.0 / r for r in leaf)
    z = oxyline.impedance(m, "in", [0.0])[0]
    assert z.real == pytest.approx(want, rel=1e-9)
    assert not m.network.circuit_kept()  # the model's own network is left as it was
