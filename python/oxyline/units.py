"""Unit conversion at the file boundary. Inside oxyline everything is SI."""

from __future__ import annotations

MMHG = 133.322368  # Pa

# factor that turns a value in the file's unit system into SI, per physical quantity
CGS_TO_SI: dict[str, float] = {
    "length": 1e-2,  # cm -> m
    "pressure": 0.1,  # dyn/cm^2 -> Pa
    "flow": 1e-6,  # mL/s -> m^3/s
    "resistance": 1e5,  # dyn s/cm^5 -> Pa s/m^3
    "capacitance": 1e-5,  # cm^5/dyn -> m^3/Pa
    "inductance": 1e5,  # dyn s^2/cm^5 -> Pa s^2/m^3
    "stenosis": 1e11,  # dyn s^2/cm^8 -> Pa s^2/m^6
    "density": 1e3,  # g/cm^3 -> kg/m^3
    "viscosity": 0.1,  # poise -> Pa s
    "modulus": 0.1,  # dyn/cm^2 -> Pa
    "time": 1.0,
    "none": 1.0,
}


def factor(units: str, quantity: str) -> float:
    """Multiplier from ``units`` ("SI" or "cgs") to SI for ``quantity``."""
    if units.lower() == "si":
        return 1.0
    if units.lower() == "cgs":
        return CGS_TO_SI[quantity]
    raise ValueError(f"units must be 'SI' or 'cgs', got {units!r}")
