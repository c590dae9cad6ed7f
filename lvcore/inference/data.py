"""Measured data for calibration: LVV (mL) and 24 circumferential strains.

Three file formats are read by :func:`read_measurements` (by suffix):

CSV (``.csv``)
    A header row with the columns of :data:`lvcore.domain.outputs.OUTPUT_COLUMNS`
    (``lvv_ml, strain_01 .. strain_24``), or ``lvv_ml, aha_01 .. aha_16``
    (``aha_17``, the apical cap, allowed and unused) for AHA segments,
    optionally preceded by a ``subject`` column, one row per measurement.
    A header-less file of 25 numbers per row (lvcore order) is also accepted.
JSON (``.json``)
    One object or a list of objects (or ``{"subjects": [...]}``), each
    ``{"subject": "HV1", "lvv_ml": 140.2, "strains": [24 or 16 values],
    "segments": "lvcore" | "aha", "segment_offset_deg": 0}``; the last two
    are optional; ``strain_01..`` / ``aha_01..`` keys may replace ``strains``.
MATLAB (``.mat``, read with :func:`scipy.io.loadmat`)
    Variables ``lvv_ml`` (scalar or n-vector, mL), ``strains`` (24 or 16
    values, or an n x 24 / n x 16 matrix, one row per subject), optional
    ``subject`` (char array or cell array of n names), ``segments``
    (``'lvcore'`` or ``'aha'``) and ``segment_offset_deg`` (scalar).

Strains in AHA segments (or lvcore sectors rotated by an offset) are mapped
onto lvcore's 6 x 4 grid with :mod:`lvcore.inference.segments`.

Several loaded states per subject
    Rows (CSV lines, JSON objects, .mat rows) with the same ``subject`` are the
    subject's loaded states: each has its own ``edp_mmhg`` and ``lvv_ml``, and
    strains or none (blank CSV cells, a JSON object without ``strains``, a row of
    NaN in .mat: that state then informs through its volume only). Every state
    needs its pressure, no two states of a subject may share one, at least one
    state needs strains, and the geometric measures (a subject has one geometry)
    must agree where they are repeated. The state with strains at the lowest
    pressure is the subject's primary one (:attr:`MeasuredData.y`); the others
    are :attr:`MeasuredData.states` (:class:`LoadedState`).

Validation raises :class:`lvcore.exceptions.DataError` with what to fix:
wrong column count, missing values, strains with the wrong sign convention
or in percent, volumes in the wrong unit (m³, mm³, litres), and for several
loaded states a state without ``edp_mmhg`` or two states at one pressure
(naming the row and the column).
"""
from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from lvcore.safety import limits
from lvcore.exceptions import DataError
from lvcore.domain.outputs import N_OUTPUTS, OUTPUT_COLUMNS

#: Plausible LV end-diastolic volume range (mL) accepted without complaint.
LVV_RANGE_ML = (20.0, 600.0)
#: Largest plausible |strain| (dimensionless Green strain).
MAX_ABS_STRAIN = 0.6
#: Optional per-subject columns (CSV), keys (JSON) and variables (.mat): the end-diastolic pressure
#: (mmHg) and the geometric measures of ``--geometry infer`` (:mod:`lvcore.inference.geometry_prior`).
#: Each measure may come with its standard deviation, ``<measure>_sd`` (mL, mL, mm).
OPTIONAL_COLUMNS = ("edp_mmhg", "reference_volume_ml", "wall_volume_ml", "long_axis_mm", "reference_volume_ml_sd",
                    "wall_volume_ml_sd", "long_axis_mm_sd")


#: Most loaded states one subject may have (each adds an emulator evaluation to every sampler step).
MAX_LOADED_STATES = 10
#: Two loaded states of one subject closer than this in pressure (mmHg) are the same state given twice.
DUPLICATE_EDP_TOL_MMHG = 1e-6


@dataclass(frozen=True)
class LoadedState:
    """One further loaded state of a subject (beyond its primary one, :attr:`MeasuredData.y`).

    Attributes
    ----------
    edp_mmhg : float
        The state's end-diastolic (filling) pressure (mmHg).
    y : ndarray, shape (25,)
        ``[LVV (mL), strain_01 .. strain_24]``; the strains are NaN when the state has none (volume only).
    where : str
        The file row it came from (for messages).
    """

    edp_mmhg: float
    y: np.ndarray
    where: str = ""

    @property
    def lvv_ml(self) -> float:
        return float(self.y[0])

    @property
    def has_strains(self) -> bool:
        """True when the state's 24 strains were measured."""
        return bool(np.all(np.isfinite(self.y[1:])))


