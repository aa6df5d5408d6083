"""CSV/TSV (or pandas DataFrame) vessel and boundary-condition tables.

Vessel table, one row per vessel. Columns: ``name``, ``from``, ``to``, ``length``, ``radius`` or
``radius_in``/``radius_out``, ``wall_thickness``, ``youngs_modulus``, ``poisson_ratio``, and
optionally ``segments``, ``arrangement``, ``output``, ``description``; lumped vessels leave the
geometry empty and fill ``resistance``, ``inductance``, ``capacitance``,
``stenosis_coefficient``. Aliases: ``source``/``target``, ``thickness``/``h``, ``E``, ``nu``,
``lumped_resistance``, …

Boundary-condition table, one row per node: ``node``, ``type`` (flow, pressure, resistance, rcr)
and the parameter columns of that type: ``value`` (constant flow/pressure), ``waveform`` (path,
relative to the table, of a two-column time/value file), ``interpolation``, ``steady``,
``fourier_period``, ``fourier_mean``, ``fourier_cos``, ``fourier_sin`` (space-separated
coefficients), ``resistance``, ``pressure``, ``proximal_resistance``, ``capacitance``,
``distal_resistance``.

Values are in the model's units (``units="SI"`` by default, or ``"cgs"``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from oxyline.description import copy_description
from oxyline.errors import ModelError
from oxyline.io._common import (
    ALIASES,
    LUMPED_COLUMNS,
    VESSEL_COLUMNS,
    PathLike,
    build,
    check_path,
    confined_file,
    is_missing,
    model_source,
    plain,
    read_regular_text,
)
from oxyline.io.native import dump_native, read_mapping
from oxyline.model import Model

BC_COLUMNS = ("node", "type", "value", "waveform", "interpolation", "steady", "fourier_period",
              "fourier_mean", "fourier_cos", "fourier_sin", "resistance", "pressure",
              "proximal_resistance", "capacitance", "distal_resistance")
_STRING_VESSEL = {"name", "from", "to", "arrangement", "description"}
_INT_VESSEL = {"segments"}


def _exact_float_option() -> dict[str, str]:
    """read_csv's option for floats read back exactly as written: pandas 2's default parser
    rounds the last digit, pandas >= 3's is exact and deprecates the option."""
    import pandas as pd

    return {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}


def _sep(path: Path) -> str:
    return "\t" if path.suffix.lower() in (".tsv", ".txt") else ","


def _read_frame(source: Any, what: str, string_columns: tuple[str, ...]) -> tuple[Any, str]:
    import pandas as pd

    if isinstance(source, pd.DataFrame):
        return source.copy(), f"{what} table"
    import io

    p = check_path(source)
    text = read_regular_text(p, f"{what} table")
    try:
        df = pd.read_csv(io.StringIO(text), sep=_sep(p), comment="#", skipinitialspace=True,
                         dtype={c: str for c in string_columns}, keep_default_na=True,
                         **_exact_float_option())
    except Exception as exc:
        raise ModelError(f"{p}: cannot read the {what} table: {exc}") from exc
    df.columns = [str(c).strip() for c in df.columns]
    return df, str(p)


