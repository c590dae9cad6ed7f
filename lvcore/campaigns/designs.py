"""Space-filling designs over a :class:`~lvcore.core.space.ParameterSpace`.

All designs are drawn with :mod:`scipy.stats.qmc` (or numpy's Generator for
plain random sampling) from a seed, in the unit cube, and then mapped to the
space's physical values:

``sobol``
    scrambled Sobol sequence (``qmc.Sobol(scramble=True)``); a power-of-two
    ``n`` keeps its balance properties (others are allowed, with scipy's
    warning silenced).
``lhs``
    Latin hypercube (``qmc.LatinHypercube``).
``random``
    independent uniform draws.
``exp``
    the chapter's BO start design: a Latin hypercube whose material
    dimensions (a, b, af, bf) are warped by ``exp`` and rescaled linearly to
    the parameter's bounds, ``x = lo + (e^u - 1)/(e - 1) (hi - lo)`` (with the
    ``bo4``/``bo6`` spaces this is the chapter's [0.1, 10]); the other
    dimensions are mapped as usual.

A design is saved as CSV: one comment line ``# lvcore-design {json}`` holding
the space, method, seed and size, then a header ``row,<names...>`` and one
line per design point (physical units).
"""
from __future__ import annotations

import csv
import io
import json
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lvcore.core.space import ParameterSpace
from lvcore.exceptions import CampaignError
from lvcore.domain.outputs import THETA_NAMES

METHODS = ("sobol", "lhs", "random", "exp")
HEADER_TAG = "# lvcore-design "


