"""Built-in network models, loadable by name.

>>> import oxyline
>>> "adan56" in oxyline.catalogue.list()
True
>>> m = oxyline.catalogue.load("adan56")
>>> len(m.vessel_names)
77

Shipped models (converted to oxyline's native YAML in ``oxyline/models_data/``; the openBF model
library is Apache-2.0, see ``models_data/LICENSE`` and ``models_data/NOTICE`` for citations):

* ``cca`` — common carotid artery, Boileau et al. 2015 benchmark (1 vessel, WK3 outlet);
* ``aortic-bifurcation`` (alias ``ibif``) — Boileau et al. 2015 aortic bifurcation (3, 2 WK3);
* ``adan56`` — Boileau et al. 2015 ADAN56 (77 segments, 31 WK3), clean inflow;
* ``circle-of-willis`` — Alastruey et al. 2007 circle of Willis and main systemic arteries
  (33 segments with anastomoses, 11 WK2);
* ``matthys37`` — Matthys et al. 2007 37-artery in-vitro network (16 resistive outlets);
* ``whole-body-140`` — the arterial tree of circulatory_autogen's FinalModel (Apache-2.0,
  ADAN-86/ADAN-218 parameters): 140 0-D segments and 95 terminal R-C-R compartments, heart and
  veins replaced by the Mynard & Smolich 2015 aortic flow scaled to the model's 4.18 L/min,
  terminal resistances calibrated (x 7.67) to the source's observed 12.0 kPa mean aortic
  pressure, the source's wall viscosity kept (113/62 mmHg, no ringing; converted by
  :func:`oxyline.io.circulatory_autogen.to_native_dict`; see ``docs/models.md``);
* ``pwdb-116`` — the Pulse Wave DataBase 116-artery network (Charlton et al. 2019; geometry of
  Mynard & Smolich 2015) for PWDB's 25-year baseline subject: PWDB's wall law, its 16 vascular
  beds as 46 RCR outlets calibrated to the subject's mean aortic root pressure, the Mynard
  aortic inflow scaled to its heart rate, stroke volume and ejection time; the base of the
  virtual populations of :mod:`oxyline.populations` (``docs/populations.md``).

They were converted with :func:`oxyline.io.openbf.to_native_dict` (default options; script
``benches/make_models_data.py``). Every example network of ``oxyline/examples/`` (e.g.
``bifurcation``) loads as well, and other modules can add models with :func:`register`.
"""

from __future__ import annotations

import builtins
import re
from collections.abc import Callable
from importlib import resources
from typing import Any

from oxyline import _core, examples
from oxyline.errors import ModelError
from oxyline.memory import gc_paused
from oxyline.model import Model, build_model
from oxyline.structured_tree import (
    murray_root_radii,
    replace_terminal_vessels,
    replace_windkessels,
)

_DATA = "oxyline.models_data"

#: name -> (file in models_data, one-line description)
BUILTIN: dict[str, tuple[str, str]] = {
    "cca": ("cca.yaml", "Boileau 2015 common carotid artery (openBF), 1 vessel, WK3"),
    "aortic-bifurcation": ("aortic-bifurcation.yaml",
                           "Boileau 2015 aortic bifurcation (openBF ibif), 3 vessels, 2 WK3"),
    "adan56": ("adan56.yaml", "Boileau 2015 ADAN56 (openBF), 77 segments, 31 WK3"),
    "circle-of-willis": ("circle-of-willis.yaml",
                         "Alastruey 2007 circle of Willis (openBF), 33 segments, loops, 11 WK2"),
    "matthys37": ("matthys37.yaml",
                  "Matthys 2007 37-artery in-vitro network (openBF), 16 resistive outlets"),
    "whole-body-140": ("whole-body-140.yaml",
                       ("circulatory_autogen FinalModel arterial tree (ADAN-86/218), 140 segments "
                        "+ 95 terminal R-C-R (calibrated to 12 kPa mean), Mynard aortic inflow")),
    "pwdb-116": ("pwdb-116.yaml",
                 ("PWDB 116-artery network (Charlton 2019), 25-y baseline subject, 46 RCR "
                  "calibrated to its mean pressure, Mynard aortic inflow")),
}
ALIASES: dict[str, str] = {
    "ibif": "aortic-bifurcation",
    "circle_of_willis": "circle-of-willis",
    "cow": "circle-of-willis",
    "matthys2007": "matthys37",
    "invitro_model": "matthys37",
    "whole-body": "whole-body-140",
    "finalmodel": "whole-body-140",
    "pwdb": "pwdb-116",
    "pwdb116": "pwdb-116",
}
_registered: dict[str, tuple[Callable[[], Any], str]] = {}