@dataclass(frozen=True)
class MeasuredData:
    """One subject's measurements.

    Attributes
    ----------
    y : ndarray, shape (25,)
        ``[LVV (mL), strain_01 .. strain_24]`` (Green strain, end diastole reference, negative).
    subject : str
        Identifier (``subject`` column, else ``row<i>``).
    source : str
        File the data came from ("" if built in memory).
    synthetic : bool
        True for generated data (shown to users as synthetic).
    extras : dict
        The optional per-subject values of :data:`OPTIONAL_COLUMNS` that were given
        (``edp_mmhg``, ``reference_volume_ml``, ``wall_volume_ml``, ``long_axis_mm``).
    states : tuple of LoadedState
        The subject's other loaded states, by increasing pressure (empty for one state); ``y`` and
        ``extras["edp_mmhg"]`` are the primary state's (the lowest pressure with strains).
    strain_layer : str or None
        The wall layer the file declares for its strains (:mod:`lvcore.inference.strain_layers`); None: undeclared.
    """

    y: np.ndarray
    subject: str = ""
    source: str = ""
    synthetic: bool = False
    extras: dict = field(default_factory=dict)
    states: tuple = ()
    strain_layer: str | None = None

    @property
    def n_states(self) -> int:
        """Number of loaded states (1 + the further ones)."""
        return 1 + len(self.states)

    def all_states(self) -> list[LoadedState]:
        """Every loaded state, the primary one included, by increasing pressure."""
        primary = LoadedState(float(self.edp_mmhg) if self.edp_mmhg is not None else float("nan"), self.y, "primary")
        return sorted((primary,) + tuple(self.states), key=lambda st: st.edp_mmhg)

    @property
    def edp_mmhg(self) -> float | None:
        """The subject's end-diastolic pressure (mmHg), if the data give it."""
        return self.extras.get("edp_mmhg")

    @property
    def measures(self) -> dict:
        """The geometric measures the data give (reference_volume_ml, wall_volume_ml, long_axis_mm)."""
        return {k: v for k, v in self.extras.items() if k != "edp_mmhg" and not k.endswith("_sd")}

    @property
    def measure_sds(self) -> dict:
        """Standard deviations of the measures that the data give (``<measure>_sd`` columns), by measure name."""
        return {k[:-3]: v for k, v in self.extras.items() if k.endswith("_sd")}

    @property
    def lvv_ml(self) -> float:
        return float(self.y[0])

    @property
    def strains(self) -> np.ndarray:
        return self.y[1:]


def check_volume(lvv, where: str = "measurements") -> float:
    """Check one LV volume (mL): finite, positive, in mL (not m³, litres or mm³), plausible; return it.

    Raises
    ------
    DataError
        With the problem and the fix.
    """
    lvv = float(lvv)
    if not np.isfinite(lvv):
        raise DataError(f"{where}: missing or non-finite values in lvv_ml; fill them in or drop the row")
    if lvv <= 0:
        raise DataError(f"{where}: lvv_ml = {lvv:g} must be a positive volume in mL")
    if lvv < 1e-3:
        raise DataError(f"{where}: lvv_ml = {lvv:g} looks like cubic metres; multiply by 1e6 to give mL")
    if lvv < 2.0:
        raise DataError(f"{where}: lvv_ml = {lvv:g} looks like litres; multiply by 1000 to give mL")
    if lvv > 1e4:
        raise DataError(f"{where}: lvv_ml = {lvv:g} looks like mm³; divide by 1000 to give mL")
    if not LVV_RANGE_ML[0] <= lvv <= LVV_RANGE_ML[1]:
        raise DataError(
            f"{where}: lvv_ml = {lvv:g} is outside the plausible range {LVV_RANGE_ML} mL; check the unit (mL)"
        )
    return lvv


