r"""Likelihood terms beyond one loaded state: further loaded states and the Klotz EDPVR prior.

With one pressure, 24 strains and one volume, the stiffness parameters a and b
are fixed only as a combination. Two sources of information pin them further:

Several loaded states (:class:`StateTerm`)
    Each further (pressure, volume[, strains]) measurement of the subject adds
    ``LVV_k ~ N(eta_0(theta; EDP_k), sd_V^2)`` and, when the state has strains
    and the model has a strain likelihood, ``strains_k ~ (the model's strain
    likelihood at eta(theta; EDP_k))``. The likelihood is the sum over states:
    the states' noise is independent, theta and the geometry are shared. The
    discrepancy model adds its one discrepancy ``b + v`` to every state's
    strains (a shape-model error that does not change with pressure).
    Needs a forward model with an EDP input (the ``angles`` emulator, a
    subject emulator built with ``--inputs theta,edp``).

The Klotz prior (:class:`KlotzPrior`, ``lvcore calibrate --prior klotz``)
    Klotz et al. (2006), Am J Physiol Heart Circ Physiol 291:H403-H412: the
    normalised EDPVR of human hearts, ``EDP = An EDVn^Bn`` with
    ``EDVn = (V - V0)/(V30 - V0)``, An = 27.78 mmHg, Bn = 2.76
    (:mod:`lvcore.domain.physiology`). Their single-beat prediction of the volume at
    pressure p from one point (EDP, EDV) and V0 is

    .. math:: V_p = V_0 + (EDV - V_0)\,\frac{EDVn(p)}{EDVn(EDP)}
              = V_0 + (EDV - V_0)\,(p/EDP)^{1/B_n}

    (:func:`lvcore.domain.physiology.klotz_volume` through :func:`lvcore.domain.physiology.klotz_v30`; the curve's own
    normalising "V30", where EDVn = 1, lies at An = 27.78 mmHg on the fit, so the volume at 30 mmHg is
    2.8 % of the rise above it higher; the term uses the volumes at 20 and 30 mmHg on the curve).

    The term is ``(V20, V30)_model ~ N((V20, V30)_Klotz, C)`` on the model's own
    volumes at 20 and 30 mmHg (the emulator evaluated there), with
    ``(V20, V30)_Klotz`` predicted from the model's EDV at the measured EDP
    (which the volume likelihood ties to the measured EDV with sd_V; putting
    the measured EDV itself there would count its noise twice) and the
    model's V0, the reference (stress-free) cavity volume: fixed by a mesh,
    PC scores or a subject emulator's geometry, sampled with ``--geometry infer``.
    ``C = sd_Bn^2 g g^T + diag((r (V_p - V0))^2)``: the population scatter of
    the exponent (``g = dV_p/dBn``, linearised at Klotz's Bn) and an
    independent share of the rise above V0 for curves that are not exact
    power laws. The values (:data:`KLOTZ_BN_SD`, :data:`KLOTZ_RESIDUAL_REL_SD`)
    are this package's conservative choice: the references available when it
    was written did not give the paper's reported scatter of An and Bn
    (docs/calibration.md says so). Needs a forward model whose EDP input
    covers 20 and 30 mmHg; no bundled emulator does (``angles``: 6-14 mmHg),
    so a subject emulator built with ``--inputs theta,edp --bound edp=6,30``
    is the route; emulators are never extrapolated for it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import jax.numpy as jnp
import numpy as np

from lvcore.domain import physiology
from lvcore.exceptions import DataError

#: Pressures (mmHg) of the Klotz prior's volumes.
KLOTZ_PRESSURES_MMHG = (20.0, 30.0)
#: Population sd of the Klotz exponent Bn (dimensionless): this package's conservative choice, 0.5 = 18 % of 2.76
#: (the paper's own scatter of An and Bn was not available to us; docs/calibration.md).
KLOTZ_BN_SD = 0.5
#: Independent sd of V20 and V30 as a share of their rise above V0 (deviation from a pure power law).
KLOTZ_RESIDUAL_REL_SD = 0.05
#: Prior names of ``--prior``.
PRIOR_NAMES = ("none", "klotz")


@dataclass(frozen=True, eq=False)
class StateTerm:
    """One further loaded state in the likelihood.

    Attributes
    ----------
    forward : TraceableForward
        The subject's forward model at this state's EDP (same inputs and geometry as the primary).
    y : ndarray, shape (25,)
        Measured ``[LVV (mL), 24 strains]``; NaN strains when the state has none.
    edp_mmhg : float
    """

    forward: Any
    y: np.ndarray
    edp_mmhg: float

    @property
    def has_strains(self) -> bool:
        return bool(np.all(np.isfinite(np.asarray(self.y)[1:])))


@dataclass(frozen=True, eq=False)
class KlotzPrior:
    """The Klotz et al. (2006) EDPVR as a likelihood term on the model's V20 and V30 (module docstring).

    Attributes
    ----------
    forward_by_pressure : tuple of TraceableForward
        The subject's forward model at each of :data:`KLOTZ_PRESSURES_MMHG`.
    edp_mmhg : float
        The primary state's (measured) EDP, where the single-beat prediction is anchored.
    v0_ml : float or None
        Fixed reference cavity volume V0 (mL); None when ``v0_fn`` gives it from the parameters.
    v0_fn : callable or None
        ``v0_fn(params) -> V0`` (mL), traceable (``--geometry infer``).
    bn_sd, residual_rel_sd : float
        :data:`KLOTZ_BN_SD`, :data:`KLOTZ_RESIDUAL_REL_SD`.
    """

    forward_by_pressure: tuple
    edp_mmhg: float
    v0_ml: float | None = None
    v0_fn: Callable | None = None
    bn_sd: float = KLOTZ_BN_SD
    residual_rel_sd: float = KLOTZ_RESIDUAL_REL_SD
    pressures_mmhg: tuple = KLOTZ_PRESSURES_MMHG

    def __post_init__(self):
        if (self.v0_ml is None) == (self.v0_fn is None):
            raise ValueError("give V0 as a number (v0_ml) or a function of the parameters (v0_fn), not both")
        if not self.edp_mmhg > 0:
            raise DataError(f"--prior klotz needs the measured EDP > 0 mmHg, got {self.edp_mmhg:g}")
        if len(self.forward_by_pressure) != len(self.pressures_mmhg):
            raise ValueError("one forward model per Klotz pressure")

    def ratios(self) -> np.ndarray:
        """``EDVn(p)/EDVn(EDP)`` at the prior's pressures (Klotz's normalised curve, :func:`lvcore.domain.physiology.klotz_edvn`)."""
        return np.asarray([float(physiology.klotz_edvn(p) / physiology.klotz_edvn(self.edp_mmhg))
                           for p in self.pressures_mmhg])

    def v0(self, params):
        """V0 (mL) at ``params``."""
        return self.v0_ml if self.v0_fn is None else self.v0_fn(params)

    def target(self, edv_ml, v0_ml):
        """Klotz's single-beat volumes (mL) at :attr:`pressures_mmhg` through (EDP, ``edv_ml``) and ``v0_ml``."""
        return v0_ml + (edv_ml - v0_ml) * jnp.asarray(self.ratios())

    def covariance(self, edv_ml, v0_ml):
        """Covariance (mL²) of the prior's volumes: the Bn scatter (linearised) plus the independent residual."""
        r = jnp.asarray(self.ratios())
        logs = jnp.asarray([math.log(p / self.edp_mmhg) for p in self.pressures_mmhg])
        rise = (edv_ml - v0_ml) * r
        g = rise * logs / physiology.KLOTZ_BN ** 2
        return self.bn_sd ** 2 * jnp.outer(g, g) + jnp.diag((self.residual_rel_sd * rise) ** 2 + 1e-6)

    def volumes(self, params):
        """The model's volumes (mL) at :attr:`pressures_mmhg`."""
        return jnp.stack([fw(params)[0] for fw in self.forward_by_pressure])

    def log_density(self, params, edv_ml):
        """The term's log density at ``params`` given the model's EDV at the measured EDP."""
        import numpyro.distributions as dist

        v0 = self.v0(params)
        return dist.MultivariateNormal(self.target(edv_ml, v0),
                                       covariance_matrix=self.covariance(edv_ml, v0)).log_prob(self.volumes(params))

    def record(self, measured_edv_ml: float | None = None, v0_ml: float | None = None) -> dict:
        """JSON-ready description (summary.json's ``prior``)."""
        rec = {"name": "klotz",
               "reference": "Klotz et al. (2006), Am J Physiol Heart Circ Physiol 291:H403-H412",
               "curve": f"EDP = {physiology.KLOTZ_AN_MMHG:g} * EDVn^{physiology.KLOTZ_BN:g}, EDVn = (V - V0)/(V30 - V0)",
               "pressures_mmhg": list(self.pressures_mmhg), "anchored_at_edp_mmhg": float(self.edp_mmhg),
               "bn_sd": float(self.bn_sd), "residual_rel_sd": float(self.residual_rel_sd),
               "v0": "inferred with the geometry" if self.v0_fn is not None else "the geometry's reference cavity",
               "scatter_source": "this package's conservative choice (the paper's reported scatter was not available)"}
        if self.v0_ml is not None:
            rec["v0_ml"] = float(self.v0_ml)
        if measured_edv_ml is not None and (v0_ml if v0_ml is not None else self.v0_ml) is not None:
            v0 = float(v0_ml if v0_ml is not None else self.v0_ml)
            rec["single_beat_from_measured_ml"] = {f"V{p:g}": float(v) for p, v in
                                                  zip(self.pressures_mmhg, np.asarray(self.target(measured_edv_ml, v0)))}
        return rec