@dataclass(frozen=True)
class Design:
    """Design points in physical units.

    Parameters
    ----------
    space : ParameterSpace
        The space the points live in (columns follow ``space.names``).
    points : np.ndarray
        ``(n, space.dim)`` physical values.
    method : str
        How the points were drawn (one of :data:`METHODS`, or ``"custom"``).
    seed : int or None
        The seed used.
    """

    space: ParameterSpace
    points: np.ndarray
    method: str = "custom"
    seed: int | None = None

    def __post_init__(self):
        pts = np.asarray(self.points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != self.space.dim:
            raise CampaignError(f"design points must be (n, {self.space.dim}) for space '{self.space.name}', got {pts.shape}")
        if not np.all(np.isfinite(pts)):
            raise CampaignError("design points must be finite")
        pts.setflags(write=False)
        object.__setattr__(self, "points", pts)

    @property
    def n(self) -> int:
        return self.points.shape[0]

    def cases(self, resolution: str = "default") -> list[dict]:
        """Simulator case dictionaries, one per row (:func:`lvcore.mechanics.case_inputs.space_case`)."""
        from lvcore.mechanics.case_inputs import space_case

        return [space_case(self.space, row, resolution) for row in self.points]


def unit_design(method: str, n: int, dim: int, seed: int) -> np.ndarray:
    """``(n, dim)`` points in [0, 1) from one of :data:`METHODS` (``exp`` = LHS).

    ``n`` and ``n x dim`` are checked against :data:`lvcore.safety.limits.MAX_DESIGN_POINTS` and
    :data:`~lvcore.safety.limits.MAX_DESIGN_VALUES` before anything is drawn, so every design written
    here can be read back by ``lvcore campaign run`` (:data:`~lvcore.safety.limits.MAX_DESIGN_BYTES`).
    """
    from lvcore.safety import limits

    if n < 1:
        raise CampaignError(f"a design needs n >= 1 points, got {n}")
    if n > limits.MAX_DESIGN_POINTS:
        raise CampaignError(f"a design of {n:,} points is more than the limit of {limits.MAX_DESIGN_POINTS:,} "
                            "(lvcore.safety.limits.MAX_DESIGN_POINTS); split the campaign")
    if n * dim > limits.MAX_DESIGN_VALUES:
        raise CampaignError(f"a design of {n:,} points x {dim} parameters = {n * dim:,} values is more than the limit "
                            f"of {limits.MAX_DESIGN_VALUES:,} (lvcore.safety.limits.MAX_DESIGN_VALUES); use fewer points")
    if not 0 <= int(seed) <= 2 ** 32 - 1:
        raise CampaignError(f"design seed must be an integer from 0 to 2^32 - 1, got {str(seed)[:40]}")
    # imported here: scipy.stats costs ~0.8 CPU-s to import, and reading a design (every campaign worker) needs none
    from scipy.stats import qmc

    if method == "sobol":
        sampler = qmc.Sobol(d=dim, scramble=True, seed=seed)
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*balance properties.*")
            return sampler.random(n)
    if method in ("lhs", "exp"):
        return qmc.LatinHypercube(d=dim, seed=seed).random(n)
    if method == "random":
        return np.random.default_rng(seed).random((n, dim))
    raise CampaignError(f"unknown design method '{method}'; choose one of {METHODS}")


def exp_warp(u: np.ndarray) -> np.ndarray:
    """The chapter's exp warp of [0, 1] onto [0, 1]: ``(e^u - 1) / (e - 1)``."""
    return np.expm1(u) / np.expm1(1.0)


def make_design(space: ParameterSpace, method: str, n: int, seed: int) -> Design:
    """Draw an ``n``-point design of ``method`` over ``space`` from ``seed``.

    Parameters
    ----------
    space : ParameterSpace
        The parameter space (e.g. :func:`lvcore.campaigns.get_space`); its bounds are in physical units
        (a, af in kPa; b, bf dimensionless; angles in degrees; EDP in mmHg).
    method : {"sobol", "lhs", "random", "exp"}
        How the unit-cube points are drawn (see the module docstring).
    n : int
        Number of points (a power of two keeps a Sobol design balanced).
    seed : int
        Seed of the draw, 0 to 2^32 - 1: the same seed gives the same design.

    Returns
    -------
    Design
        ``(n, space.dim)`` points in physical units, columns in ``space.names`` order.

    Examples
    --------
    A 4-point Sobol design over the material parameters, saved as CSV and read back unchanged:

    >>> import tempfile
    >>> from pathlib import Path
    >>> from lvcore.campaigns import get_space, load_design, make_design, save_design
    >>> design = make_design(get_space("material"), "sobol", 4, seed=0)
    >>> design.space.names, design.points.shape
    (('a', 'b', 'af', 'bf'), (4, 4))
    >>> bool(all(p.lower <= x <= p.upper for row in design.points for p, x in zip(design.space.parameters, row)))
    True
    >>> path = save_design(design, Path(tempfile.mkdtemp()) / "design.csv")
    >>> again = load_design(path)
    >>> bool((again.points == design.points).all()), again.method, again.seed
    (True, 'sobol', 0)
    """
    u = unit_design(method, int(n), space.dim, int(seed))
    x = space.from_unit(u)
    if method == "exp":
        for i, p in enumerate(space.parameters):
            if p.name in THETA_NAMES:
                x[:, i] = p.lower + exp_warp(u[:, i]) * (p.upper - p.lower)
    return Design(space, x, method, int(seed))


# ----- CSV ------------------------------------------------------------------

def save_design(design: Design, path: str | Path) -> Path:
    """Write ``design`` as CSV (see the module docstring); returns the path."""
    path = Path(path)
    meta = {"space": design.space.to_dict(), "method": design.method, "seed": design.seed, "n": design.n}
    buf = io.StringIO()
    buf.write(HEADER_TAG + json.dumps(meta) + "\n")
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(("row",) + design.space.names)
    for i, row in enumerate(design.points):
        writer.writerow([i] + [repr(float(v)) for v in row])
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(buf.getvalue())
    return path


def load_design(path: str | Path) -> Design:
    """Read a design CSV written by :func:`save_design`.

    Raises
    ------
    CampaignError
        If the file is missing, lacks the ``# lvcore-design`` line, has
        columns that do not match its space, non-numeric or missing values,
        out-of-order row numbers or points outside the space's bounds.
    """
    from lvcore.safety import limits

    path = Path(path)
    lines = limits.read_text_file(path, limits.MAX_DESIGN_BYTES, "design file", CampaignError).splitlines()
    if len(lines) > limits.MAX_DESIGN_POINTS + 2:
        raise CampaignError(f"design file '{path}' has {len(lines) - 2:,} rows, more than the limit of "
                            f"{limits.MAX_DESIGN_POINTS:,} (lvcore.safety.limits.MAX_DESIGN_POINTS)")
    where = f"design file '{path}'"
    if not lines or not lines[0].startswith(HEADER_TAG):
        raise CampaignError(f"{where}: first line must be '{HEADER_TAG.strip()} {{...}}' (write designs with `lvcore design`)")
    meta = limits.loads_json(lines[0][len(HEADER_TAG):], f"{where}: the metadata line", CampaignError)
    if not isinstance(meta, dict) or "space" not in meta:
        raise CampaignError(f"{where}: the metadata line has no 'space'")
    space = ParameterSpace.from_dict(meta["space"])
    rows = list(csv.reader(lines[1:]))
    if not rows:
        raise CampaignError(f"{where}: no header line")
    header = tuple(c.strip() for c in rows[0])
    expected = ("row",) + space.names
    if header != expected:
        raise CampaignError(f"{where}: columns {list(header)} do not match the space '{space.name}': expected {list(expected)}")
    body = [r for r in rows[1:] if any(c.strip() for c in r)]
    if not body:
        raise CampaignError(f"{where}: no design rows")
    values = np.empty((len(body), space.dim))
    for k, r in enumerate(body):
        line_no = k + 3
        if len(r) != len(expected):
            raise CampaignError(f"{where}, line {line_no}: expected {len(expected)} values, got {len(r)}")
        try:
            idx = int(r[0])
            values[k] = [float(c) for c in r[1:]]
        except ValueError as err:
            raise CampaignError(f"{where}, line {line_no}: not a number ({err})") from err
        if idx != k:
            raise CampaignError(f"{where}, line {line_no}: row number {idx}, expected {k} (rows must be 0, 1, 2, ...)")
        if not np.all(np.isfinite(values[k])):
            raise CampaignError(f"{where}, line {line_no}: values must be finite")
    inside = space.contains(values)
    if not np.all(inside):
        bad = int(np.flatnonzero(~inside)[0])
        raise CampaignError(f"{where}: row {bad} lies outside the bounds of space '{space.name}'")
    if "n" in meta and int(meta["n"]) != len(body):
        raise CampaignError(f"{where}: metadata says n={meta['n']} but the file has {len(body)} rows (truncated?)")
    return Design(space, values, str(meta.get("method", "custom")), meta.get("seed"))
