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

* strains ``~ MVN(eta, sigma_S^2 I + Sigma_rep)``;
* LVV ``~ N(eta_0, sigma_V^2 + (r_V eta_0)^2)``;
* each geometric measure ``~ N(m(h, s), sd^2 + (r_m m_measured)^2)``.

The asset is SYNTHETIC (a SYNTHETIC cohort and shape model), bundled as
``assets/shape_model/SYNTHETIC_representation_error_<k>pc.json``.

**With a mesh** (``--geometry FILE``, a template or volume mesh) the
emulator runs at the mesh's size-normalised ``k``-mode projection: the same
reconstruction, at a known ``(h, s)``, so the same error applies (the
strains and the LVV; there are no geometric measures to widen).
:func:`given_geometry_floor` wraps that forward model
(:class:`FlooredForward`) so the models and the verdict use the same
variances as in infer mode. PC scores (``--geometry scores.json``), the
mean shape and a subject emulator get no floor: the first two are shape-model
shapes by construction (the mean shape warns that the subject's is not), the
last has the subject's own geometry bound in.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
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
    """

    n_pc: int
    strain_cov: np.ndarray
    lvv_rel_sd: float
    measure_rel_sd: dict = field(default_factory=dict)
    n_cases: int = 0
    source: str = ""

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

    @property
    def strain_sd(self) -> np.ndarray:
        """Per-segment sd of the strain error (strain)."""
        return np.sqrt(np.diag(self.strain_cov))

    @property
    def strain_rms(self) -> float:
        """Root mean square over the 24 segments of the strain error sd (strain)."""
        return float(np.sqrt(np.mean(np.diag(self.strain_cov))))

    def strain_covariance(self, sigma_s2):
        """``sigma_s2 * I + strain_cov`` (JAX-traceable in ``sigma_s2``), the strain covariance of infer mode."""
        import jax.numpy as jnp

        return jnp.asarray(sigma_s2) * jnp.eye(24) + jnp.asarray(self.strain_cov)

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
                "measure_rel_sd": dict(self.measure_rel_sd)}


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
    return RepresentationError(n_pc=int(meta["n_pc"]), strain_cov=np.asarray(st["strain_cov"], dtype=float),
                               lvv_rel_sd=float(st["lvv_rel_sd"]), measure_rel_sd=dict(st.get("measure_rel_sd", {})),
                               n_cases=int(st["n_cases"]), source=f"{p.name} ({meta.get('label', '')})")


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


def given_geometry_floor(forward, kind: str, mode: str = "floor", n_pc: int = 5, representation=None):
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
    return FlooredForward(forward, rep), {"mode": "floor", **rep.record()}


__all__ = ["FORMAT", "MEASURE_KEYS", "MESH_KINDS", "asset_file", "RepresentationError", "representation_error_stats",
           "load_representation_error", "FlooredForward", "given_geometry_floor"]
