"""``oxyline.impedance(model, node, direction=...)`` at a junction against the closed form of
the same hand-built lumped network, computed here with numpy (no oxyline output).

The network: a feed vessel ``p`` (in → j, flow inlet) and two daughters ``a`` (j → oa,
resistance outlet) and ``b`` (j → ob, three-element Windkessel), all lumped (R, L, C per
vessel, split evenly over its segments). Per arrangement a segment is the series branch
z = r + iωl between its end nodes with its capacitor c at the proximal node (inverted-L), the
distal node (L) or half at each (π). The impedance of a ladder follows from its far end by
Z ← 1/(iω c_node + 1/(z + Z)). Seen from j:

* downstream: the daughters in parallel, each with its own capacitor shares at j;
* upstream: the feed vessel seen backwards from j, closed at its flow inlet (zero flow), with
  its own capacitor share at j;
* both: the two in parallel (every branch and the whole capacitance at j).

Tolerance 1e-9: two exact evaluations of a rational function (the core's sparse elimination
of the ~40-unknown circuit and this recursion) differ by rounding times conditioning.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

import oxyline

VESSELS = {  # R (Pa s/m^3), L (Pa s^2/m^3), C (m^3/Pa), segments
    "p": (4.0e7, 2.0e6, 6.0e-11, 3),
    "a": (9.0e7, 3.5e6, 3.0e-11, 4),
    "b": (1.6e8, 5.0e6, 2.0e-11, 2),
}
RA = 2.0e9  # resistance outlet of a
RP, CW, RD = 3.0e8, 4.0e-10, 1.7e9  # Windkessel outlet of b
FREQS = np.array([0.5, 1.0, 3.0, 10.0, 25.0])
SHARES = {"inverted-L": (1.0, 0.0), "L": (0.0, 1.0), "pi": (0.5, 0.5)}


def network(arrangement: str) -> dict[str, Any]:
    ends = {"p": ("in", "j"), "a": ("j", "oa"), "b": ("j", "ob")}
    vessels = [{"name": n, "from": ends[n][0], "to": ends[n][1], "segments": k,
                "lumped": {"resistance": r, "inductance": ll, "capacitance": c}}
               for n, (r, ll, c, k) in VESSELS.items()]
    return {"name": "junction", "units": "SI", "arrangement": arrangement, "period": 1.0,
            "vessels": vessels,
            "boundary_conditions": {
                "in": {"type": "flow", "value": 1e-6},
                "oa": {"type": "resistance", "resistance": RA},
                "ob": {"type": "rcr", "proximal_resistance": RP, "capacitance": CW,
                       "distal_resistance": RD}}}


def node_caps(name: str, arrangement: str) -> np.ndarray:
    """Capacitance of vessel ``name`` at each of its k + 1 nodes (inlet first)."""
    _, _, c, k = VESSELS[name]
    prox, dist = SHARES[arrangement]
    caps = np.zeros(k + 1)
    caps[:-1] += prox * c / k
    caps[1:] += dist * c / k
    return caps


def forward(name: str, arrangement: str, w: float, z_load: complex) -> complex:
    """Vessel ``name`` seen from its inlet node (its own capacitance there included), ending
    in the load ``z_load`` at its outlet node."""
    r, ll, _, k = VESSELS[name]
    caps = node_caps(name, arrangement)
    z_seg = (r + 1j * w * ll) / k
    y = 1j * w * caps[k] + 1.0 / z_load
    for i in range(k - 1, -1, -1):
        y = 1j * w * caps[i] + 1.0 / (z_seg + 1.0 / y)
    return complex(1.0 / y)


def backward(name: str, arrangement: str, w: float) -> complex:
    """Vessel ``name`` seen backwards from its outlet node, its inlet closed (flow inlet)."""
    r, ll, _, k = VESSELS[name]
    caps = node_caps(name, arrangement)
    z_seg = (r + 1j * w * ll) / k
    y = 1j * w * caps[0]  # the closed end: only its capacitor (none for L: open circuit)
    for i in range(1, k + 1):
        y = 1j * w * caps[i] + (1.0 / (z_seg + 1.0 / y) if y != 0 else 0.0)
    return complex(1.0 / y)


def expected(arrangement: str, direction: str, f: float) -> complex:
    w = 2 * math.pi * f
    z_wk = RP + 1.0 / (1j * w * CW + 1.0 / RD)
    y_down = (1.0 / forward("a", arrangement, w, RA)
              + 1.0 / forward("b", arrangement, w, z_wk))
    y_up = 1.0 / backward("p", arrangement, w)
    return complex(1.0 / {"downstream": y_down, "upstream": y_up,
                          "both": y_down + y_up}[direction])


@pytest.mark.parametrize("arrangement", list(SHARES))
@pytest.mark.parametrize("direction", ["downstream", "upstream", "both"])
def test_junction_impedance_matches_the_ladder_closed_form(arrangement: str,
                                                           direction: str) -> None:
    z = oxyline.impedance(network(arrangement), "j", FREQS, direction=direction)
    want = np.array([expected(arrangement, direction, f) for f in FREQS])
    np.testing.assert_allclose(z, want, rtol=1e-9)


def test_downstream_is_the_default_and_differs_from_the_junction_view() -> None:
    m = network("inverted-L")
    z = oxyline.impedance(m, "j", FREQS)
    np.testing.assert_allclose(z, oxyline.impedance(m, "j", FREQS, direction="downstream"),
                               rtol=1e-12)
    # the feed vessel's dead end matters: the junction view is far from the downstream one
    both = oxyline.impedance(m, "j", FREQS, direction="both")
    assert np.abs(both / z - 1).max() > 0.1


def test_zero_frequency_downstream_is_the_steady_resistance() -> None:
    """Z(0) downstream of j = (R_a + R_A) ∥ (R_b + R_p + R_d), for every arrangement."""
    want = 1.0 / (1.0 / (VESSELS["a"][0] + RA) + 1.0 / (VESSELS["b"][0] + RP + RD))
    for arrangement in SHARES:
        z = oxyline.impedance(network(arrangement), "j", [0.0])[0]
        assert z.real == pytest.approx(want, rel=1e-12)
        assert abs(z.imag) <= 1e-12 * want


@pytest.mark.parametrize("bad", ["down", "", "Downstream", None, 1])
def test_bad_direction_is_a_model_error_naming_the_argument(bad: Any) -> None:
    with pytest.raises(oxyline.ModelError, match="direction"):
        oxyline.impedance(network("L"), "j", [1.0], direction=bad)


def test_empty_and_closed_sides_are_typed_errors() -> None:
    m = network("inverted-L")
    with pytest.raises(oxyline.ModelError, match="nothing upstream"):
        oxyline.impedance(m, "in", [1.0], direction="upstream")
    # the feed vessel seen from j is closed at its flow inlet: no finite Z(0)
    with pytest.raises(oxyline.ModelError, match="no pressure boundary.*0 Hz"):
        oxyline.impedance(m, "j", [0.0], direction="upstream")
