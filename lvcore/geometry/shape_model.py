"""PCA shape model of LV geometries on the fixed template.

Geometries fitted by :mod:`lvcore.geometry.fitting` are already aligned: base
plane ``z = base_z``, long axis on −z, phi = 0 towards the septum. The model
is a PCA of the flattened node coordinates (mm, no scaling):

    x = mean + Σ_k h_k · std_k · component_k

Scores ``h`` are **standardised** (unit variance over the training set), so
``h ~ N(0, 1)`` describes the training population and ``±2`` is two standard
deviations along a mode. A case ``{"geometry": {"kind": "pca", "scores": [...]}}``
is ``reconstruct(scores)``: missing trailing scores are zero.

Files: ``<stem>.npz`` (plain arrays, no pickle) + ``<stem>.json`` (metadata).
The bundled model is ``assets/shape_model/SYNTHETIC_shape_model.{npz,json}`` (package data),
built by ``scripts/build_cohort.py`` from the SYNTHETIC cohort.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lvcore.exceptions import GeometryError
from lvcore.geometry.template import DEFAULT_TEMPLATE, LVTemplate
from lvcore.resources import asset_path

#: The bundled model (package data, see :mod:`lvcore.resources`).
BUNDLED_MODEL = asset_path("shape_model", "SYNTHETIC_shape_model.json")


@dataclass(frozen=True)
class ShapeModel:
    """A PCA model of template node coordinates.

    Attributes
    ----------
    mean : (n_nodes, 3) array
        Mean shape (mm).
    components : (n_modes, 3 n_nodes) array
        Orthonormal modes (rows), flattened node order ``nodes.ravel()``.
    std : (n_modes,) array
        Standard deviation of the training scores along each mode (mm).
    explained_variance_ratio : (n_modes,) array
        Fraction of the total training variance per mode.
    template : tuple of int
        (n_circ, n_long, n_trans) of the template.
    train_ids : tuple of str
        Identifiers of the training geometries.
    label : str
        Provenance, e.g. "SYNTHETIC cohort (scripts/build_cohort.py, seed 20240601)".
    """

    mean: np.ndarray
    components: np.ndarray
    std: np.ndarray
    explained_variance_ratio: np.ndarray
    template: tuple = (DEFAULT_TEMPLATE.n_circ, DEFAULT_TEMPLATE.n_long, DEFAULT_TEMPLATE.n_trans)
    train_ids: tuple = ()
    label: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def n_modes(self) -> int:
        return int(self.components.shape[0])

    @property
    def n_nodes(self) -> int:
        return int(self.mean.shape[0])

    # ------------------------------------------------------------------ maps
    def project(self, nodes, n_modes: int | None = None) -> np.ndarray:
        """Standardised scores of a geometry (or a batch ``(m, n_nodes, 3)``) on the first ``n_modes``."""
        x = np.asarray(nodes, float)
        single = x.ndim == 2
        x = x.reshape(-1, self.n_nodes * 3) if not single else x.reshape(1, -1)
        if x.shape[1] != self.n_nodes * 3:
            raise GeometryError(f"geometry has {x.shape[1] // 3} nodes, the shape model has {self.n_nodes}")
        k = self.n_modes if n_modes is None else self._k(n_modes)
        h = (x - self.mean.ravel()) @ self.components[:k].T / self.std[:k]
        return h[0] if single else h

    def reconstruct(self, scores) -> np.ndarray:
        """Nodes (mm) from standardised scores; fewer scores than modes means zeros for the rest.

        ``scores`` of shape (k,) gives (n_nodes, 3); shape (m, k) gives (m, n_nodes, 3).
        """
        h = np.asarray(scores, float)
        single = h.ndim == 1
        h = np.atleast_2d(h)
        k = h.shape[1]
        if k > self.n_modes:
            raise GeometryError(f"{k} scores given, the shape model has only {self.n_modes} modes")
        if not np.all(np.isfinite(h)):
            raise GeometryError("PCA scores must be finite numbers")
        x = self.mean.ravel() + (h * self.std[:k]) @ self.components[:k]
        x = x.reshape(-1, self.n_nodes, 3)
        return x[0] if single else x

    def reconstruct_nodes(self, nodes, n_modes: int) -> np.ndarray:
        """The ``n_modes``-mode reconstruction of a geometry (projection then reconstruction)."""
        return self.reconstruct(self.project(nodes, n_modes))

    def reconstruction_mse_cm2(self, nodes, n_modes: int) -> float:
        """Mean squared node distance (cm²) between a geometry and its k-mode reconstruction."""
        from lvcore.geometry.measures import node_mse_cm2

        return node_mse_cm2(nodes, self.reconstruct_nodes(nodes, n_modes))

    def mode_shape(self, mode: int, sd: float) -> np.ndarray:
        """Mean shape moved ``sd`` standard deviations along mode ``mode`` (0-based)."""
        h = np.zeros(mode + 1)
        h[mode] = sd
        return self.reconstruct(h)

    def sample_scores(self, rng, n: int, n_modes: int | None = None) -> np.ndarray:
        """(n, k) standardised scores drawn from N(0, I)."""
        k = self.n_modes if n_modes is None else self._k(n_modes)
        return np.random.default_rng(rng).standard_normal((n, k))

    def sample(self, rng, n: int, n_modes: int | None = None) -> np.ndarray:
        """(n, n_nodes, 3) random geometries from the Gaussian shape model (mm)."""
        return self.reconstruct(self.sample_scores(rng, n, n_modes))

    def _k(self, k) -> int:
        k = int(k)
        if not 0 <= k <= self.n_modes:
            raise GeometryError(f"n_modes must be in 0..{self.n_modes}, got {k}")
        return k

    # ------------------------------------------------------------------ files
    def save(self, path) -> Path:
        """Write ``<stem>.npz`` and ``<stem>.json``; returns the JSON path."""
        path = Path(path)
        stem = path.with_suffix("")
        stem.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(
            stem.with_suffix(".npz"),
            mean=self.mean.astype(np.float32),
            components=self.components.astype(np.float32),
            std=self.std.astype(np.float64),
            explained_variance_ratio=self.explained_variance_ratio.astype(np.float64),
        )
        meta = {
            "format": "lvcore.shape_model/1",
            "arrays": stem.with_suffix(".npz").name,
            "template": list(self.template),
            "n_modes": self.n_modes,
            "n_nodes": self.n_nodes,
            "train_ids": list(self.train_ids),
            "label": self.label,
            "scores": "standardised: h_k = component_k . (x - mean) / std_k",
            "units": "mm",
            "explained_variance_ratio": [float(v) for v in self.explained_variance_ratio],
            **({"extra": self.extra} if self.extra else {}),
        }
        out = stem.with_suffix(".json")
        out.write_text(json.dumps(meta, indent=1))
        return out


def fit_shape_model(geometries, ids=None, n_modes: int | None = None, label: str = "",
                    template: LVTemplate = DEFAULT_TEMPLATE) -> ShapeModel:
    """PCA of aligned geometries ``(m, n_nodes, 3)`` (mm).

    Keeps ``min(n_modes, m - 1)`` modes (all non-trivial ones by default), so
    with all modes every training geometry is reconstructed exactly.
    """
    X = np.asarray(geometries, float)
    if X.ndim != 3 or X.shape[1:] != (template.n_nodes, 3):
        raise GeometryError(f"geometries must have shape (m, {template.n_nodes}, 3), got {X.shape}")
    m = X.shape[0]
    if m < 3:
        raise GeometryError(f"a shape model needs at least 3 geometries, got {m}")
    flat = X.reshape(m, -1)
    mean = flat.mean(axis=0)
    _, sv, vt = np.linalg.svd(flat - mean, full_matrices=False)
    var = sv**2 / (m - 1)
    keep = min(m - 1, n_modes or m - 1)
    keep = int(min(keep, np.count_nonzero(var > var[0] * 1e-12)))
    return ShapeModel(
        mean=mean.reshape(-1, 3),
        components=vt[:keep],
        std=np.sqrt(var[:keep]),
        explained_variance_ratio=var[:keep] / var.sum(),
        template=(template.n_circ, template.n_long, template.n_trans),
        train_ids=tuple(str(i) for i in (ids if ids is not None else range(m))),
        label=label,
    )


def load_shape_model(path=None) -> ShapeModel:
    """Load a shape model (``.json`` or ``.npz`` path, or the stem); default the bundled SYNTHETIC model."""
    path = BUNDLED_MODEL if path is None else Path(path)
    stem = path.with_suffix("") if path.suffix in (".json", ".npz") else path
    jpath, npath = stem.with_suffix(".json"), stem.with_suffix(".npz")
    if not jpath.exists() or not npath.exists():
        hint = " (build it with `python scripts/build_cohort.py`)" if path == BUNDLED_MODEL else ""
        raise GeometryError(f"shape model files '{jpath.name}' and '{npath.name}' not found in '{stem.parent}'{hint}")
    from lvcore.safety import limits

    meta = limits.read_json_file(jpath, limits.MAX_SHAPE_MODEL_BYTES, "shape model", GeometryError)
    from lvcore.safety.headers import load_npz

    # array headers are checked against the limits before numpy allocates (lvcore.safety.headers)
    raw = load_npz(npath, limits.MAX_SHAPE_MODEL_BYTES, "shape model", GeometryError,
                   keys=("mean", "components", "std", "explained_variance_ratio"))
    try:
        arrays = {k: np.asarray(v, dtype=float) for k, v in raw.items()}
    except (ValueError, TypeError) as err:
        raise GeometryError(f"shape model '{npath}': arrays must be real numbers ({str(err)[:200]})") from None
    if not isinstance(meta, dict) or meta.get("format") != "lvcore.shape_model/1":
        meta = meta if isinstance(meta, dict) else {}
        raise GeometryError(f"'{jpath}' is not an lvcore shape model (format {meta.get('format')!r})")
    mean, comp = arrays["mean"], arrays["components"]
    if (comp.ndim != 2 or arrays["std"].ndim != 1 or mean.size % 3 or comp.shape[1] != mean.size
            or arrays["std"].shape[0] != comp.shape[0]):
        raise GeometryError(f"shape model '{stem}' arrays are inconsistent: mean {mean.shape}, components {comp.shape}")
    return ShapeModel(mean=mean.reshape(-1, 3), components=comp, std=arrays["std"],
                      explained_variance_ratio=arrays["explained_variance_ratio"],
                      template=tuple(meta.get("template", ())), train_ids=tuple(meta.get("train_ids", ())),
                      label=str(meta.get("label", "")), extra=dict(meta.get("extra", {})))
