"""ADAN56 and the circle of Willis against openBF's stored 1-D results with Poiseuille and
Womersley segments (``wall_friction``), as ``validate_openbf.py`` compares them: prints the
table of docs/validation.md ("Friction options against openBF"). ~10 min.

openBF's own friction is the quasi-steady profile law (``gamma_profile``); the importer folds it
into the model viscosity, which the Womersley cells then also use.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).parent))

import validate_openbf as vo

import oxyline

_READ = vo.read_openbf


def reader(friction: str) -> Any:
    def read(path: Path, **options: Any) -> oxyline.Model:
        data = _READ(path, **options).to_dict()
        data["wall_friction"] = friction
        return oxyline.load_model(data)
    return read


def main() -> None:
    rows = []
    for model in ("adan56", "circle_of_willis"):
        for friction in ("poiseuille", "womersley"):
            vo.read_openbf = reader(friction)
            s = vo.summary(vo.compare(model)["rows"])
            rows.append((model, friction, s))
    vo.read_openbf = _READ
    print("| model | friction | mean P max / median | pulse P max / median | mean Q max / median |")
    print("|---|---|---:|---:|---:|")
    for model, friction, s in rows:
        cells = " | ".join(f"{100 * s[k][0]:.2f} / {100 * s[k][1]:.2f}"
                           for k in ("mean_p", "pp", "mean_q"))
        print(f"| {model} | {friction} | {cells} |")


if __name__ == "__main__":
    main()
