"""Regenerate ``python/oxyline/models_data/*.yaml`` from the openBF model library in
``tests/data/openbf`` (Apache-2.0) with :func:`oxyline.io.openbf.to_native_dict`, and
``whole-body-140`` from circulatory_autogen's FinalModel in ``tests/data/circulatory_autogen``
(Apache-2.0) with :func:`oxyline.io.circulatory_autogen.to_native_dict` (inflow: the Mynard
template of ``tests/data/pwdb``, MIT; terminal resistances calibrated to the source's
observed mean aortic pressure, wall viscosity kept: :data:`WHOLE_BODY_OPTIONS`), and ``pwdb-116``
from PWDB's ``116_artery_model.txt`` with :func:`oxyline.populations.model_dict` (the file is
not in the repository, see docs/populations.md: pass its path, or it is read from a ``shared/``
reference folder beside the repository; skipped when absent), and the whole trees
``adan56-st`` and ``whole-body-140-st`` from those built-ins (:func:`whole_trees`).

    python benches/make_models_data.py [--pwdb-geometry PATH/116_artery_model.txt]
    python benches/make_models_data.py --whole-trees-only
"""

from __future__ import annotations

import re
import shutil
import warnings
from pathlib import Path

import yaml

from oxyline.io import circulatory_autogen
from oxyline.io.openbf import to_native_dict

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "tests" / "data"  # the source files, with their licences (tests/data/README.md)
OPENBF = DATA / "openbf"
OUT = REPO / "python" / "oxyline" / "models_data"
CA = DATA / "circulatory_autogen"
PWDB = DATA / "pwdb"

SOURCES = {
    "cca": ("models/boileau2015/cca/cca.yaml", "Boileau et al. 2015, common carotid artery"),
    "aortic-bifurcation": ("models/boileau2015/ibif/ibif.yaml",
                           "Boileau et al. 2015, aortic bifurcation"),
    "adan56": ("models/boileau2015/adan56/adan56.yaml",
               "Boileau et al. 2015, ADAN56 (Blanco et al. 2015); inflow repaired"),
    "circle-of-willis": ("models/alastruey2007/circle_of_willis.yaml",
                         "Alastruey et al. 2007, circle of Willis + main systemic arteries"),
    "matthys37": ("models/matthys2007/invitro_model.yaml",
                  "Matthys et al. 2007, 37-artery in-vitro network"),
}


def _flow(value: object) -> str:
    return yaml.safe_dump(value, default_flow_style=True, width=10**6, sort_keys=False).strip()


def dump(d: dict) -> str:
    """Native YAML: block mappings at the top, one flow mapping per vessel and per boundary
    condition (tables on one line)."""
    lines = []
    for key, value in d.items():
        if key == "vessels":
            lines.append("vessels:")
            lines += [f"  - {_flow(v)}" for v in value]
        elif key == "boundary_conditions":
            lines.append("boundary_conditions:")
            lines += [f"  {node}: {_flow(bc)}" for node, bc in value.items()]
        elif isinstance(value, dict):
            lines.append(f"{key}: {_flow(value)}")
        else:
            lines.append(yaml.safe_dump({key: value}, sort_keys=False, width=100,
                                        default_flow_style=False).rstrip())
    return "\n".join(lines) + "\n"


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    for name, (rel, cite) in SOURCES.items():
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            d = to_native_dict(OPENBF / rel, name=name)
        notes = sorted({str(w.message) for w in caught})
        header = [f"# oxyline built-in model '{name}': {cite}.",
                  f"# Converted from the openBF model library (INSIGNEO/openBF, Apache-2.0), file {rel},",
                  "# by oxyline.io.openbf.to_native_dict (defaults: linear taper, WK2 = R1 parallel to Cc,",
                  "# linearised at the steady mean pressure); regenerate: benches/make_models_data.py.",
                  "# Citations: NOTICE.",
                  *[f"# importer note: {n}" for n in notes]]
        text = "\n".join(header) + "\n" + dump(d)
        if yaml.safe_load(text) != d:
            raise SystemExit(f"{name}: YAML round trip changed the model")
        (OUT / f"{name}.yaml").write_text(text)
        print(name, len(d["vessels"]), "vessels")
    shutil.copy(OPENBF / "LICENSE", OUT / "LICENSE")
    whole_body()
    whole_trees()
    pwdb_116()