def _with_structured_trees(base: str) -> Callable[[], Any]:
    def build() -> Any:
        data = replace_windkessels(load_dict(base))
        data["name"] = f"{base}-st"
        data["simulation"] = dict(WHOLE_TREE_SIMULATION)
        return data

    return build


def terminal_compartments(data: dict[str, Any]) -> builtins.list[str]:
    """The first lumped vessel of each lumped terminal compartment of ``data``: from every
    pressure outlet, up through lumped vessels to the one that starts where a geometric vessel
    ends (whole-body-140: the 95 ``*_T`` terminals; not the ``.wall`` dead ends).

    >>> import oxyline
    >>> d = oxyline.catalogue.load_dict("whole-body-140")
    >>> len(oxyline.catalogue.terminal_compartments(d))
    95
    """
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


def _wall_branch_owner(name: str, ends: dict[str, dict[str, Any]]) -> tuple[str, str]:
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


def _compliant_arteries(data: dict[str, Any]) -> dict[str, Any]:
    """``data`` (whole-body-140) with each dead-end wall branch (R_v = 0.01 s/C in series
    with C, to a zero-flow end: the source's wall viscosity) folded back into the vessel whose
    capacitor it is: the vessel gets the source's E and h(r_0) (Poisson ratio 0) and
    arrangement, so that every compliance holds lumen volume, which transport needs (a
    capacitor without volume stores blood but no solute). The wall viscosity is dropped; the
    steady state is unchanged (wall branches carry no steady flow)."""
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
    return {**data, "vessels": builtins.list(vessels.values()), "boundary_conditions": bcs}


def _whole_body_trees(min_radius: float = 1.0e-4) -> dict[str, Any]:
    """whole-body-140 with each lumped terminal compartment (R_T/2, C_T with its wall
    viscosity, R_T/2) replaced by a structured tree of steady resistance R_T, rooted in a
    vessel whose radius follows Murray's law from the base model's steady flows; tree vessels
    cut at 1 cm like adan56's; the named arteries compliant again (their wall branches folded
    back, so oxygen can run; docs/structured-tree.md)."""
    base = load_dict("whole-body-140")
    terminals = terminal_compartments(base)
    radii = murray_root_radii(base, build(base).network.steady_state(), terminals)
    data = _compliant_arteries(
        replace_terminal_vessels(base, radii, min_radius=min_radius, max_length=0.01))
    data["name"] = "whole-body-140-st"
    data["simulation"] = dict(WHOLE_TREE_SIMULATION)
    return data


#: built-in whole trees (1e5-1e6 segments: seconds to a minute to load)
WHOLE_TREES = ("adan56-st", "whole-body-140-st")
#: their run settings: the issue-9 budget run (one cycle of generalized-alpha at 1 ms, vessel
#: output every 10 ms); more cycles with ``cycles=``/``--cycles`` or ``until_periodic``
WHOLE_TREE_SIMULATION = {"cycles": 1, "dt": 1.0e-3, "method": "generalized-alpha",
                         "output": {"cycles": "last", "every": 0.01}}
#: whole trees: every terminal Windkessel replaced by a structured tree of the same steady
#: resistance (rule: :func:`oxyline.structured_tree.replace_windkessels`, docs/structured-tree.md)
_registered["adan56-st"] = (_with_structured_trees("adan56"),
                            ("ADAN56 with 31 structured trees (min radius 0.1 mm) instead of "
                             "WK3: 262,512 vessels, 314,489 segments"))
_registered["whole-body-140-st"] = (_whole_body_trees,
                                    ("whole-body-140 with 95 structured trees (min radius 0.1 mm, "
                                     "Murray root radii) instead of its terminal R-C-R: "
                                     "256,368 vessels, 305,949 segments"))


def register(name: str, loader: Callable[[], Any], description: str = "") -> None:
    """Add a named model: ``loader()`` returns an :class:`oxyline.Model` or a model dict.

    >>> import oxyline
    >>> oxyline.catalogue.register("tiny", lambda: oxyline.catalogue.load("bifurcation"), "demo")
    >>> oxyline.catalogue.load("tiny").vessel_names[0]
    'parent'
    """
    _registered[name] = (loader, description)


def _examples() -> builtins.list[str]:
    """Names of the example networks (``oxyline/examples/<name>.yaml``)."""
    return sorted(p.name[:-5] for p in resources.files(examples).iterdir()
                  if p.name.endswith(".yaml"))