def validate_measurements(y, where: str = "measurements") -> np.ndarray:
    """Check one row ``[LVV (mL), 24 strains]`` and return it as float64.

    Raises
    ------
    DataError
        With the problem and the fix.
    """
    try:
        arr = np.asarray(y, dtype=float).reshape(-1)
    except (TypeError, ValueError) as err:
        raise DataError(f"{where}: values must be numbers ({err})") from None
    if arr.size != N_OUTPUTS:
        raise DataError(
            f"{where}: expected {N_OUTPUTS} values (lvv_ml then strain_01..strain_24), got {arr.size}"
        )
    bad = [OUTPUT_COLUMNS[i] for i in np.flatnonzero(~np.isfinite(arr))]
    if bad:
        raise DataError(f"{where}: missing or non-finite values in {', '.join(bad)}; fill them in or drop the row")
    check_volume(arr[0], where)
    strains = arr[1:]
    if np.max(np.abs(strains)) > 1.0:
        raise DataError(
            f"{where}: strains up to {np.max(np.abs(strains)):g} look like percent; divide by 100 "
            "(Green strain is dimensionless, typically -0.05 to -0.25)"
        )
    n_pos = int(np.sum(strains > 0))
    if n_pos > strains.size // 2:
        raise DataError(
            f"{where}: {n_pos} of 24 strains are positive; circumferential Green strain with end diastole "
            "as reference is negative during filling. Flip the sign (or convert from an early-diastole "
            "reference with E_ed = (1/(1+2E) - 1)/2)"
        )
    if np.max(np.abs(strains)) > MAX_ABS_STRAIN:
        worst = OUTPUT_COLUMNS[1 + int(np.argmax(np.abs(strains)))]
        raise DataError(f"{where}: {worst} = {strains[np.argmax(np.abs(strains))]:g} is implausibly large "
                        f"(|strain| > {MAX_ABS_STRAIN}); check the data")
    return arr


def check_extras(values: dict, where: str) -> dict:
    """Validate the optional per-subject values (:data:`OPTIONAL_COLUMNS`); empty ones are dropped.

    Raises
    ------
    DataError
        Naming the column and the fix (EDP outside 2-40 mmHg, a measure outside its plausible range).
    """
    from lvcore.inference.geometry_prior import check_measure_sds, check_measures
    from lvcore.inference.guards import EDP_RANGE_MMHG

    out = {}
    for name, value in values.items():
        if value is None or (isinstance(value, str) and value.strip().lower() in ("", "nan")):
            continue
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise DataError(f"{where}: {name} = {str(value)[:40]!r} is not a number") from None
        if isinstance(value, bool) or not np.isfinite(v):
            if isinstance(value, float) and np.isnan(v):
                continue
            raise DataError(f"{where}: {name} must be a finite number, got {value}")
        out[name] = v
    edp = out.get("edp_mmhg")
    if edp is not None and not EDP_RANGE_MMHG[0] <= edp <= EDP_RANGE_MMHG[1]:
        raise DataError(f"{where}: edp_mmhg = {edp:g} is outside the physiological range {EDP_RANGE_MMHG[0]:g}-"
                        f"{EDP_RANGE_MMHG[1]:g} mmHg; give the end-diastolic pressure in mmHg (1 kPa = 7.5 mmHg)")
    out.update(check_measures({k: v for k, v in out.items() if k != "edp_mmhg" and not k.endswith("_sd")}, where))
    sds = check_measure_sds({k[:-3]: v for k, v in out.items() if k.endswith("_sd")}, where, by="column")
    out.update({f"{k}_sd": v for k, v in sds.items()})
    return out


def _is_number(s) -> bool:
    try:
        float(s)
        return True
    except (TypeError, ValueError):
        return False


@dataclass(frozen=True)
class _Pending:
    """One validated file row before the rows of a subject are joined into its loaded states."""

    subject: str
    y: np.ndarray
    has_strains: bool
    extras: dict
    where: str
    source: str
    no_strain_message: str = ""


def _pending_row(values, subject, where: str, source: str, extras: dict | None,
                 no_strain_message: str = "") -> _Pending:
    """Validate one row ``[LVV, 24 strains]``: a row whose strains are all empty (NaN) is a volume-only
    loaded state (allowed only beside another state of the subject, :func:`_join_states`)."""
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.size == N_OUTPUTS and np.all(np.isnan(arr[1:])):
        check_volume(arr[0], where)
        y, has = arr, False
    else:
        y, has = validate_measurements(arr, where=where), True
    return _Pending(str(subject), y, has, check_extras(extras or {}, where), where, source, no_strain_message)