#: the built-in's importer options: R_T calibrated to the observed mean aortic pressure, the
#: source's wall viscosity kept (see docs/models.md, "Calibration")
WHOLE_BODY_OPTIONS = {"terminal_resistance_scale": "calibrate", "wall_viscosity": True}


def high_frequency_fraction(time, p, f_cut: float = 20.0) -> float:
    """Share of the spectral energy of p - mean(p) (one period, uniform samples) above f_cut."""
    import numpy as np

    x = np.asarray(p) - np.mean(p)
    e = np.abs(np.fft.rfft(x))**2
    f = np.fft.rfftfreq(len(x), float(time[1] - time[0]))
    return float(e[f > f_cut].sum() / e[1:].sum())


def aortic_numbers(d: dict) -> dict[str, float]:
    """Mean/systolic/diastolic pressure [kPa] at aortic_arch_C46's C node (circulatory_autogen's
    ``aortic_arch_C46/u``), cardiac output [L/min] and the > 20 Hz energy share, last cycle."""
    import oxyline

    res = oxyline.simulate(d, until_periodic=1e-6, max_cycles=200)
    t = res.time[:-1]
    p = res.vessel("aortic_arch_C46").pressure_out[:-1]
    q = res.vessel("ascending_aorta_C0").flow_in[:-1]
    return {"mean": p.mean() / 1e3, "sys": p.max() / 1e3, "dia": p.min() / 1e3,
            "co": q.mean() * 6e4, "hf": high_frequency_fraction(t, p)}


def whole_body() -> None:
    """``whole-body-140``: circulatory_autogen FinalModel arterial tree (commit 8e028f37),
    terminal resistances calibrated to the observed 12.0 kPa mean aortic pressure, wall viscosity
    kept."""
    res = CA / "resources"
    files = (res / "FinalModel_vessel_array.csv", res / "FinalModel_parameters.csv")
    kw = {"obs_data_json": res / "FinalModel_obs_data.json",
          "mynard_template": PWDB / "Mynard2015_aortic_flow_template.csv"}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        raw = circulatory_autogen.to_native_dict(*files, **kw, name="whole-body-140")
        scale, module, target = circulatory_autogen.calibrate_terminal_resistance_scale(
            raw, kw["obs_data_json"])
        d = circulatory_autogen.to_native_dict(*files, **kw, **WHOLE_BODY_OPTIONS,
                                               name="whole-body-140")
    notes = sorted({str(w.message) for w in caught})
    before, after = aortic_numbers(raw), aortic_numbers(d)

    def lines(n: dict[str, float]) -> list[str]:
        mmhg = 0.133322
        return [(f"#   mean {n['mean']:.2f} kPa ({n['mean'] / mmhg:.0f} mmHg), systolic/diastolic "
                 f"{n['sys']:.2f}/{n['dia']:.2f} kPa ({n['sys'] / mmhg:.0f}/{n['dia'] / mmhg:.0f} "
                 f"mmHg),"),
                (f"#   pulse {n['sys'] - n['dia']:.2f} kPa, {n['hf'] * 100:.2g} % of the pressure "
                 f"energy above 20 Hz")]

    header = ["# oxyline built-in model 'whole-body-140': circulatory_autogen FinalModel arterial tree.",
              "# Converted from FinbarArgus/circulatory_autogen (Apache-2.0, commit 8e028f37),",
              "# resources/FinalModel_vessel_array.csv + FinalModel_parameters.csv, by",
              "# oxyline.io.circulatory_autogen.to_native_dict; inflow: Mynard & Smolich 2015 aortic",
              "# flow template from peterhcharlton/pwdb (MIT) scaled to FinalModel_obs_data.json",
              f"# ({after['co']:.2f} L/min).",
              f"# Calibration: every terminal resistance R_T x {scale:.6g} (one uniform factor, keeps",
              "# the source's R_T ratios), found by calibrate_terminal_resistance_scale so that the",
              f"# cycle-mean pressure at {module} (steady resistive solve, exact for the linear",
              f"# circuit) equals FinalModel_obs_data.json's {target:g} Pa at the mean inflow. Terminal",
              "# compliances as in the source (the observations hold no pulse pressure). The source's",
              "# wall viscosity R_v = 0.01 s/C is kept (wall_viscosity=True: dead-end '.wall' branches,",
              "# vessels rigid tubes of the source radius and length).",
              "# Last cycle at aortic_arch_C46 (its C node), this model:",
              *lines(after),
              "# the raw source values (scale 1, no R_v) for comparison:",
              *lines(before),
              "# Regenerate: benches/make_models_data.py. Licences and citations: NOTICE.",
              *[f"# importer note: {n}" for n in notes]]
    text = "\n".join(header) + "\n" + dump(d)
    if yaml.safe_load(text) != d:
        raise SystemExit("whole-body-140: YAML round trip changed the model")
    (OUT / "whole-body-140.yaml").write_text(text)
    print("whole-body-140", len(d["vessels"]), "vessels, R_T scale", scale)
    shutil.copy(CA / "LICENSE", OUT / "LICENSE-circulatory_autogen")
    shutil.copy(PWDB / "LICENSE", OUT / "LICENSE-pwdb")


