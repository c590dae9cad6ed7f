r"""Exact uniform scaling of the LV reference geometry: size is free.

Scale the reference (stress-free, early-diastolic) geometry by ``s`` about a
point of the base plane, ``X' = s X``, and keep the pressure, the material
and the fibres (given by helix angles on the template's parametric
coordinates, so the fibre field is the same at corresponding points). Then
``u'(X') = s u(X' / s)`` solves the scaled problem:

* the deformation gradient ``F' = I + Grad' u' = F`` at corresponding points,
  so the first Piola stress ``P(F)`` is the same;
* equilibrium ``Div' P = Div P / s = 0`` holds;
* the pressure traction ``P N = -p J F^{-T} N`` holds, the unit normal ``N``
  of the scaled surface being the same;
* the base conditions (no z displacement of the base plane, three
  circumferential pins; or all base dofs clamped) map onto themselves.

Hence every strain is unchanged and every volume scales by ``s^3`` (lengths
by ``s``). The identity needs every load and constraint to be free of a
length scale: it does *not* hold with an epicardial Robin spring
(``boundary.epicardial_spring``, k in kPa/mm: its traction ``k u`` grows
with ``s`` while the stress does not), and the shipped emulators have none. The finite-element problem on the scaled template mesh is the same
discrete problem with the same factors, so the identity holds to the Newton
tolerance (``tests/test_geometry_scaling.py`` checks it with the simulator at
``s = 0.6`` and ``s = 1.5``).

This module applies the identity wherever a geometry meets an emulator:

* :func:`scale_outputs` multiplies the LVV of ``[LVV, 24 strains]`` by ``s^3``;
* :class:`ScaledForward` wraps any :class:`lvcore.core.Forward` that way;
* :func:`size_normalised_scores` splits a subject's template mesh into a
  scale ``s`` and PC scores ``h`` of the shape model, so a subject of any
  size lands on scores the emulator was trained on.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

#: Range of the scale factor accepted by calibration (the ``--geometry infer`` prior is log-uniform on it).
#: With the SYNTHETIC shape model's reference cavities of 62-110 mL it reaches about 10-500 mL.
SCALE_BOUNDS = (0.5, 1.8)


def scale_outputs(y, s):
    """``[LVV, 24 strains]`` of the geometry scaled by ``s``: LVV (mL) times ``s^3``, strains unchanged.

    Works on NumPy and JAX arrays of shape ``(..., 25)`` and is differentiable in ``s``.
    """
    if isinstance(y, np.ndarray) and np.ndim(s) == 0:
        out = np.array(y, dtype=float, copy=True)
        out[..., 0] *= float(s) ** 3
        return out
    import jax.numpy as jnp

    y = jnp.asarray(y)
    return y.at[..., 0].multiply(jnp.asarray(s) ** 3)


def scale_nodes(nodes, s: float, base_z: float | None = None) -> np.ndarray:
    """Template nodes (mm) scaled by ``s`` about the point ``(0, 0, base_z)`` of the base plane.

    ``base_z`` defaults to the mean height of the template's base nodes, so
    the scaled geometry keeps its base plane.
    """
    from lvcore.geometry.template import DEFAULT_TEMPLATE

    x = np.asarray(nodes, dtype=float)
    if base_z is None:
        base_z = float(np.mean(x[DEFAULT_TEMPLATE.base_nodes, 2]))
    origin = np.array([0.0, 0.0, float(base_z)])
    return origin + float(s) * (x - origin)


def scale_ellipsoid(lv, s: float):
    """A :class:`~lvcore.geometry.analytic.TruncatedEllipsoidLV` scaled by ``s`` about the origin."""
    from lvcore.geometry.analytic import EllipsoidSurface, TruncatedEllipsoidLV

    def surf(e):
        return EllipsoidSurface(e.rs * s, e.rl * s, None if e.ry is None else e.ry * s)

    return TruncatedEllipsoidLV(surf(lv.endo), surf(lv.epi), lv.base_z * s)


@dataclass(frozen=True)
class ScaledScores:
    """A template geometry as scale times a shape-model shape.

    Attributes
    ----------
    h : ndarray
        Standardised PC scores of the size-normalised geometry.
    scale : float
        ``s``: the subject is ``s`` times the shape with scores ``h``.
    projection_mse_cm2 : float
        Mean squared node distance (cm², at the subject's size) between the
        subject and ``s`` times the ``len(h)``-mode reconstruction.
    unscaled_h : ndarray
        Scores of the plain projection (``s = 1``), for comparison.
    """

    h: np.ndarray
    scale: float
    projection_mse_cm2: float
    unscaled_h: np.ndarray = field(default_factory=lambda: np.zeros(0))


def size_normalised_scores(nodes, n_pc: int = 5, model=None) -> ScaledScores:
    """Split template nodes into a scale ``s`` and the shape model's scores ``h``.

    The base plane is moved to the shape model's (``z = 0``); the scale is
    the cube root of the ratio of reference cavity volumes,
    ``s = (V_cav(x) / V_cav(mean shape))^(1/3)``, and ``h`` is the projection
    of ``x / s``: the subject's shape at the population's mean size. (A
    size from a least-squares fit of ``x / s`` to the shape space is
    ill-conditioned here, because the first mode is itself mostly size; the
    volume ratio is unique and is the measure a user has.)

    Parameters
    ----------
    nodes : (n_nodes, 3) array
        Aligned template nodes (mm): long axis on -z, phi = 0 towards the septum.
    n_pc : int
    model : ShapeModel, optional
        Default the bundled SYNTHETIC model.
    """
    from lvcore.geometry.shape_model import load_shape_model
    from lvcore.geometry.measures import cavity_volume
    from lvcore.geometry.template import DEFAULT_TEMPLATE

    model = load_shape_model() if model is None else model
    x = np.asarray(nodes, dtype=float)
    base = DEFAULT_TEMPLATE.base_nodes
    x = x - np.array([0.0, 0.0, np.mean(x[base, 2]) - np.mean(model.mean[base, 2])])
    t = float(np.cbrt(float(cavity_volume(model.mean, DEFAULT_TEMPLATE)) / float(cavity_volume(x, DEFAULT_TEMPLATE))))
    h = np.asarray(model.project(x * t, n_pc), dtype=float)
    recon = model.reconstruct(h) / t
    mse = float(np.mean(np.sum((recon - x) ** 2, axis=1)) / 100.0)
    return ScaledScores(h=h, scale=1.0 / t, projection_mse_cm2=mse,
                        unscaled_h=np.asarray(model.project(x, n_pc), dtype=float))


@dataclass(frozen=True, eq=False)
class ScaledForward:
    """A forward model of the reference geometry scaled by ``scale``: LVV times ``scale^3``.

    Wraps any :class:`lvcore.core.Forward` (emulator, simulator, stand-in);
    inputs, bounds and capabilities (:class:`~lvcore.core.JacobianForward`,
    :class:`~lvcore.core.TraceableForward`) are the wrapped model's. With ``scale = 1``
    it returns the wrapped model's outputs unchanged.

    Parameters
    ----------
    forward : Forward
    scale : float
        Uniform scale factor ``s`` of the reference geometry (> 0).
    """

    forward: Any
    scale: float = 1.0

    def __post_init__(self):
        s = float(self.scale)
        if not (np.isfinite(s) and s > 0):
            raise ValueError(f"scale must be a positive number, got {self.scale}")
        object.__setattr__(self, "scale", s)

    @property
    def input_names(self) -> tuple:
        return tuple(self.forward.input_names)

    @property
    def input_bounds(self) -> Mapping:
        return self.forward.input_bounds

    @property
    def label(self) -> str:
        base = getattr(self.forward, "label", type(self.forward).__name__)
        return base if self.scale == 1.0 else f"{base} x scale {self.scale:.4g}"

    def __getattr__(self, name):
        # Capabilities are the wrapped model's (lvcore.core.forward's protocols test for these attributes):
        # `jacobian` and `apply` exist exactly when the wrapped model has them, and scale its outputs.
        if name in ("forward", "scale"):
            raise AttributeError(name)
        if name == "jacobian":
            inner = self.forward.jacobian
            return lambda inputs, **kwargs: self._scaled(inner(inputs, **kwargs))
        if name == "apply":
            inner_apply = self.forward.apply
            return lambda x: scale_outputs(inner_apply(x), self.scale)
        # everything else (emulator, conditions, base, ...) is the wrapped model's
        return getattr(self.forward, name)

    def __call__(self, params):
        return scale_outputs(self.forward(params), self.scale)

    def evaluate(self, inputs, **kwargs):
        return self._scaled(self.forward.evaluate(inputs, **kwargs))

    def _scaled(self, batch):
        f = self.scale ** 3
        y = np.array(batch.outputs, dtype=float, copy=True)
        y[:, 0] *= f
        jac = None
        if batch.jacobian is not None:
            jac = np.array(batch.jacobian, dtype=float, copy=True)
            jac[:, 0, :] *= f
        return dataclasses.replace(batch, outputs=y, jacobian=jac)


__all__ = ["SCALE_BOUNDS", "scale_outputs", "scale_nodes", "scale_ellipsoid", "ScaledScores",
           "size_normalised_scores", "ScaledForward"]
