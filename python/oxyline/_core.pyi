"""Type stubs for the Rust extension module ``oxyline._core``."""

from collections.abc import Callable, Mapping
from typing import Any, TypedDict

import numpy as np
import numpy.typing as npt
from typing_extensions import Unpack

__version__: str
build_profile: str
# the column schema of the output (oxyline_core::output)
VESSEL_VARIABLES: list[str]
SEGMENT_VARIABLES: list[str]
SPECIES_VESSEL_VARIABLES: list[str]
SPECIES_SEGMENT_VARIABLES: list[str]
BALANCE_VARIABLES: list[str]
TISSUE_VESSEL_VARIABLES: list[str]
TISSUE_SEGMENT_VARIABLES: list[str]
TISSUE_BALANCE_VARIABLES: list[str]
ML_O2: float
#: the keywords of RunOptions (rust/oxyline-py/src/settings.rs)
RUN_SETTINGS: list[str]
# the run-settings schema (oxyline_core::model::settings)
STARTS: list[str]
OPTIONS: list[str]
# a checkpoint file's schema (oxyline_core::run::checkpoint::meta)
CHECKPOINT_FORMAT: str
CHECKPOINT_FILE_VERSION: int
CHECKPOINT_STATE_SCALARS: list[str]
CHECKPOINT_MAX_EVERY_SECONDS: float
#: the settings a resumed run may change
RUN_CONTROL: list[str]

class RunOptions(TypedDict, total=False):
    """The run settings ``Network.simulate`` and ``Ensemble.run`` share (``**settings``)."""

    cycles: int  # default 10
    method: str  # "auto", "rk4" or "generalized-alpha"
    rho_infty: float  # 0.5
    dt: float | None
    until_periodic: float | None
    max_cycles: int  # 100
    output_all_cycles: bool
    start: str  # "steady", "periodic", "zero", "svzerod-steady" or "svzerod-zero"
    newton_atol: float | None
    max_iterations: int  # 30
    segments: bool  # True
    transport: bool  # True
    variables: list[str] | None
    vessels: list[str] | None
    rtol: float | None  # error control (generalized-alpha, variable step)
    atol: dict[str, float] | None  # by kind: pressure, flow, volume, species

class ModelError(ValueError): ...
class UnstableTimeStep(ModelError): ...
class SolverError(RuntimeError): ...

class NativeParts:
    """The vessels and plain outlets of a native model read by the binding (plain ones by its
    fast reader, the rest by the core's schema); handed to :class:`Network` as ``parts``."""

    def __init__(self, vessels: list[Any], units: str) -> None: ...
    def slow_vessels(self) -> list[int]: ...
    def read_rest(self, vessels: list[Any], units: str) -> list[tuple[float, str]]: ...
    def read_outlets(self, bcs: dict[Any, Any], units: str) -> list[Any]: ...
    def names(self) -> list[str]: ...

