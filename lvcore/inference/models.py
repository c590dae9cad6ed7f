r"""numpyro models for calibrating theta = (a, b, af, bf) from LVV and 24 strains.

Each model is a plain function of the measured data ``y`` (25 values: LVV in
mL then 24 circumferential strains, :mod:`lvcore.domain.outputs` order) and a
JAX-traceable forward model (a :class:`lvcore.core.TraceableForward`, e.g.
:class:`lvcore.emulator.EmulatorForward`). Priors follow
the chapter's Table 9.1 and live in :data:`PRIORS` so that the blocked
HMC-within-Gibbs sampler uses the very same densities.

Models
------
(i) :func:`volume_model` — LVV only: ``y0 ~ N(eta0, sigma_V^2)``, sigma_V fixed
    (:data:`lvcore.core.space.SIGMA_V_ML`, 5 mL).
(ii) :func:`iid_model` — LVV term plus ``y_i ~ N(eta_i, sigma_S^2)`` iid,
    ``sigma_S^2 ~ IG(0.001, 0.001)``.
(iii) :func:`discrepancy_model` — LVV term plus
    ``y_i ~ N(eta_i + b_i + v, sigma_S^2)``, ``b = L b_tilde`` a whitened GP
    with the polar kernel of :mod:`lvcore.inference.kernels`,
    ``v ~ N(0, 0.05^2)``, ``lambda ~ Gamma(2, 2)``,
    ``sigma_1^2, sigma_2^2 ~ IG(0.001, 0.001)``, ``c ~ U(0, pi)``, ``tau ~ U(4, 10)``.
    ``kernel="product"`` swaps the chapter's additive kernel for the product (sector × level) one,
    ``sigma_1^2 W_c k_z`` (:func:`lvcore.inference.kernels.polar_product_kernel`), whose GP has no
    ``sigma_2^2``: :func:`hyper_priors` of that kind leaves it out, so it is not sampled.

A forward model that carries the shape model's representation error (a mesh's floor,
:class:`lvcore.inference.representation_error.FlooredForward`, or ``--geometry infer``) widens every model:
the LVV sd becomes :func:`lvv_sd`; the iid strains become ``MVN(eta, sigma_S^2 I + Sigma_rep)``
(:func:`strain_likelihood`); in the discrepancy model ``Sigma_rep`` is a known part of the discrepancy,
``b ~ N(0, K + Sigma_rep)`` (:func:`discrepancy_cholesky`), the strains staying ``N(eta + b + v, sigma_S^2)``:
the same distribution of the data given (theta, sigma_S^2, GP hyperparameters, v), with ``sigma_S^2``
conjugate, so joint NUTS and the blocked sampler (:class:`lvcore.inference.gibbs.PolarGPGibbs`) state one
model and ``disc`` means the same in both.

A forward model that carries further likelihood terms (several loaded states of the subject, the
Klotz EDPVR prior: :class:`lvcore.inference.loaded_states.LoadedStatesForward`) adds them to
each model through :func:`extra_terms`; the volume-only model reads only the states' volumes.

With ``infer_angles=True`` the fibre angles get uniform priors
``alpha_endo ~ U(-90, 0)``, ``alpha_epi ~ U(0, 90)`` (degrees) and are passed
to the forward model (which must accept them).
"""
from __future__ import annotations

import math

import jax.numpy as jnp
import numpyro
import numpyro.distributions as dist

from lvcore.domain.conditions import SIGMA_V_ML
from lvcore.core.forward import TraceableForward
from lvcore.core.space import ANGLE_BOUNDS, THETA_BOUNDS  # Table 9.1 and the angle ranges
from lvcore.exceptions import ForwardError
from lvcore.inference import kernels
from lvcore.domain.outputs import ANGLE_NAMES, N_OUTPUTS, THETA_NAMES
#: Inverse-gamma (shape, scale) of every variance prior.
IG_SHAPE, IG_SCALE = 0.001, 0.001
#: Standard deviation of the global strain bias v.
V_SD = 0.05
#: GP hyperparameter names of the chapter's additive kernel, in a fixed order (:func:`hyper_names` per kernel).
HYPER_NAMES = ("lam", "sigma1_sq", "sigma2_sq", "c", "tau")
#: The discrepancy model's kernels (:data:`lvcore.inference.kernels.KERNEL_KINDS`); the first, the chapter's, is
#: the default everywhere.
KERNEL_KINDS = kernels.KERNEL_KINDS
DEFAULT_KERNEL = "additive"
MODEL_NAMES = ("volume", "iid", "discrepancy")
#: How the likelihood models are named wherever a user reads them (app, report, study figures).
MODEL_LABELS = {"volume": "(i) volume only", "iid": "(ii) iid strains", "discrepancy": "(iii) polar-GP discrepancy"}


