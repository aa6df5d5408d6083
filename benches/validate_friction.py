"""ADAN56 and the circle of Willis against openBF's stored 1-D results with Poiseuille and
Womersley segments (``wall_friction``), as ``validate_openbf.py`` compares them: prints one
row per model and option as it goes (~4 runs to periodicity; over 25 min on a loaded
2-core machine).

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
    print("| model | friction | mean P max / median | pulse P max / median | mean Q max / median |")
    print("|---|---|---:|---:|---:|", flush=True)
    for model in ("adan56", "circle_of_willis"):
        for friction in ("poiseuille", "womersley"):
            vo.read_openbf = reader(friction)
            s = vo.summary(vo.compare(model)["rows"])
            cells = " | ".join(f"{100 * s[k][0]:.2f} / {100 * s[k][1]:.2f}"
                               for k in ("mean_p", "pp", "mean_q"))
            print(f"| {model} | {friction} | {cells} |", flush=True)
    vo.read_openbf = _READ


if __name__ == "__main__":
    main()
