"""Hyperelastic strain-energy densities (kPa), pure jax.numpy functions.

Every law has the signature ``W(F, frame, params) -> scalar`` with ``F`` the
deformation gradient (3, 3), ``frame`` the rows ``(f0, s0, n0)`` of the local
fibre/sheet/sheet-normal frame (reference configuration) and ``params`` a 1-D
array in the order of :data:`PARAM_ORDER`. Incompressibility is imposed
separately (by the volumetric penalty in :mod:`lvcore.mechanics.element`);
the isotropic parts use the isochoric invariant ``Ī1 = J^{-2/3} I1`` so that
the reference configuration is stress free.

Laws
----
* ``holzapfel-ogden`` (Holzapfel & Ogden 2009; 8 parameters):
  ``W = a/(2b)(e^{b(Ī1−3)} − 1) + Σ_{i=f,s} a_i/(2b_i)(e^{b_i (I4i−1)²} − 1)·[I4i > 1]
  + a_fs/(2b_fs)(e^{b_fs I8fs²} − 1)``, with ``I4f = f0·C f0``, ``I4s = s0·C s0``,
  ``I8fs = f0·C s0``. The fibre and sheet terms act only in tension.
* ``guccione`` (Guccione et al. 1991, as in Land et al. 2015):
  ``W = C/2 (e^Q − 1)``, ``Q = b_f E11² + b_t (E22² + E33² + 2 E23²) + 2 b_fs (E12² + E13²)``,
  ``E`` the isochoric Green strain ``(J^{-2/3} C − I)/2`` in fibre coordinates
  (1 = f0, 2 = s0, 3 = n0); the deviatoric–volumetric split makes the law
  well behaved under the volumetric penalty and equals Guccione's at J = 1.
* ``neo-hookean``: ``W = mu/2 (Ī1 − 3)``.
"""
from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from lvcore import units
from lvcore.mechanics.kinematics import det3, green_strain, isochoric_i1, right_cauchy_green

#: Parameter order of the ``params`` array for each law.
PARAM_ORDER = {
    "holzapfel-ogden": ("a", "b", "af", "bf", "as", "bs", "afs", "bfs"),
    "guccione": ("C", "bf", "bt", "bfs"),
    "neo-hookean": ("mu",),
}
#: Parameters with units of stress (kPa); used to scale the volumetric penalty.
MODULUS_KEYS = {"holzapfel-ogden": ("a", "af", "as", "afs"), "guccione": ("C",), "neo-hookean": ("mu",)}


def _expm1_over(a, b, x):
    """a/(2b) (e^{b x} − 1), accurate for small b x."""
    return a / (2.0 * b) * jnp.expm1(b * x)


def holzapfel_ogden(F, frame, params):
    """Holzapfel–Ogden energy density (kPa); see module docstring."""
    a, b, af, bf, as_, bs, afs, bfs = (params[i] for i in range(8))
    C = right_cauchy_green(F)
    f0, s0 = frame[0], frame[1]
    i4f = f0 @ C @ f0
    i4s = s0 @ C @ s0
    i8 = f0 @ C @ s0
    ef = jnp.where(i4f > 1.0, i4f - 1.0, 0.0)
    es = jnp.where(i4s > 1.0, i4s - 1.0, 0.0)
    return (
        _expm1_over(a, b, isochoric_i1(F) - 3.0)
        + _expm1_over(af, bf, ef * ef)
        + _expm1_over(as_, bs, es * es)
        + _expm1_over(afs, bfs, i8 * i8)
    )


def guccione(F, frame, params):
    """Guccione energy density (kPa) in fibre coordinates; see module docstring."""
    c, bf, bt, bfs = (params[i] for i in range(4))
    Fbar = F * det3(F) ** (-1.0 / 3.0)
    E = frame @ green_strain(Fbar) @ frame.T
    Q = (
        bf * E[0, 0] ** 2
        + bt * (E[1, 1] ** 2 + E[2, 2] ** 2 + 2.0 * E[1, 2] ** 2)
        + 2.0 * bfs * (E[0, 1] ** 2 + E[0, 2] ** 2)
    )
    return 0.5 * c * jnp.expm1(Q)


def neo_hookean(F, frame, params):
    """Isochoric neo-Hookean energy density (kPa): mu/2 (Ī1 − 3)."""
    return 0.5 * params[0] * (isochoric_i1(F) - 3.0)


LAWS = {"holzapfel-ogden": holzapfel_ogden, "guccione": guccione, "neo-hookean": neo_hookean}


def energy_function(law: str):
    """The energy density function of ``law`` (raises ValueError naming the choices)."""
    try:
        return LAWS[law]
    except KeyError:
        raise ValueError(f"unknown material law {law!r}; choose one of {sorted(LAWS)}") from None


def param_vector(law: str, params) -> np.ndarray:
    """Parameters as a float64 array in :data:`PARAM_ORDER` (HO fixed values filled in)."""
    p = dict(params)
    if law == "holzapfel-ogden":
        for k, v in units.HO_FIXED.items():
            p.setdefault(k, v)
    missing = [k for k in PARAM_ORDER[law] if k not in p]
    if missing:
        raise ValueError(f"material law {law!r} needs parameters {missing}")
    return np.array([float(p[k]) for k in PARAM_ORDER[law]], dtype=np.float64)


def modulus_scale(law: str, params) -> float:
    """A stiffness scale (kPa) of the law: the largest stress-like parameter."""
    p = dict(zip(PARAM_ORDER[law], param_vector(law, params)))
    return float(max(p[k] for k in MODULUS_KEYS[law]))
