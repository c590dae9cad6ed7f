r"""A cohort for the hierarchical calibration: the measured-data CSV of several subjects, each with its geometry
and optionally its group, and a SYNTHETIC cohort drawn from a known population.

Cohort CSV
    The measured-data CSV of :mod:`lvcore.inference.data` (``subject`` first, then ``lvv_ml, strain_01 ..
    strain_24``; several rows of one subject with their own ``edp_mmhg`` are its loaded states; the geometric
    measures of ``--geometry infer`` as columns) plus two optional columns:

    ``geometry``
        The subject's geometry as ``lvcore calibrate --geometry`` takes it: a PC-scores file (.json/.csv with an
        optional ``scale``), a mesh, ``mean`` or ``infer``; a relative path is read from the CSV's folder.
        Without the column every subject gets the command line's ``--geometry``.
    ``group``
        A label (e.g. ``control``, ``HFpEF``); with two or more groups each gets its own population mean and the
        differences in the mean are reported.

    :func:`read_cohort` refuses (:class:`lvcore.exceptions.DataError`, naming the row and the column) a cohort of
    one subject, a subject whose geometry cannot be read, a subject with two geometries or groups, a group of one
    subject, and everything the measured-data reader refuses (a state without its pressure, two states at one
    pressure, ...).

SYNTHETIC cohort
    :func:`synthetic_cohort` draws ``log theta_i ~ N(mu, Sigma)`` (kept inside Table 9.1's box), a geometry per
    subject (PC scores and a scale), and data from the emulator at the ``chapter`` conditions with noise
    sigma_V = 5 mL and sigma_S = 0.03; :func:`write_cohort` writes the CSV, one scores file per subject and the
    truth (``truth.json``), all labelled SYNTHETIC.
"""
from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lvcore.core.space import THETA_BOUNDS
from lvcore.domain.conditions import SIGMA_S, SIGMA_V_ML, THETA_TILDE
from lvcore.domain.outputs import OUTPUT_COLUMNS, THETA_NAMES
from lvcore.exceptions import DataError, LVCoreError
from lvcore.safety import limits

#: The cohort CSV's own columns (the measured-data reader leaves them out).
COHORT_COLUMNS = ("group", "geometry")
#: Fewest subjects of a cohort and of each group.
MIN_SUBJECTS = 2
#: Most groups of one cohort.
MAX_GROUPS = 8
#: Strain noise sd of the SYNTHETIC cohort (the chapter's sigma_S).
SYNTHETIC_SIGMA_S = SIGMA_S
#: Population of the SYNTHETIC cohort: the mean of log theta (theta~ of the chapter's operator study) ...
SYNTHETIC_MU = dict(THETA_TILDE)
#: ... and the sds of log theta and their correlation matrix (order a, b, af, bf).
SYNTHETIC_SD = (0.30, 0.25, 0.30, 0.25)
SYNTHETIC_CORR = ((1.0, -0.3, 0.2, 0.0), (-0.3, 1.0, 0.0, 0.1), (0.2, 0.0, 1.0, -0.2), (0.0, 0.1, -0.2, 1.0))


@dataclass(frozen=True)
class Cohort:
    """A read cohort.

    Attributes
    ----------
    rows : tuple of lvcore.inference.data.MeasuredData
        One per subject, in file order.
    geometry : dict
        Subject -> the geometry as given (a path resolved against the CSV's folder, ``mean`` or ``infer``), or
        None when the file has no ``geometry`` column.
    group : dict
        Subject -> its group label; empty without a ``group`` column.
    where : dict
        Subject -> the file line of its first row (for messages).
    source : str
    """

    rows: tuple
    geometry: dict = field(default_factory=dict)
    group: dict = field(default_factory=dict)
    where: dict = field(default_factory=dict)
    source: str = ""

    @property
    def subjects(self) -> list[str]:
        return [r.subject for r in self.rows]

    @property
    def groups(self) -> list[str]:
        """The group labels in order of first appearance (empty without groups)."""
        return list(dict.fromkeys(self.group[s] for s in self.subjects)) if self.group else []


def _cohort_columns(path: Path) -> tuple[list[str], list[list[str]]]:
    text = limits.read_text_file(path, limits.MAX_MEASURED_BYTES, "cohort file", DataError)
    lines = [ln for ln in csv.reader(io.StringIO(text))]
    if not lines:
        raise DataError(f"{path.name}: no data rows")
    return [c.strip() for c in lines[0]], lines[1:]


