"""Measured data for calibration: LVV (mL) and 24 circumferential strains.

CSV layout: a header row with the columns of
:data:`lvcore.outputs.OUTPUT_COLUMNS` (``lvv_ml, strain_01 .. strain_24``),
optionally preceded by a ``subject`` column, and one row per measurement.
A header-less file of 25 numbers per row in that order is also accepted.

Validation raises :class:`lvcore.exceptions.DataError` with what to fix:
wrong column count, missing values, strains with the wrong sign convention
or in percent, and volumes in the wrong unit (m³, mm³, litres).
"""
from __future__ import annotations

import csv
import io
from dataclasses import dataclass
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
    """

    y: np.ndarray
    subject: str = ""
    source: str = ""
    synthetic: bool = False

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
        data_cols = [i for i in range(len(header)) if i != subject_col]
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
        out.append(MeasuredData(y=y, subject=subject, source=str(path)))
    return out


def write_measured_csv(path, rows: list[MeasuredData]) -> Path:
    """Write measurements in the layout :func:`read_measured_csv` reads (with a subject column)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    df = pd.DataFrame([r.y for r in rows], columns=list(OUTPUT_COLUMNS))
    df.insert(0, "subject", [r.subject or f"row{i + 1}" for i, r in enumerate(rows)])
    df.to_csv(path, index=False, float_format="%.8g")
    return path


__all__ = ["MeasuredData", "validate_measurements", "read_measured_csv", "write_measured_csv", "LVV_RANGE_ML"]