#: the whole trees' run settings: the budgeted run of a whole tree (one cycle of
#: generalized-alpha at 1 ms, vessel output every 10 ms); more cycles with
#: ``cycles=``/``--cycles`` or ``until_periodic``
WHOLE_TREE_SIMULATION = {"cycles": 1, "dt": 1.0e-3, "method": "generalized-alpha",
                         "output": {"cycles": "last", "every": 0.01}}


def adan56_st() -> dict:
    """``adan56-st``: adan56 with every terminal Windkessel replaced by a structured tree of
    the same steady resistance (:func:`oxyline.structured_tree.replace_windkessels`,
    docs/structured-tree.md)."""
    from oxyline import catalogue
    from oxyline.structured_tree import replace_windkessels

    data = replace_windkessels(catalogue.load_dict("adan56"))
    data["name"] = "adan56-st"
    data["simulation"] = dict(WHOLE_TREE_SIMULATION)
    return data


def terminal_compartments(data: dict) -> list[str]:
    """The first lumped vessel of each lumped terminal compartment of ``data``: from every
    pressure outlet, up through lumped vessels to the one that starts where a geometric vessel
    ends (whole-body-140: the 95 ``*_T`` terminals; not the ``.wall`` dead ends)."""
    arriving = {v["to"]: v for v in data["vessels"]}
    out = []
    for node, bc in data["boundary_conditions"].items():
        if not (isinstance(bc, dict) and bc.get("type") == "pressure" and node in arriving):
            continue
        v = arriving[node]
        while "lumped" in v and "lumped" in arriving.get(v["from"], {}):
            v = arriving[v["from"]]
        if "lumped" in v:
            out.append(v["name"])
    return out


#: E and h(r_0) in a whole-body-140 vessel description (io.circulatory_autogen writes them)
_WALL_LAW = re.compile(r"E ([-+.\deE]+) Pa, h\(r_0\) ([-+.\deE]+) m")


def _wall_branch_owner(name: str, ends: dict[str, dict]) -> tuple[str, str]:
    """(vessel, arrangement) whose capacitor the dead-end wall branch ``name`` holds, by the
    naming of io.circulatory_autogen's wall-viscosity form: ``<node>.wall_in_<v>`` and
    ``.wall_out_<v>`` (pi), ``<node>.wall_<v>`` (inverted-L), ``<v>.mid.wall`` (the pi x 2 of
    a T), ``<node>.wall`` (L: the vessel ending at node)."""
    node, _, tag = name.rpartition(".wall")
    for prefix, arrangement in (("_in_", "pi"), ("_out_", "pi"), ("_", "inverted-L")):
        if tag.startswith(prefix):
            return tag[len(prefix):], arrangement
    if node.endswith(".mid"):
        return node[:-len(".mid")], "pi x 2"
    return ends[node]["name"], "L"