def prior_bounds(infer_angles: bool = False, forward=None) -> dict[str, tuple[float, float]]:
    """Bounds of the uniform priors: Table 9.1 (and :data:`ANGLE_BOUNDS`), narrowed to the
    forward model's valid box.

    Parameters
    ----------
    infer_angles : bool
        Include the fibre angles (degrees).
    forward : Forward, optional
        Each prior is cut to its intersection with the forward model's
        ``input_bounds`` (an emulator's training box, see
        :class:`lvcore.emulator.EmulatorForward`): the ``angles`` emulator, for
        one, is trained on b, bf >= 0.5 only.

    Raises
    ------
    ValueError
        If a parameter's prior and the forward model's box do not overlap.
    """
    bounds = {n: THETA_BOUNDS[n] for n in THETA_NAMES}
    if infer_angles:
        bounds.update({n: ANGLE_BOUNDS[n] for n in ANGLE_NAMES})
    for n, (lo, hi) in (dict(forward.input_bounds) if forward is not None else {}).items():
        if n in bounds:
            cut = (max(bounds[n][0], lo), min(bounds[n][1], hi))
            if not cut[0] < cut[1]:
                raise ValueError(f"the prior of '{n}' {bounds[n]} and the forward model's box [{lo}, {hi}] do not overlap")
            bounds[n] = cut
    return bounds


def theta_priors(infer_angles: bool = False, forward=None) -> dict:
    """Uniform priors of the forward-model parameters over :func:`prior_bounds`."""
    return {n: dist.Uniform(*b) for n, b in prior_bounds(infer_angles, forward).items()}


def sigma_s2_prior():
    """``sigma_S^2 ~ IG(0.001, 0.001)`` (strain²)."""
    return dist.InverseGamma(IG_SHAPE, IG_SCALE)


def check_kernel(kind: str) -> str:
    """``kind`` if it is one of :data:`KERNEL_KINDS`, else a ValueError naming them."""
    if kind not in KERNEL_KINDS:
        raise ValueError(f"discrepancy kernel must be one of {KERNEL_KINDS}, got {kind!r}")
    return kind


def hyper_names(kind: str = DEFAULT_KERNEL) -> tuple:
    """The GP hyperparameters the discrepancy model samples with kernel ``kind``: :data:`HYPER_NAMES` for the
    additive kernel, the same less ``sigma2_sq`` for the product kernel (its one variance is ``sigma1_sq``)."""
    check_kernel(kind)
    return HYPER_NAMES if kind == "additive" else tuple(n for n in HYPER_NAMES if n != "sigma2_sq")


def hyper_priors(kind: str = DEFAULT_KERNEL) -> dict:
    """GP hyperparameter priors (Table 9.1): lam, sigma1_sq, sigma2_sq, c (rad), tau; ``kind="product"``: the
    product kernel's, without ``sigma2_sq`` (:func:`hyper_names`)."""
    priors = {
        "lam": dist.Gamma(2.0, 2.0),
        "sigma1_sq": dist.InverseGamma(IG_SHAPE, IG_SCALE),
        "sigma2_sq": dist.InverseGamma(IG_SHAPE, IG_SCALE),
        "c": dist.Uniform(0.0, math.pi),
        "tau": dist.Uniform(4.0, 10.0),
    }
    return {n: priors[n] for n in hyper_names(kind)}


def v_prior():
    """Global strain bias ``v ~ N(0, 0.05^2)``."""
    return dist.Normal(0.0, V_SD)


def _check_y(y):
    if y is not None and jnp.shape(y) != (N_OUTPUTS,):
        raise ValueError(f"y must have shape ({N_OUTPUTS},) [LVV, 24 strains], got {jnp.shape(y)}")


def check_traceable(forward, infer_angles: bool = False) -> None:
    """Raise :class:`ForwardError` unless ``forward`` can be traced by JAX and reads the sampled parameters."""
    if not isinstance(forward, TraceableForward):
        raise ForwardError(f"forward model '{getattr(forward, 'label', type(forward).__name__)}' is not JAX-traceable; "
                           "NUTS needs gradients through it: calibrate with an emulator (lvcore.emulator.EmulatorForward)")
    want = THETA_NAMES + (ANGLE_NAMES if infer_angles else ())
    if tuple(forward.input_names) != want:
        raise ForwardError(f"calibration samples {list(want)}; the forward model reads {list(forward.input_names)}"
                           + (" (use infer_angles=True or bind the angles in)" if set(ANGLE_NAMES) <= set(forward.input_names) else ""))


