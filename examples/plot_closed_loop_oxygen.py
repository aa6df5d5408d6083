"""
Oxygen around a closed circulation
==================================

`closed-loop-o2` carries oxygen around a resting adult's circulation with no inlet: the lungs
load it, the organs consume it, and the loop runs to its periodic state. The figure shows the
cycle-mean PO2 and haemoglobin saturation of every compartment; the printed summary
holds the arterial and mixed-venous saturations, the oxygen consumption and the residual of
Fick's principle (lung uptake = cardiac output × arteriovenous content difference).
"""

import matplotlib.pyplot as plt

from oxyline import closed_loop

p = closed_loop.load("closed-loop-o2")
p["dt"] = 4e-3  # s; docs/oxygen.md quotes 1 ms
res = closed_loop.simulate_o2(p)
s = res.summary()
print(f"SaO2 {s['SaO2']:.3f}, SvO2 {s['SvO2']:.3f}, VO2 {s['VO2']:.0f} mL/min, "
      f"Fick residual {s['fick_residual']:.1e}")

names = res.compartments
fig, (ax_p, ax_s) = plt.subplots(1, 2, sharey=True, figsize=(8, 4.5), layout="constrained")
ax_p.barh(names, res.po2.mean(axis=0))
ax_s.barh(names, 100 * res.saturation.mean(axis=0))
ax_p.set_xlabel("cycle-mean PO2 [mmHg]")
ax_s.set_xlabel("cycle-mean SO2 [%]")
ax_p.invert_yaxis()
fig.suptitle("closed-loop-o2: oxygen in each compartment at the periodic state")
plt.show()
