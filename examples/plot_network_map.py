"""
Mean pressure across the aortic bifurcation
===========================================

The built-in `aortic-bifurcation` network (Boileau et al. 2015, from the openBF model library),
run to periodicity; the map colours each vessel by its time-mean inlet pressure.
"""

import matplotlib.pyplot as plt

import oxyline
import oxyline.plot as op

model = oxyline.load_model("aortic-bifurcation")
res = oxyline.simulate(model, cycles=3)
for name in res.vessels:
    v = res.vessel(name)
    print(f"{name:8s} {v.pressure_in.mean() / 133.322:6.1f} mmHg  {v.flow_in.mean() * 1e6:6.2f} mL/s")

fig = op.network_map(model, result=res, values="pressure")
plt.show()
