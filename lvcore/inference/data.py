"""Measured data for calibration: LVV (mL) and 24 circumferential strains.

Three file formats are read by :func:`read_measurements` (by suffix):

CSV (``.csv``)
    A header row with the columns of :data:`lvcore.outputs.OUTPUT_COLUMNS`
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

Validation raises :class:`lvcore.exceptions.DataError` with what to fix:
wrong column count, missing values, strains with the wrong sign convention
or in percent, and volumes in the wrong unit (m³, mm³, litres).
"""
from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from lvcore import limits
from lvcore.exceptions import DataError
from lvcore.outputs import N_OUTPUTS, OUTPUT_COLUMNS

#: Plausible LV end-diastolic volume range (mL) accepted without complaint.
LVV_RANGE_ML = (20.0, 600.0)
#: Largest plausible |strain| (dimensionless Green strain).
MAX_ABS_STRAIN = 0.6
#: Optional per-subject columns (CSV), keys (JSON) and variables (.mat): the end-diastolic pressure
#: (mmHg) and the geometric measures of ``--geometry infer`` (:mod:`lvcore.inference.geometry_prior`).
#: Each measure may come with its standard deviation, ``<measure>_sd`` (mL, mL, mm).
OPTIONAL_COLUMNS = ("edp_mmhg", "reference_volume_ml", "wall_volume_ml", "long_axis_mm", "reference_volume_ml_sd",
                    "wall_volume_ml_sd", "long_axis_mm_sd")


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
    """

    y: np.ndarray
    subject: str = ""
    source: str = ""
    synthetic: bool = False
    extras: dict = field(default_factory=dict)

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
    lvv = arr[0]
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


def read_measured_csv(path) -> list[MeasuredData]:
    """Read and validate a measured-data CSV (see module docstring); one :class:`MeasuredData` per row."""
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
                        "(lvcore.limits.MAX_MEASURED_ROWS); split the file")
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
        data_cols = [i for i in range(len(header)) if i != subject_col and i not in extra_cols]
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
    out = []
    seen: dict[str, int] = {}
    for i, (_, row) in enumerate(body.iterrows()):
        line = i + (2 if has_header else 1)
        subject = str(row.iloc[subject_col]).strip() if subject_col is not None else f"row{i + 1}"
        if subject in seen:
            raise DataError(f"{path.name}: subject '{subject[:80]}' appears on line {seen[subject]} and line {line}; "
                            "subject IDs must be unique (rename or drop one of the rows)")
        seen[subject] = line
        values = pd.to_numeric(row.iloc[data_cols], errors="coerce").to_numpy(dtype=float)
        nonnum = [OUTPUT_COLUMNS[j] for j, v in enumerate(row.iloc[data_cols])
                  if not _is_number(v) and str(v).strip().lower() not in ("", "nan")]
        if nonnum:
            raise DataError(f"{path.name} line {line}: non-numeric values in {', '.join(nonnum)}")
        y = validate_measurements(values, where=f"{path.name} line {line}")
        extras = check_extras({name: row.iloc[i] for i, name in extra_cols.items()}, f"{path.name} line {line}")
        out.append(MeasuredData(y=y, subject=subject, source=str(path), extras=extras))
    return out


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
         extras: dict | None = None) -> MeasuredData:
    from lvcore.inference.segments import N_AHA, to_lvcore

    try:
        st = np.asarray(strains, dtype=float).reshape(-1)
        lv = float(np.asarray(lvv, dtype=float).reshape(-1)[0]) if np.size(lvv) == 1 else float("nan")
    except (TypeError, ValueError) as err:
        raise DataError(f"{where}: values must be numbers ({err})") from None
    if np.size(lvv) != 1:
        raise DataError(f"{where}: lvv_ml must be one number per subject, got {np.size(lvv)}")
    expected = {"lvcore": (N_OUTPUTS - 1,), "aha": (N_AHA, N_AHA + 1)}[convention]
    if st.size not in expected:
        raise DataError(f"{where}: {st.size} strains for '{convention}' segments; expected "
                        f"{' or '.join(str(e) for e in expected)}"
                        + (" (use --segments aha for AHA 16-segment data)" if st.size in (N_AHA, N_AHA + 1) else "")
                        + (" (use --segments lvcore for lvcore's 24 regions)" if st.size == N_OUTPUTS - 1 else ""))
    if not np.all(np.isfinite(st)):
        raise DataError(f"{where}: missing or non-finite strains; fill them in or drop the subject")
    y = validate_measurements(np.r_[lv, to_lvcore(st, convention, offset_deg)], where=where)
    return MeasuredData(y=y, subject=str(subject), source=source, extras=check_extras(extras or {}, where))


def _read_json(path: Path, segments, offset_deg) -> list[MeasuredData]:
    from lvcore.inference.segments import AHA_COLUMNS

    obj = limits.read_json_file(path, limits.MAX_MEASURED_BYTES, "measured-data file", DataError)
    if isinstance(obj, dict) and "subjects" in obj:
        obj = obj["subjects"]
    items = obj if isinstance(obj, list) else [obj]
    if not items:
        raise DataError(f"{path.name}: no subjects")
    if len(items) > limits.MAX_MEASURED_ROWS:
        raise DataError(f"{path.name}: {len(items):,} subjects is more than the limit of {limits.MAX_MEASURED_ROWS:,} "
                        "(lvcore.limits.MAX_MEASURED_ROWS); split the file")
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
            keys = OUTPUT_COLUMNS[1:] if conv == "lvcore" else AHA_COLUMNS
            missing = [k for k in keys if k not in it]
            if missing:
                raise DataError(f"{where}: missing 'strains' (a list) or the keys {', '.join(missing[:4])}...")
            st = [it[k] for k in keys]
        out.append(_row(it["lvv_ml"], st, it.get("subject", f"row{i + 1}"), where, conv, off, str(path),
                        {k: it[k] for k in OPTIONAL_COLUMNS if k in it}))
    return out


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
    return [_row(lvv[i], st[i], subjects[i], f"{path.name} subject {subjects[i]}", conv, off, str(path),
                 {k: float(v[i]) for k, v in extras.items()})
            for i in range(n)]


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

        return [MeasuredData(y=np.r_[r.y[0], rotate_lvcore(r.y[1:], off)], subject=r.subject, source=r.source,
                             extras=r.extras)
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
    return out


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
    list of MeasuredData, strains on lvcore's 6 x 4 grid.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"measured-data file {path} does not exist (or is not a file)")
    if offset_deg is not None and not np.isfinite(offset_deg):
        raise DataError(f"--segment-offset must be a finite angle in degrees, got {offset_deg}")
    suffix = path.suffix.lower()
    if suffix == ".json":
        return _read_json(path, segments, offset_deg)
    if suffix == ".mat":
        return _read_mat(path, segments, offset_deg)
    if suffix in (".csv", ".txt", ""):
        return _read_csv_any(path, segments, offset_deg)
    raise DataError(f"{path.name}: unknown measured-data format '{suffix}'; use {', '.join(MEASUREMENT_SUFFIXES)}")


def write_measured_csv(path, rows: list[MeasuredData]) -> Path:
    """Write measurements in the layout :func:`read_measured_csv` reads (with a subject column)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    df = pd.DataFrame([r.y for r in rows], columns=list(OUTPUT_COLUMNS))
    df.insert(0, "subject", [r.subject or f"row{i + 1}" for i, r in enumerate(rows)])
    df.to_csv(path, index=False, float_format="%.8g")
    return path


__all__ = ["MeasuredData", "OPTIONAL_COLUMNS", "check_extras", "validate_measurements", "read_measured_csv", "read_measurements", "write_measured_csv",
           "LVV_RANGE_ML", "MEASUREMENT_SUFFIXES"]
