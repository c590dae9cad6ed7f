r"""Polar Gaussian-process kernel for the strain discrepancy (chapter eq. 9.7).

The 24 circumferential strains live on a cylinder: sector angle
:math:`\gamma \in \{0, \pi/3, \dots, 5\pi/3\}` and short-axis level
:math:`z \in \{0, 1, 2, 3\}` (0 basal). Region ``r = 6 * level + sector`` has
``x_r = (sector * pi / 3, level)``, matching :mod:`lvcore.domain.outputs`.

The kernel is additive,

.. math::

    k((\gamma, z), (\gamma', z')) = \sigma_1^2 W_c(d(\gamma, \gamma'); c, \tau)
                                  + \sigma_2^2 k_z(z, z'; \lambda),

with the geodesic distance on the circle :math:`d = \arccos(\cos(\gamma - \gamma'))`
(radians, in :math:`[0, \pi]`), the Wendland-type polar kernel

.. math::

    W_c(t) = \left(1 + \tau \frac{t}{c}\right)\left(1 - \frac{t}{c}\right)_+^{\tau},

positive definite on the circle for :math:`\tau \ge 4` and :math:`0 < c \le \pi`,
and the squared-exponential :math:`k_z = \exp(-(z - z')^2 / (2 \lambda^2))`.

Because the kernel is a *sum* of a function of :math:`\gamma` alone and a
function of :math:`z` alone, its Gram matrix on the 6 x 4 grid has rank at most
6 + 4 - 1 = 9: draws of b are "sector profile + level profile". It is
positive semi-definite, not definite, so :func:`gram` adds a small absolute
nugget (default 1e-8, i.e. a standard deviation of 1e-4 in strain units, far
below MRI strain noise of about 0.03) before any Cholesky factorisation.

A variant beside it, the **product** (sector × level) kernel
:func:`polar_product_kernel`,

.. math::

    k((\gamma, z), (\gamma', z')) = \sigma^2 W_c(d(\gamma, \gamma'); c, \tau)\, k_z(z, z'; \lambda),

has on the grid the Gram matrix :math:`\sigma^2 K_z \otimes W` (levels × sectors),
of full rank 24 whenever :math:`W` (6 × 6, positive definite for
:math:`\tau \ge 4`, :math:`0 < c \le \pi`) and :math:`K_z` (4 × 4, distinct
levels) are: it can represent a sector × level interaction, which the
additive kernel cannot. ``gram(hyper, kind="product")`` builds it (``hyper``:
``sigma1_sq`` is its variance σ², ``sigma2_sq`` is not used).

The discrepancy model takes either: the chapter's additive kernel is the default everywhere;
``kind="product"`` reaches :func:`lvcore.inference.models.discrepancy_cholesky`, the numpyro model
:func:`lvcore.inference.models.discrepancy_model` (``kernel=``), the blocked sampler
:class:`lvcore.inference.gibbs.PolarGPGibbs` (``kernel=``) and, through
:class:`lvcore.inference.sampler_config.SamplerConfig` ``discrepancy_kernel``, ``lvcore calibrate
--discrepancy-kernel product`` and ``lvcore study mismatch --discrepancy-kernel product``. With the product
kernel the GP has no ``sigma2_sq`` (:func:`lvcore.inference.models.hyper_priors`).
"""
from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from lvcore.geometry.template import N_LEVELS, N_REGIONS, N_SECTORS

#: Default absolute nugget added to the Gram diagonal (strain² units).
DEFAULT_NUGGET = 1e-8


def strain_grid() -> np.ndarray:
    """Locations ``x_r = (gamma, z)`` of the 24 strain regions, shape (24, 2).

    Row ``r = 6 * level + sector`` holds ``(sector * pi / 3, level)``;
    gamma in radians, z the level index (0 basal ... 3 apical).
    """
    r = np.arange(N_REGIONS)
    sector = r % N_SECTORS
    level = r // N_SECTORS
    return np.stack([sector * (2.0 * np.pi / N_SECTORS), level.astype(float)], axis=1)


def geodesic_distance(gamma1, gamma2):
    """Geodesic distance on the unit circle, ``arccos(cos(gamma1 - gamma2))`` in [0, pi] (rad)."""
    cosd = jnp.clip(jnp.cos(jnp.asarray(gamma1) - jnp.asarray(gamma2)), -1.0, 1.0)
    return jnp.arccos(cosd)


def wendland_polar(t, c, tau):
    r"""Wendland-type polar correlation :math:`W_c(t) = (1 + \tau t/c)(1 - t/c)_+^\tau`.

    Parameters
    ----------
    t : array_like
        Geodesic distance (rad), >= 0.
    c : float
        Compact-support radius (rad), ``0 < c <= pi``; ``W_c(t) = 0`` for ``t >= c``.
    tau : float
        Smoothness/shape exponent; positive definite on the circle for ``tau >= 4``.
    """
    r = jnp.asarray(t) / c
    base = jnp.clip(1.0 - r, 0.0, None)
    return (1.0 + tau * r) * base**tau


