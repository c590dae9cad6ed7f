r"""The shape model's representation error: a known model discrepancy of ``--geometry infer``.

With ``--geometry infer`` the subject's reference geometry is ``s *
reconstruct(h)``, a shape of the first ``k`` modes of the shape model (the
emulator's ``h1..hk``). A real LV is not such a shape: even at its best
``(h, s)`` the forward model of the reconstruction differs from the forward
model of the subject. That difference does not shrink with better data, so
a likelihood that ignores it is overconfident: noise-free data let the iid
``sigma_S`` shrink to the size of the misfit, and the structured misfit then
biases ``a_f``/``b_f`` with confident intervals (issue 24).

It is estimated once, from the SYNTHETIC cohort and the FE simulator, by
``scripts/build_representation_error.py``: for every cohort shape ``x`` that
the shape model did not see (the held-out volunteers and operator-study
patients, and each training shape under a leave-one-out refit of the PCA),
split ``x`` into ``s`` and the ``k``-mode scores ``h``
(:func:`lvcore.geometry.scaling.size_normalised_scores`), simulate ``x`` and
``s * reconstruct(h)`` at one theta of a Sobol design over the emulator's box
(the emulator's conditions), and record

* the strain difference ``d = strains(x) - strains(recon)`` (24 values);
* the relative error of the inflation at matched reference cavity,
  ``(EDV/V0)(x) / (EDV/V0)(recon) - 1`` (the inferred scale fits the measured
  reference cavity, so the inflation ratio is what the LVV misses);
* the relative errors of the geometric measures (reference cavity, wall
  volume, long axis) of ``recon`` against ``x``.

:func:`representation_error_stats` turns them into a 24 x 24 strain
covariance (second moment about zero, so a mean bias counts too;
Ledoit-Wolf shrinkage, :func:`sklearn.covariance.ledoit_wolf`) and relative
standard deviations (root mean squares). The models of
:mod:`lvcore.inference.models` then use, in infer mode,

* strains ``~ MVN(eta, sigma_S^2 I + Sigma_rep)`` (iid model); in the discrepancy model ``Sigma_rep`` is a
  known part of the discrepancy: ``b ~ N(0, K_GP + Sigma_rep)``, strains ``~ N(eta + b + v, sigma_S^2 I)``
  (the same distribution of the data; ``sigma_S^2`` stays conjugate for the blocked sampler);
* LVV ``~ N(eta_0, sigma_V^2 + (r_V eta_0)^2)``;
* each geometric measure ``~ N(m(h, s), sd^2 + (r_m m_measured)^2)``.

The asset is SYNTHETIC (a SYNTHETIC cohort and shape model), bundled as
``assets/shape_model/SYNTHETIC_representation_error_<k>pc.json``.

**With a mesh** (``--geometry FILE``, a template or volume mesh) the
emulator runs at the mesh's size-normalised ``k``-mode projection: the same
reconstruction, at a known ``(h, s)``, so the same error applies (the
strains and the LVV; there are no geometric measures to widen). The strain
floor is scaled to the mesh's own projection error
(:meth:`RepresentationError.for_projection`): the asset's cases give how a
shape's strain error grows with its projection error
(:func:`projection_scaling_fit`), so a mesh the shape model reproduces well
gets less floor than one it reproduces badly. The factor is a run-time value
of the compiled samplers, so one program still serves every mesh.
:func:`given_geometry_floor` wraps that forward model
(:class:`FlooredForward`) so the models and the verdict use the same
variances as in infer mode. PC scores (``--geometry scores.json``), the
mean shape and a subject emulator get no floor: the first two are shape-model
shapes by construction (the mean shape warns that the subject's is not), the
last has the subject's own geometry bound in.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from lvcore.exceptions import DataError
from lvcore.resources import asset_path

#: Format tag of the asset.
FORMAT = "lvcore.representation_error/1"
#: Geometric measures whose relative representation error is recorded (those of ``--geometry infer``).
MEASURE_KEYS = ("reference_volume_ml", "wall_volume_ml", "long_axis_mm")


def asset_file(n_pc: int) -> Path:
    """The bundled asset of the first ``n_pc`` modes of the SYNTHETIC shape model."""
    return asset_path("shape_model", f"SYNTHETIC_representation_error_{int(n_pc)}pc.json")


@dataclass(frozen=True)
class RepresentationError:
    """Model discrepancy of a ``k``-mode shape-model geometry (module docstring).

    Attributes
    ----------
    n_pc : int
        Modes of the shape model the geometry is restricted to.
    strain_cov : ndarray, shape (24, 24)
        Covariance (strain²) of the strain error, added to ``sigma_S^2 I``.
    lvv_rel_sd : float
        Relative sd of the LVV at matched reference cavity (fraction of the LVV).
    measure_rel_sd : dict
        Relative sd of each geometric measure of ``s * reconstruct(h)`` (fraction of the measure).
    n_cases : int
        Shapes behind the estimate.
    source : str
        Where it comes from (asset path and its label).
    projection_fit : dict
        How the cases' strain error grows with their projection error (:func:`projection_scaling_fit`);
        empty when the asset has no per-case projection errors.
    strain_scale : float
        Factor on ``strain_cov`` for one mesh (:meth:`for_projection`; 1 for the cohort's mean, and in infer
        mode). Inside a compiled sampler it is a traced run-time value, so one program serves every mesh.
    projection_mse_cm2 : float or None
        The mesh's own projection error at the mean size (cm²) behind ``strain_scale`` (None: the cohort's
        mean floor).
    """

    n_pc: int
    strain_cov: np.ndarray
    lvv_rel_sd: float
    measure_rel_sd: dict = field(default_factory=dict)
    n_cases: int = 0
    source: str = ""
    projection_fit: dict = field(default_factory=dict)
    strain_scale: Any = 1.0
    projection_mse_cm2: float | None = None

    def __post_init__(self):
        cov = np.asarray(self.strain_cov, dtype=float)
        if cov.shape != (24, 24) or not np.all(np.isfinite(cov)) or not np.allclose(cov, cov.T, atol=1e-15):
            raise DataError(f"representation error: strain_cov must be a finite symmetric 24 x 24 matrix, got "
                            f"shape {cov.shape}")
        if np.linalg.eigvalsh(cov).min() < -1e-12 * max(1.0, float(np.abs(cov).max())):
            raise DataError("representation error: strain_cov is not positive semi-definite")
        if not (np.isfinite(self.lvv_rel_sd) and 0.0 <= self.lvv_rel_sd < 1.0):
            raise DataError(f"representation error: lvv_rel_sd must lie in [0, 1), got {self.lvv_rel_sd}")
        object.__setattr__(self, "strain_cov", cov)
        object.__setattr__(self, "lvv_rel_sd", float(self.lvv_rel_sd))
        object.__setattr__(self, "measure_rel_sd", {k: float(v) for k, v in dict(self.measure_rel_sd).items()})
        if isinstance(self.strain_scale, (int, float, np.floating, np.integer)):  # not a traced run-time value
            if not (np.isfinite(self.strain_scale) and self.strain_scale > 0):
                raise DataError(f"representation error: strain_scale must be finite and > 0, got {self.strain_scale}")
            object.__setattr__(self, "strain_scale", float(self.strain_scale))

    @property
    def effective_strain_cov(self) -> np.ndarray:
        """``strain_scale * strain_cov`` (strain²): the covariance added to ``sigma_S^2 I`` for this geometry."""
        return float(self.strain_scale) * self.strain_cov

    def for_projection(self, projection_mse_cm2: float, scale: float = 1.0) -> "RepresentationError":
        """The floor of a mesh whose k-mode projection misses it by ``projection_mse_cm2``.

        ``strain_cov`` is the cohort's mean second moment; a mesh far from the shape space gets more, one
        close to it less: ``strain_scale = (c0 + c1 p) / mean`` with ``c0, c1`` of
        :func:`projection_scaling_fit` (1 at the cohort's mean) and ``p = projection_mse_cm2 / scale**2``
        the error at the shape model's mean size (strains do not change with size; the node distances do).
        Without a fit (an asset with no per-case projection errors) the floor is returned unchanged.

        Parameters
        ----------
        projection_mse_cm2 : float
            Mean squared node distance (cm²) between the mesh and its reconstruction
            (:func:`lvcore.geometry.scaling.size_normalised_scores`).
        scale : float
            The mesh's size factor ``s`` against the shape model's mean shape.
        """
        mse, s = float(projection_mse_cm2), float(scale)
        if not (np.isfinite(mse) and mse >= 0 and np.isfinite(s) and s > 0):
            raise DataError(f"representation error: projection_mse_cm2 must be finite and >= 0 and the scale "
                            f"finite and > 0, got {mse} and {s}")
        fit = self.projection_fit
        if not fit:
            return self
        p = mse / s ** 2
        factor = (fit["intercept"] + fit["slope"] * p) / fit["mean"]
        return replace(self, strain_scale=float(factor), projection_mse_cm2=p)

    @property
    def strain_sd(self) -> np.ndarray:
        """Per-segment sd of the strain error (strain), ``strain_scale`` included."""
        return np.sqrt(np.diag(self.effective_strain_cov))

    @property
    def strain_rms(self) -> float:
        """Root mean square over the 24 segments of the strain error sd (strain), ``strain_scale`` included."""
        return float(np.sqrt(np.mean(np.diag(self.effective_strain_cov))))

    def strain_rep_covariance(self):
        """``Sigma_rep = strain_scale * strain_cov`` (strain²), JAX-traceable in ``strain_scale``.

        The covariance the likelihoods add for this geometry: to ``sigma_S^2 I`` in the iid model, to the GP
        discrepancy's ``K`` in the discrepancy model (:func:`lvcore.inference.models.discrepancy_cholesky`).
        """
        import jax.numpy as jnp

        return jnp.asarray(self.strain_scale) * jnp.asarray(self.strain_cov)

    def lvv_sd(self, sigma_v, eta0):
        """LVV sd (mL) with the floor: ``sqrt(sigma_v^2 + (lvv_rel_sd eta0)^2)`` (JAX-traceable)."""
        import jax.numpy as jnp

        return jnp.sqrt(jnp.asarray(sigma_v) ** 2 + (self.lvv_rel_sd * jnp.asarray(eta0)) ** 2)

    def measure_sd(self, name: str, sd: float, measured: float) -> float:
        """Sd of a geometric measure with the floor: ``sqrt(sd^2 + (rel_sd measured)^2)``."""
        r = self.measure_rel_sd.get(name, 0.0)
        return float(np.hypot(float(sd), r * float(measured)))

    def record(self) -> dict:
        """What summary.json reports."""
        return {"n_pc": self.n_pc, "source": self.source, "n_cases": self.n_cases,
                "strain_sd_rms": self.strain_rms, "strain_sd_min": float(self.strain_sd.min()),
                "strain_sd_max": float(self.strain_sd.max()), "lvv_rel_sd": self.lvv_rel_sd,
                "measure_rel_sd": dict(self.measure_rel_sd), "strain_scale": float(self.strain_scale),
                "projection_mse_cm2": self.projection_mse_cm2,
                "projection_fit": dict(self.projection_fit),
                "beyond_cohort": bool(self.projection_fit and self.projection_mse_cm2 is not None
                                      and self.projection_mse_cm2 > self.projection_fit["mse_max"])}


def representation_error_stats(strain_deltas, lvv_rel_deltas, measure_rel_deltas: dict | None = None) -> dict:
    """Covariance and relative sds from per-shape representation errors.

    Parameters
    ----------
    strain_deltas : (n, 24) array
        ``strains(x) - strains(recon)`` per case.
    lvv_rel_deltas : (n,) array
        ``(EDV/V0)(x) / (EDV/V0)(recon) - 1`` per case.
    measure_rel_deltas : dict of (n,) arrays, optional
        Relative error of each geometric measure of ``recon`` against ``x``.

    Returns
    -------
    dict
        ``strain_cov`` (24 x 24 list; the second moment about zero, shrunk by
        Ledoit-Wolf towards a multiple of the identity), ``lvv_rel_sd`` and
        ``measure_rel_sd`` (root mean squares), ``n_cases`` and the shrinkage.
    """
    from sklearn.covariance import ledoit_wolf

    d = np.asarray(strain_deltas, dtype=float)
    if d.ndim != 2 or d.shape[1] != 24 or d.shape[0] < 2:
        raise DataError(f"strain_deltas must be (n >= 2, 24), got {d.shape}")
    if not np.all(np.isfinite(d)):
        raise DataError("strain_deltas hold non-finite values")
    # assume_centered: the second moment about zero, so a systematic bias of the reconstruction counts as error
    cov, shrinkage = ledoit_wolf(d, assume_centered=True)
    rv = np.asarray(lvv_rel_deltas, dtype=float).reshape(-1)
    if rv.shape[0] != d.shape[0]:
        raise DataError(f"lvv_rel_deltas has {rv.shape[0]} cases, strain_deltas {d.shape[0]}")
    rms = lambda v: float(np.sqrt(np.mean(np.square(np.asarray(v, dtype=float)))))  # noqa: E731
    return {"strain_cov": cov.tolist(), "shrinkage": float(shrinkage), "lvv_rel_sd": rms(rv),
            "measure_rel_sd": {k: rms(v) for k, v in dict(measure_rel_deltas or {}).items()},
            "n_cases": int(d.shape[0]), "estimator": "sklearn.covariance.ledoit_wolf(assume_centered=True)"}


def projection_scaling_fit(projection_mse_cm2, strain_deltas) -> dict:
    """How a shape's strain representation error grows with its projection error (for :meth:`for_projection`).

    Fits ``mean(d_i^2) = c0 + c1 p_i`` (non-negative least squares, :func:`scipy.optimize.nnls`) over the
    cases ``i``, with ``d_i`` a case's 24 strain errors and ``p_i`` its projection error at the shape model's
    mean size (cm², ``projection_mse_cm2 / scale**2``), and reports Spearman's rank correlation of the two
    as the evidence for it.

    Returns
    -------
    dict
        ``intercept`` c0 and ``slope`` c1 (strain², strain²/cm²), ``mean`` (the cases' mean of
        ``mean(d_i^2)``, the trace/24 of the mean floor), ``mse_min`` / ``mse_max`` (cm², the cases' range),
        ``spearman_rho``, ``spearman_p`` and ``n``.
    """
    from scipy.optimize import nnls
    from scipy.stats import spearmanr

    p = np.asarray(projection_mse_cm2, dtype=float).reshape(-1)
    s2 = np.mean(np.square(np.asarray(strain_deltas, dtype=float)), axis=1)
    if p.shape[0] != s2.shape[0] or p.shape[0] < 3 or not np.all(np.isfinite(p)):
        raise DataError(f"projection scaling fit: need >= 3 cases with finite projection errors, got {p.shape[0]}")
    (c0, c1), _ = nnls(np.c_[np.ones_like(p), p], s2)
    rho, pval = spearmanr(p, s2)
    return {"intercept": float(c0), "slope": float(c1), "mean": float(s2.mean()), "mse_min": float(p.min()),
            "mse_max": float(p.max()), "spearman_rho": float(rho), "spearman_p": float(pval), "n": int(p.shape[0])}


def load_representation_error(n_pc: int = 5, path=None) -> RepresentationError:
    """The representation error of ``n_pc`` modes (default: the bundled SYNTHETIC asset).

    Raises
    ------
    DataError
        If the file is missing (build it with ``python scripts/build_representation_error.py``) or malformed.
    """
    p = asset_file(n_pc) if path is None else Path(path)
    if not p.is_file():
        raise DataError(f"representation error of {n_pc} modes: '{p}' not found; build it with "
                        f"`python scripts/build_representation_error.py --n-pc {n_pc}`")
    meta = json.loads(p.read_text())
    if meta.get("format") != FORMAT:
        raise DataError(f"{p.name}: not a representation-error file (format {meta.get('format')!r}, want {FORMAT})")
    if int(meta["n_pc"]) != int(n_pc):
        raise DataError(f"{p.name} is for {meta['n_pc']} modes, the emulator uses {n_pc}")
    st = meta["stats"]
    cases = [c for c in meta.get("cases", []) if "projection_mse_cm2" in c and "strain_delta" in c]
    fit = (projection_scaling_fit([c["projection_mse_cm2"] / float(c.get("scale", 1.0)) ** 2 for c in cases],
                                  [c["strain_delta"] for c in cases]) if len(cases) >= 3 else {})
    return RepresentationError(n_pc=int(meta["n_pc"]), strain_cov=np.asarray(st["strain_cov"], dtype=float),
                               lvv_rel_sd=float(st["lvv_rel_sd"]), measure_rel_sd=dict(st.get("measure_rel_sd", {})),
                               n_cases=int(st["n_cases"]), source=f"{p.name} ({meta.get('label', '')})",
                               projection_fit=fit)


#: Geometry kinds (:class:`lvcore.inference.guards.GeometrySource`) that are a subject's mesh seen through its
#: k-mode projection, and so carry the shape model's representation error.
MESH_KINDS = ("template-mesh", "volume-mesh")


@dataclass(frozen=True, eq=False)
class FlooredForward:
    """A forward model that carries a :class:`RepresentationError` (``representation``).

    Outputs, inputs, bounds and capabilities (``jacobian``, ``apply``, ``evaluate``) are the wrapped
    model's, unchanged; the likelihoods of :mod:`lvcore.inference.models` and the verdict read
    ``representation`` and widen their variances by it, as for ``--geometry infer``.
    """

    forward: Any
    representation: RepresentationError

    @property
    def input_names(self) -> tuple:
        return tuple(self.forward.input_names)

    @property
    def input_bounds(self):
        return self.forward.input_bounds

    @property
    def label(self) -> str:
        return getattr(self.forward, "label", type(self.forward).__name__)

    def __getattr__(self, name):
        if name in ("forward", "representation"):
            raise AttributeError(name)
        return getattr(self.forward, name)   # jacobian / apply / evaluate / scale / emulator ... as wrapped

    def __call__(self, params):
        return self.forward(params)


def given_geometry_floor(forward, kind: str, mode: str = "floor", n_pc: int = 5, representation=None,
                         projection_mse_cm2: float | None = None):
    """The representation-error floor of a given geometry (``--geometry FILE``; module docstring).

    Parameters
    ----------
    forward : Forward
        The emulator at the geometry's scores and scale (a :class:`lvcore.geometry.scaling.ScaledForward`).
    kind : str
        The geometry's kind: a floor only for :data:`MESH_KINDS`.
    mode : {"floor", "off"}
        ``--representation-error``.
    n_pc : int
        Modes of the emulator's shape space (selects the bundled asset).
    representation : RepresentationError, optional
        Default :func:`load_representation_error` of ``n_pc``.
    projection_mse_cm2 : float, optional
        The mesh's own projection error (:attr:`lvcore.inference.guards.GeometrySource.projection_mse_cm2`;
        taken to the mean size with ``forward.scale``): the floor is scaled to it
        (:meth:`RepresentationError.for_projection`). None: the cohort's mean floor.

    Returns
    -------
    forward : Forward
        ``forward`` itself, or a :class:`FlooredForward` around it.
    record : dict or None
        ``{"mode": "floor", **representation.record()}`` when floored, else None.
    """
    if mode not in ("floor", "off"):
        raise ValueError(f"--representation-error must be 'floor' or 'off', got {mode!r}")
    if mode == "off" or kind not in MESH_KINDS:
        return forward, None
    rep = load_representation_error(n_pc) if representation is None else representation
    if projection_mse_cm2 is not None:
        rep = rep.for_projection(projection_mse_cm2, float(getattr(forward, "scale", 1.0)))
    return FlooredForward(forward, rep), {"mode": "floor", **rep.record()}


__all__ = ["FORMAT", "MEASURE_KEYS", "MESH_KINDS", "asset_file", "RepresentationError", "representation_error_stats",
           "projection_scaling_fit", "load_representation_error", "FlooredForward", "given_geometry_floor"]
