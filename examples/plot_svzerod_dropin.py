"""
An svZeroDSolver input through the drop-in
==========================================

`oxyline.svzerod.simulate` runs an svZeroDSolver JSON configuration and returns the same
DataFrame as `svzerod.simulate` (the file's own units, cgs by convention). Here a single vessel
between a pulsatile inflow table and an RCR Windkessel; the figure shows the inlet pressure in
mmHg (1 mmHg = 1333.22 dyn/cm²).
"""

import matplotlib.pyplot as plt
import numpy as np

import oxyline.svzerod as svz

t = np.linspace(0.0, 1.0, 51)
q = 5.0 + 4.0 * np.sin(2 * np.pi * t).clip(0)            # mL/s
cfg = {
    "simulation_parameters": {"number_of_cardiac_cycles": 8,
                              "number_of_time_pts_per_cardiac_cycle": 201},
    "boundary_conditions": [
        {"bc_name": "INFLOW", "bc_type": "FLOW", "bc_values": {"Q": q.tolist(), "t": t.tolist()}},
        {"bc_name": "OUT", "bc_type": "RCR",
         "bc_values": {"Rp": 100.0, "C": 1.0e-3, "Rd": 1000.0, "Pd": 0.0}}],
    "vessels": [{"vessel_id": 0, "vessel_name": "branch0_seg0",
                 "zero_d_element_type": "BloodVessel",
                 "zero_d_element_values": {"R_poiseuille": 50.0, "C": 1.0e-5, "L": 1.0},
                 "boundary_conditions": {"inlet": "INFLOW", "outlet": "OUT"}}],
}
df = svz.simulate(cfg)
print(df.attrs["units"]["pressure_in"], len(df), "rows")

fig, ax = plt.subplots(figsize=(6, 3.5))
ax.plot(df.time, df.pressure_in / 1333.22, label="inlet pressure")
ax.set_xlabel("time (s)")
ax.set_ylabel("pressure (mmHg)")
ax.legend()
fig.tight_layout()
plt.show()