def list() -> builtins.list[str]:
    """Names of all built-in models: the shipped networks, the examples and registered ones.

    >>> import oxyline
    >>> {"cca", "adan56", "bifurcation"} <= set(oxyline.catalogue.list())
    True
    """
    return sorted(set(BUILTIN) | set(_registered) | set(_examples()))


def describe() -> dict[str, str]:
    """Name -> one-line description of every built-in model.

    >>> import oxyline
    >>> oxyline.catalogue.describe()["adan56"]
    'Boileau 2015 ADAN56 (openBF), 77 segments, 31 WK3'
    """
    out = {name: desc for name, (_f, desc) in BUILTIN.items()}
    out.update({name: desc for name, (_l, desc) in _registered.items()})
    for name in _examples():
        out.setdefault(name, "example network (oxyline/examples)")
    return dict(sorted(out.items()))


def _canonical(name: str) -> str:
    key = name.strip()
    if key in BUILTIN or key in _registered:
        return key
    low = key.lower()
    if low in ALIASES:
        return ALIASES[low]
    hyphen = low.replace("_", "-")
    if hyphen in BUILTIN:
        return hyphen
    return key


def path(name: str) -> Any:
    """Path (importlib resource) of a shipped model file.

    >>> import oxyline
    >>> oxyline.catalogue.path("cca").name
    'cca.yaml'
    """
    key = _canonical(name)
    if key in BUILTIN:
        return resources.files(_DATA) / BUILTIN[key][0]
    if key in _examples():
        return resources.files(examples) / f"{key}.yaml"
    raise ModelError(f"'{name}': not a shipped model file (shipped: "
                     f"{', '.join([*BUILTIN, *_examples()])})")


_LOADER: Any = None


def _shipped_yaml(text: str) -> Any:
    """A shipped (trusted) YAML file, read with libyaml (7x faster than the pure-Python YAML
    1.2 reader of user files on whole-body-140) and YAML 1.2's numbers: ``5.0e5`` and
    ``2.8931e9`` (no dot or no exponent sign) are floats, as :func:`oxyline.load_model` reads
    them from a user file, not the strings of YAML 1.1."""
    global _LOADER
    import yaml

    if _LOADER is None:
        base = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
        _LOADER = type("Yaml12NumbersLoader", (base,), {})
        _LOADER.add_implicit_resolver(
            "tag:yaml.org,2002:float",
            re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
            "-+0123456789.")
    return yaml.load(text, Loader=_LOADER)  # a safe loader with one more resolver


def shipped_data(filename: str) -> Any:
    """A data file shipped in ``oxyline/models_data`` (a built-in parameter set or table).

    >>> import oxyline
    >>> oxyline.catalogue.shipped_data("closed-loop-o2.yaml")["standard"]["period"]
    0.8
    """
    return _shipped_yaml((resources.files(_DATA) / filename).read_text())


def load_dict(name: str) -> dict[str, Any]:
    """A shipped model as a native model dict (SI), e.g. to edit before loading; for a whole
    tree, the compact dict with its ``structured-tree`` conditions (grown on load).

    >>> import oxyline
    >>> d = oxyline.catalogue.load_dict("cca")
    >>> d["vessels"][0]["name"]
    'common_carotid_artery'
    """
    if _canonical(name) in WHOLE_TREES:
        return _registered[_canonical(name)][0]()
    data = _shipped_yaml(path(name).read_text())
    if not isinstance(data, dict):
        raise ModelError(f"built-in model '{name}': corrupted file")
    return data


def build(data: dict[str, Any]) -> Model:
    """The :class:`Model` of a native model dict (a copy of it is validated and assembled).

    >>> import oxyline
    >>> d = oxyline.catalogue.load_dict("bifurcation")
    >>> d["vessels"][0]["youngs_modulus"] = 8e5    # a stiffer parent
    >>> oxyline.catalogue.build(d).vessel_names
    ['parent', 'daughter1', 'daughter2']
    """
    with gc_paused():
        return build_model(data)


def load(name: str) -> Model:
    """Load a built-in model (shipped network, example or registered model) by name.

    >>> import oxyline
    >>> oxyline.catalogue.load("aortic-bifurcation").vessel_names
    ['parent', 'd1', 'd2']
    """
    key = _canonical(name)
    if key in _registered:
        out = _registered[key][0]()
        return out if isinstance(out, Model) else build(out)
    if key in BUILTIN or key in _examples():
        return build(load_dict(key))
    raise ModelError(f"'{name}': neither a file nor a built-in model "
                     f"(built-ins: {', '.join(list())})")


__all__ = ["ALIASES", "BUILTIN", "WHOLE_TREES", "build", "describe", "list", "load", "load_dict",
           "path", "register"]