@dataclass(frozen=True, eq=False)
class LoadedStatesForward:
    """A subject's forward model (its primary loaded state) with further likelihood terms.

    Calls, attributes (``input_names``, ``input_bounds``, ``sample_latents``, ``representation``, ...) and the
    outputs ``(25,)`` are those of the primary state's forward model, so everything that reads one state (the
    verdict's fit check, posterior predictive, derived quantities) reads the primary one; the numpyro models of
    :mod:`lvcore.inference.models` add :meth:`likelihood_terms`.

    Attributes
    ----------
    forward : TraceableForward
        The primary state's forward model.
    states : tuple of StateTerm
        The further loaded states.
    klotz : KlotzPrior or None
    """

    forward: Any
    states: tuple = ()
    klotz: KlotzPrior | None = None

    def __post_init__(self):
        names = tuple(self.forward.input_names)
        for st in self.states:
            if tuple(st.forward.input_names) != names:
                raise ValueError(f"a loaded state's forward model reads {st.forward.input_names}, the primary {names}")

    def __call__(self, params):
        return self.forward(params)

    def __getattr__(self, name):
        if name.startswith("__") or name in ("forward", "states", "klotz"):
            raise AttributeError(name)
        return getattr(self.forward, name)

    @property
    def input_names(self):
        return self.forward.input_names

    @property
    def input_bounds(self):
        return self.forward.input_bounds

    @property
    def label(self) -> str:
        extra = [f"{len(self.states) + 1} loaded states"] if self.states else []
        extra += ["Klotz EDPVR prior"] if self.klotz is not None else []
        return f"{self.forward.label} ({', '.join(extra)})" if extra else self.forward.label

    def state_outputs(self, params):
        """The further states' outputs, shape ``(n_states - 1, 25)``."""
        return jnp.stack([st.forward(params) for st in self.states])

    def likelihood_terms(self, params, eta, *, sigma_v: float, sigma_s2=None, strain_offset=0.0,
                         strain_floor: bool = True) -> None:
        """numpyro sites of the further states (``lvv_obs_state<k>``, ``strain_obs_state<k>``) and of the Klotz prior.

        Parameters
        ----------
        params : dict
            The sampled parameters (theta, angles, latent geometry).
        eta : array (25,)
            The primary state's outputs.
        sigma_v : float
            LVV noise sd (mL).
        sigma_s2 : array or None
            Strain noise variance; None for the volume-only model (strains not modelled).
        strain_offset : array
            Added to every state's strain mean (the discrepancy model's ``b + v``).
        strain_floor : bool
            Widen the states' strains by the representation error, if the forward model carries one; False
            where ``strain_offset`` already holds it (the discrepancy model's b, shared by every state).
        """
        import numpyro
        import numpyro.distributions as dist

        from lvcore.inference.models import lvv_sd, strain_likelihood

        if self.states:
            etas = numpyro.deterministic("eta_states", self.state_outputs(params))
            for k, st in enumerate(self.states, start=2):
                e = etas[k - 2]
                y = jnp.asarray(st.y, dtype=jnp.float64)
                numpyro.sample(f"lvv_obs_state{k}", dist.Normal(e[0], lvv_sd(e[0], sigma_v, self.forward)), obs=y[0])
                if sigma_s2 is not None and st.has_strains:
                    floored = self.forward if strain_floor else None
                    numpyro.sample(f"strain_obs_state{k}", strain_likelihood(e[1:] + strain_offset, sigma_s2,
                                                                             floored), obs=y[1:])
        if self.klotz is not None:
            vols = numpyro.deterministic("klotz_volumes", self.klotz.volumes(params))
            numpyro.deterministic("klotz_v0", jnp.asarray(self.klotz.v0(params), dtype=jnp.float64))
            numpyro.factor("klotz_prior", self.klotz.log_density(params, eta[0]))
            del vols


