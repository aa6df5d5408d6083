"""
Pressure and flow in the carotid bifurcation
============================================

The built-in `bifurcation` example (a common carotid artery splitting into two daughters, a
Fourier inflow and resistive outlets), run for five cycles; the last cycle's pressure and flow
at the inlet of each vessel.
"""

import matplotlib.pyplot as plt

import oxyline
import oxyline.plot as op

res = oxyline.simulate("bifurcation", cycles=5)
print(res.settings["method"], res.settings["dt"])
for name in res.vessels:
    v = res.vessel(name)
    print(f"{name:10s} mean pressure {v.pressure_in.mean() / 133.322:6.1f} mmHg, "
          f"mean flow {v.flow_in.mean() * 1e6:5.2f} mL/s")

fig = op.waveforms(res, ["parent", "daughter1", "daughter2"])
plt.show()