class Network:
    """An assembled network, built from a canonical SI model: its dicts (read in place by the
    core's serde types) or its JSON text. ``max_memory``: the memory limit in bytes."""

    def __init__(self, model: dict[str, Any] | str, max_memory: float | None = None,
                 keep_circuit: bool | None = None) -> None: ...
    def summary(self) -> dict[str, Any]: ...
    def circuit_kept(self) -> bool: ...
    def passes(self) -> int:
        """2 for a transport model whose closures need a flow-only pass first, else 1."""
    def plausibility(self) -> list[dict[str, Any]]:
        """The model's values outside their physiological ranges (element, key, value, unit,
        low, high, likely_cause, more, message), for :class:`oxyline.PlausibilityWarning`."""
    def layout(self) -> dict[str, Any]: ...
    def transport_layout(self) -> dict[str, Any] | None: ...
    def output_layout(
        self,
        *,
        variables: list[str] | None = None,
        vessels: list[str] | None = None,
        segments: bool = True,
    ) -> dict[str, Any]:
        """Layout of an output selection: ``vessels``, ``segment_count``, ``segment_position``,
        ``vessel_variables``, ``segment_variables``, ``n_columns`` and, for transport models,
        ``transport`` (``species``, its selected variables, ``segment_count``,
        ``columns_per_species``). Unknown names raise ModelError."""
    def segment_table(self) -> dict[str, Any]:
        """Per flow segment (model order): ``vessel`` (index into ``vessel_names``), ``index``,
        ``resistance``, ``inductance``, ``compliance``, ``stenosis``, ``volume``, ``length``,
        ``radius_in``, ``radius_out``, ``x0``, ``x1``, ``position`` (numpy arrays, SI)."""
    def steady_state(self) -> dict[str, Any]:
        """Exact steady state of the mean boundary conditions: ``state``, graph ``nodes`` and
        their ``node_pressure``, output ``vessels`` and their ``pressure_in``,
        ``pressure_out``, ``flow_in``, ``flow_out``."""
    def unknown_names(self) -> list[str]: ...
    def valve_closure(self, name: str, dp: list[float]) -> npt.NDArray[np.float64]:
        """svZeroDSolver's valve_status of valve element ``name`` at the pressure differences
        ``dp`` = P_front − P_behind (0 open, 1 closed)."""
    def circuit(self) -> dict[str, Any]: ...
    def source_flows(self, t: float) -> list[float]: ...
    def derivative(
        self, t: float, state: list[float] | npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...
    def rk4_stability_limit(self, method: str = "auto") -> tuple[float, str, bool]: ...
    def rk4_step_ceiling(self) -> float: ...
    def rk4_step_refinement(
        self, *, period: float, output_every: float, tol: float, max_factor: int,
        **settings: Unpack[RunOptions],
    ) -> tuple[int, float, bool]: ...
    def rk4_operator(self) -> tuple[np.ndarray, int]: ...
    def input_impedance(self, node: str, omega: float) -> tuple[float, float]: ...
    def input_impedances(
        self, node: str, frequencies: list[float], direction: str = "downstream"
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...
    def simulate(
        self,
        *,
        period: float,
        output_every: float,
        all_unknowns: bool = False,
        heart: bool = False,
        progress: Callable[[float, float], None] | None = None,
        chunk_sink: Callable[[dict[str, Any]], None] | None = None,
        chunk_rows: int = 1024,
        keep_current_cycle: bool = True,
        checkpoint_sink: Callable[[dict[str, Any]], None] | None = None,
        checkpoint_every_cycles: int | None = None,
        checkpoint_every_seconds: float | None = None,
        resume: dict[str, Any] | None = None,
        svzerod: dict[str, Any] | None = None,
        **settings: Unpack[RunOptions],
    ) -> dict[str, Any]:
        """Run the network; with ``chunk_sink``, the output rows are handed to it during the
        run in dicts of at most ``chunk_rows`` rows (``times``, ``data`` and, for transport
        runs, ``transport``: ``species``, ``data``, ``initial_stored``) instead of being
        returned. An exception from ``chunk_sink`` stops the run and is returned as ``error``;
        ``max_buffered_rows`` is the most output rows the core held at once. With last-cycle
        output, ``keep_current_cycle=False`` records nothing before the last cycle (a streaming
        run then holds at most one chunk; a run stopped earlier returns no rows). ``heart``:
        the dict and every chunk also have ``chamber_volume`` {chamber: m^3 per row} and
        ``valve_status`` {valve: int8 per row, 1 open}; a chunk's valves go on from the last's.

        The step control defaults as in ``oxyline.simulate``: without ``rtol``, ``dt`` and
        checkpoints and with a method other than ``rk4`` the run is error-controlled at rtol
        1e-3; ``rtol=None`` keeps the automatic fixed step."""

class Ensemble:
    """A parsed base model whose variants run in parallel on the core's threads."""

    def __init__(self, model_json: str,
                 targets: list[tuple[str, int | str]] | None = None) -> None: ...
    def run(
        self,
        feed: Callable[
            [],
            tuple[int, str | None, float, float, dict[int, Any] | None, dict[str, Any] | None,
                  npt.NDArray[np.float64] | None,
                  list[tuple[int, npt.NDArray[np.float64], npt.NDArray[np.float64]]] | None]
            | None,
        ],
        *,
        on_done: Callable[
            [int, dict[str, Any] | None, dict[str, Any] | None, str | None, str | None], None
        ],
        workers: int | None = None,
        summary: bool = False,
        heart: bool = False,
        **settings: Unpack[RunOptions],
    ) -> bool:
        """Run the variants ``feed()`` hands over (``(i, canonical patch JSON or None,
        period, output_every, vessels, outlets, values, tables)``, ``values`` one SI number
        per ``targets`` entry (NaN: the base value), ``tables`` the new ``(target, time,
        value)`` of ``table`` targets; None when there are no more) on ``workers``
        threads (default
        ``OXYLINE_NUM_THREADS`` or every core), the GIL released; ``on_done(i, raw, layout,
        error_kind, error)`` is called on this thread as each finishes. False if Ctrl-C
        stopped it."""

def closed_loop_run(params: dict[str, Any], flows: Any, max_cycles: Any, tol: Any,
                    shooting: Any) -> dict[str, Any]:
    """The closed loop of a parameter set (published units) run in one call: settings checked,
    circulation built, heart run when it gives the flows (None: the set's `flows`; "table",
    "heart" or a steps x branches table), O2 to the periodic state; flat arrays out, with the
    compartments' and branches' names, the cycle's ``summary`` (the keys of
    ``ClosedLoopO2Result.summary()``) and its flow-weighted means (``weighted``: per recorded
    compartment variable, branches x compartments)."""
def closed_loop_heart_model(params_json: str) -> dict[str, Any]:
    """The native model dict of a parameter set's closed-loop heart circulation."""
def closed_loop_heart_value(params_json: str, path: str) -> float:
    """The number at ``path`` (``vessels.<name>.<key>...``) of a parameter set's closed-loop
    heart model, in the model's own units (its ``heart_values`` written over the built ones)."""
def closed_loop_heart_run_options(params_json: str) -> dict[str, Any]:
    """The run options of a parameter set's closed-loop heart as the loop runs it
    (``newton_atol`` for svZeroDSolver's block)."""
def closed_loop_layout(params_json: str, table: bool) -> tuple[str, np.ndarray | None]:
    """The closed loop's SI layout (JSON: compartments, branches, binding, organ_resistances,
    solubility_per_mmhg, cardiac_output) of a parameter set in its published units and, with
    ``table``, its prescribed flow table (steps x branches, m^3/s)."""
def outlet_root_radius(node: str, vessels: list[Any] | None) -> float:
    """The radius (model units) of the first vessel end at outlet ``node``: a structured
    tree's default root radius there."""
def windkessel_tree_match(node: str, rcr: Mapping[str, Any], root_radius: float,
                          viscosity: float, min_radius: float, tree_fraction: float,
                          alpha: float, beta: float, length_ratio: float
                          ) -> tuple[float, float]:
    """(min_radius, terminal resistance) of the structured tree that keeps the RCR's steady
    resistance R_p + R_d."""
def svzerod_output_rows(cycles: int, steps: int, extra: int, interval: int, all_cycles: bool
                        ) -> tuple[np.ndarray, np.ndarray]:
    """svZeroDSolver's output rows of a run extended by its cycle-to-cycle rule: (global step
    indices, output times in units of dt)."""
def chamber_elastance(name: str, chamber_json: str, times: list[float]
                      ) -> tuple[np.ndarray, np.ndarray]:
    """(E(t), V_rest(t)) of a canonical chamber spec (JSON text) at ``times``."""
def tangent_sensitivities(model_json: str, paths: list[str], signals: list[tuple[str, str]],
                          period: float, steps_per_cycle: int, rho_infty: float = 0.5,
                          max_cycles: int = 2000, tol: float = 1e-12) -> dict[str, Any]:
    """The signals over the periodic cycle of a canonical model, flow (vessel, variable) and
    oxygen (vessel, name; vessel "" for the network's balance fluxes) alike, and their exact
    derivatives with respect to the parameter ``paths``, flow and oxygen alike
    (oxyline.calibrate)."""
def target_tangents(model_json: str, paths: list[str], signals: list[tuple[str, str]],
                    targets: list[tuple[str, list[int], list[float] | None]], period: float,
                    steps_per_cycle: int, rho_infty: float = 0.5, max_cycles: int = 2000,
                    tol: float = 1e-12) -> dict[str, Any]:
    """Every target's (values, jacobian by ``paths``) at the periodic state by one tangent
    run of ``signals``: a target is (output, its signals' columns, a series' times or None
    for the cycle's steps); a pulse-wave velocity's path length from the model
    (oxyline.calibrate)."""
def target_gradients(model_json: str, paths: list[str], signals: list[tuple[str, str]],
                     targets: list[tuple[str, list[int], list[float] | None]], period: float,
                     steps_per_cycle: int, rho_infty: float = 0.5, max_cycles: int = 2000,
                     tol: float = 1e-12) -> dict[str, Any]:
    """:func:`target_tangents` by the adjoint: the targets' output weights built by the core
    from the one primal cycle, one backward sweep per target value; ``outputs`` (each
    target's values) and ``gradients`` (the targets' rows × parameters)."""

class CalibrationProblem:
    """svZeroDSolver's calibration residual (oxyline_core::calibration): RCL vessels
    ``(name, (P_in, Q_in, P_out, Q_out) variable indices, (R, C, L, S) slots)`` and junction
    branches ``(name, (P_in, P_out, Q_out), (R, L, S))`` over observations ``y``, ``dy``
    (variable-major, ``n_obs`` samples per variable)."""

    def __init__(self, vessels: list[tuple[str, tuple[int, ...], tuple[int, ...]]],
                 branches: list[tuple[str, tuple[int, ...], tuple[int, ...]]],
                 y: np.ndarray, dy: np.ndarray, n_obs: int) -> None: ...
    def normal_equations(self, alpha: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """(Σr², Jᵀr by slot, the blocks of JᵀJ concatenated row-major: vessels, then
        branches) at ``alpha``."""
    def fit(self, start: np.ndarray, active: list[bool], max_iterations: int,
            initial_damping: float, tolerance_gradient: float, tolerance_increment: float
            ) -> tuple[np.ndarray, int, bool]:
        """svZeroDSolver's Levenberg–Marquardt fit from ``start`` of the slots marked in
        ``active``: (values, iterations, converged); ``SolverError`` for a singular step."""

# the core's model schema (oxyline_core::model::native) on native model dicts
def read_vessels(vessels: list[Any], units: str) -> list[dict[str, Any]]: ...
def read_conditions(bcs: Any, units: str
                    ) -> tuple[dict[str, Any], list[tuple[float, str]]]: ...
def check_periods(data: Any, periods: list[tuple[float, str]],
                  vessels: list[Any] | None = None) -> float | None: ...
class VariantReader:
    """The reader of an ensemble's variants: ``base``'s canonical vessels and conditions (a
    canonical model dict; None: every element is read) and its conditions' periods."""

    def __init__(self, base: dict[str, Any] | None = None) -> None: ...
    def read(self, data: Any, vessels: list[int] = ..., nodes: list[str] = ...
             ) -> tuple[str, dict[str, Any], float | None, dict[str, Any]]:
        """(name, canonical description, period, transport facts) of a native model read in
        the core's one order; the base's canonical vessels and conditions are reused except
        those at ``vessels`` (indices) and ``nodes``. A ModelError about one of them has
        ``element``."""
    def check(self, source: dict[str, Any], patches: list[Any], numbers: list[int]) -> None:
        """Raise ModelError for the first patch (variant ``numbers[i]``) with a path that
        names nothing of the native model ``source``."""
    def prepare(self, source: dict[str, Any], patch: Any, k: int
                ) -> tuple[str, dict[int, Any] | None, dict[str, Any] | None,
                           tuple[str, dict[str, Any], float | None, dict[str, Any]],
                           dict[str, Any]]:
        """Variant ``k``: ``patch`` merged into ``source`` by the core and its changed elements
        read: (changed blood/transport sections as JSON, changed canonical vessels by index,
        changed canonical conditions by node, ``read``'s tuple, the native model dict).
        ModelError names the variant and the patch paths."""
def column_keys(parts: list[str], dotted: bool, vessels: list[str], nodes: list[str],
                variant: int) -> list[str]:
    """The keys of a patch table's column (dotted pieces, or a multi-level column's levels)."""
def resolve_settings(sim: Any, overrides: Any, period: float | None) -> dict[str, Any]: ...
def run_facts(settings: dict[str, Any], run: dict[str, Any] | None = None,
              valves: bool = False) -> dict[str, Any]:
    """The settings and facts a run records with its result (oxyline_core::run::facts)."""
def segmentation_facts(summary: dict[str, Any]) -> dict[str, Any]:
    """How the model's vessels were cut, from ``Network.summary()``."""
def checkpoint_interval(value: Any, file: bool = True) -> dict[str, Any]:
    """``checkpoint_every`` as ``Network.simulate``'s keywords; ModelError if bad."""
def check_checkpoint_meta(file: str, meta: Any, arrays: dict[str, np.ndarray]) -> None:
    """CheckpointError naming ``file`` and the field unless ``meta`` and ``arrays`` fit the
    schema."""
def check_resumed(keys: list[str]) -> None:
    """ModelError naming the settings a resumed run cannot change."""
class ColumnStatsFold:
    """Each column's time mean (trapezoidal), min and max over rows added chunk by chunk."""
    def __init__(self, n_cols: int) -> None: ...
    def push(self, times: np.ndarray, data: np.ndarray) -> None: ...
    def finish(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None: ...
class BoundsMonitor:
    """The physical-bounds monitor of one run (docs/physics.md §2.8): each species' range
    computed once from the canonical transport section (None: no species), the recorded rows
    fed chunk by chunk and read in place."""
    def __init__(self, transport: Mapping[str, Any] | None) -> None: ...
    def update(self, time: np.ndarray, vessels: list[str], segment_count: list[int],
               species: list[tuple[str, np.ndarray, list[str], np.ndarray, list[str],
                                   np.ndarray, float, float | None]],
               flows: tuple[np.ndarray, np.ndarray] | None, oxygen: str | None) -> None: ...
    def messages(self) -> list[str]: ...
def species_bounds(species: Mapping[str, Any]) -> tuple[float, float] | None:
    """[min, max] of a species' inlet, backflow, initial and wall values (mol/m^3), None for a
    species with a prescribed source; ``species`` read as the model's own species."""
def forcing_frequency(data: Any, rtol: float | None = None) -> tuple[float, float]:
    """The highest significant frequency (Hz) of a native model's flow and pressure
    waveforms and the tolerance it was found at (the `segments: auto` rule)."""
