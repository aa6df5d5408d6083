"""
A Vascular Model Repository patient model
=========================================

`0140_2001` is a patient model of the Vascular Model Repository, reduced to 0-D and tuned by
svZeroDSolver's calibrator (`tests/data/svzerod`, its licence beside it). `oxyline.load_model`
reads the svZeroDSolver file (cgs, converted to SI), and the standard figures follow: the
pressures of the inlet and four outlets, and their flows with one panel per decade of peak flow.
"""

from pathlib import Path

import matplotlib.pyplot as plt

import oxyline
import oxyline.plot as op

CASE = "tests/data/svzerod/cases/vmr/reference/0140_2001_optimal_from_0d.json"
try:  # run as a script
    here = Path(__file__).resolve().parent
except NameError:  # run by the documentation build, from the examples folder
    here = Path.cwd()
model = oxyline.load_model(next(d / CASE for d in (here.parent, here, Path.cwd())
                                if (d / CASE).exists()))
res = oxyline.simulate(model, cycles=3, until_periodic=None)
print(f"{len(model.vessel_names)} vessels; cardiac period {model.period:.3f} s")

fig = op.waveforms(res, op.representative_vessels(res, model, n=5))
plt.show()