def squared_exponential(z1, z2, lengthscale):
    """Squared-exponential correlation ``exp(-(z1 - z2)**2 / (2 lengthscale**2))`` (levels)."""
    dz = jnp.asarray(z1) - jnp.asarray(z2)
    return jnp.exp(-0.5 * (dz / lengthscale) ** 2)


def _sector_and_level_factors(x1, x2, c, tau, lengthscale):
    """The two factors of the polar kernels between point sets ``(gamma [rad], z [level])``: the Wendland
    function of the geodesic sector distance and the squared exponential in level, each shape (n, m)."""
    x1 = jnp.asarray(x1)
    x2 = jnp.asarray(x2)
    d = geodesic_distance(x1[:, None, 0], x2[None, :, 0])
    return wendland_polar(d, c, tau), squared_exponential(x1[:, None, 1], x2[None, :, 1], lengthscale)


def polar_kernel(x1, x2, *, sigma1_sq, sigma2_sq, c, tau, lengthscale):
    r"""Additive polar kernel :math:`\sigma_1^2 W_c(d) + \sigma_2^2 k_z` between point sets.

    Parameters
    ----------
    x1, x2 : array_like, shape (n, 2) and (m, 2)
        Points ``(gamma [rad], z [level])``.
    sigma1_sq, sigma2_sq : float
        Signal variances of the polar and z components (strain²).
    c, tau : float
        Wendland support (rad) and exponent.
    lengthscale : float
        SE length scale in z (levels), the chapter's lambda.

    Returns
    -------
    jax.Array, shape (n, m)
    """
    w, kz = _sector_and_level_factors(x1, x2, c, tau, lengthscale)
    return sigma1_sq * w + sigma2_sq * kz


def polar_product_kernel(x1, x2, *, sigma_sq, c, tau, lengthscale):
    r"""Product (sector × level) polar kernel :math:`\sigma^2 W_c(d)\, k_z` between point sets.

    Parameters
    ----------
    x1, x2 : array_like, shape (n, 2) and (m, 2)
        Points ``(gamma [rad], z [level])``.
    sigma_sq : float
        Signal variance (strain²).
    c, tau : float
        Wendland support (rad) and exponent.
    lengthscale : float
        SE length scale in z (levels).

    Returns
    -------
    jax.Array, shape (n, m)
    """
    w, kz = _sector_and_level_factors(x1, x2, c, tau, lengthscale)
    return sigma_sq * w * kz


#: Kernel forms :func:`gram` builds: the chapter's additive one and the product variant.
KERNEL_KINDS = ("additive", "product")


def gram(hyper, x=None, nugget: float = DEFAULT_NUGGET, kind: str = "additive"):
    """Gram matrix on the strain grid plus ``nugget * I`` (strain²), shape (24, 24).

    Parameters
    ----------
    hyper : mapping
        Keys ``sigma1_sq, sigma2_sq, c, tau, lam`` (lam = SE length scale in levels); the product kernel uses
        ``sigma1_sq`` as its variance and ignores ``sigma2_sq``.
    x : array_like, optional
        Points; default :func:`strain_grid`.
    nugget : float
        Absolute diagonal jitter (strain²); see the module docstring for why.
    kind : {"additive", "product"}
        The chapter's additive kernel (default) or the product variant.
    """
    if kind not in KERNEL_KINDS:
        raise ValueError(f"kernel kind must be one of {KERNEL_KINDS}, got {kind!r}")
    x = strain_grid() if x is None else x
    if kind == "product":
        k = polar_product_kernel(x, x, sigma_sq=hyper["sigma1_sq"], c=hyper["c"], tau=hyper["tau"],
                                 lengthscale=hyper["lam"])
    else:
        k = polar_kernel(
            x, x,
            sigma1_sq=hyper["sigma1_sq"], sigma2_sq=hyper["sigma2_sq"],
            c=hyper["c"], tau=hyper["tau"], lengthscale=hyper["lam"],
        )
    return k + nugget * jnp.eye(k.shape[0])


def gram_cholesky(hyper, x=None, nugget: float = DEFAULT_NUGGET, kind: str = "additive"):
    """Lower Cholesky factor L of :func:`gram` (``K = L L^T``) of the kernel ``kind``."""
    return jnp.linalg.cholesky(gram(hyper, x, nugget, kind))


__all__ = [
    "DEFAULT_NUGGET", "strain_grid", "geodesic_distance", "wendland_polar",
    "squared_exponential", "polar_kernel", "polar_product_kernel", "KERNEL_KINDS", "gram", "gram_cholesky",
    "N_LEVELS",
]