def _join_states(rows: list[_Pending], name: str) -> list[MeasuredData]:
    """One :class:`MeasuredData` per subject: rows with the same subject are its loaded states.

    Raises
    ------
    DataError
        Naming the row and the column: a state without ``edp_mmhg``, two states at one pressure, a subject
        whose states all lack strains, geometric measures that differ between a subject's rows, more than
        :data:`MAX_LOADED_STATES` states; a single row without strains.
    """
    groups: dict[str, list[_Pending]] = {}
    for r in rows:
        groups.setdefault(r.subject, []).append(r)
    out = []
    for subject, rs in groups.items():
        shown = subject[:80]
        if len(rs) == 1:
            r = rs[0]
            if not r.has_strains:
                if r.no_strain_message:
                    raise DataError(r.no_strain_message)
                validate_measurements(r.y, r.where)  # raises: names the empty strain columns
            out.append(MeasuredData(y=r.y, subject=subject, source=r.source, extras=r.extras))
            continue
        if len(rs) > MAX_LOADED_STATES:
            raise DataError(f"{name}: subject '{shown}' has {len(rs)} rows (loaded states); at most "
                            f"{MAX_LOADED_STATES} are allowed (lvcore.inference.data.MAX_LOADED_STATES)")
        seen: dict[float, str] = {}
        for r in rs:
            edp = r.extras.get("edp_mmhg")
            if edp is None:
                rows = "; ".join(x.where for x in rs)
                raise DataError(f"{r.where}: column edp_mmhg is missing or empty, but subject '{shown}' has {len(rs)} "
                                f"rows ({rows}): rows with one subject ID are its loaded states and each needs its end-diastolic "
                                "pressure in mmHg (give edp_mmhg on every row, or give the rows different subject IDs)")
            same = next((w for p, w in seen.items() if abs(p - edp) <= DUPLICATE_EDP_TOL_MMHG), None)
            if same is not None:
                raise DataError(f"{r.where}: column edp_mmhg = {edp:g} mmHg repeats the pressure of {same} for subject "
                                f"'{shown}'; each loaded state needs its own pressure (drop the repeated measurement "
                                "or average the two into one row)")
            seen[edp] = r.where
        merged: dict[str, tuple[float, str]] = {}
        for r in rs:
            for k, v in r.extras.items():
                if k == "edp_mmhg":
                    continue
                if k in merged and abs(merged[k][0] - v) > 1e-9:
                    raise DataError(f"{r.where}: column {k} = {v:g} differs from {merged[k][1]} ({merged[k][0]:g}) for "
                                    f"subject '{shown}'; a subject has one geometry: give its measures on one row, or "
                                    "the same on every row")
                merged.setdefault(k, (v, r.where))
        with_strains = [r for r in rs if r.has_strains]
        if not with_strains:
            raise DataError(f"{rs[0].where}: none of the {len(rs)} loaded states of subject '{shown}' has strains; "
                            "give the strains of at least one state")
        primary = min(with_strains, key=lambda r: r.extras["edp_mmhg"])
        states = tuple(LoadedState(float(r.extras["edp_mmhg"]), r.y, r.where)
                       for r in sorted(rs, key=lambda r: r.extras["edp_mmhg"]) if r is not primary)
        extras = {k: v for k, (v, _) in merged.items()}
        extras["edp_mmhg"] = float(primary.extras["edp_mmhg"])
        out.append(MeasuredData(y=primary.y, subject=subject, source=primary.source, extras=extras, states=states))
    return out