def _sample_params(infer_angles: bool, forward) -> dict:
    """theta (and the angles) from their priors, plus whatever latent geometry the forward model samples
    (``forward.sample_latents()``: the PC scores and scale of ``--geometry infer``,
    :class:`lvcore.inference.geometry_prior.InferredGeometryForward`)."""
    params = {n: numpyro.sample(n, d) for n, d in theta_priors(infer_angles, forward).items()}
    latents = getattr(forward, "sample_latents", None)
    if latents is not None:
        params.update(latents())
    return params


def representation_error(forward):
    """The shape model's representation error the forward model carries (``--geometry infer``), or None.

    :class:`lvcore.inference.geometry_prior.InferredGeometryForward` carries one
    (:mod:`lvcore.inference.representation_error`); every other forward model none.
    """
    return None if forward is None else getattr(forward, "representation", None)


def lvv_sd(eta0, sigma_v, forward=None):
    """Sd (mL) of the LVV likelihood: ``sigma_v``, with the representation error's floor
    ``sqrt(sigma_v^2 + (r_V eta0)^2)`` when ``forward`` carries one."""
    rep = representation_error(forward)
    return sigma_v if rep is None else rep.lvv_sd(sigma_v, eta0)


def strain_likelihood(mean, sigma_s2, forward=None):
    """Distribution of the 24 strains: iid ``N(mean, sigma_s2)``, or, when ``forward`` carries a
    representation error, ``MVN(mean, sigma_s2 I + Sigma_rep)`` (the shape model's known discrepancy;
    the covariance of :func:`strain_noise_covariance`)."""
    if strain_floor(forward) is None:
        return dist.Normal(mean, jnp.sqrt(sigma_s2)).to_event(1)
    return dist.MultivariateNormal(mean, covariance_matrix=strain_noise_covariance(sigma_s2, forward))


def strain_rep_covariance(forward):
    """The known strain covariance ``Sigma_rep`` (strain², 24 x 24) the forward model carries, or None."""
    rep = representation_error(forward)
    return None if rep is None else rep.strain_rep_covariance()


def strain_floor(forward, model: str = "iid"):
    """The representation error's covariance that the likelihood ``model`` adds to the strains' own noise
    (strain², 24 x 24), or None.

    ``iid`` (and the verdict's reference likelihood): ``Sigma_rep`` when ``forward`` carries one.
    ``discrepancy``: None, ``Sigma_rep`` is a known part of the discrepancy b (:func:`discrepancy_cholesky`),
    so a posterior draw of b already holds it. ``volume``: None (the strains are not modelled).
    """
    if model not in MODEL_NAMES:
        raise ValueError(f"unknown model '{model}'; choose one of {MODEL_NAMES}")
    return strain_rep_covariance(forward) if model == "iid" else None


def strain_noise_covariance(sigma_s2, forward=None, model: str = "iid"):
    """Covariance (strain², shape ``sigma_s2.shape + (24, 24)``) of the 24 measured strains about the likelihood's
    strain mean: ``sigma_s2 I`` plus :func:`strain_floor` (``Sigma_rep`` in the iid model with a floor).

    The one place that composes the strains' noise: the likelihood (:func:`strain_likelihood`), the posterior
    predictive (:func:`lvcore.inference.diagnostics.posterior_predictive`) and the verdict
    (:mod:`lvcore.inference.verdict`) all read it. JAX-traceable; ``sigma_s2`` may have leading (draw) axes.
    """
    s2 = jnp.asarray(sigma_s2)
    cov = s2[..., None, None] * jnp.eye(24)
    floor = strain_floor(forward, model)
    return cov if floor is None else cov + floor


