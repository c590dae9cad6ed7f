"""A SYNTHETIC closed-form forward model for tests and benchmarks only (not a model of the heart).

:class:`AnalyticForward` is a :class:`~lvcore.core.forward.TraceableForward`
(pure JAX, microseconds per point): campaigns, optimisers, samplers and
studies are tested on it where the simulator or an emulator would be too
slow or would hide a bug in the method.
"""
from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from lvcore.core.forward import JaxForward
from lvcore.domain.outputs import ANGLE_NAMES, THETA_NAMES


def _analytic_matrix() -> np.ndarray:
    """Fixed smooth loading of the 4 log-parameters onto the 24 regions (deterministic)."""
    r = np.arange(24)
    gamma = (r % 6) * np.pi / 3
    z = (r // 6) / 3.0
    return np.stack([
        1.0 + 0.3 * z,
        0.6 + 0.4 * np.cos(gamma),
        0.8 * np.sin(gamma + 0.5) + 0.3 * z,
        0.5 - 0.6 * z + 0.3 * np.cos(2 * gamma),
    ], axis=1)


@dataclass(frozen=True)
class AnalyticForward(JaxForward):
    """SYNTHETIC closed-form stand-in forward model, for tests and benchmarks only.

    Smooth, differentiable and identifiable from 25 noisy outputs; it is not a
    model of the heart. With ``u = log(theta / theta_ref)``:
    ``LVV = 140 - 25 tanh(0.5 u_a + 0.3 u_b + 0.3 u_af + 0.2 u_bf)`` (mL) and
    ``strain_r = -0.15 + 0.04 sum_j M_rj u_j + 0.004 |u|^2`` with ``M`` a fixed
    smooth map over (sector, level). If ``alpha_endo``/``alpha_epi`` are in
    ``input_names`` they shift the strains linearly, by 0.02 per 30 degrees
    times fixed sector (alpha_endo) and level (alpha_epi) patterns that no
    change of theta can mimic.
    """

    theta_ref: tuple[float, float, float, float] = (0.6, 5.0, 1.5, 5.0)
    input_names: tuple[str, ...] = THETA_NAMES
    label: str = "analytic stand-in (SYNTHETIC, tests only)"

    @property
    def input_bounds(self) -> dict:
        return {}

    def __call__(self, params):
        u = jnp.stack([jnp.log(jnp.asarray(params[n]) / r) for n, r in zip(THETA_NAMES, self.theta_ref)])
        lvv = 140.0 - 25.0 * jnp.tanh(0.5 * u[0] + 0.3 * u[1] + 0.3 * u[2] + 0.2 * u[3])
        m = jnp.asarray(_analytic_matrix())
        strains = -0.15 + 0.04 * (m @ u) + 0.004 * jnp.sum(u**2)
        if ANGLE_NAMES[0] in self.input_names:
            r = jnp.arange(24)
            zz = (r // 6) / 3.0
            gg = (r % 6) * jnp.pi / 3
            # patterns orthogonal to every column of M and to a constant, so the angles are identifiable
            endo_pattern = jnp.sin(2.0 * gg)                 # sectors
            epi_pattern = 9.0 * (zz - 0.5) ** 2 - 1.25       # levels: +1, -1, -1, +1
            strains = strains + 0.02 * (params["alpha_endo"] + 60.0) / 30.0 * endo_pattern \
                + 0.02 * (params["alpha_epi"] - 60.0) / 30.0 * epi_pattern
        return jnp.concatenate([lvv[None], strains])


__all__ = ["AnalyticForward"]