def read_measured_csv(path, skip_columns: tuple = ()) -> list[MeasuredData]:
    """Read and validate a measured-data CSV (see module docstring); one :class:`MeasuredData` per subject.

    ``skip_columns``: header names another reader owns (a cohort's ``group`` and ``geometry``,
    :mod:`lvcore.inference.cohort`), left out here."""
    path = Path(path)
    text = limits.read_text_file(path, limits.MAX_MEASURED_BYTES, "measured-data file", DataError)
    try:
        raw = pd.read_csv(io.StringIO(text), header=None, dtype=str, skip_blank_lines=True, comment="#")
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, ValueError, OverflowError,
            csv.Error) as err:
        raise DataError(f"{path.name}: cannot parse as CSV ({str(err)[:200]})") from None
    if raw.empty:
        raise DataError(f"{path.name}: no data rows")
    if raw.shape[0] > limits.MAX_MEASURED_ROWS + 1:
        raise DataError(f"{path.name}: {raw.shape[0]:,} rows is more than the limit of {limits.MAX_MEASURED_ROWS:,} "
                        "(lvcore.safety.limits.MAX_MEASURED_ROWS); split the file")
    first = [str(v).strip() for v in raw.iloc[0].tolist()]
    has_header = not all(_is_number(v) for v in first if v not in ("", "nan"))
    expected = ", ".join(OUTPUT_COLUMNS[:2]) + ", ..., " + OUTPUT_COLUMNS[-1]
    if has_header:
        header = first
        body = raw.iloc[1:]
        subject_col = None
        if header and header[0].lower() in ("subject", "id", "subject_id"):
            subject_col = 0
        extra_cols = {i: header[i] for i in range(len(header)) if header[i] in OPTIONAL_COLUMNS}
        data_cols = [i for i in range(len(header)) if i != subject_col and i not in extra_cols
                     and header[i] not in skip_columns and header[i] != "strain_layer"]  # strain_layers.py
        if len(data_cols) != N_OUTPUTS:
            raise DataError(
                f"{path.name}: expected {N_OUTPUTS} data columns ({expected}), found {len(data_cols)}"
            )
        names = [header[i] for i in data_cols]
        if names != list(OUTPUT_COLUMNS):
            wrong = [f"{got!r} (expected {exp!r})" for got, exp in zip(names, OUTPUT_COLUMNS) if got != exp]
            raise DataError(f"{path.name}: unexpected column names: {', '.join(wrong[:5])}"
                            + (" ..." if len(wrong) > 5 else "") + f"; use {expected}")
    else:
        body = raw
        subject_col = None
        extra_cols = {}
        data_cols = list(range(raw.shape[1]))
        if len(data_cols) != N_OUTPUTS:
            raise DataError(
                f"{path.name}: expected {N_OUTPUTS} columns ({expected}), found {len(data_cols)}"
            )
    if body.empty:
        raise DataError(f"{path.name}: header but no data rows")
    pending = []
    for i, (_, row) in enumerate(body.iterrows()):
        line = i + (2 if has_header else 1)
        subject = str(row.iloc[subject_col]).strip() if subject_col is not None else f"row{i + 1}"
        values = pd.to_numeric(row.iloc[data_cols], errors="coerce").to_numpy(dtype=float)
        nonnum = [OUTPUT_COLUMNS[j] for j, v in enumerate(row.iloc[data_cols])
                  if not _is_number(v) and str(v).strip().lower() not in ("", "nan")]
        if nonnum:
            raise DataError(f"{path.name} line {line}: non-numeric values in {', '.join(nonnum)}")
        pending.append(_pending_row(values, subject, f"{path.name} line {line}", str(path),
                                    {name: row.iloc[i] for i, name in extra_cols.items()}))
    return _join_states(pending, path.name)


# --------------------------------------------------------------------------- any format, any segment convention
#: File suffixes :func:`read_measurements` understands.
MEASUREMENT_SUFFIXES = (".csv", ".json", ".mat")


def _resolve_convention(file_value, cli_value, where: str) -> str:
    from lvcore.inference.segments import CONVENTIONS

    for v, who in ((file_value, "the file"), (cli_value, "--segments")):
        if v is not None and v not in CONVENTIONS:
            raise DataError(f"{where}: segment convention {v!r} from {who} not understood; use lvcore or aha")
    if file_value is not None and cli_value is not None and file_value != cli_value:
        raise DataError(f"{where}: the file says its strains are in '{file_value}' segments but --segments says "
                        f"'{cli_value}'; drop one or make them agree")
    return file_value or cli_value or "lvcore"


