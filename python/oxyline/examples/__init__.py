"""Built-in example networks, loadable by name: ``oxyline.examples.load("bifurcation")``."""

from __future__ import annotations

from importlib import resources
from typing import Any

_HERE = resources.files(__name__)


def names() -> list[str]:
    """Names of the built-in examples."""
    return sorted(p.name[:-5] for p in _HERE.iterdir() if p.name.endswith(".yaml"))


def path(name: str) -> Any:
    """Path (importlib resource) of a built-in example file."""
    p = _HERE / f"{name}.yaml"
    if not p.is_file():
        from oxyline.errors import ModelError

        raise ModelError(f"'{name}': neither a file nor a built-in example "
                         f"(built-ins: {', '.join(names())})")
    return p


def load(name: str) -> Any:
    """Load a built-in example as a validated :class:`oxyline.Model`."""
    from oxyline.loader import load_model
    from oxyline.models import _shipped_yaml

    return load_model(_shipped_yaml(path(name).read_text()))
