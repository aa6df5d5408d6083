"""openBF's viscoelastic wall (``visco-elastic: true``) imported as ``wall_viscosity``.

openBF v2 (``src/vessel.jl``, ``src/solver.jl``) gives a viscoelastic vessel the wall viscosity
Gamma = b0 + b1/(2 R0), b0 = 0.6 kg/s, b1 = 1.5e-3 kg m/s, and solves it as the momentum
diffusion dQ/dt = Cv d2Q/dx2 with Cv = Gamma/(rho sqrt(A0)). The truths here are written from
those equations alone:

* the linear wave number of openBF's equations, k^2 = w^2/(A0/(rho C') + i w Cv), against the
  one of a Kelvin-Voigt line, k^2 = w^2 rho C'/(A0 (1 + i w tau)), tau = eta/E, fixes
  tau = Cv rho C'/A0 with C' = dA/dP = 2 A0/beta (openBF's beta = sqrt(pi/A0) h0 E/(1 - 0.25));
* the input impedance of the imported common carotid (openBF's ``cca``, made viscoelastic)
  against the closed-form transmission line of openBF's linearised equations closed by its
  three-element Windkessel.

No stored openBF reference result uses the viscoelastic wall, so no waveform is compared.
"""

from __future__ import annotations

import cmath
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import data_path

import oxyline
from oxyline.errors import ModelError
from oxyline.io.openbf import read_openbf, to_native_dict

CCA = data_path("openbf", "models", "boileau2015", "cca", "cca.yaml")
IBIF = data_path("openbf", "models", "boileau2015", "ibif", "ibif.yaml")


def _viscoelastic_copy(src: Path, tmp: Path, value: object = True) -> Path:
    """The openBF file ``src`` with ``visco-elastic: value`` on every vessel (inlet copied)."""
    text = src.read_text()
    assert "visco-elastic" not in text and "  - label:" in text
    flag = yaml.safe_dump(value).split("\n")[0]
    out = tmp / src.name
    out.write_text(text.replace("  - label:", f"  - visco-elastic: {flag}\n    label:"))
    for f in src.parent.glob("*.dat"):
        (tmp / f.name).write_bytes(f.read_bytes())
    return out


def _quiet(path: Path, **options: object) -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return to_native_dict(path, **options)


def _cca() -> tuple[dict[str, float], dict[str, float]]:
    """The carotid's vessel entry and blood, as numbers (YAML 1.1 reads 700.0e3 as text)."""
    cfg = yaml.safe_load(CCA.read_text())
    num = {k: float(x) for k, x in cfg["network"][0].items()
           if k not in ("label", "inlet_impedance_matching")}
    return num, {k: float(x) for k, x in cfg["blood"].items()}


def _openbf_tau(r0: float, h0: float, e: float, rho: float) -> float:
    """Relaxation time that gives a Kelvin-Voigt line openBF's viscoelastic wave number."""
    a0 = math.pi * r0**2
    gamma = 0.6 + 0.00150 * 0.5 / r0  # openBF v2's Gamma (b0 + b1/(2 R0))
    cv = gamma / (rho * math.sqrt(a0))
    beta = math.sqrt(math.pi / a0) * h0 * e / (1 - 0.5**2)
    compliance = 2 * a0 / beta  # dA/dP at A0
    return cv * rho * compliance / a0


def test_imported_wall_viscosity_is_openbfs_gamma(tmp_path: Path) -> None:
    raw, blood = _cca()
    f = _viscoelastic_copy(CCA, tmp_path)
    v = _quiet(f, openbf_compat=True, linearize="pext")["vessels"][0]
    tau = _openbf_tau(raw["R0"], raw["h0"], raw["E"], blood["rho"])
    assert v["wall_viscosity"] / raw["E"] == pytest.approx(tau, rel=1e-12)
    # a few milliseconds: the scale of arterial wall relaxation
    assert 1e-3 < tau < 1e-2
    # the linearisation pressure does not change it (C' and Gamma/(A0 sqrt A) scale alike)
    v_mean = _quiet(f, openbf_compat=True)["vessels"][0]
    assert v_mean["wall_viscosity"] == pytest.approx(v["wall_viscosity"], rel=1e-12)