def _row(lvv, strains, subject, where: str, convention: str, offset_deg: float, source: str,
         extras: dict | None = None) -> _Pending:
    from lvcore.inference.segments import N_AHA, to_lvcore

    try:
        st = np.asarray(strains, dtype=float).reshape(-1)
        lv = float(np.asarray(lvv, dtype=float).reshape(-1)[0]) if np.size(lvv) == 1 else float("nan")
    except (TypeError, ValueError) as err:
        raise DataError(f"{where}: values must be numbers ({err})") from None
    if np.size(lvv) != 1:
        raise DataError(f"{where}: lvv_ml must be one number per subject, got {np.size(lvv)}")
    expected = {"lvcore": (N_OUTPUTS - 1,), "aha": (N_AHA, N_AHA + 1)}[convention]
    if st.size == 0:  # a loaded state measured by its volume only (a JSON object without strains)
        return _pending_row(np.r_[lv, np.full(N_OUTPUTS - 1, np.nan)], subject, where, source, extras,
                            f"{where}: missing 'strains' (a list) or the keys {', '.join(_strain_keys(convention)[:4])}...")
    if st.size not in expected:
        raise DataError(f"{where}: {st.size} strains for '{convention}' segments; expected "
                        f"{' or '.join(str(e) for e in expected)}"
                        + (" (use --segments aha for AHA 16-segment data)" if st.size in (N_AHA, N_AHA + 1) else "")
                        + (" (use --segments lvcore for lvcore's 24 regions)" if st.size == N_OUTPUTS - 1 else ""))
    if st.size and np.all(np.isnan(st)):  # a loaded state measured by its volume only
        return _pending_row(np.r_[lv, np.full(N_OUTPUTS - 1, np.nan)], subject, where, source, extras,
                            f"{where}: missing or non-finite strains; fill them in or drop the subject")
    if not np.all(np.isfinite(st)):
        raise DataError(f"{where}: missing or non-finite strains; fill them in or drop the subject")
    return _pending_row(np.r_[lv, to_lvcore(st, convention, offset_deg)], subject, where, source, extras)


def _strain_keys(convention: str) -> tuple:
    """The per-segment strain keys (JSON) or columns (CSV) of a segment convention."""
    from lvcore.inference.segments import AHA_COLUMNS

    return tuple(OUTPUT_COLUMNS[1:]) if convention == "lvcore" else tuple(AHA_COLUMNS)


def _read_json(path: Path, segments, offset_deg) -> list[MeasuredData]:
    obj = limits.read_json_file(path, limits.MAX_MEASURED_BYTES, "measured-data file", DataError)
    if isinstance(obj, dict) and "subjects" in obj:
        obj = obj["subjects"]
    items = obj if isinstance(obj, list) else [obj]
    if not items:
        raise DataError(f"{path.name}: no subjects")
    if len(items) > limits.MAX_MEASURED_ROWS:
        raise DataError(f"{path.name}: {len(items):,} subjects is more than the limit of {limits.MAX_MEASURED_ROWS:,} "
                        "(lvcore.safety.limits.MAX_MEASURED_ROWS); split the file")
    out = []
    for i, it in enumerate(items):
        where = f"{path.name} subject {i + 1}"
        if not isinstance(it, dict):
            raise DataError(f"{where}: expected an object with lvv_ml and strains, got {type(it).__name__}")
        if "lvv_ml" not in it:
            raise DataError(f"{where}: missing 'lvv_ml' (end-diastolic volume, mL)")
        conv = _resolve_convention(it.get("segments"), segments, where)
        off = float(it.get("segment_offset_deg", 0.0)) if offset_deg is None else float(offset_deg)
        if "strains" in it:
            st = it["strains"]
        else:
            keys = _strain_keys(conv)
            missing = [k for k in keys if k not in it]
            if len(missing) == len(keys):
                st = []  # no strains: a volume-only loaded state (refused for a subject's only state)
            elif missing:
                raise DataError(f"{where}: missing 'strains' (a list) or the keys {', '.join(missing[:4])}...")
            else:
                st = [it[k] for k in keys]
        if st is None:
            st = []
        out.append(_row(it["lvv_ml"], st, it.get("subject", f"row{i + 1}"), where, conv, off, str(path),
                        {k: it[k] for k in OPTIONAL_COLUMNS if k in it}))
    return _join_states(out, path.name)


def _mat_string(v) -> str | None:
    if v is None:
        return None
    a = np.asarray(v)
    if a.dtype.kind in "US":
        return "".join(str(x) for x in a.reshape(-1)).strip()
    if a.dtype == object and a.size == 1:
        return _mat_string(a.reshape(-1)[0])
    return str(a)


