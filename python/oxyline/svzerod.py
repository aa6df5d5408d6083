"""svZeroDSolver drop-in: run svZeroDSolver JSON inputs with oxyline's core.

:func:`simulate` takes an svZeroDSolver configuration (a dict or a path to a JSON file) and
returns the same pandas DataFrame as ``svzerod.simulate``, in the file's own units (named in
``df.attrs["units"]``); :func:`to_model` converts it to an oxyline model (SI). With the default
``method="generalized-alpha"`` the time stepping, the steady initialisation and the Newton
stopping rule are svZeroDSolver's, so results agree with the peer's to round-off. Elements,
options, units and measured errors: docs/svzerod.md. The reader is
:mod:`oxyline.io.svzerod.reader`, the runner :mod:`oxyline.io.svzerod.dropin`, the exporter
:mod:`oxyline.io.svzerod.writer`, the calibrator :mod:`oxyline.io.svzerod.calibrator`.

Example::

    import oxyline.svzerod as svz

    config = {
        "simulation_parameters": {"number_of_cardiac_cycles": 2,
                                  "number_of_time_pts_per_cardiac_cycle": 5},
        "boundary_conditions": [
            {"bc_name": "INFLOW", "bc_type": "FLOW", "bc_values": {"Q": [5.0, 5.0], "t": [0.0, 1.0]}},
            {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": 100.0, "Pd": 100.0}},
        ],
        "vessels": [
            {"vessel_id": 0, "vessel_name": "aorta", "zero_d_element_type": "BloodVessel",
             "zero_d_element_values": {"R_poiseuille": 100.0, "C": 1e-4},
             "boundary_conditions": {"inlet": "INFLOW", "outlet": "OUT"}},
        ],
    }
    df = svz.simulate(config)                 # same frame as svzerod.simulate(config)
    print(df.round(6).iloc[0].to_dict())
    # {'name': 'aorta', 'time': 0.0, 'flow_in': 5.0, 'flow_out': 5.0,
    #  'pressure_in': 1100.0, 'pressure_out': 600.0}
    df_rk4 = svz.simulate(config, method="rk4")   # explicit RK4, same output times
    model = svz.to_model(config)              # an oxyline.Model, for oxyline.simulate etc.
"""

from oxyline.io.svzerod.calibrator import calibrate
from oxyline.io.svzerod.dropin import simulate
from oxyline.io.svzerod.reader import (
    RunSettings,
    file_units,
    run_settings,
    to_model,
    to_oxyline_dict,
)

__all__ = ["RunSettings", "calibrate", "file_units", "run_settings", "simulate", "to_model",
           "to_oxyline_dict"]
