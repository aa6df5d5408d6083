"""
Input impedance of the bifurcation
==================================

`oxyline.impedance` gives the input impedance Z(f) = P/Q seen from a node into the network
downstream of it. At f = 0 it is the steady resistance of the network, here the parent vessel's
Poiseuille resistance in series with the two outlet resistances in parallel.
"""

import matplotlib.pyplot as plt
import numpy as np

import oxyline
import oxyline.plot as op

model = oxyline.load_model("bifurcation")
f = np.linspace(0.0, 20.0, 81)
z = oxyline.impedance(model, "inlet", f)
print(f"Z(0) = {z.real[0]:.4e} Pa s/m^3")

fig = op.impedance(f, z, label="bifurcation, from the inlet")
plt.show()