def has_extra_terms(forward) -> bool:
    """True when ``forward`` carries further loaded states or the Klotz prior (the blocked sampler cannot)."""
    return isinstance(forward, LoadedStatesForward) and (bool(forward.states) or forward.klotz is not None)


def check_edp_input(emulator, name: str, what: str) -> None:
    """Refuse (DataError, exit 2) ``what`` for an emulator trained at a fixed EDP.

    Raises
    ------
    DataError
        Naming the emulator, its fixed EDP and the emulators that take one.
    """
    from lvcore.domain.outputs import EDP_NAME

    if EDP_NAME in tuple(emulator.input_names):
        return
    fixed = dict(getattr(emulator, "fixed", None) or {}).get(EDP_NAME)
    at = f" of {float(fixed):g} mmHg" if fixed is not None else ""
    raise DataError(f"{what} needs an emulator with an EDP input; '{name}' was trained at a fixed EDP{at}. Use "
                    "--emulator angles (EDP 6-14 mmHg), --emulator edpvr (EDP 1-30 mmHg, fibre angles -60/60 deg) or a "
                    "subject emulator built with `lvcore emulator build --inputs theta,edp` (its --bound edp=LO,HI "
                    "sets the pressures it covers)")


def edp_box(emulator) -> tuple[float, float]:
    """The EDP range (mmHg) of an emulator's training box."""
    from lvcore.domain.outputs import EDP_NAME

    names = tuple(emulator.input_names)
    i = names.index(EDP_NAME)
    return float(emulator.lower[i]), float(emulator.upper[i])