def compliant_arteries(data: dict) -> dict:
    """``data`` (whole-body-140) with each dead-end wall branch (R_v = 0.01 s/C in series
    with C, to a zero-flow end: the source's wall viscosity) folded back into the vessel whose
    capacitor it is: the vessel gets the source's E and h(r_0) (Poisson ratio 0) and
    arrangement, so that every compliance holds lumen volume, which transport needs (a
    capacitor without volume stores blood but no solute). The wall viscosity is dropped; the
    steady state is unchanged (wall branches carry no steady flow)."""
    from oxyline import _core
    from oxyline.errors import ModelError

    bcs = dict(data["boundary_conditions"])
    vessels = {v["name"]: dict(v) for v in data["vessels"]}
    ends = {v["to"]: v for v in data["vessels"] if "lumped" not in v}
    walls: dict[str, tuple[str, float]] = {}  # vessel -> (arrangement, its capacitance)
    for v in data["vessels"]:
        if ".wall" in v["name"] and bcs.get(v["to"]) == {"type": "flow", "value": 0.0}:
            owner, arrangement = _wall_branch_owner(v["name"], ends)
            walls[owner] = (arrangement, walls.get(owner, ("", 0.0))[1]
                            + v["lumped"]["capacitance"])
            del vessels[v["name"]], bcs[v["to"]]
    for name, (arrangement, c) in walls.items():
        v = vessels[name]
        law = _WALL_LAW.search(v.get("description", ""))
        if law is None:
            raise ModelError(f"whole-body-140 vessel '{name}': no E and h(r_0) in its "
                             f"description")
        e, h = float(law.group(1)), float(law.group(2))
        if arrangement == "pi x 2":  # the two rigid halves around the T's capacitor
            half = vessels.pop(f"{name}.distal_half")
            v.update({"to": half["to"], "segments": 2, "length": v["length"] + half["length"]})
            arrangement = "pi"
        # the branches hold the source's C (its wall law, Poisson ratio 0): E from C keeps C
        # exact; the description's E (6 digits) only checks that it is this vessel's
        exact = _core.circulatory_autogen_youngs_modulus(v["radius"], v["length"], c, h)
        if abs(exact / e - 1.0) > 1e-5:
            raise ModelError(f"whole-body-140 vessel '{name}': its wall branches give "
                             f"E = {exact:g} Pa, its description {e:g} Pa")
        v.update({"arrangement": arrangement, "youngs_modulus": exact, "wall_thickness": h,
                  "poisson_ratio": 0.0})
    return {**data, "vessels": list(vessels.values()), "boundary_conditions": bcs}


def whole_body_trees(min_radius: float = 1.0e-4) -> dict:
    """``whole-body-140-st``: whole-body-140 with each lumped terminal compartment (R_T/2,
    C_T with its wall viscosity, R_T/2) replaced by a structured tree of steady resistance
    R_T, rooted in a vessel whose radius follows Murray's law from the base model's steady
    flows; tree vessels cut at 1 cm like adan56's; the named arteries compliant again (their
    wall branches folded back, so oxygen can run; docs/structured-tree.md). ``min_radius``:
    coarser variants for the tests."""
    from oxyline import catalogue
    from oxyline.structured_tree import murray_root_radii, replace_terminal_vessels

    base = catalogue.load_dict("whole-body-140")
    terminals = terminal_compartments(base)
    steady = catalogue.build(base).network.steady_state()
    radii = murray_root_radii(base, steady, terminals)
    data = compliant_arteries(
        replace_terminal_vessels(base, radii, min_radius=min_radius, max_length=0.01))
    data["name"] = "whole-body-140-st"
    data["simulation"] = dict(WHOLE_TREE_SIMULATION)
    return data


