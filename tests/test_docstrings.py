"""Every public function and class has a docstring with an example, and every example in the
package's docstrings runs and prints what it says (doctest)."""

from __future__ import annotations

import doctest
import importlib
import inspect
import os
from pathlib import Path

import pytest

import oxyline

PACKAGE = Path(oxyline.__file__).parent
os.environ.setdefault("MPLBACKEND", "Agg")
pytest.importorskip("matplotlib")

#: the public modules beside the top level (docs/api.md and the figures pages)
SUBMODULES = ("oxyline.plot", "oxyline.plot_oxygen", "oxyline.svzerod", "oxyline.sensitivity",
              "oxyline.catalogue")


def _modules_with_examples() -> list[str]:
    out = []
    for p in sorted(PACKAGE.rglob("*.py")):
        if ">>>" in p.read_text(encoding="utf-8"):
            rel = p.relative_to(PACKAGE.parent).with_suffix("")
            out.append(".".join(rel.parts).removesuffix(".__init__"))
    return out


def _public() -> list[tuple[str, object]]:
    """The functions and classes a user calls: ``oxyline.__all__`` (not the exception and
    warning types, whose docstrings say when they are raised) and the public functions of the
    public submodules."""
    out: list[tuple[str, object]] = []
    for name in oxyline.__all__:
        obj = getattr(oxyline, name)
        if name.startswith("__") or inspect.ismodule(obj):
            continue
        if isinstance(obj, type) and issubclass(obj, BaseException) \
                and not issubclass(obj, oxyline.PlausibilityWarning):
            continue
        out.append((f"oxyline.{name}", obj))
    for mod_name in SUBMODULES:
        mod = importlib.import_module(mod_name)
        for name, obj in vars(mod).items():
            if not name.startswith("_") and inspect.isfunction(obj) \
                    and obj.__module__ == mod_name:
                out.append((f"{mod_name}.{name}", obj))
    return out


def test_every_public_function_and_class_has_an_example() -> None:
    public = _public()
    assert len(public) > 40
    missing = [name for name, obj in public if ">>>" not in (inspect.getdoc(obj) or "")]
    assert missing == []


@pytest.mark.parametrize("module", _modules_with_examples())
def test_the_examples_of_a_module_run(module: str) -> None:
    import matplotlib.pyplot as plt

    from oxyline import catalogue

    mod = importlib.import_module(module)
    registered = dict(catalogue._registered)  # an example registers a model: not for later tests
    try:
        result = doctest.testmod(mod, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE,
                                 report=True)
    finally:
        catalogue._registered.clear()
        catalogue._registered.update(registered)
        plt.close("all")
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples of {module} failed"