def test_viscoelastic_option_overrides_the_files_key(tmp_path: Path) -> None:
    elastic = _quiet(IBIF)
    assert all("wall_viscosity" not in v for v in elastic["vessels"])
    every = _quiet(IBIF, viscoelastic=True)
    assert all(v["wall_viscosity"] > 0 for v in every["vessels"])
    f = _viscoelastic_copy(IBIF, tmp_path)
    assert all("wall_viscosity" not in v for v in _quiet(f, viscoelastic=False)["vessels"])
    assert [v["wall_viscosity"] for v in _quiet(f)["vessels"]] == pytest.approx(
        [v["wall_viscosity"] for v in every["vessels"]], rel=1e-12)


def test_bad_viscoelastic_value_names_the_vessel(tmp_path: Path) -> None:
    f = _viscoelastic_copy(CCA, tmp_path, value="yes")
    with pytest.raises(ModelError, match=r"common_carotid_artery.*'visco-elastic'.*'yes'"):
        _quiet(f)
    with pytest.raises(ModelError, match="viscoelastic"):
        _quiet(CCA, viscoelastic="yes")
    with pytest.raises(ModelError, match="wall_friction"):
        _quiet(CCA, wall_friction="darcy")


def _line_impedance(f_hz: float, length: float, r0: float, h0: float, e: float, rho: float,
                    mu: float, tau: float, z_end: complex) -> complex:
    """Input impedance of openBF's linearised viscoelastic vessel closed by ``z_end``."""
    w = 2 * math.pi * f_hz
    a0 = math.pi * r0**2
    compliance = 2 * a0 / (math.sqrt(math.pi / a0) * h0 * e / 0.75)
    z = 8 * math.pi * mu / a0**2 + 1j * w * rho / a0  # openBF's friction (gamma 2), flat inertia
    y = 1j * w * compliance / (1 + 1j * w * tau)
    g, zc = cmath.sqrt(z * y), cmath.sqrt(z / y)
    t = cmath.tanh(g * length)
    return zc * (z_end + zc * t) / (zc + z_end * t)


def test_imported_viscoelastic_carotid_impedance_is_openbfs_line(tmp_path: Path) -> None:
    """oxyline.impedance of the imported vessel (π segments of 1 mm) against the closed form
    of openBF's linearised viscoelastic equations, 1-20 Hz: within 0.1 % (the π segments'
    second-order error at 126 segments is ~1e-4), and 1-10 % away from the elastic line."""
    f = _viscoelastic_copy(CCA, tmp_path)
    d = _quiet(f, openbf_compat=True, linearize="pext", max_segment_length=1e-3)
    d["arrangement"] = "pi"
    v, blood = _cca()
    tau = _openbf_tau(v["R0"], v["h0"], v["E"], blood["rho"])
    freqs = np.array([1.0, 2.0, 5.0, 10.0, 20.0])
    z = oxyline.impedance(d, "n1", freqs)
    for fk, zk in zip(freqs, z, strict=True):
        w = 2 * math.pi * fk
        wk3 = v["R1"] + v["R2"] / (1 + 1j * w * v["R2"] * v["Cc"])
        args = (fk, v["L"], v["R0"], v["h0"], v["E"], blood["rho"], blood["mu"])
        exact = _line_impedance(*args, tau, wk3)
        elastic = _line_impedance(*args, 0.0, wk3)
        assert abs(zk / exact - 1) < 1e-3, (fk, zk, exact)
        assert abs(elastic / exact - 1) > 1e-3, (fk, elastic, exact)


def test_read_openbf_runs_a_viscoelastic_model(tmp_path: Path) -> None:
    """The imported model runs; its mean pressure is the elastic one (a wall viscosity only
    acts on changes) and its pulse is damped."""
    f = _viscoelastic_copy(CCA, tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ve = read_openbf(f, openbf_compat=True)
        el = read_openbf(CCA, openbf_compat=True)
    p = {}
    for name, m in (("ve", ve), ("el", el)):
        res = oxyline.simulate(m, start="periodic", cycles=2, until_periodic=None)
        p[name] = np.asarray(res.vessel("common_carotid_artery").pressure_in)
    assert p["ve"].mean() == pytest.approx(p["el"].mean(), rel=1e-4)
    assert np.ptp(p["ve"]) < np.ptp(p["el"])