def _read_mat(path: Path, segments, offset_deg) -> list[MeasuredData]:
    import scipy.io

    limits.check_regular_file(path, limits.MAX_MEASURED_BYTES, "measured-data file", DataError)
    try:
        mat = scipy.io.loadmat(path, squeeze_me=False, chars_as_strings=True)
    except (ValueError, TypeError, OSError, NotImplementedError) as err:
        raise DataError(f"{path.name}: cannot read as a MATLAB .mat file ({err}); v7.3 (HDF5) files must be "
                        "saved with -v7 or converted") from None
    names = sorted(k for k in mat if not k.startswith("__"))
    for req in ("lvv_ml", "strains"):
        if req not in mat:
            raise DataError(f"{path.name}: MATLAB variable '{req}' not found (found: {', '.join(names) or 'none'}); "
                            "see docs/calibration.md for the variable names")
    conv = _resolve_convention(_mat_string(mat.get("segments")), segments, path.name)
    off = float(np.asarray(mat.get("segment_offset_deg", 0.0), dtype=float).reshape(-1)[0])         if offset_deg is None else float(offset_deg)
    try:
        lvv = np.asarray(mat["lvv_ml"], dtype=float).reshape(-1)
        st = np.asarray(mat["strains"], dtype=float)
    except (TypeError, ValueError) as err:
        raise DataError(f"{path.name}: lvv_ml and strains must be numeric arrays ({err})") from None
    n = lvv.size
    if n > limits.MAX_MEASURED_ROWS:
        raise DataError(f"{path.name}: {n:,} subjects is more than the limit of {limits.MAX_MEASURED_ROWS:,}")
    if st.ndim == 1 or (1 in st.shape and n == 1):
        st = st.reshape(1, -1)
    elif st.ndim == 2 and st.shape[0] != n and st.shape[1] == n:
        st = st.T  # strains stored one column per subject
    if st.ndim != 2 or st.shape[0] != n:
        raise DataError(f"{path.name}: 'strains' has shape {np.shape(mat['strains'])} but 'lvv_ml' has {n} value(s); "
                        "give one row of strains per subject")
    subjects = [f"row{i + 1}" for i in range(n)]
    if "subject" in mat:
        raw = np.asarray(mat["subject"])
        if raw.dtype == object:
            subjects = [_mat_string(v) for v in raw.reshape(-1)]
        elif raw.dtype.kind in "US":
            subjects = [str(v).strip() for v in raw.reshape(-1)] if n > 1 else ["".join(raw.reshape(-1)).strip()]
        if len(subjects) != n:
            raise DataError(f"{path.name}: 'subject' names {len(subjects)} subjects, 'lvv_ml' {n}")
    extras = {}
    for k in OPTIONAL_COLUMNS:
        if k in mat:
            try:
                vals = np.asarray(mat[k], dtype=float).reshape(-1)
            except (TypeError, ValueError):
                raise DataError(f"{path.name}: MATLAB variable '{k}' must be numeric") from None
            if vals.size not in (1, n):
                raise DataError(f"{path.name}: '{k}' has {vals.size} values but 'lvv_ml' has {n}; give one per subject")
            extras[k] = np.broadcast_to(vals, (n,))
    return _join_states([_row(lvv[i], st[i], subjects[i], f"{path.name} row {i + 1} (subject {subjects[i]})", conv,
                              off, str(path), {k: float(v[i]) for k, v in extras.items()})
                         for i in range(n)], path.name)


