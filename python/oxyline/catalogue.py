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
  virtual populations of :mod:`oxyline.populations` (``docs/populations.md``);
* ``adan56-st`` and ``whole-body-140-st`` — whole trees: adan56's Windkessels and
  whole-body-140's terminal compartments replaced by structured trees (grown on load,
  ``docs/structured-tree.md``).

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

from oxyline import examples
from oxyline.errors import ModelError
from oxyline.memory import gc_paused
from oxyline.model import Model, build_model

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
    "adan56-st": ("adan56-st.yaml", ("ADAN56 with 31 structured trees (min radius 0.1 mm) "
                                     "instead of WK3: 262,512 vessels, 314,489 segments")),
    "whole-body-140-st": ("whole-body-140-st.yaml",
                          ("whole-body-140 with 95 structured trees (min radius 0.1 mm, Murray "
                           "root radii) instead of its terminal R-C-R: 256,368 vessels, 305,949 "
                           "segments")),
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


#: built-in whole trees (1e5-1e6 segments: seconds to a minute to load); their files hold the
#: compact dict (the trees as ``structured-tree`` conditions, grown on load) and the budgeted
#: run of a whole tree as their ``simulation`` (one cycle of generalized-alpha at 1 ms,
#: vessel output every 10 ms); the recipes: ``benches/make_models_data.py``
WHOLE_TREES = ("adan56-st", "whole-body-140-st")


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