def discrepancy_cholesky(hyper, nugget: float = kernels.DEFAULT_NUGGET, rep_cov=None, kind: str = DEFAULT_KERNEL):
    """Lower Cholesky factor of the discrepancy's covariance ``K(hyper) + nugget I (+ Sigma_rep)`` (strain).

    Parameters
    ----------
    hyper : mapping
        GP hyperparameters (:func:`hyper_names` of ``kind``).
    nugget : float
        Diagonal jitter of the Gram matrix (strain²).
    rep_cov : array (24, 24), optional
        The representation error's known covariance (:func:`strain_rep_covariance`, strain²); None: the
        GP's alone, exactly :func:`lvcore.inference.kernels.gram_cholesky`.
    kind : {"additive", "product"}
        The GP's kernel (:func:`lvcore.inference.kernels.gram`): the chapter's additive one (default, rank 9 on
        the grid) or the product (sector × level) one (full rank 24).
    """
    if rep_cov is None:
        return kernels.gram_cholesky(hyper, nugget=nugget, kind=kind)
    return jnp.linalg.cholesky(kernels.gram(hyper, nugget=nugget, kind=kind) + rep_cov)


def _volume_term(eta0, y, sigma_v, forward=None):
    numpyro.sample("lvv_obs", dist.Normal(eta0, lvv_sd(eta0, sigma_v, forward)), obs=None if y is None else y[0])


def extra_terms(forward, params, eta, sigma_v, sigma_s2=None, strain_offset=0.0, strain_floor: bool = True) -> None:
    """The forward model's further likelihood terms, if it carries any (``forward.likelihood_terms``: further
    loaded states, the Klotz prior; :mod:`lvcore.inference.loaded_states`); nothing otherwise.

    ``strain_floor=False``: ``strain_offset`` already carries the representation error (the discrepancy
    model's b), so the further states' strains get ``sigma_S^2 I`` only."""
    terms = getattr(forward, "likelihood_terms", None)
    if terms is not None:
        terms(params, eta, sigma_v=sigma_v, sigma_s2=sigma_s2, strain_offset=strain_offset, strain_floor=strain_floor)


def volume_model(y=None, *, forward, sigma_v: float = SIGMA_V_ML, infer_angles: bool = False):
    """Model (i): LVV only, ``y0 ~ N(eta0(theta), sigma_v^2)``; strains are ignored."""
    _check_y(y)
    params = _sample_params(infer_angles, forward)
    eta = numpyro.deterministic("eta", forward(params))
    _volume_term(eta[0], y, sigma_v, forward)
    extra_terms(forward, params, eta, sigma_v)


def iid_model(y=None, *, forward, sigma_v: float = SIGMA_V_ML, infer_angles: bool = False):
    """Model (ii): LVV term plus iid Gaussian strains with inferred ``sigma_S^2``."""
    _check_y(y)
    params = _sample_params(infer_angles, forward)
    sigma_s2 = numpyro.sample("sigma_s2", sigma_s2_prior())
    eta = numpyro.deterministic("eta", forward(params))
    _volume_term(eta[0], y, sigma_v, forward)
    numpyro.sample("strain_obs", strain_likelihood(eta[1:], sigma_s2, forward), obs=None if y is None else y[1:])
    extra_terms(forward, params, eta, sigma_v, sigma_s2)


def discrepancy_model(y=None, *, forward, sigma_v: float = SIGMA_V_ML, infer_angles: bool = False,
                      nugget: float = kernels.DEFAULT_NUGGET, kernel: str = DEFAULT_KERNEL):
    """Model (iii): strains ``~ N(eta + b + v, sigma_S^2)`` with ``b = L b_tilde`` a polar GP.

    ``disc_tilde ~ N(0, I_24)`` is the whitened discrepancy; ``disc`` (= b, named so it cannot clash with the
    material parameter b) is recorded as a deterministic site. ``L`` is the Cholesky factor of the
    polar-kernel Gram matrix (plus ``nugget``) on the 6 x 4 strain grid, plus the representation error's
    ``Sigma_rep`` when the forward model carries one (:func:`discrepancy_cholesky`; module docstring): b is
    then the GP discrepancy and the shape model's known one together, and further loaded states share it.
    ``kernel``: the GP's kernel, the chapter's ``"additive"`` (default) or ``"product"`` (sector × level; no
    ``sigma2_sq`` site, :func:`hyper_priors`).
    """
    _check_y(y)
    params = _sample_params(infer_angles, forward)
    sigma_s2 = numpyro.sample("sigma_s2", sigma_s2_prior())
    hyper = {n: numpyro.sample(n, d) for n, d in hyper_priors(kernel).items()}
    b_tilde = numpyro.sample("disc_tilde", dist.Normal(0.0, 1.0).expand([24]).to_event(1))
    v = numpyro.sample("v", v_prior())
    rep_cov = strain_rep_covariance(forward)
    chol = discrepancy_cholesky(hyper, nugget, rep_cov, kernel)
    b = numpyro.deterministic("disc", chol @ b_tilde)
    eta = numpyro.deterministic("eta", forward(params))
    _volume_term(eta[0], y, sigma_v, forward)
    # Sigma_rep is inside b: the strains' own noise is sigma_S^2 I (strain_likelihood without a floor)
    numpyro.sample("strain_obs", strain_likelihood(eta[1:] + b + v, sigma_s2), obs=None if y is None else y[1:])
    extra_terms(forward, params, eta, sigma_v, sigma_s2, b + v, strain_floor=rep_cov is None)


