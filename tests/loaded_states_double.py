"""A SYNTHETIC pressure-dependent stand-in forward model for the loaded-state and Klotz-prior tests (not a heart).

With ``u = log(theta / (0.6, 5, 1.5, 5))``:
``LVV(p) = V0 + 70 exp(-0.4 (u_a + u_b)) (p / 8)^e``, ``e = exp(-0.5 u_b) / 2.76``, p in mmHg: a power law in
the pressure, so at b = 5 (exponent 1/Bn with Klotz's Bn = 2.76) the truth follows the Klotz et al. (2006)
curve through V0 for any a. At 8 mmHg the volume fixes only ``u_a + u_b`` (a and b trade off along a ridge);
a second pressure fixes the exponent, hence b and then a. The strains are those of
:class:`lvcore.testing.analytic.AnalyticForward` times ``(p / 8)^0.5``.
"""
from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp

from lvcore.core.forward import JaxForward
from lvcore.domain.outputs import THETA_NAMES
from lvcore.testing.analytic import AnalyticForward


@dataclass(frozen=True)
class PowerLawForward(JaxForward):
    """SYNTHETIC stand-in at one pressure ``edp_mmhg``; ``v0_ml`` its reference volume (module docstring)."""

    edp_mmhg: float = 8.0
    v0_ml: float = 80.0
    input_names: tuple = THETA_NAMES
    label: str = "power-law stand-in (SYNTHETIC, tests only)"

    @property
    def input_bounds(self) -> dict:
        return {}

    def __call__(self, params):
        ua = jnp.log(jnp.asarray(params["a"]) / 0.6)
        ub = jnp.log(jnp.asarray(params["b"]) / 5.0)
        e = jnp.exp(-0.5 * ub) / 2.76
        lvv = self.v0_ml + 70.0 * jnp.exp(-0.4 * (ua + ub)) * (self.edp_mmhg / 8.0) ** e
        strains = AnalyticForward()(params)[1:] * (self.edp_mmhg / 8.0) ** 0.5
        return jnp.concatenate([lvv[None], strains])


def at(edp_mmhg: float, v0_ml: float = 80.0) -> PowerLawForward:
    return PowerLawForward(edp_mmhg=float(edp_mmhg), v0_ml=float(v0_ml))