def _per_subject(column: str, header: list[str], body: list[list[str]], name: str) -> dict:
    """Subject -> (value, line) of a cohort column, refusing a subject with two different values."""
    if column not in header:
        return {}
    k = header.index(column)
    out: dict = {}
    for i, cells in enumerate(body):
        if not any(c.strip() for c in cells):
            continue
        line = i + 2
        subject = cells[0].strip() if cells else ""
        value = cells[k].strip() if k < len(cells) else ""
        if not value:
            raise DataError(f"{name} line {line}: column {column} is empty for subject '{subject[:80]}'; give every "
                            f"row its {column}")
        if subject in out and out[subject][0] != value:
            raise DataError(f"{name} line {line}: column {column} = {value[:80]!r} differs from line "
                            f"{out[subject][1]} ({out[subject][0][:80]!r}) for subject '{subject[:80]}'; a subject "
                            f"has one {column}")
        out.setdefault(subject, (value, line))
    return out


def read_cohort(path) -> Cohort:
    """Read and check a cohort CSV (module docstring).

    Raises
    ------
    DataError
        Naming the row and the column: see the module docstring.
    """
    from lvcore.inference.data import read_measured_csv

    path = Path(path)
    if not path.is_file():
        raise DataError(f"cohort file {path} does not exist (or is not a file)")
    if path.suffix.lower() not in (".csv", ".txt"):
        raise DataError(f"{path.name}: a cohort is a CSV file (subject, [group], [geometry], lvv_ml, strain_01 ..)")
    header, body = _cohort_columns(path)
    if not header or header[0].lower() not in ("subject", "id", "subject_id"):
        raise DataError(f"{path.name} line 1: column 1 must be 'subject' (the cohort's subject IDs), got "
                        f"{(header[0] if header else '')[:40]!r}")
    rows = read_measured_csv(path, skip_columns=COHORT_COLUMNS)
    geometry = _per_subject("geometry", header, body, path.name)
    group = _per_subject("group", header, body, path.name)
    first = {}
    for i, cells in enumerate(body):
        if cells and cells[0].strip():
            first.setdefault(cells[0].strip(), i + 2)
    if len(rows) < MIN_SUBJECTS:
        lines = ", ".join(str(first[r.subject]) for r in rows if r.subject in first)
        raise DataError(f"{path.name} line {lines or 2}: column subject holds one subject "
                        f"('{rows[0].subject[:80]}'); a hierarchical calibration needs a cohort of at least "
                        f"{MIN_SUBJECTS} subjects (for one subject run lvcore calibrate without --hierarchical)")
    if group:
        _check_groups(group, path.name)
    geo = {s: _resolve_path(v, path.parent) for s, (v, _) in geometry.items()}
    return Cohort(tuple(rows), geo, {s: v for s, (v, _) in group.items()}, first, str(path))


def _check_groups(group: dict, name: str) -> None:
    counts: dict = {}
    for subject, (label, line) in group.items():
        counts.setdefault(label, []).append(line)
    if len(counts) > MAX_GROUPS:
        raise DataError(f"{name}: column group has {len(counts)} groups; at most {MAX_GROUPS} are allowed")
    for label, lines in counts.items():
        if len(counts) > 1 and len(lines) < MIN_SUBJECTS:
            raise DataError(f"{name} line {lines[0]}: column group = {label[:40]!r} has one subject; each group "
                            f"needs at least {MIN_SUBJECTS} (merge it into another group or drop the column)")


def _resolve_path(value: str, folder: Path) -> str:
    if value.strip().lower() in ("mean", "infer"):
        return value.strip().lower()
    p = Path(value)
    return str(p if p.is_absolute() else folder / p)