MODELS = {"volume": volume_model, "iid": iid_model, "discrepancy": discrepancy_model}


def get_model(name: str):
    """Model function by name: ``volume``, ``iid`` or ``discrepancy``."""
    try:
        return MODELS[name]
    except KeyError:
        raise ValueError(f"unknown model '{name}'; choose one of {MODEL_NAMES}") from None


#: One-line meaning of every parameter a calibration reports (the app's tooltips and tables).
PARAMETER_HELP = {
    "a": "a (kPa): isotropic stiffness of the Holzapfel-Ogden law, scales the matrix term a/(2b)(e^{b(I1-3)}-1).",
    "b": "b (-): isotropic exponent; how fast the matrix stiffens with stretch.",
    "af": "a_f (kPa): fibre stiffness, scales the fibre term a_f/(2b_f)(e^{b_f(I4f-1)²}-1).",
    "bf": "b_f (-): fibre exponent; how fast the fibres stiffen with stretch.",
    "alpha_endo": "α_endo (deg): fibre angle at the endocardium (inferred only with 'infer' fibre angles).",
    "alpha_epi": "α_epi (deg): fibre angle at the epicardium (inferred only with 'infer' fibre angles).",
    "sigma_s_sq": "σ_S² (strain²): variance of the iid strain measurement noise; prior IG(0.001, 0.001).",
    "sigma_s2": "σ_S² (strain²): variance of the iid strain measurement noise; prior IG(0.001, 0.001).",
    "v": "v (strain): global strain bias of the discrepancy b(x), the same offset in all 24 segments; prior N(0, 0.05²).",
    "lam": "λ (levels): correlation length of the polar-GP discrepancy across the three short-axis levels; prior Gamma(2, 2).",
    "sigma1_sq": "σ₁² (strain²): variance of the discrepancy's circumferential component (polar Wendland kernel around each ring; with the product kernel, the variance of the whole sector × level GP); prior IG(0.001, 0.001).",
    "sigma2_sq": "σ₂² (strain²): variance of the discrepancy's base-to-apex (level) component (the additive kernel only); prior IG(0.001, 0.001).",
    "c": "c (rad): compact-support radius of the polar kernel: segments further apart than c around the ring are uncorrelated; prior U(0, π).",
    "tau": "τ (-): shape/smoothness exponent of the polar Wendland kernel (positive definite for τ ≥ 4); prior U(4, 10).",
}


def parameter_meaning(name: str, max_chars: int = 48) -> str:
    """The short meaning of a parameter for a table cell (:data:`PARAMETER_HELP` up to its first clause).

    ``"a"`` -> ``"isotropic stiffness of the Holzapfel-Ogden law"``. Table cells
    stay narrow enough to show whole; the full text stays in :data:`PARAMETER_HELP`.
    """
    import re

    text = PARAMETER_HELP.get(str(name), "")
    text = text.split(": ", 1)[-1]
    text = re.split(r"[;,:]| \(|\. | across ", text)[0].strip().rstrip(".")
    return text if len(text) <= max_chars else text[: max_chars - 1].rstrip() + "…"


__all__ = [
    "parameter_meaning", "MODEL_LABELS", "SIGMA_V_ML", "THETA_BOUNDS", "ANGLE_BOUNDS", "check_traceable", "HYPER_NAMES", "MODEL_NAMES", "MODELS",
    "PARAMETER_HELP", "prior_bounds", "theta_priors", "sigma_s2_prior", "hyper_priors", "v_prior",
    "volume_model", "iid_model", "discrepancy_model", "get_model", "representation_error", "lvv_sd",
    "strain_likelihood", "extra_terms", "strain_rep_covariance", "strain_floor", "strain_noise_covariance",
    "discrepancy_cholesky", "KERNEL_KINDS", "DEFAULT_KERNEL", "check_kernel", "hyper_names",
]
