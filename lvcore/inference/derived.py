r"""What one calibration identifies: derived quantities with their posterior.

With one loaded state (one pressure, one volume, 24 strains) the data fix a
*combination* of the HO stiffness parameters, not ``a`` and ``b`` each
(docs/real_data.md, *What one pressure can and cannot tell*). The quantities
below are what the data do determine, each computed per posterior draw so
that its interval is a posterior interval:

* **EDPVR** (:func:`fe_load_path`): the end-diastolic cavity volume at 0 (the
  reference cavity V₀), 5, 10, 15, 20, 25 and 30 mmHg, computed consistently
  with the calibration: the same geometry (PC scores and scale, or the subject
  emulator's mesh), base condition, fibre angles and mesh resolution (the
  emulator's training resolution). Where the EDPVR emulator (an EDP input of
  0-30 mmHg on the ``chapter`` geometry space, :mod:`lvcore.emulator.edpvr`)
  covers the calibration (PC-score geometry, given or inferred, any scale;
  angles -60°/60°; its base and mesh; every draw in its box) it is evaluated
  directly, its held-out volume error added to the predictive band; so is a
  subject emulator's own EDPVR emulator (:mod:`lvcore.emulator.subject_edpvr`,
  trained on its mesh when it was built with one) for a calibration through it;
  otherwise (subject emulators without one, inferred angles, other bases or
  meshes, draws outside the box) the FE simulator
  solves each draw and pressure, warm-started (draws ordered along a
  continuation path, :func:`lvcore.execution.chains.continuation_order`).
  ``derived["path"]`` says which. The volume at the data's EDP gives the
  emulator-to-FE offset (the calibration emulator against the FE volume, or
  against the EDPVR emulator), reported with the curve, and the mean
  end-diastolic fibre stretch.
* **Stress** (:func:`stress_summary`): the fibre and cross-fibre Cauchy
  stress of the HO law at a fixed fibre stretch of 1.10 and at the subject's
  mean end-diastolic fibre stretch (:func:`lvcore.mechanics.stress.ho_fibre_stress`).
* **Ridge** (:func:`ridge`): the principal directions of the posterior
  covariance of log θ; the best-determined combination
  ``log a + k_b log b + k_af log af + k_bf log bf`` with its 90 % width, and
  the least-determined one.
* **Contraction** (:func:`contraction`): per parameter ``1 − var_post/var_prior``
  of log θ (the prior is uniform on the linear scale; its log-scale variance
  is exact). Below :data:`WEAK_CONTRACTION` a parameter is reported as weakly
  identified: information, not a defect.

Intervals are equal-tailed (5 % and 95 % quantiles) everywhere, as in the
verdict.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

import numpy as np

from lvcore.domain.outputs import ANGLE_NAMES, EDP_NAME, THETA_NAMES

#: Pressures (mmHg) of the derived EDPVR besides 0 mmHg (V₀).
EDPVR_PRESSURES_MMHG = (5.0, 10.0, 15.0, 20.0, 25.0, 30.0)
#: Posterior draws behind each derived quantity (at least 100: a 90 % band from fewer is mostly noise).
N_DERIVED_DRAWS = 100
#: Fixed fibre stretch (-) of the stress at a common strain.
FIXED_FIBRE_STRETCH = 1.10
#: Contraction (1 − var_post/var_prior on the log scale) below which a parameter is reported as weakly identified.
WEAK_CONTRACTION = 0.5
#: Central interval of every derived quantity.
LEVELS = (0.05, 0.5, 0.95)
#: The EDPVR emulator (an EDP input, 0-30 mmHg) evaluated instead of FE load paths where it covers the calibration.
DEFAULT_EDPVR_EMULATOR = "edpvr"


def default_draws() -> int:
    """Posterior draws behind the derived quantities unless told: :data:`N_DERIVED_DRAWS`, or the environment's
    ``LVCORE_DERIVED_DRAWS`` (an integer 0-2000; 0 skips them, e.g. in a test suite or a batch that does not
    read them)."""
    import os

    from lvcore.exceptions import DataError

    raw = os.environ.get("LVCORE_DERIVED_DRAWS", "").strip()
    if not raw:
        return N_DERIVED_DRAWS
    try:
        n = int(raw)
    except ValueError:
        raise DataError(f"LVCORE_DERIVED_DRAWS must be an integer 0-2000, got {raw!r}") from None
    if not 0 <= n <= 2000:
        raise DataError(f"LVCORE_DERIVED_DRAWS must be an integer 0-2000, got {n}")
    return n


def default_edpvr_emulator() -> str | None:
    """The EDPVR emulator unless told: the environment's ``LVCORE_EDPVR_EMULATOR`` (a name, or ``none`` for the FE
    load path everywhere), else :data:`DEFAULT_EDPVR_EMULATOR`."""
    import os

    raw = os.environ.get("LVCORE_EDPVR_EMULATOR", "").strip()
    if not raw:
        return DEFAULT_EDPVR_EMULATOR
    return None if raw.lower() == "none" else raw


# --------------------------------------------------------------------------- contraction and the ridge
def log_uniform_moments(lower: float, upper: float) -> tuple[float, float]:
    """Mean and variance of ``log X`` for ``X ~ Uniform(lower, upper)``, ``0 < lower < upper`` (exact).

    Uses ``∫ log x dx = x (log x − 1)`` and ``∫ log² x dx = x (log² x − 2 log x + 2)``.
    """
    lo, hi = float(lower), float(upper)
    if not 0 < lo < hi:
        raise ValueError(f"need 0 < lower < upper, got {lo}, {hi}")
    w = hi - lo

    def f1(x):
        return x * (math.log(x) - 1.0)

    def f2(x):
        lx = math.log(x)
        return x * (lx * lx - 2.0 * lx + 2.0)

    m1 = (f1(hi) - f1(lo)) / w
    m2 = (f2(hi) - f2(lo)) / w
    return m1, max(m2 - m1 * m1, 0.0)


def contraction(samples: Mapping[str, np.ndarray], bounds: Mapping[str, tuple[float, float]]) -> dict:
    """Posterior contraction ``1 − var_post/var_prior`` of log θ per parameter.

    Parameters
    ----------
    samples : mapping
        Posterior draws of ``a, b, af, bf`` (any shape).
    bounds : mapping
        The uniform prior's bounds per parameter (linear scale, kPa or -).

    Returns
    -------
    dict
        ``name -> contraction`` (1: pinned by the data, 0: nothing learned; can be slightly negative by Monte Carlo
        noise).
    """
    out = {}
    for n in THETA_NAMES:
        if n not in samples or n not in bounds:
            continue
        v = np.log(np.asarray(samples[n], float).reshape(-1))
        _, var_prior = log_uniform_moments(*bounds[n])
        out[n] = float(1.0 - np.var(v, ddof=1) / var_prior)
    return out


def _combination(vec: np.ndarray, names=THETA_NAMES) -> dict:
    """A direction in log θ, scaled so that its largest coefficient is 1."""
    vec = np.asarray(vec, float)
    coef = vec / vec[int(np.argmax(np.abs(vec)))]
    return {f"log_{n}": float(c) for n, c in zip(names, coef)}


def _text(coef: Mapping[str, float]) -> str:
    parts = []
    for k, c in coef.items():
        if abs(c) < 0.005:
            continue
        name = k
        if not parts:
            parts.append(name if abs(c - 1) < 1e-9 else f"{c:.2f} {name}")
        else:
            parts.append(f"{'+' if c >= 0 else '-'} {abs(c):.2f} {name}")
    return " ".join(parts)


def ridge(samples: Mapping[str, np.ndarray]) -> dict:
    """The posterior's principal directions in log θ: what the data determine and what they leave open.

    The eigenvector of the posterior covariance of ``(log a, log b, log af, log bf)`` with the smallest
    variance is the best-determined combination, the one with the largest the least-determined. Each is
    reported scaled so a's coefficient is 1, with the equal-tailed 90 % width of the combination's draws (in
    log units, and as the factor ``exp(width)``).

    Returns
    -------
    dict
        ``best`` and ``least`` (``coefficients``, ``text``, ``median``, ``width90_log``, ``width90_factor``,
        ``sd_log``), ``eigenvalues`` (ascending), ``correlation_log_a_log_b``.
    """
    z = np.column_stack([np.log(np.asarray(samples[n], float).reshape(-1)) for n in THETA_NAMES])
    cov = np.cov(z, rowvar=False)
    lam, vecs = np.linalg.eigh(cov)
    out = {"eigenvalues": [float(v) for v in lam],
           "correlation_log_a_log_b": float(cov[0, 1] / math.sqrt(cov[0, 0] * cov[1, 1]))}

    def entry(coef, zz):
        comb = zz @ np.array(list(coef.values()))
        q05, q50, q95 = np.quantile(comb, LEVELS)
        return {"coefficients": coef, "text": _text(coef), "median": float(q50), "q05": float(q05),
                "q95": float(q95), "width90_log": float(q95 - q05), "width90_factor": float(math.exp(q95 - q05)),
                "sd_log": float(np.std(comb, ddof=1))}

    for key, col in (("best", 0), ("least", -1)):
        out[key] = entry(_combination(vecs[:, col]), z)
    # the matrix pair alone: log a + k log b, the combination one pressure pins (docs/real_data.md)
    lam2, vec2 = np.linalg.eigh(cov[:2, :2])
    v = vec2[:, 0] / vec2[0, 0] if abs(vec2[0, 0]) > 1e-12 else vec2[:, 0]
    out["a_b"] = entry({"log_a": float(v[0]), "log_b": float(v[1])}, z[:, :2])
    return out


# --------------------------------------------------------------------------- the FE load path
@dataclass(frozen=True)
class LoadPath:
    """FE volumes of posterior draws along the load path (see :func:`fe_load_path`).

    Attributes
    ----------
    pressures_mmhg : ndarray (P,)
        The curve's pressures, 0 first (V₀).
    volumes_ml : ndarray (N, P)
        Cavity volume (mL) of each draw at each pressure (NaN where a solve failed).
    edp_mmhg : float
        The data's end-diastolic pressure.
    volume_at_edp_ml : ndarray (N,)
        The FE cavity volume at the EDP.
    fibre_stretch_at_edp : ndarray (N,)
        Volume-weighted mean fibre stretch of the wall at the EDP (NaN if not computed).
    n_failed : int
        Solves that did not converge.
    resolution, base : str
    seconds : float
        Wall time of the solves (s).
    """

    pressures_mmhg: np.ndarray
    volumes_ml: np.ndarray
    edp_mmhg: float
    volume_at_edp_ml: np.ndarray
    fibre_stretch_at_edp: np.ndarray
    n_failed: int
    resolution: str
    base: str
    seconds: float


def _geometry_section(draw: Mapping, geometry: Mapping | None) -> dict:
    if geometry is not None:
        return dict(geometry)
    return {"kind": "pca", "scores": [float(v) for v in draw["h"]]}


def fe_load_path(draws: Sequence[Mapping], *, edp_mmhg: float, angles: tuple[float, float], base: str,
                 resolution: str = "default", geometry: Mapping | None = None,
                 pressures_mmhg: Sequence[float] = EDPVR_PRESSURES_MMHG, fibre_stretch: bool = True,
                 progress=None) -> LoadPath:
    """FE cavity volumes of posterior draws at each pressure and at the EDP.

    Parameters
    ----------
    draws : sequence of mapping
        Each ``{"a", "b", "af", "bf"}`` (kPa, -, kPa, -), with ``"h"`` (PC scores) and ``"scale"`` (-) of the
        geometry unless ``geometry`` is given, and optionally ``"alpha_endo"``, ``"alpha_epi"`` (deg).
    edp_mmhg : float
        The data's EDP (mmHg): its volume and the mean fibre stretch there are returned too.
    angles : (float, float)
        Fibre angles (deg) of draws without their own.
    base : {"sliding", "clamped"}
    resolution : str
        Mesh preset; the calibration emulator's training resolution.
    geometry : mapping, optional
        A fixed geometry section (a subject emulator's mesh); otherwise each draw's ``pca`` scores ``h``, and its
        volumes are multiplied by ``scale³`` (the scaled problem has the same deformation: lvcore.geometry.scaling).
    pressures_mmhg : sequence of float
        Increasing pressures in (0, 30] mmHg.
    fibre_stretch : bool
        Compute the mean fibre stretch at the EDP.
    progress : callable(done, total), optional

    Returns
    -------
    LoadPath
    """
    from lvcore.execution import chains
    from lvcore.domain import units
    from lvcore.mechanics.case_inputs import build_case
    from lvcore.mechanics.fibre_stretch import mean_fibre_stretch
    from lvcore.mechanics.forward import _as_warm, case_values, continue_or_solve

    p = np.asarray(pressures_mmhg, float)
    if p.ndim != 1 or p.size == 0 or np.any(np.diff(p) <= 0) or p[0] <= 0 or p[-1] > 30.0:
        raise ValueError("pressures_mmhg must increase, within (0, 30] mmHg")
    edp = float(edp_mmhg)
    levels = np.unique(np.r_[p, edp])
    n, m = len(draws), levels.size
    t0 = time.perf_counter()
    # every (draw, pressure) is one point of a continuation chain (lvcore.execution.chains): each solve starts from the
    # predicted state of its converged neighbours in (log theta, angles, pressure, PC scores)
    names = THETA_NAMES + ANGLE_NAMES + (EDP_NAME,)
    n_pc = 0 if geometry is not None else len(draws[0]["h"])
    rows, cases = [], []
    for i, d in enumerate(draws):
        inputs = {k: float(d[k]) for k in THETA_NAMES}
        inputs["alpha_endo"] = float(d.get("alpha_endo", angles[0]))
        inputs["alpha_epi"] = float(d.get("alpha_epi", angles[1]))
        geom = _geometry_section(d, geometry)
        for j, pj in enumerate(levels):
            cases.append(build_case({**inputs, EDP_NAME: float(pj)}, geometry=geom, resolution=resolution, base=base))
            rows.append([inputs[k] for k in names[:-1]] + [float(pj)] + ([] if geometry is not None
                                                                           else [float(v) for v in d["h"]]))
    X = np.asarray(rows, float)
    U = chains.scaled_coordinates(names + tuple(f"h{k + 1}" for k in range(n_pc)), X)
    order = chains.continuation_order(U) if len(cases) > 2 else np.arange(len(cases))
    done = [0]

    def solve(key, initial):
        case = cases[key]
        res = continue_or_solve(case, initial)
        done[0] += 1
        if progress is not None:
            progress(done[0], len(cases))
        if res is None:
            return None, None
        lam = float("nan")
        if fibre_stretch and abs(float(X[key, len(names) - 1]) - edp) < 1e-12:
            lam = float(mean_fibre_stretch(case, res))
        out = (res.cavity_volume_mm3[0] / units.MM3_PER_ML, res.cavity_volume_mm3[1] / units.MM3_PER_ML, lam)
        return out, _as_warm(res, case_values(case))

    solved = chains.solve_in_order(list(map(int, order)), U[order], [], solve)
    vols = np.full((n, m), np.nan)
    v0 = np.full(n, np.nan)
    stretch = np.full(n, np.nan)
    failed = 0
    for r in solved:
        i, j = divmod(r.key, m)
        if r.result is None:
            failed += 1
            continue
        s3 = 1.0 if geometry is not None else float(draws[i].get("scale", 1.0)) ** 3
        v0[i], vols[i, j] = r.result[0] * s3, r.result[1] * s3
        if np.isfinite(r.result[2]):
            stretch[i] = r.result[2]
    at = [int(np.flatnonzero(np.isclose(levels, pj))[0]) for pj in p]
    volumes = np.column_stack([v0, vols[:, at]])
    k_edp = int(np.flatnonzero(np.isclose(levels, edp))[0])
    return LoadPath(np.r_[0.0, p], volumes, edp, vols[:, k_edp], stretch, failed, resolution, base,
                    time.perf_counter() - t0)


def _edpvr_path(draws, *, edp_mmhg, angles, base, resolution, geometry, progress, pressures_mmhg,
                edpvr_emulator) -> tuple[LoadPath, dict]:
    """The EDPVR of the draws from the EDPVR emulator where it covers the calibration, else from FE load paths;
    with how (``path``, ``emulator``, ``reason``, ``source``, ``volume_log_sd_at_edp``)."""
    from lvcore.emulator import edpvr

    emu, why = edpvr.emulator_for(draws, geometry=geometry, angles=angles, base=base, resolution=resolution,
                                  edp_mmhg=edp_mmhg, pressures_mmhg=pressures_mmhg, name=edpvr_emulator)
    if emu is None:
        path = fe_load_path(draws, edp_mmhg=edp_mmhg, angles=angles, base=base, resolution=resolution,
                            geometry=geometry, progress=progress, pressures_mmhg=pressures_mmhg)
        return path, {"path": "fe", "emulator": None, "reason": why, "volume_log_sd_at_edp": 0.0,
                      "source": f"FE simulator ({path.resolution} mesh, {path.base} base)"}
    e = edpvr.emulated_load_path(emu, draws, edp_mmhg=edp_mmhg, pressures_mmhg=pressures_mmhg)
    if progress is not None:
        progress(len(draws), len(draws))
    volumes, stretch = edpvr.emulator_error_draws(emu, e, edp_mmhg)
    path = LoadPath(e.pressures_mmhg, volumes, float(edp_mmhg), e.volume_at_edp_ml, stretch, 0,
                    emu.resolution, emu.base, e.seconds)
    sd = e.volume_log_sd_at_edp
    what = "subject EDPVR emulator" if emu.is_subject else "EDPVR emulator"
    mesh = "the subject emulator's mesh, " if emu.is_subject else ""
    return path, {"path": "emulator", "emulator": emu.name, "reason": "", "volume_log_sd_at_edp": sd,
                  "source": f"{what} '{emu.name}' (FE-trained, {mesh}{emu.resolution} mesh, {emu.base} base; its "
                            "held-out error at each pressure drawn into the EDPVR and the fibre stretch, and at "
                            f"{float(edp_mmhg):g} mmHg ({100 * sd:.2f} %) added to the band of the check; the offset "
                            "is the calibration emulator against it)"}


# --------------------------------------------------------------------------- stress
def stress_summary(thetas: Mapping[str, np.ndarray], fibre_stretch_at_edp: np.ndarray | None) -> dict:
    """Fibre and cross-fibre Cauchy stress (kPa) at :data:`FIXED_FIBRE_STRETCH` and at the mean ED fibre stretch.

    Parameters
    ----------
    thetas : mapping
        Draws of ``a, b, af, bf`` (arrays of one length).
    fibre_stretch_at_edp : ndarray, optional
        Each draw's mean end-diastolic fibre stretch (:func:`fe_load_path`).

    Returns
    -------
    dict
        ``fixed_stretch`` and ``end_diastolic`` entries, each with ``stretch`` and ``fibre_kpa`` /
        ``cross_fibre_kpa`` quantile records; ``deformation`` says which homogeneous state is meant.
    """
    from lvcore.mechanics.stress import ho_fibre_stress

    th = {n: np.asarray(thetas[n], float).reshape(-1) for n in THETA_NAMES}
    out = {"deformation": "strip-biaxial: fibre stretch λ, in-plane cross-fibre stretch 1, wall normal 1/λ "
                          "(incompressible) and traction-free; Cauchy stress in kPa"}
    ff, ss = ho_fibre_stress(th, FIXED_FIBRE_STRETCH)
    out["fixed_stretch"] = {"stretch": FIXED_FIBRE_STRETCH, "fibre_kpa": quantiles(ff),
                            "cross_fibre_kpa": quantiles(ss)}
    if fibre_stretch_at_edp is not None:
        lam = np.asarray(fibre_stretch_at_edp, float).reshape(-1)
        ok = np.isfinite(lam)
        if ok.any():
            ff, ss = ho_fibre_stress({n: v[ok] for n, v in th.items()}, lam[ok])
            out["end_diastolic"] = {"stretch": quantiles(lam[ok]), "fibre_kpa": quantiles(ff),
                                    "cross_fibre_kpa": quantiles(ss), "n_draws": int(ok.sum())}
    return out


def quantiles(x) -> dict:
    """``{"q05", "median", "q95"}`` of finite draws (NaN-aware; None when there are none)."""
    x = np.asarray(x, float).reshape(-1)
    x = x[np.isfinite(x)]
    if not x.size:
        return {"q05": None, "median": None, "q95": None}
    q = np.quantile(x, LEVELS)
    return {"q05": float(q[0]), "median": float(q[1]), "q95": float(q[2])}


# --------------------------------------------------------------------------- the whole record
@dataclass(frozen=True)
class DerivedDraws:
    """Per-draw values behind ``derived`` (saved next to summary.json as ``*_derived.npz``).

    Attributes
    ----------
    index : ndarray (N,)
        Positions of the draws in the flattened (chain, draw) posterior.
    theta : dict of ndarray (N,)
    edpvr_pressures_mmhg : ndarray (P,)
    edpvr_ml : ndarray (N, P)
    emulated_edv_ml : ndarray (N,)
        The calibration forward model's LVV (at the data's EDP) of the same draws.
    fe_edv_ml : ndarray (N,)
    fibre_stretch_ed : ndarray (N,)
    """

    index: np.ndarray
    theta: dict
    edpvr_pressures_mmhg: np.ndarray
    edpvr_ml: np.ndarray
    emulated_edv_ml: np.ndarray
    fe_edv_ml: np.ndarray
    fibre_stretch_ed: np.ndarray
    extra: dict = field(default_factory=dict)

    def save(self, path) -> None:
        np.savez(path, index=self.index, edpvr_pressures_mmhg=self.edpvr_pressures_mmhg, edpvr_ml=self.edpvr_ml,
                 emulated_edv_ml=self.emulated_edv_ml, fe_edv_ml=self.fe_edv_ml,
                 fibre_stretch_ed=self.fibre_stretch_ed, **{f"theta_{k}": v for k, v in self.theta.items()},
                 **{k: np.asarray(v) for k, v in self.extra.items()})


def thinned_indices(n_total: int, n: int = N_DERIVED_DRAWS) -> np.ndarray:
    """``n`` evenly spaced positions in ``range(n_total)`` (all of them when there are fewer)."""
    n = min(int(n), int(n_total))
    return np.unique(np.linspace(0, n_total - 1, n).round().astype(int))


def posterior_draws(idata, n: int = N_DERIVED_DRAWS, *, h=None, scale: float = 1.0) -> tuple[list[dict], np.ndarray]:
    """Thinned posterior draws for :func:`fe_load_path`: θ, and the geometry (the posterior's ``h1..`` and ``scale``
    when the geometry was inferred, else the given ``h`` and ``scale``), and inferred fibre angles.

    Returns
    -------
    draws : list of dict
    index : ndarray
        Positions in the flattened (chain, draw) posterior.
    """
    from lvcore.domain.outputs import is_pc_name

    post = idata.posterior
    flat = {k: np.asarray(post[k]).reshape(-1) for k in post.data_vars
            if np.asarray(post[k]).ndim == 2}
    idx = thinned_indices(flat["a"].size, n)
    pcs = sorted((k for k in flat if is_pc_name(k)), key=lambda k: int(k[1:]))
    draws = []
    for i in idx:
        d = {k: float(flat[k][i]) for k in THETA_NAMES}
        if pcs:
            d["h"] = [float(flat[k][i]) for k in pcs]
            d["scale"] = float(flat["scale"][i]) if "scale" in flat else 1.0
        elif h is not None:
            d["h"] = [float(v) for v in np.asarray(h, float)]
            d["scale"] = float(scale)
        for k in ("alpha_endo", "alpha_epi"):
            if k in flat:
                d[k] = float(flat[k][i])
        draws.append(d)
    return draws, idx


def predictive_interval(volumes_ml: np.ndarray, sd_ml, level: float = 0.99, seed: int = 0) -> tuple[float, float]:
    """Central ``level`` interval of ``volume + N(0, sd²)`` over the draws (a posterior predictive interval, mL)."""
    v = np.asarray(volumes_ml, float).reshape(-1)
    sd = np.broadcast_to(np.asarray(sd_ml, float), v.shape)
    ok = np.isfinite(v)
    rng = np.random.default_rng(seed)
    rep = (v[ok][:, None] + sd[ok][:, None] * rng.standard_normal((int(ok.sum()), 200))).ravel()
    lo = (1 - level) / 2
    q = np.quantile(rep, [lo, 1 - lo])
    return float(q[0]), float(q[1])


def derive(idata, *, bounds: Mapping[str, tuple[float, float]], edp_mmhg: float, angles: tuple[float, float],
           base: str, resolution: str, measured_edv_ml: float | None, lvv_sd_ml, h=None, scale: float = 1.0,
           geometry: Mapping | None = None, n_draws: int = N_DERIVED_DRAWS, progress=None,
           pressures_mmhg: Sequence[float] = EDPVR_PRESSURES_MMHG,
           edpvr_emulator: str | None = "auto") -> tuple[dict, DerivedDraws]:
    """Every derived quantity of one calibration (module docstring) and the per-draw values behind them.

    Parameters
    ----------
    idata : arviz.InferenceData
        The calibration's posterior (``a, b, af, bf``, ``eta``; ``h1..``, ``scale`` with an inferred geometry).
    bounds : mapping
        θ's prior bounds (for the contraction).
    edp_mmhg, angles, base, resolution
        The calibration's conditions (mmHg, deg, base condition, the emulator's training resolution).
    measured_edv_ml : float, optional
        The measured LVV at the EDP (mL).
    lvv_sd_ml : float or callable
        The volume likelihood's sd (mL), or a function of the model's LVV (representation error included).
    h, scale : geometry of a given mesh (PC scores and scale); ignored when the posterior has its own.
    geometry : a fixed geometry section (subject emulator).
    n_draws : int
        Posterior draws behind the EDPVR and the stress (>= 100 for a 90 % band worth reading).
    pressures_mmhg : sequence of float
        The EDPVR's pressures besides 0 mmHg (default :data:`EDPVR_PRESSURES_MMHG`).
    edpvr_emulator : str or None
        The EDPVR emulator evaluated directly where it covers the calibration
        (:func:`lvcore.emulator.edpvr.emulator_for`); None: the FE load path; ``"auto"`` (default):
        :func:`default_edpvr_emulator`.

    Returns
    -------
    record : dict
        ``derived`` of summary.json: ``edpvr``, ``edpvr_check``, ``stress``, ``ridge``, ``contraction``,
        ``weakly_identified``, ``n_draws``, ``path`` (``"emulator"`` or ``"fe"``), ``emulator`` (the EDPVR
        emulator's name or None), ``path_reason`` (why the FE path, else ""), ``seconds``.
    draws : DerivedDraws
    """
    from lvcore.domain import physiology

    t0 = time.perf_counter()
    post = idata.posterior
    samples = {n: np.asarray(post[n]) for n in THETA_NAMES}
    draws, idx = posterior_draws(idata, n_draws, h=h, scale=scale)
    path, via = _edpvr_path(draws, edp_mmhg=edp_mmhg, angles=angles, base=base, resolution=resolution,
                            geometry=geometry, progress=progress, pressures_mmhg=pressures_mmhg,
                            edpvr_emulator=default_edpvr_emulator() if edpvr_emulator == "auto" else edpvr_emulator)
    eta0 = np.asarray(post["eta"]).reshape(-1, np.asarray(post["eta"]).shape[-1])[idx, 0] if "eta" in post else \
        np.full(idx.size, np.nan)
    offset = path.volume_at_edp_ml - eta0
    sd = lvv_sd_ml(path.volume_at_edp_ml) if callable(lvv_sd_ml) else float(lvv_sd_ml)
    # the EDPVR emulator's own held-out error (relative, at the EDP) adds to the data's volume sd
    sd_emu = via["volume_log_sd_at_edp"] * path.volume_at_edp_ml
    sd = np.sqrt(np.asarray(sd, float) ** 2 + sd_emu ** 2)
    edpvr = [{"pressure_mmhg": float(p), **quantiles(path.volumes_ml[:, j])}
             for j, p in enumerate(path.pressures_mmhg)]
    check = {"edp_mmhg": float(edp_mmhg), "fe_edv": quantiles(path.volume_at_edp_ml),
             "emulator_to_fe_offset_ml": quantiles(offset), "source": via["source"] + f", {len(draws)} posterior draws",
             "n_failed_solves": int(path.n_failed)}
    if via["path"] == "emulator":
        check["edpvr_emulator_sd_ml"] = quantiles(sd_emu)
    if measured_edv_ml is not None:
        lo, hi = predictive_interval(path.volume_at_edp_ml, sd, level=0.99)
        check.update({"measured_edv_ml": float(measured_edv_ml), "predictive_99": [lo, hi],
                      "inside": bool(lo <= float(measured_edv_ml) <= hi)})
        v0 = float(np.nanmedian(path.volumes_ml[:, 0]))
        if edp_mmhg > 0:
            v30 = physiology.klotz_v30(float(measured_edv_ml), float(edp_mmhg), v0)
            check["klotz"] = {"v0_ml": v0, "v30_ml": float(v30),
                              "volumes_ml": [float(physiology.klotz_volume(p, v0, v30)) for p in path.pressures_mmhg]}
    con = contraction(samples, bounds)
    weak = {n: f"{n}: contraction {c:.2f} (< {WEAK_CONTRACTION:g}): the data say little about {n} on its own; "
               "read the identified combination and the EDPVR instead"
            for n, c in con.items() if c < WEAK_CONTRACTION}
    thin = {n: np.asarray(samples[n]).reshape(-1)[idx] for n in THETA_NAMES}
    record = {"edpvr": edpvr, "edpvr_check": check,
              "stress": stress_summary(thin, path.fibre_stretch_at_edp),
              "ridge": ridge(samples), "contraction": con, "weakly_identified": list(weak.values()),
              "n_draws": int(len(draws)), "interval": "equal-tailed 90 % (q05-q95)",
              "path": via["path"], "emulator": via["emulator"], "path_reason": via["reason"],
              "seconds": {"fe": path.seconds if via["path"] == "fe" else 0.0,
                          "emulator": path.seconds if via["path"] == "emulator" else 0.0,
                          "total": time.perf_counter() - t0}}
    dd = DerivedDraws(idx, thin, path.pressures_mmhg, path.volumes_ml, eta0, path.volume_at_edp_ml,
                      path.fibre_stretch_at_edp, extra={"path": np.array(via["path"])})
    return record, dd


def check_flags(record: Mapping) -> list[str]:
    """Consistency flags from the derived record: the measured (EDP, EDV) outside the EDPVR's 99 % predictive
    interval at the EDP (the FE curve of the posterior cannot reach the measurement)."""
    c = record.get("edpvr_check", {})
    if c.get("inside", True):
        return []
    lo, hi = c["predictive_99"]
    how = "EDPVR emulator" if record.get("path") == "emulator" else "FE simulator"
    return [f"the EDPVR of the posterior misses the measured point: EDV {c['measured_edv_ml']:.1f} mL at "
            f"{c['edp_mmhg']:g} mmHg lies outside its 99 % predictive interval [{lo:.1f}, {hi:.1f}] mL ({how}; "
            f"emulator-to-FE offset {c['emulator_to_fe_offset_ml']['median']:+.1f} mL)"]


__all__ = ["EDPVR_PRESSURES_MMHG", "N_DERIVED_DRAWS", "DEFAULT_EDPVR_EMULATOR", "default_edpvr_emulator", "default_draws", "FIXED_FIBRE_STRETCH", "WEAK_CONTRACTION", "LoadPath",
           "DerivedDraws", "log_uniform_moments", "contraction", "ridge", "fe_load_path", "stress_summary",
           "quantiles", "posterior_draws", "thinned_indices", "predictive_interval", "derive", "check_flags", "text_table", "summary_rows",
           "format_interval", "stress_phrases"]


def text_table(record: Mapping) -> str:
    """The derived quantities as the CLI prints them (equal-tailed 90 % intervals)."""
    lines = ["identified quantities (median [90 % interval]):"]
    ed = record["edpvr"]
    lines.append("  EDPVR, cavity volume (mL): " + ", ".join(
        f"{r['pressure_mmhg']:g} mmHg {r['median']:.1f} [{r['q05']:.1f}, {r['q95']:.1f}]" for r in ed
        if r["median"] is not None))
    c = record["edpvr_check"]
    if "measured_edv_ml" in c:
        lo, hi = c["predictive_99"]
        lines.append(f"  measured EDV {c['measured_edv_ml']:.1f} mL at {c['edp_mmhg']:g} mmHg: "
                     f"{'inside' if c['inside'] else 'OUTSIDE'} the EDPVR's 99 % predictive interval "
                     f"[{lo:.1f}, {hi:.1f}]; emulator-to-FE offset {c['emulator_to_fe_offset_ml']['median']:+.2f} mL")
    lines += [f"  {phrase}" for phrase in stress_phrases(record["stress"])]
    rg = record["ridge"]
    lines.append(f"  best-determined combination: {rg['best']['text']} = {rg['best']['median']:.2f} "
                 f"(90 % width {rg['best']['width90_log']:.2f}, a factor {rg['best']['width90_factor']:.2f})")
    ab = rg["a_b"]
    lines.append(f"  matrix pair: {ab['text']} = {ab['median']:.2f} (90 % width a factor {ab['width90_factor']:.2f})")
    lines.append(f"  least-determined: {rg['least']['text']} (90 % width a factor {rg['least']['width90_factor']:.0f});"
                 f" corr(log a, log b) {rg['correlation_log_a_log_b']:+.2f}")
    lines.append("  contraction (1 - var_post/var_prior, log scale): " + ", ".join(
        f"{k} {v:.2f}" for k, v in record["contraction"].items()))
    lines += [f"  note: {n}" for n in record["weakly_identified"]]
    return "\n".join(lines)


def format_interval(q: Mapping, digits: int = 2, unit: str = "") -> str:
    """``"median unit [q05, q95]"`` of a quantile record (equal-tailed 90 %), or ``"n/a"`` when it has no median;
    the one formatting of a derived quantity used by the CLI's table and the app's panel."""
    if q.get("median") is None:
        return "n/a"
    return f"{q['median']:.{digits}f}{unit} [{q['q05']:.{digits}f}, {q['q95']:.{digits}f}]"


_q = format_interval


def stress_phrases(stress: Mapping, emphasis: Callable[[str], str] = str) -> list[str]:
    """The Cauchy stresses of a derived record (``record["stress"]``) in words, one phrase per stretch: at the fixed
    fibre stretch and, where recorded, at the mean end-diastolic one (medians and equal-tailed 90 % intervals, kPa).
    ``emphasis`` marks each phrase's heading (the app's panel: markdown bold); the CLI's table and the panel both
    use these phrases."""
    def values(q: Mapping) -> str:
        return f"fibre {_q(q['fibre_kpa'], 2, ' kPa')}; cross-fibre {_q(q['cross_fibre_kpa'], 2, ' kPa')}"

    fs = stress["fixed_stretch"]
    heading = f"Cauchy stress at fibre stretch {fs['stretch']:.2f}"
    out = [f"{emphasis(heading)}: {values(fs)}"]
    if "end_diastolic" in stress:
        e = stress["end_diastolic"]
        out.append(f"{emphasis('At the mean end-diastolic fibre stretch')} {_q(e['stretch'], 3)}: {values(e)}")
    return out


def summary_rows(record: Mapping) -> list[dict]:
    """The derived quantities as table rows: ``quantity``, ``unit``, ``median``, ``q05``, ``q95`` (equal-tailed 90 %),
    for a report table or a download (the EDPVR's pressures, the stress, the identified combinations)."""
    rows = [{"quantity": f"V at {r['pressure_mmhg']:g} mmHg" + (" (V₀)" if r["pressure_mmhg"] == 0 else ""),
             "unit": "mL", "median": r["median"], "q05": r["q05"], "q95": r["q95"]} for r in record["edpvr"]]
    st = record["stress"]
    for key, label in (("fixed_stretch", f"at fibre stretch {FIXED_FIBRE_STRETCH:.2f}"),
                       ("end_diastolic", "at the mean end-diastolic fibre stretch")):
        if key not in st:
            continue
        if key == "end_diastolic":
            rows.append({"quantity": "mean end-diastolic fibre stretch", "unit": "-", **_qrow(st[key]["stretch"])})
        rows.append({"quantity": f"fibre stress {label}", "unit": "kPa", **_qrow(st[key]["fibre_kpa"])})
        rows.append({"quantity": f"cross-fibre stress {label}", "unit": "kPa", **_qrow(st[key]["cross_fibre_kpa"])})
    for key, label in (("a_b", "matrix pair"), ("best", "best-determined combination")):
        e = record["ridge"][key]
        rows.append({"quantity": f"{label}: {e['text']}", "unit": "log", "median": e["median"], "q05": e["q05"],
                     "q95": e["q95"]})
    rows += [{"quantity": f"contraction of log {k}", "unit": "-", "median": v, "q05": None, "q95": None}
             for k, v in record["contraction"].items()]
    return rows


def _qrow(q: Mapping) -> dict:
    return {"median": q.get("median"), "q05": q.get("q05"), "q95": q.get("q95")}
