"""|Z| and phase at the ADAN56 aortic root, Windkessel outlets against structured trees
(adan56-st), for docs/structured-tree.md. Prints load and impedance times; writes
docs/figures/adan56_st_impedance.png. Run: python benches/adan56_st_impedance.py"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

import oxyline
from oxyline import plot

if __name__ == "__main__":
    f = np.linspace(0.0, 20.0, 81)
    fig = None
    for name in ("adan56", "adan56-st"):
        t0 = time.perf_counter()
        m = oxyline.catalogue.load(name)
        t1 = time.perf_counter()
        inlet = next(iter(plot.inlets(m)))
        z = oxyline.impedance(m, inlet, f)
        t2 = time.perf_counter()
        s = m.network.summary()
        print(f"{name}: {s['vessels']} vessels, {s['segments']} segments, {s['unknowns']} "
              f"unknowns; load {t1 - t0:.1f} s, Z at {len(f)} frequencies {t2 - t1:.2f} s; "
              f"Z(0) = {z[0].real:.6e} Pa s/m3, |Z(5 Hz)| = {abs(z[20]):.4e}; "
              f"load average {os.getloadavg()[0]:.1f}")
        fig = plot.impedance(f, z, label=name, ax=None if fig is None else fig.axes)
    out = Path(__file__).resolve().parents[1] / "docs" / "figures" / "adan56_st_impedance.png"
    fig.savefig(out, dpi=120)
    print(f"written {out}")
