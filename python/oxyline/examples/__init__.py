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
    import yaml

    from oxyline.loader import load_model

    data = yaml.safe_load(path(name).read_text())
    return load_model(data)