def check_klotz_pressures(emulator, name: str, pressures: Sequence[float] = KLOTZ_PRESSURES_MMHG) -> None:
    """Refuse ``--prior klotz`` (DataError) unless the emulator's EDP box covers the prior's pressures."""
    check_edp_input(emulator, name, "--prior klotz")
    lo, hi = edp_box(emulator)
    out = [p for p in pressures if not lo <= p <= hi]
    if out:
        raise DataError(f"--prior klotz puts its term on the model's volumes at {', '.join(f'{p:g}' for p in pressures)} "
                        f"mmHg, but the '{name}' emulator covers EDP {lo:g}-{hi:g} mmHg ({', '.join(f'{p:g}' for p in out)} "
                        "outside; an emulator is never extrapolated for the prior). Use --emulator edpvr (EDP 1-30 mmHg, "
                        "PC scores or --geometry infer) or build a subject emulator that covers them: `lvcore "
                        "emulator build --geometry FILE --inputs theta,edp --bound edp=6,30`")


def reference_volume_ml(geometry_section: dict) -> float:
    """Reference (stress-free) cavity volume V0 (mL) of a case's geometry section, as the simulator meshes it."""
    from lvcore.domain import conditions, units
    from lvcore.mechanics.case import Case
    from lvcore.mechanics.simulate import prepare_case

    case = Case.from_dict({"geometry": dict(geometry_section),
                           "material": {"law": "holzapfel-ogden", **conditions.THETA_TILDE},
                           "load": {"pressure": 8, "units": "mmHg"}})
    return float(prepare_case(case).v_ref) / units.MM3_PER_ML


__all__ = ["KLOTZ_PRESSURES_MMHG", "KLOTZ_BN_SD", "KLOTZ_RESIDUAL_REL_SD", "PRIOR_NAMES", "StateTerm", "KlotzPrior",
           "LoadedStatesForward", "has_extra_terms", "check_edp_input", "edp_box", "check_klotz_pressures",
           "reference_volume_ml"]