def _read_csv_any(path: Path, segments, offset_deg) -> list[MeasuredData]:
    from lvcore.inference.segments import AHA_COLUMNS

    import io

    text = limits.read_text_file(path, limits.MAX_MEASURED_BYTES, "measured-data file", DataError)
    first_line = next((ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")), "")
    first = [v.strip() for v in first_line.split(",")]
    is_aha = any(v in AHA_COLUMNS for v in first)
    conv = _resolve_convention("aha" if is_aha else None, segments, path.name)
    if conv == "lvcore" and not is_aha:
        rows = read_measured_csv(path)
        off = 0.0 if offset_deg is None else float(offset_deg)
        if off == 0.0:
            return rows
        from lvcore.inference.segments import rotate_lvcore

        def rot(y):
            return np.r_[y[0], rotate_lvcore(y[1:], off)] if np.all(np.isfinite(y[1:])) else y

        return [MeasuredData(y=rot(r.y), subject=r.subject, source=r.source, extras=r.extras,
                             states=tuple(LoadedState(s.edp_mmhg, rot(s.y), s.where) for s in r.states))
                for r in rows]
    if not is_aha:
        raise DataError(f"{path.name}: --segments aha needs columns lvv_ml, aha_01 .. aha_16 (aha_17 optional)")
    try:
        df = pd.read_csv(io.StringIO(text), comment="#")
    except (pd.errors.ParserError, pd.errors.EmptyDataError) as err:
        raise DataError(f"{path.name}: cannot parse as CSV ({err})") from None
    if len(df) > limits.MAX_MEASURED_ROWS:
        raise DataError(f"{path.name}: {len(df):,} rows is more than the limit of {limits.MAX_MEASURED_ROWS:,}")
    cols = [c for c in AHA_COLUMNS if c in df.columns]
    if len(cols) != len(AHA_COLUMNS) or "lvv_ml" not in df.columns:
        missing = [c for c in ("lvv_ml",) + AHA_COLUMNS if c not in df.columns]
        raise DataError(f"{path.name}: AHA data need columns lvv_ml, aha_01 .. aha_16; missing {', '.join(missing)}")
    subj = next((c for c in df.columns if str(c).lower() in ("subject", "id", "subject_id")), None)
    off = 0.0 if offset_deg is None else float(offset_deg)
    out = []
    for i, row in df.iterrows():
        vals = pd.to_numeric(row[list(cols)], errors="coerce").to_numpy(dtype=float)
        lvv = pd.to_numeric(pd.Series([row["lvv_ml"]]), errors="coerce").to_numpy(dtype=float)
        name = str(row[subj]) if subj else f"row{i + 1}"
        out.append(_row(lvv, vals, name, f"{path.name} line {i + 2}", "aha", off, str(path),
                        {k: row[k] for k in OPTIONAL_COLUMNS if k in df.columns}))
    return _join_states(out, path.name)


def read_measurements(path, segments: str | None = None, offset_deg: float | None = None) -> list[MeasuredData]:
    """Read measured data from CSV, JSON or MATLAB ``.mat`` (see the module docstring).

    Parameters
    ----------
    path : str or Path
    segments : {"lvcore", "aha"}, optional
        Segment convention of the strains; default: what the file says, else
        ``lvcore``. A contradiction between the two is an error.
    offset_deg : float, optional
        lvcore angle φ (deg) of the data's septal centre (AHA) or of the data's
        sector-0 start (lvcore); default: the file's ``segment_offset_deg``, else 0.

    Returns
    -------
    list of MeasuredData, strains on lvcore's 6 x 4 grid, with the wall layer the file declares
    (:func:`lvcore.inference.strain_layers.declared_strain_layer`).
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"measured-data file {path} does not exist (or is not a file)")
    if offset_deg is not None and not np.isfinite(offset_deg):
        raise DataError(f"--segment-offset must be a finite angle in degrees, got {offset_deg}")
    suffix = path.suffix.lower()
    readers = {".json": _read_json, ".mat": _read_mat, ".csv": _read_csv_any, ".txt": _read_csv_any, "": _read_csv_any}
    if suffix in readers:
        from dataclasses import replace

        from lvcore.inference.strain_layers import declared_strain_layer

        rows = readers[suffix](path, segments, offset_deg)
        layer = declared_strain_layer(path)
        return rows if layer is None else [replace(r, strain_layer=layer) for r in rows]
    raise DataError(f"{path.name}: unknown measured-data format '{suffix}'; use {', '.join(MEASUREMENT_SUFFIXES)}")


def write_measured_csv(path, rows: list[MeasuredData]) -> Path:
    """Write measurements in the layout :func:`read_measured_csv` reads (with a subject column; one row per
    loaded state, with an ``edp_mmhg`` column when any row has a pressure)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    states = [(r.subject or f"row{i + 1}", s.edp_mmhg if r.states else r.edp_mmhg, s.y)
              for i, r in enumerate(rows) for s in (r.all_states() if r.states else [LoadedState(0.0, r.y)])]
    df = pd.DataFrame([y for *_, y in states], columns=list(OUTPUT_COLUMNS))
    df.insert(0, "subject", [s for s, *_ in states])
    if any(e is not None for _, e, _ in states):
        df.insert(1, "edp_mmhg", [e for _, e, _ in states])
    df.to_csv(path, index=False, float_format="%.8g")
    return path


__all__ = ["MeasuredData", "LoadedState", "MAX_LOADED_STATES", "check_volume", "OPTIONAL_COLUMNS", "check_extras", "validate_measurements", "read_measured_csv", "read_measurements", "write_measured_csv",
           "LVV_RANGE_ML", "MEASUREMENT_SUFFIXES"]