def whole_trees() -> None:
    """``adan56-st`` and ``whole-body-140-st``: the compact dicts (their structured trees as
    ``structured-tree`` conditions, grown when the model loads)."""
    notes = {
        "adan56-st": ["adan56 with each of its 31 terminal Windkessels replaced by a structured",
                      "tree of the same steady resistance (structured_tree.replace_windkessels)."],
        "whole-body-140-st": ["whole-body-140 with each of its 95 lumped terminal compartments",
                              "replaced by a Murray root vessel and a structured tree of the same",
                              "steady resistance, the named arteries' wall branches folded back",
                              "(docs/structured-tree.md, \"Built-in whole tree\")."],
    }
    for name, build in (("adan56-st", adan56_st), ("whole-body-140-st", whole_body_trees)):
        d = build()
        header = [f"# oxyline built-in model '{name}':", *(f"# {n}" for n in notes[name]),
                  "# The trees grow on load. Regenerate: "
                  + "benches/make_models_data.py --whole-trees-only."]
        text = "\n".join(header) + "\n" + dump(d)
        if yaml.safe_load(text) != d:
            raise SystemExit(f"{name}: YAML round trip changed the model")
        (OUT / f"{name}.yaml").write_text(text)
        print(name, len(d["vessels"]), "vessels,", len(d["boundary_conditions"]), "conditions")


PWDB_GEOMETRY = REPO.parent / "shared" / "networks" / "pwdb" / "116_artery_model.txt"


def pwdb_116(geometry: Path | None = None) -> None:
    """``pwdb-116``: PWDB's 116-artery network for its 25-y baseline subject, terminal
    Windkessels calibrated to the subject's mean aortic root pressure."""
    import argparse

    import numpy as np

    import oxyline
    from oxyline import populations, pwdb

    if geometry is None:
        ap = argparse.ArgumentParser()
        ap.add_argument("--pwdb-geometry", type=Path, default=PWDB_GEOMETRY)
        geometry = ap.parse_args().pwdb_geometry
    if not geometry.exists():
        print(f"pwdb-116: {geometry} not found, skipped")
        return
    geo = pwdb.read_geometry(geometry)
    row = populations.baseline_row()
    d = populations.model_dict(geo, row)
    res = oxyline.simulate(d)
    p = res.vessel(geo[0]["name"]).pressure_in[:-1] / pwdb.MMHG
    mmhg = [(f"#   aortic root: mean {p.mean():.2f} mmHg (target {row['mbp']:.2f}), systolic/diastolic "
            f"{p.max():.1f}/{p.min():.1f} mmHg, {res.settings['cycles_run']} cycles to "
            f"periodicity {res.settings['periodic_error']:.1e}")]
    header = ["# oxyline built-in model 'pwdb-116': the Pulse Wave DataBase 116-artery network",
              "# (Charlton et al. 2019, Am J Physiol Heart Circ Physiol 317:H1062), baseline subject.",
              "# Geometry: peterhcharlton/pwdb commit 5a0d472, pwdb_v0.1/Input Data/116_artery_model.txt",
              "# (values adapted by PWDB from Mynard & Smolich 2015, Ann Biomed Eng 43:1443; the file is",
              "# excluded from PWDB's MIT grant: literature data, cited, see NOTICE). Wall law, vascular",
              "# beds, outflow pressure, age-specific parameters: PWDB (MIT), recomputed by",
              "# oxyline.populations (docs/populations.md). Inflow: Mynard & Smolich 2015 template",
              "# (PWDB, MIT) scaled to HR/SV/LVET. Terminal R x one factor per subject so that the",
              "# steady (= cycle-mean) aortic root pressure is the subject's mean pressure.",
              *mmhg,
              "# Regenerate: benches/make_models_data.py --pwdb-geometry PATH. Citations: NOTICE."]
    text = "\n".join(header) + "\n" + dump(d)
    if yaml.safe_load(text) != d:
        raise SystemExit("pwdb-116: YAML round trip changed the model")
    (OUT / "pwdb-116.yaml").write_text(text)
    shutil.copy(PWDB / "Mynard2015_aortic_flow_template.csv",
                OUT / "mynard2015_aortic_flow_template.csv")
    print("pwdb-116", len(d["vessels"]), "vessels;", mmhg[0][2:], np.isfinite(p).all())


if __name__ == "__main__":
    import sys

    if "--whole-trees-only" in sys.argv:
        whole_trees()
    elif "--pwdb-geometry" in sys.argv or "--pwdb-only" in sys.argv:
        if "--pwdb-only" in sys.argv:
            sys.argv.remove("--pwdb-only")
        pwdb_116()
    else:
        main()
