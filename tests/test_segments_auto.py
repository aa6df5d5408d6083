"""``segments: auto`` against exact transmission lines, and the spatial error estimate.

* A uniform elastic tube closed by a mismatched resistance: its input impedance in closed form,

      Z_in = Z_c (Z_T + Z_c tanh γℓ) / (Z_c + Z_T tanh γℓ),
      γ = √((r + iωl) iωc),  Z_c = √((r + iωl) / (iωc)),

  with r = 8μ/(πa⁴), l = ρ/(πa²), c = 2πa³(1 − ν²)/(E h) per length (a the radius, ν = ½),
  written here from the physics, not read from the model.
* A structured tree against Olufsen's recursion (a line per vessel, parallel at every
  bifurcation: tests/test_womersley.py), Poiseuille friction.

In both, ``auto`` at rtol must bring the input impedance within rtol of the exact one at every
harmonic of the forcing it keeps (:func:`oxyline.forcing_harmonics`), for rtol 1e-2 and 1e-3.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_womersley import A_, B_, EH_R, LRR, olufsen, z_poiseuille

import oxyline
from oxyline.cli import main
from oxyline.convergence import inlet_space_error

RHO, MU = 1050.0, 3.5e-3
RADIUS, LENGTH = 4e-3, 0.3  # m
E, H = 4.0e5, 4e-4  # Pa, m: c ≈ √(E h / 2ρa) ≈ 4.4 m/s
Z_T = 5.0e7  # outlet resistance (Pa s/m^3), ~1/3 of the tube's Z_c: reflections shape Z_in
# a pulse-like inflow: harmonics 1-8 of 1 Hz, amplitudes falling as 1/k^2
INFLOW = {"period": 1.0, "mean": 5e-6,
          "cos": [4e-6 / k**2 for k in range(1, 9)], "sin": [2e-6 / k**2 for k in range(1, 9)]}


def tube(arrangement: str, rtol: float, segments: Any = "auto") -> dict[str, Any]:
    return {"name": "tube", "arrangement": arrangement,
            "blood": {"density": RHO, "viscosity": MU},
            "segmentation": {"rtol": rtol},
            "vessels": [{"name": "v", "from": "in", "to": "out", "length": LENGTH,
                         "radius": RADIUS, "wall_thickness": H, "youngs_modulus": E,
                         "segments": segments}],
            "boundary_conditions": {"in": {"type": "flow", "fourier": INFLOW},
                                    "out": {"type": "resistance", "resistance": Z_T}}}


def exact_tube(f: np.ndarray) -> np.ndarray:
    w = 2 * np.pi * f
    r, l = 8 * MU / (np.pi * RADIUS**4), RHO / (np.pi * RADIUS**2)
    c = 2 * np.pi * RADIUS**3 * 0.75 / (E * H)
    z, y = r + 1j * w * l, 1j * w * c
    g, zc = np.sqrt(z * y), np.sqrt(z / y)
    t = np.tanh(g * LENGTH)
    return zc * (Z_T + zc * t) / (zc + Z_T * t)


@pytest.mark.parametrize("arrangement", ["pi", "inverted-L", "L"])
@pytest.mark.parametrize("rtol", [1e-2, 1e-3])
def test_auto_tube_is_within_rtol_of_the_transmission_line(arrangement: str,
                                                           rtol: float) -> None:
    model = tube(arrangement, rtol)
    f = oxyline.forcing_harmonics(model)
    # the series' power falls as 1/k^4: all but rtol of it is in the first few harmonics
    assert f[0] == 1.0 and 2 <= len(f) <= 8
    z = oxyline.impedance(model, "in", f)
    err = np.abs(z / exact_tube(f) - 1.0)
    assert err.max() <= rtol, (arrangement, rtol, err)
    # and not by luck of a huge count: the next coarser explicit count is outside rtol
    n = oxyline.load_model(model).summary()["segments"]
    z1 = oxyline.impedance(tube(arrangement, rtol, max(1, n // 2)), "in", f)
    assert n == 1 or np.abs(z1 / exact_tube(f) - 1.0).max() > rtol / 4, (n, arrangement)


def tree_model(root: float, rtol: float, segments: Any = "auto") -> dict[str, Any]:
    return {"name": "st", "arrangement": "pi", "blood": {"density": RHO, "viscosity": MU},
            "segmentation": {"rtol": rtol},
            "vessels": [{"name": "feed", "from": "in", "to": "out", "length": 1e-3,
                         "radius": root}],
            "boundary_conditions": {
                "in": {"type": "flow", "fourier": {**INFLOW, "mean": 1e-7,
                                                   "cos": [x / 50 for x in INFLOW["cos"]],
                                                   "sin": [x / 50 for x in INFLOW["sin"]]}},
                "out": {"type": "structured-tree", "alpha": A_, "beta": B_,
                        "length_ratio": LRR, "min_radius": 0.3 * root,
                        "stiffness": {"youngs_modulus": EH_R * 10, "thickness_ratio": 0.1},
                        "segments": segments}}}


@pytest.mark.parametrize("rtol", [1e-2, 1e-3])
def test_auto_structured_tree_is_within_rtol_of_olufsens_recursion(rtol: float) -> None:
    root = 2e-3
    model = tree_model(root, rtol)
    f = oxyline.forcing_harmonics(model)
    exact = np.array([olufsen(root, 0.3 * root, 2 * math.pi * fi, z_poiseuille) for fi in f])
    z = oxyline.impedance(model, "out", f)
    err = np.abs(z / exact - 1.0)
    assert err.max() <= rtol, (rtol, err)
    # one segment per tree vessel (the former default) is no closer, and outside 1e-3
    err1 = np.abs(oxyline.impedance(tree_model(root, rtol, 1), "out", f) / exact - 1.0).max()
    assert err1 >= err.max() and (rtol > 1e-3 or err1 > rtol), (err1, err)


def test_model_level_auto_leaves_explicit_segments_alone() -> None:
    two = {**tube("pi", 1e-3, 3), "segmentation": {"segments": "auto", "rtol": 1e-3}}
    two["vessels"] = [dict(two["vessels"][0], name="a", to="mid"),
                      {k: v for k, v in two["vessels"][0].items() if k != "segments"}
                      | {"name": "b", "from": "mid"}]
    table = oxyline.load_model(two).network.segment_table()
    counts = np.bincount(table["vessel"].astype(np.intp))  # numpy 2.0 casts no uint64
    assert counts[0] == 3 and counts[1] > 3  # b's count from the rule, a's its own
    plain = {**two, "segmentation": {}}
    plain["vessels"] = [two["vessels"][0], dict(two["vessels"][1], segments=3)]
    ref = oxyline.load_model(plain).network.segment_table()
    # the explicit vessel's segments are the same rows either way (one code path)
    for key in ("resistance", "inductance", "compliance"):
        np.testing.assert_array_equal(table[key][:3], ref[key][:3])


@pytest.mark.parametrize(("where", "value", "match"), [
    ("vessel", "autox", r"vessel 'v'.*'segments' must be an integer >= 1 or 'auto'"),
    ("model", "autox", r"segmentation.*'segments' must be 'auto'"),
    ("rtol", 0.0, r"segmentation.*'rtol' must be in \(0, 1\)"),
    ("rtol", 1.0, r"segmentation.*'rtol' must be in \(0, 1\)"),
    ("rtol", -1e-3, r"segmentation.*'rtol' must be in \(0, 1\)"),
    ("rtol", float("nan"), r"segmentation.*'rtol' must be finite"),
    ("tree", "autox", r"'segments' must be an integer >= 1 or 'auto'"),
])
def test_bad_auto_settings_are_model_errors(where: str, value: Any, match: str) -> None:
    if where == "tree":
        model = tree_model(2e-3, 1e-2, value)
    else:
        model = tube("pi", 1e-3)
        if where == "vessel":
            model["vessels"][0]["segments"] = value
        elif where == "model":
            model["segmentation"] = {"segments": value}
        else:
            model["segmentation"] = {"rtol": value}
    with pytest.raises(oxyline.ModelError, match=match):
        oxyline.load_model(model).summary()


def test_space_error_estimate_brackets_the_true_error(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    """The estimate (one doubling's change) against the true error of the model's own
    segmentation at the kept harmonics: a π ladder's change is ~3/4 of its error
    (Richardson), so within 0.3-1.2 times it."""
    model = tube("pi", 1e-2, 4)
    f = oxyline.forcing_harmonics(model)
    true = np.abs(oxyline.impedance(model, "in", f) / exact_tube(f) - 1.0).max()
    res = oxyline.simulate(model, cycles=1, estimate_space_error=True)
    est = res.error_estimate["space"]
    assert 0.3 * true <= est <= 1.2 * true, (est, true)
    assert est == pytest.approx(inlet_space_error(model), rel=1e-12)
    # recorded in the file's attributes and read back
    path = tmp_path / "run.nc"
    res.to_netcdf(path)
    back = oxyline.open_result(path)
    assert back.error_estimate["space"] == pytest.approx(est, rel=1e-12)
    with pytest.raises(oxyline.ModelError, match="estimate_space_error"):
        oxyline.simulate(model, cycles=1, estimate_space_error="yes")
    # the command line's summary says it
    model_file = tmp_path / "tube.yaml"
    import yaml

    model_file.write_text(yaml.safe_dump(model))
    assert main(["run", str(model_file), "--cycles", "1", "--estimate-space-error"]) == 0
    assert "space: the inlet impedance moves" in capsys.readouterr().out


def without_segmentation(model: dict[str, Any]) -> dict[str, Any]:
    """``model`` with no segmentation key anywhere (no ``segments``, no ``segmentation``)."""
    out = {k: v for k, v in model.items() if k != "segmentation"}
    out["vessels"] = [{k: v for k, v in x.items() if k != "segments"} for x in model["vessels"]]
    out["boundary_conditions"] = {n: {k: v for k, v in bc.items() if k != "segments"}
                                  for n, bc in model["boundary_conditions"].items()}
    return out


def test_a_model_without_segmentation_keys_is_cut_by_the_auto_rule() -> None:
    """The default: a tube and a structured tree that state no segmentation are within the
    default rtol (1e-3) of their exact lines at every kept harmonic; one segment per vessel
    (what a model without segmentation keys got before ``auto`` was the default) is not."""
    tube_model = without_segmentation(tube("pi", 1e-3))
    f = oxyline.forcing_harmonics(tube_model)
    s = oxyline.load_model(tube_model).summary()
    assert s["auto_segments"] == s["segments"] > 1 and s["auto_rtol"] == 1e-3
    err = np.abs(oxyline.impedance(tube_model, "in", f) / exact_tube(f) - 1.0).max()
    one = np.abs(oxyline.impedance(tube("pi", 1e-3, 1), "in", f) / exact_tube(f) - 1.0).max()
    assert err <= 1e-3 < one, (err, one)
    root = 2e-3
    tree = without_segmentation(tree_model(root, 1e-3))
    f = oxyline.forcing_harmonics(tree)
    exact = np.array([olufsen(root, 0.3 * root, 2 * math.pi * fi, z_poiseuille) for fi in f])
    s = oxyline.load_model(tree).summary()
    # the tree's vessels are cut by the rule; the feed vessel too (it states no segments)
    assert s["auto_vessels"] == s["vessels"] and s["auto_segments"] > s["vessels"]
    err = np.abs(oxyline.impedance(tree, "out", f) / exact - 1.0).max()
    one = np.abs(oxyline.impedance(tree_model(root, 1e-3, 1), "out", f) / exact - 1.0).max()
    assert err <= 1e-3 < one, (err, one)


def test_explicit_one_segment_is_the_single_pi_section() -> None:
    """``segments: 1`` keeps one section: its input impedance is the closed form of one π
    section of the tube's total R, L, C (C/2 - R + iωL - C/2) closed by Z_T, to rounding."""
    model = tube("pi", 1e-3, 1)
    f = oxyline.forcing_harmonics(model)
    w = 2 * np.pi * f
    r = 8 * MU * LENGTH / (np.pi * RADIUS**4)
    ell = RHO * LENGTH / (np.pi * RADIUS**2)
    c = 2 * np.pi * RADIUS**3 * 0.75 * LENGTH / (E * H)
    z_out = 1.0 / (1.0 / Z_T + 1j * w * c / 2)
    z_in = 1.0 / (1.0 / (r + 1j * w * ell + z_out) + 1j * w * c / 2)
    m = oxyline.load_model(model)
    assert m.summary()["segments"] == 1 and m.summary()["auto_segments"] == 0
    # 1e-9: the core's segment integral of a uniform tube and these products differ in rounding
    np.testing.assert_allclose(oxyline.impedance(model, "in", f), z_in, rtol=1e-9)
    # a lumped element (an RCL block, or a lumped π section) stays one segment without
    # segmentation keys: its author sized it
    for arrangement in ("RCL", "pi"):
        lumped = without_segmentation(tube("pi", 1e-3))
        lumped["vessels"][0] = {"name": "v", "from": "in", "to": "out",
                                "arrangement": arrangement,
                                "lumped": {"resistance": r, "inductance": ell, "capacitance": c}}
        s = oxyline.load_model(lumped).summary()
        assert s["segments"] == 1 and s["auto_segments"] == 0, arrangement


def test_a_model_without_any_key_is_a_pi_ladder_within_rtol_and_one_segment_is_unchanged(
        ) -> None:
    """No segmentation and no arrangement key: the tube is cut by the rule in π sections
    (the order-2 arrangement; the default where nothing is stated) and is within the default
    rtol of the exact line at every kept harmonic, with fewer segments than the inverted-L
    ladder the same rule gives when that arrangement is stated (first order: ~the square of
    the count). An explicit ``segments: 1`` without an arrangement keeps the one inverted-L
    section (C at the inlet, then R + iωL into Z_T): its closed form to rounding."""
    bare = without_segmentation(tube("pi", 1e-3))
    bare.pop("arrangement")
    f = oxyline.forcing_harmonics(bare)
    m = oxyline.load_model(bare)
    n_pi = m.summary()["segments"]
    assert m.summary()["auto_segments"] == n_pi > 1
    err = np.abs(oxyline.impedance(m, "in", f) / exact_tube(f) - 1.0).max()
    assert err <= 1e-3, err
    # the same count as the π ladder stated explicitly: the arrangement, not the rule, moved
    assert oxyline.load_model(without_segmentation(tube("pi", 1e-3))).summary()[
        "segments"] == n_pi
    n_inv = oxyline.load_model(without_segmentation(tube("inverted-L", 1e-3))).summary()[
        "segments"]
    assert n_pi**2 < 4 * n_inv, (n_pi, n_inv)
    one = {**bare, "vessels": [{**bare["vessels"][0], "segments": 1}]}
    w = 2 * np.pi * f
    r = 8 * MU * LENGTH / (np.pi * RADIUS**4)
    ell = RHO * LENGTH / (np.pi * RADIUS**2)
    c = 2 * np.pi * RADIUS**3 * 0.75 * LENGTH / (E * H)
    z_in = 1.0 / (1j * w * c + 1.0 / (r + 1j * w * ell + Z_T))
    assert oxyline.load_model(one).summary()["auto_segments"] == 0
    # 1e-9: the core's segment integral of a uniform tube and these products differ in rounding
    np.testing.assert_allclose(oxyline.impedance(one, "in", f), z_in, rtol=1e-9)


def test_the_memory_limit_sees_the_auto_count_before_assembly() -> None:
    """A limit between the bytes of one segment and of the auto count refuses the default
    model (ResourceError naming max_memory) and lets the one-segment model load."""
    model = without_segmentation(tube("pi", 1e-3))
    n = oxyline.load_model(model).summary()["segments"]
    elements = 1 + 2  # one vessel, two boundary conditions
    need_one = oxyline._core.model_bytes(1, elements, 0.0, 0)
    need_auto = oxyline._core.model_bytes(n, elements, 0.0, 0)
    assert need_auto > need_one
    limit = 0.5 * (need_one + need_auto)
    with pytest.raises(oxyline.ResourceError, match="max_memory"):
        oxyline.load_model({**model, "simulation": {"max_memory": limit}})
    one = tube("pi", 1e-3, 1)
    assert oxyline.load_model({**one, "simulation": {"max_memory": limit}}).summary()[
        "segments"] == 1


def test_the_result_and_the_cli_say_how_the_segments_were_chosen(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = without_segmentation(tube("pi", 1e-3))
    n = oxyline.load_model(model).summary()["segments"]
    res = oxyline.simulate(model, cycles=1, dt=1e-3, method="generalized-alpha")
    assert res.settings["segments_total"] == res.settings["segments_auto"] == n
    assert res.settings["segmentation"] == "auto"
    assert res.settings["segmentation_rtol"] == 1e-3
    explicit = oxyline.simulate(tube("pi", 1e-3, 3), cycles=1, dt=1e-3,
                               method="generalized-alpha")
    assert explicit.settings["segmentation"] == "explicit"
    assert explicit.settings["segments_total"] == 3 and explicit.settings["segments_auto"] == 0
    import yaml

    path = tmp_path / "tube.yaml"
    path.write_text(yaml.safe_dump(model))
    assert main(["validate", str(path)]) == 0
    assert f"segments: {n}, all by the auto rule (rtol 0.001)" in capsys.readouterr().out
    assert main(["run", str(path), "--cycles", "1"]) == 0
    assert f"segments: {n}, all by the auto rule" in capsys.readouterr().out
