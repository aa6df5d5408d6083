"""
Oxygen along the paper's carotid bifurcation
============================================

`paper-bifurcated` is the bifurcation verification case of the transmission-line oxygen paper
(Sci Rep 2018, doi:10.1038/s41598-018-23743-2): blood flow and dissolved oxygen on the same
segments, with the Graetz wall closure. The figure shows the time-mean PO2 and pressure along
the path from the inlet to the internal carotid outlet; the mass balance closes to round-off.
"""

import matplotlib.pyplot as plt

import oxyline
import oxyline.plot as op

model = oxyline.load_model("paper-bifurcated")
res = oxyline.simulate(model, cycles=2)
for name, po2 in zip(res.vessels, res.po2_out[-1]):
    print(f"{name}: PO2 {po2:.2f} mmHg at the vessel's end")
mb = res.o2_mass_balance
print(f"relative O2 mass-balance residual: {mb['residual'][-1] / mb['inflow'][-1]:.1e}")

fig = op.profile(res, model, "ICA", quantity=["po2", "pressure"])
plt.show()