def _number(value: Any, where: str, column: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ModelError(f"{where}: column '{column}' must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ModelError(f"{where}: column '{column}' must be finite, got {value!r}")
    return v


def _canonical_column(col: str) -> str:
    """Column name in the schema: aliases resolved, case-insensitive, '-'/' ' read as '_'."""
    c = col.strip()
    low = c.lower().replace("-", "_").replace(" ", "_")
    return ALIASES.get(c) or ALIASES.get(low) or (
        low if low in set(VESSEL_COLUMNS) | set(LUMPED_COLUMNS) else c)


def _vessels_from_frame(df: Any, where: str) -> list[dict[str, Any]]:
    columns = {c: _canonical_column(c) for c in df.columns}
    known = set(VESSEL_COLUMNS) | set(LUMPED_COLUMNS)
    for c, k in columns.items():
        if k not in known:
            raise ModelError(f"{where}: unknown column '{c}' (known: {', '.join(sorted(known))})")
    for need in ("name", "from", "to"):
        if need not in columns.values():
            raise ModelError(f"{where}: missing column '{need}'")
    vessels = []
    for i, row in enumerate(df.to_dict("records")):
        name = row.get(next(c for c, k in columns.items() if k == "name"))
        el = f"{where}: row {i + 1} (vessel '{name}')"
        v: dict[str, Any] = {}
        lumped: dict[str, Any] = {}
        for c, k in columns.items():
            val = row[c]
            if is_missing(val):
                continue
            if k in _STRING_VESSEL:
                v[k] = str(val).strip()
            elif k in _INT_VESSEL:  # the schema refuses a fraction, naming the vessel
                n = _number(val, el, c)
                v[k] = int(n) if n.is_integer() else n
            elif k == "output":
                v[k] = str(val).strip().lower() in ("1", "true", "yes", "1.0")
            elif k in LUMPED_COLUMNS:
                lumped[k] = _number(val, el, c)
            else:
                v[k] = _number(val, el, c)
        if lumped:
            v["lumped"] = lumped
        vessels.append(v)
    return vessels


def _read_waveform_file(path: Path, where: str) -> tuple[list[float], list[float]]:
    """Two columns (time, value), comma/tab/space separated, optional header and # comments."""
    if not path.exists():
        raise ModelError(f"{where}: waveform file {path} not found")
    text = read_regular_text(path, f"waveform file of {where}")
    times, values = [], []
    for ln, line in enumerate(text.splitlines(), 1):
        line = line.split("#")[0].strip()
        if not line:
            continue
        parts = line.replace(",", " ").replace(";", " ").split()
        try:
            t, v = float(parts[0]), float(parts[1])
        except (ValueError, IndexError):
            if not times:  # header
                continue
            raise ModelError(f"{path}: line {ln}: expected two numbers (time, value), got "
                             f"{line!r}") from None
        times.append(t)
        values.append(v)
    if len(times) < 2:
        raise ModelError(f"{path}: a waveform needs at least two (time, value) rows")
    return times, values


def _coefficients(value: Any, where: str, column: str) -> list[float]:
    if isinstance(value, (list, tuple)):
        return [_number(x, where, column) for x in value]
    return [_number(x, where, column) for x in str(value).replace(",", " ").split()]


def _bcs_from_frame(df: Any, where: str, base: Path | None) -> dict[str, dict[str, Any]]:
    df = df.rename(columns=lambda c: str(c).strip().lower().replace("-", "_").replace(" ", "_"))
    for c in df.columns:
        if c not in BC_COLUMNS and c not in ("flow", "time"):
            raise ModelError(f"{where}: unknown column '{c}' (known: {', '.join(BC_COLUMNS)})")
    for need in ("node", "type"):
        if need not in df.columns:
            raise ModelError(f"{where}: missing column '{need}'")
    out: dict[str, dict[str, Any]] = {}
    for i, row in enumerate(df.to_dict("records")):
        node = str(row["node"]).strip()
        el = f"{where}: row {i + 1} (node '{node}')"
        kind = str(row["type"]).strip().lower()
        bc: dict[str, Any] = {"type": kind}
        cell = {k: v for k, v in row.items() if not is_missing(v)}
        if kind in ("flow", "pressure"):
            q = kind
            lists = isinstance(cell.get("time"), (list, tuple))  # DataFrame with list cells
            if lists or "waveform" in cell:
                if lists:
                    bc["time"] = [_number(x, el, "time") for x in cell["time"]]
                    bc[q] = [_number(x, el, q) for x in cell.get(q, [])]
                else:
                    wp = Path(str(cell["waveform"]).strip())
                    bc["time"], bc[q] = _read_waveform_file(
                        base / wp if not wp.is_absolute() and base is not None else wp, el)
                if "interpolation" in cell:  # a list-cell frame's as it is, a file's stripped
                    i = cell["interpolation"]
                    bc["interpolation"] = i if lists else str(i).strip()
                if "steady" in cell:
                    bc["steady"] = _number(cell["steady"], el, "steady")
            elif any(f"fourier_{k}" in cell for k in ("mean", "cos", "sin")):
                f: dict[str, Any] = {"period": _number(cell["fourier_period"], el,
                                                       "fourier_period")} \
                    if "fourier_period" in cell else {}
                f["mean"] = _number(cell.get("fourier_mean", 0.0), el, "fourier_mean")
                f.update({k: _coefficients(cell[f"fourier_{k}"], el, f"fourier_{k}")
                          for k in ("cos", "sin") if f"fourier_{k}" in cell})
                bc["fourier"] = f
            elif "value" in cell or q in cell:
                key = "value" if "value" in cell else q
                bc["value"] = _number(cell[key], el, key)
            else:
                raise ModelError(f"{el}: a {kind} condition needs 'value', 'waveform' or "
                                 "'fourier_mean'")
        else:  # resistance, rcr, ...: the schema checks the type, its keys and defaults
            bc.update({k: _number(v, el, k) for k, v in cell.items() if k not in ("node", "type")})
        if node in out:
            raise ModelError(f"{el}: node '{node}' has two boundary conditions")
        out[node] = bc
    return out


def from_tables(vessels: Any, bcs: Any = None, **model_keys: Any) -> Model:
    """Build a model from a vessel table and a boundary-condition table.

    ``vessels`` and ``bcs`` are CSV/TSV paths or pandas DataFrames (``bcs`` may also be a dict in
    the native ``boundary_conditions`` form). ``model_keys`` are the other top-level model keys
    (``name``, ``units``, ``blood``, ``period``, ``arrangement``, ``segmentation``,
    ``simulation``, …). Waveform files named in a ``waveform`` column are relative to the BC
    table. Errors name the file, the row, the vessel or node, and the column.

    >>> import pandas as pd, oxyline.io
    >>> v = pd.DataFrame({"name": ["A"], "from": ["in"], "to": ["out"], "length": [0.1],
    ...                   "radius": [0.003]})
    >>> b = pd.DataFrame({"node": ["in", "out"], "type": ["flow", "pressure"],
    ...                   "value": [1e-6, 0.0]})
    >>> oxyline.io.from_tables(v, b).vessel_names
    ['A']
    """
    return build(*_tables_dict(vessels, bcs, model_keys))


def _tables_dict(vessels: Any, bcs: Any, model_keys: dict[str, Any]) -> tuple[dict[str, Any], str]:
    """The native model dict of the tables and where they come from (for error messages)."""
    vdf, vwhere = _read_frame(vessels, "vessel", ("name", "from", "to"))
    data: dict[str, Any] = dict(model_keys)
    data["vessels"] = _vessels_from_frame(vdf, vwhere)
    if bcs is None:
        data.setdefault("boundary_conditions", {})
    elif isinstance(bcs, Mapping):
        data["boundary_conditions"] = plain(bcs)
    else:
        bdf, bwhere = _read_frame(bcs, "boundary-condition", ("node", "type", "waveform"))
        base = None if bwhere.endswith(" table") else Path(bwhere).parent
        data["boundary_conditions"] = _bcs_from_frame(bdf, bwhere, base)
    where = vwhere if bcs is None or isinstance(bcs, Mapping) else f"{vwhere} + {bwhere}"
    return data, where


def _sibling(path: Path, tag: str) -> Path:
    return path.with_name(f"{path.stem}_{tag}{path.suffix}")


def to_tables(model: Model, waveform_dir: PathLike | None = None) -> tuple[Any, Any]:
    """The model as two DataFrames ``(vessels, bcs)`` in the model's own units.

    Table waveforms go to two-column CSV files in ``waveform_dir`` (named ``<node>.csv``; the
    ``waveform`` column holds the path); without ``waveform_dir`` they stay in the DataFrame as
    lists in columns ``time`` and ``flow``/``pressure``, which only :func:`from_tables` on the
    DataFrame (not CSV) understands. Other top-level keys are in ``vessels.attrs["model"]``.
    """
    import pandas as pd

    src = model_source(model)
    rows = []
    for v in src["vessels"]:
        extra = set(v) - set(VESSEL_COLUMNS) - {"lumped"}
        if extra:  # never drop a key silently
            raise ModelError(f"vessel '{v.get('name')}': key(s) {', '.join(sorted(extra))} "
                             "cannot be written to a vessel table")
        rows.append({**{k: v[k] for k in VESSEL_COLUMNS if k in v}, **(v.get("lumped") or {})})
    cols = [c for c in (*VESSEL_COLUMNS, *LUMPED_COLUMNS) if any(c in r for r in rows)]
    vdf = pd.DataFrame(rows, columns=cols)
    if "segments" in vdf:
        vdf["segments"] = vdf["segments"].astype("Int64")
    brows = []
    wdir = Path(waveform_dir) if waveform_dir is not None else None
    for node, bc in (src.get("boundary_conditions") or {}).items():
        el = f"boundary condition '{node}'"
        kind = str(bc["type"]).lower()
        row = {"node": node, "type": kind}
        if kind not in ("flow", "pressure", "resistance", "rcr"):
            # never drop a key silently: the table has no columns for e.g. a coronary bed
            raise ModelError(f"{el}: a '{kind}' condition cannot be written to a boundary-"
                             "condition table (flow, pressure, resistance, rcr); save the model "
                             "as YAML/JSON instead")
        if kind in ("flow", "pressure"):
            if "fourier" in bc:
                f = bc["fourier"]
                row.update({f"fourier_{k}": f[k] if k in ("period", "mean")
                            else " ".join(repr(float(x)) for x in f[k])
                            for k in ("period", "mean", "cos", "sin") if k in f})
            elif "time" in bc and wdir is None:
                row["time"], row[kind] = list(bc["time"]), list(bc[kind])
            elif "time" in bc:
                wdir.mkdir(parents=True, exist_ok=True)
                wp = confined_file(wdir, node, ".csv", f"{el}: node")
                lines = [f"time,{kind}"] + [f"{float(t)!r},{float(x)!r}"
                                            for t, x in zip(bc["time"], bc[kind])]
                wp.write_text("\n".join(lines) + "\n")
                row["waveform"] = str(wp)
            else:
                row["value"] = bc.get("value", bc.get(kind))
            if "time" in bc:
                row.update({k: bc[k] for k in ("interpolation", "steady") if k in bc})
        else:
            for k in ("resistance", "proximal_resistance", "capacitance", "distal_resistance",
                      "pressure"):
                if isinstance(bc.get(k), Mapping):
                    raise ModelError(f"{el}: a time-varying '{k}' cannot be written as a "
                                     "table cell")
                if k in bc:
                    row[k] = bc[k]
        brows.append(row)
    bcols = [c for c in (*BC_COLUMNS, "time", "flow") if any(c in r for r in brows)]
    bdf = pd.DataFrame(brows, columns=bcols)
    vdf.attrs["model"] = {k: v for k, v in src.items() if k not in ("vessels",
                                                                       "boundary_conditions")}
    return vdf, bdf


def write_tables(model: Model, path: PathLike) -> list[Path]:
    """Write ``<path>`` (vessels), ``<stem>_bcs<suffix>`` (boundary conditions),
    ``<stem>_waveforms/<node>.csv`` (waveform tables) and ``<stem>_model.yaml`` (the other
    top-level keys: name, units, blood, period, simulation…). Returns the files written.
    :func:`read_tables` reads them back into the same model."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    wdir = p.with_name(f"{p.stem}_waveforms")
    vdf, bdf = to_tables(model, waveform_dir=wdir)
    sep = _sep(p)
    # waveform paths relative to the BC table
    if "waveform" in bdf:
        bdf["waveform"] = [None if is_missing(w) else str(Path(w).relative_to(p.parent))
                           for w in bdf["waveform"]]
    written = [p, _sibling(p, "bcs")]
    vdf.to_csv(p, sep=sep, index=False)
    bdf.to_csv(written[1], sep=sep, index=False)
    if wdir.exists():
        written += sorted(wdir.iterdir())
    meta = vdf.attrs["model"]
    if meta:
        written.append(dump_native(meta, p.with_name(f"{p.stem}_model.yaml")))
    return written


def read_tables(path: PathLike, bcs: PathLike | None = None, **model_keys: Any) -> Model:
    """Read tables written by :func:`write_tables`: ``path`` is the vessel table; the BC table
    defaults to ``<stem>_bcs<suffix>`` and the top-level keys to ``<stem>_model.yaml`` (both
    optional); ``model_keys`` override the latter."""
    return build(*native_dict(path, bcs, **model_keys), owned=True)


def native_dict(path: PathLike, bcs: PathLike | None = None, **model_keys: Any
                ) -> tuple[dict[str, Any], str]:
    """The native model dict of the tables :func:`read_tables` reads, and the files it came
    from (``vessels.csv + vessels_bcs.csv``, the prefix of its error messages)."""
    p = check_path(path)
    b = Path(bcs) if bcs is not None else _sibling(p, "bcs")
    keys: dict[str, Any] = {}
    meta = p.with_name(f"{p.stem}_model.yaml")
    if meta.exists():
        keys = read_mapping(meta)
    keys.update(model_keys)
    data, where = _tables_dict(p, b if bcs is not None or b.exists() else None, keys)
    return copy_description(data), where
