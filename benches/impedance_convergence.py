"""Convergence table of docs/validation.md ("Structured-tree input impedance"): largest
relative |Z| error and phase error over 1-20 Hz of a 15-vessel structured tree (plus its feed
vessel), against the exact transmission-line solution of the same tree, as the segments per
vessel are refined. Run: python benches/impedance_convergence.py"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_structured_tree import impedance_errors

if __name__ == "__main__":
    print("| arrangement | segments/vessel | max rel. error of abs(Z) | max phase error (rad) |")
    print("|---|---:|---:|---:|")
    for arrangement in ("inverted-L", "pi"):
        for n in (1, 2, 4, 8, 16, 32):
            mod, phase = impedance_errors(arrangement, n)
            print(f"| {arrangement} | {n} | {mod:.3e} | {phase:.3e} |")