def resolve_subject_geometry(cohort: Cohort, subject: str, default, *, n_pc: int, units: str = "mm"):
    """The geometry of one subject: its ``geometry`` cell (or ``default``, the command line's) as a
    :class:`lvcore.inference.guards.GeometrySource`, or ``"infer"``.

    Raises
    ------
    DataError
        Naming the subject's line and the ``geometry`` column when the file cannot be read, or the option when
        neither is given.
    """
    from lvcore.inference.guards import resolve_geometry

    spec = cohort.geometry.get(subject, default)
    name = Path(cohort.source).name or "the cohort"
    if spec is None:
        raise DataError(f"{name} line {cohort.where.get(subject, '?')}: no geometry for subject '{subject[:80]}': "
                        "give a geometry column (PC scores, a mesh, mean or infer) or --geometry for every subject")
    if str(spec).strip().lower() == "infer":
        return "infer"
    try:
        return resolve_geometry(spec, n_pc=n_pc, units=units)
    except (LVCoreError, OSError, ValueError) as err:
        where = f"line {cohort.where.get(subject, '?')}, column geometry" if subject in cohort.geometry \
            else "--geometry"
        raise DataError(f"{name} {where}: the geometry of subject '{subject[:80]}' cannot be read: "
                        f"{str(err)[:300]}") from None


# --------------------------------------------------------------------------- SYNTHETIC cohort
@dataclass(frozen=True)
class SyntheticCohort:
    """A SYNTHETIC cohort with its truth.

    Attributes
    ----------
    subjects : tuple of str
    theta : ndarray, shape (n, 4)
        True theta per subject (kPa, -, kPa, -).
    h : ndarray, shape (n, n_pc)
        PC scores per subject.
    scale : ndarray, shape (n,)
    y : ndarray, shape (n, 25), or (n, S, 25) with loaded states
        Noisy data [LVV (mL), 24 strains] (per state).
    group : tuple of str
    mu : dict
        Group -> the true mean of log theta (4,).
    cov : ndarray, shape (4, 4)
        The true covariance of log theta.
    edp_mmhg : tuple of float
        The loaded states' pressures (mmHg), one per state of ``y``; empty: one state at the emulator's fixed EDP.
    """

    subjects: tuple
    theta: np.ndarray
    h: np.ndarray
    scale: np.ndarray
    y: np.ndarray
    group: tuple
    mu: dict
    cov: np.ndarray
    edp_mmhg: tuple = ()


def population_covariance(sd=SYNTHETIC_SD, corr=SYNTHETIC_CORR) -> np.ndarray:
    """``diag(sd) corr diag(sd)`` (log theta)."""
    sd = np.asarray(sd, float)
    return sd[:, None] * np.asarray(corr, float) * sd[None, :]


