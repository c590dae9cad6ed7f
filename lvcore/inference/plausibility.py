r"""Data plausibility: a posterior-predictive check of what the model can reach.

After calibration the posterior draws of the model outputs ``eta`` (the
forward model at each draw: LVV and 24 strains, *without* the GP discrepancy
of the discrepancy model) are compared with the data. Replicates are

    y_rep_0 = eta_0 + N(0, sigma_V^2),   y_rep_i = eta_i + N(0, sigma_ref^2)  (i = 1..24)

(with a forward model that carries the shape model's representation error, a mesh's floor or
``--geometry infer``, the likelihood's floor is added as everywhere else:
``y_rep_0 ~ N(eta_0, sigma_V^2 + (r_V eta_0)^2)``, strains ``~ MVN(eta, sigma_ref^2 I + Sigma_rep)``,
:func:`lvcore.inference.diagnostics.posterior_predictive` of the iid likelihood)
with ``sigma_V`` the model's fixed LVV noise and ``sigma_ref`` a *reference*
strain noise (:data:`DEFAULT_SIGMA_REF`: the posterior sigma_S of the eight
SYNTHETIC volunteers with their own geometry, 0.034, rounded up). The
inferred sigma_S is deliberately not used: it grows to absorb any misfit,
which is exactly how a wrong geometry or implausible strains went unnoticed
(an inflated sigma_S was the only symptom).

Per output the two-sided posterior-predictive p-value is
``p_i = 2 min(P(y_rep_i >= y_i), P(y_rep_i <= y_i))`` (Monte Carlo over draws,
floored at ``1 / (n_draws + 1)``). The data are flagged when

* the LVV has ``p < ALPHA`` (the model cannot reach the volume at any
  stiffness the strains allow),
* at least :data:`MIN_BAD_STRAINS` strains have ``p < ALPHA`` (volume and
  strains imply different stiffness, the wrong geometry, or strains in the
  wrong convention),
* strains have the sign opposite to the model's by more than
  ``2 sigma_ref`` (mixed signs: the model's filling strains are all negative),
* every strain is within ``sigma_ref`` of zero (no deformation measured).

The flags are warnings, never errors: the user decides.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lvcore.domain.outputs import OUTPUT_COLUMNS

#: Reference strain noise (Green strain) of the replicates.
DEFAULT_SIGMA_REF = 0.035
#: p-value below which an output counts as not reached.
ALPHA = 0.01
#: Number of strains with p < ALPHA that flags the data (a quarter of 24).
MIN_BAD_STRAINS = 6


@dataclass(frozen=True)
class PlausibilityCheck:
    """Posterior-predictive p-values per output and the resulting flags.

    Attributes
    ----------
    p_values : ndarray, shape (25,)
        Two-sided p-value of ``[LVV, strain_01..24]``.
    flags : tuple of str
        Human-readable reasons the data look implausible (empty if none).
    sigma_ref : float
    n_draws : int
    """

    p_values: np.ndarray
    flags: tuple = field(default=())
    sigma_ref: float = DEFAULT_SIGMA_REF
    n_draws: int = 0

    @property
    def plausible(self) -> bool:
        return not self.flags

    def record(self) -> dict:
        return {"plausible": self.plausible, "flags": list(self.flags), "sigma_ref": self.sigma_ref,
                "alpha": ALPHA, "n_draws": self.n_draws,
                "p_values": {c: float(p) for c, p in zip(OUTPUT_COLUMNS, self.p_values)}}


def posterior_predictive_check(y, eta_draws, sigma_v: float, sigma_ref: float = DEFAULT_SIGMA_REF,
                               seed: int = 0, forward=None) -> PlausibilityCheck:
    """Posterior-predictive p-values and plausibility flags (see the module docstring).

    Parameters
    ----------
    y : array_like, shape (25,)
        Measured ``[LVV (mL), 24 strains]``.
    eta_draws : array_like, shape (..., 25)
        Posterior draws of the model outputs (any leading chain/draw axes).
    sigma_v : float
        LVV noise sd (mL).
    sigma_ref : float
        Reference strain noise sd.
    forward : Forward, optional
        The forward model that ran; its representation floor (if any) widens the replicates.
    """
    from lvcore.inference.diagnostics import posterior_predictive

    y = np.asarray(y, float).reshape(-1)
    eta = np.asarray(eta_draws, float).reshape(-1, y.size)
    # the iid likelihood's replicates (its floor included), with sigma_S^2 fixed at the reference noise
    y_rep = posterior_predictive({"eta": eta, "sigma_s2": np.full(eta.shape[0], float(sigma_ref) ** 2)},
                                 float(sigma_v), np.random.default_rng(seed), forward, "iid")
    n = eta.shape[0]
    upper = (np.sum(y_rep >= y, axis=0) + 1) / (n + 1)
    lower = (np.sum(y_rep <= y, axis=0) + 1) / (n + 1)
    p = np.minimum(1.0, 2.0 * np.minimum(upper, lower))
    flags = []
    if p[0] < ALPHA:
        med = float(np.median(eta[:, 0]))
        flags.append(f"the volume is not reached: measured LVV {y[0]:.1f} mL, the calibrated model gives "
                     f"{med:.1f} mL (p = {p[0]:.2g}); volume and strains imply different stiffness, or the "
                     "geometry is not the subject's")
    bad = np.flatnonzero(p[1:] < ALPHA)
    if bad.size >= MIN_BAD_STRAINS:
        rmse = float(np.sqrt(np.mean((np.median(eta[:, 1:], axis=0) - y[1:]) ** 2)))
        flags.append(f"{bad.size} of 24 strains are not reached (p < {ALPHA:g}; strain RMSE {rmse:.3f} against a "
                     f"reference noise of {sigma_ref:g}): volume and strains imply different stiffness, the geometry "
                     "is not the subject's, or the strains use another convention (sign, reference state, segments)")
    eta_med = np.median(eta[:, 1:], axis=0)
    opposite = np.flatnonzero((np.sign(y[1:]) != np.sign(eta_med)) & (np.abs(y[1:]) > 2.0 * sigma_ref))
    if opposite.size:
        names = ", ".join(OUTPUT_COLUMNS[1 + i] for i in opposite[:6]) + (" ..." if opposite.size > 6 else "")
        flags.append(f"{opposite.size} strains have the sign opposite to every filling the model can produce "
                     f"({names}); mixed signs point to a sign or reference-state error in part of the data")
    if np.all(np.abs(y[1:]) < sigma_ref):
        flags.append(f"all 24 strains are within {sigma_ref:g} of zero: no filling deformation was measured "
                     "(missing data written as 0?)")
    return PlausibilityCheck(p_values=p, flags=tuple(flags), sigma_ref=float(sigma_ref), n_draws=int(n))


def check_result(result, y, sigma_v: float, sigma_ref: float = DEFAULT_SIGMA_REF, seed: int = 0,
                 forward=None) -> PlausibilityCheck:
    """:func:`posterior_predictive_check` on a :class:`~lvcore.inference.calibrate.CalibrationResult`
    (``forward``: the forward model that ran, for its representation floor)."""
    eta = np.asarray(result.idata.posterior["eta"])
    return posterior_predictive_check(y, eta, sigma_v, sigma_ref, seed, forward)


__all__ = ["DEFAULT_SIGMA_REF", "ALPHA", "MIN_BAD_STRAINS", "PlausibilityCheck", "posterior_predictive_check",
           "check_result"]
