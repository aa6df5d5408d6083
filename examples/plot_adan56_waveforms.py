"""
Pressure and flow across the ADAN56 arterial tree
=================================================

`adan56` is the 56-artery adult network of Boileau et al. (2015), the openBF benchmark. Its
flows span three decades, from the ascending aorta to the small arteries of the arms and
head: the figure gives each decade of peak flow its own panel, with the pressures of the same
vessels above, so that the small arteries' waveforms are not flattened against the aorta's.
"""

import matplotlib.pyplot as plt

import oxyline
import oxyline.plot as op

model = oxyline.load_model("adan56")
res = oxyline.simulate(model, cycles=3, until_periodic=None, output_every=2e-3)
vessels = op.representative_vessels(res, model, n=6)
for name in vessels:
    q = res.vessel(name).flow_in
    print(f"{name}: peak flow {q.max() * 1e6:.1f} mL/s")

fig = op.waveforms(res, vessels)
plt.show()