def synthetic_cohort(n: int, emulator, *, seed: int = 0, mu: dict | None = None, cov=None, n_groups: int = 1,
                     group_ratio_a: float = 2.0, h_sd: float = 0.5, sigma_v: float = SIGMA_V_ML,
                     sigma_s: float = SYNTHETIC_SIGMA_S, edp_mmhg=()) -> SyntheticCohort:
    """Draw a SYNTHETIC cohort of ``n`` subjects (module docstring).

    Parameters
    ----------
    n : int
        Subjects (>= 2).
    emulator : lvcore.emulator.Emulator
        Gives the data at each subject's theta and geometry (its fixed conditions, e.g. the ``chapter``
        emulator's 8 mmHg and -60/60 deg); LVV (mL) times ``scale**3``.
    mu : dict, optional
        Mean of theta on the log scale, as theta values (default :data:`SYNTHETIC_MU`).
    cov : array (4, 4), optional
        Covariance of log theta (default :func:`population_covariance`).
    n_groups : int
        1, or 2: the second half of the subjects form group ``B`` whose mean of ``a`` is ``group_ratio_a`` times
        group ``A``'s.
    h_sd : float
        Sd of the PC scores (clipped to +-1.5).
    sigma_v, sigma_s : float
        Noise sds of the LVV (mL) and the strains (independent at every state).
    edp_mmhg : sequence of float, optional
        Loaded states (mmHg): every subject is measured at each of these pressures, through an emulator with an
        EDP input (e.g. ``edpvr``); empty (default): one state at the emulator's fixed EDP.
    """
    from lvcore.domain.outputs import EDP_NAME, is_pc_name
    from lvcore.geometry.scaling import scale_outputs

    if n < MIN_SUBJECTS or n_groups not in (1, 2):
        raise ValueError(f"need n >= {MIN_SUBJECTS} subjects and 1 or 2 groups, got n={n}, n_groups={n_groups}")
    rng = np.random.default_rng(seed)
    m0 = np.log([float((mu or SYNTHETIC_MU)[k]) for k in THETA_NAMES])
    cov = population_covariance() if cov is None else np.asarray(cov, float)
    labels = ("A", "B")[:n_groups]
    group = tuple("A" if (n_groups == 1 or i < n // 2) else "B" for i in range(n))
    means = {"A": m0, "B": m0 + np.log(group_ratio_a) * np.eye(4)[0]}
    lo = np.log([THETA_BOUNDS[k][0] for k in THETA_NAMES])
    hi = np.log([THETA_BOUNDS[k][1] for k in THETA_NAMES])
    chol = np.linalg.cholesky(cov)
    log_theta = np.empty((n, 4))
    for i in range(n):
        while True:   # inside the box (a draw outside it is redrawn; rare for the default population)
            x = means[group[i]] + chol @ rng.standard_normal(4)
            if np.all((x > lo) & (x < hi)):
                break
        log_theta[i] = x
    n_pc = sum(1 for nm in emulator.input_names if is_pc_name(nm))
    h = np.clip(h_sd * rng.standard_normal((n, n_pc)), -1.5, 1.5)
    scale = np.exp(0.05 * rng.standard_normal(n))
    theta = np.exp(log_theta)
    states = tuple(float(p) for p in edp_mmhg)
    if states and EDP_NAME not in emulator.input_names:
        raise ValueError(f"loaded states {list(states)} mmHg need an emulator with an EDP input ('{EDP_NAME}')")
    names = list(THETA_NAMES) + [f"h{k + 1}" for k in range(n_pc)] + ([EDP_NAME] if states else [])
    order = [names.index(nm) for nm in emulator.input_names]

    def data(pressure):
        x = np.concatenate([theta, h] + ([np.full((n, 1), pressure)] if states else []), axis=1)
        clean = np.asarray([np.asarray(scale_outputs(emulator.apply(x[i, order]), scale[i])) for i in range(n)])
        return clean + np.concatenate([sigma_v * rng.standard_normal((n, 1)),
                                       sigma_s * rng.standard_normal((n, 24))], 1)

    y = np.stack([data(p) for p in states], axis=1) if states else data(None)
    subjects = tuple(f"SYNTHETIC-C{i + 1:02d}" for i in range(n))
    return SyntheticCohort(subjects, theta, h, scale, y, group, {g: means[g] for g in labels}, cov, states)


def write_cohort(cohort: SyntheticCohort, folder) -> Path:
    """Write a SYNTHETIC cohort: ``cohort.csv`` (subject, group when there are two, geometry, data),
    ``geometry/<subject>.json`` (PC scores and scale) and ``truth.json``; return the CSV's path."""
    folder = Path(folder)
    (folder / "geometry").mkdir(parents=True, exist_ok=True)
    two = len(set(cohort.group)) > 1
    states = tuple(cohort.edp_mmhg)
    head = ["subject"] + (["group"] if two else []) + ["geometry"] + (["edp_mmhg"] if states else []) \
        + list(OUTPUT_COLUMNS)
    lines = [",".join(head)]
    for i, s in enumerate(cohort.subjects):
        geo = f"geometry/{s}.json"
        (folder / geo).write_text(json.dumps({"h": [float(v) for v in cohort.h[i]], "scale": float(cohort.scale[i]),
                                              "label": "SYNTHETIC"}))
        lead = [s] + ([cohort.group[i]] if two else []) + [geo]
        for j, y in enumerate(cohort.y[i] if states else [cohort.y[i]]):
            lines.append(",".join(lead + ([f"{states[j]:g}"] if states else []) + [f"{v:.8g}" for v in y]))
    path = folder / "cohort.csv"
    path.write_text("\n".join(lines) + "\n")
    truth = {"label": "SYNTHETIC", "theta_names": list(THETA_NAMES),
             "mu_log": {g: [float(v) for v in m] for g, m in cohort.mu.items()},
             "cov_log": np.asarray(cohort.cov).tolist(),
             "theta": {s: [float(v) for v in cohort.theta[i]] for i, s in enumerate(cohort.subjects)},
             "group": dict(zip(cohort.subjects, cohort.group)),
             "edp_mmhg": [float(p) for p in cohort.edp_mmhg]}
    (folder / "truth.json").write_text(json.dumps(truth, indent=1))
    return path


__all__ = ["Cohort", "COHORT_COLUMNS", "MIN_SUBJECTS", "read_cohort", "resolve_subject_geometry",
           "SyntheticCohort", "synthetic_cohort", "write_cohort", "population_covariance", "SYNTHETIC_MU",
           "SYNTHETIC_SD", "SYNTHETIC_CORR", "SYNTHETIC_SIGMA_S"]
