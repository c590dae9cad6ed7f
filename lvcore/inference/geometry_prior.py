r"""``--geometry infer``: the subject's shape and size sampled jointly with theta.

A subject without a mesh is described by the shape model's PC scores ``h``
(``h1..hk``, the emulator's) and a uniform scale ``s`` (:mod:`lvcore.geometry.scaling`):
the reference geometry is ``s * reconstruct(h)``. Priors:

* ``h_k ~ N(0, 1)`` (the shape model's population prior) truncated to the
  emulator's training box (``[-2, 2]`` for the shipped emulators), so the
  emulator never extrapolates;
* ``log s ~ U(log s_min, log s_max)`` on :data:`lvcore.geometry.scaling.SCALE_BOUNDS`.

The forward model is the emulator at ``(theta, h)`` with its LVV multiplied
by ``s^3`` (exact scaling). The CMR measures a user may have inform ``(h, s)``
through Gaussian likelihoods (:data:`MEASURE_SD`):

* ``reference_volume_ml`` — early-diastolic (reference) cavity volume,
  ``s^3 V_cav(reconstruct(h))``;
* ``wall_volume_ml`` — myocardial volume (mass / 1.05 g/mL), ``s^3 V_wall``;
* ``long_axis_mm`` — base plane to epicardial apex, ``s L``.

``V_cav``, ``V_wall`` and ``L`` are computed from the reconstructed template
mesh exactly, in JAX (the cavity volume is a polynomial in the node
coordinates, :func:`lvcore.geometry.measures.cavity_volume`), so NUTS gets
their gradients. Without any measure the run goes ahead with
:data:`NO_MEASURE_WARNING`: size and stiffness trade off (a larger
reference cavity inflated less looks like a smaller one inflated more).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import jax.numpy as jnp
import numpy as np

from lvcore.domain.conditions import SIGMA_V_ML
from lvcore.exceptions import DataError, EmulatorError
from lvcore.domain.outputs import ANGLE_NAMES, N_OUTPUTS, THETA_NAMES, is_pc_name

#: Geometric measures a subject may have, with their units.
MEASURE_NAMES = ("reference_volume_ml", "wall_volume_ml", "long_axis_mm")
#: Measurement standard deviation of each measure (mL, mL, mm): the volumes that of the LVV
#: (:data:`lvcore.core.space.SIGMA_V_ML`), the long axis about one CMR pixel and a half.
MEASURE_SD = {"reference_volume_ml": SIGMA_V_ML, "wall_volume_ml": SIGMA_V_ML, "long_axis_mm": 3.0}
#: The CLI options that give them.
MEASURE_OPTIONS = {"reference_volume_ml": "--reference-volume", "wall_volume_ml": "--wall-volume",
                   "long_axis_mm": "--long-axis"}
#: Plausible ranges (accepted without complaint).
MEASURE_RANGES = {"reference_volume_ml": (10.0, 500.0), "wall_volume_ml": (20.0, 600.0),
                  "long_axis_mm": (30.0, 200.0)}
#: The CLI options that set each measure's standard deviation (default :data:`MEASURE_SD`).
MEASURE_SD_OPTIONS = {"reference_volume_ml": "--reference-volume-sd", "wall_volume_ml": "--wall-volume-sd",
                      "long_axis_mm": "--long-axis-sd"}
#: The data columns (CSV), keys (JSON) and .mat variables that set them per subject.
MEASURE_SD_COLUMNS = {name: f"{name}_sd" for name in MEASURE_NAMES}
#: Accepted standard deviations (mL, mL, mm): below, the measure would pin the geometry to a precision no CMR
#: has (and the likelihood degenerates); above, it carries no information at the sizes of MEASURE_RANGES.
MEASURE_SD_RANGES = {"reference_volume_ml": (0.5, 50.0), "wall_volume_ml": (0.5, 50.0), "long_axis_mm": (0.2, 30.0)}
#: Site name of the scale.
SCALE_NAME = "scale"
#: Warning of a run without any geometric measure.
NO_MEASURE_WARNING = ("--geometry infer without --reference-volume (or --wall-volume / --long-axis, or the data's "
                      "reference_volume_ml column): the subject's size is inferred from the LVV and strains alone, "
                      "and size and stiffness trade off (a larger reference cavity inflated less fits the same LVV "
                      "as a smaller one inflated more); measure the early-diastolic cavity volume and give it")


def _given_numbers(values: Mapping[str, Any] | None, where: str, label_of: Callable[[str], str]):
    """``(name, value as given, value as float, label)`` of each measure given: an unknown name or a value that is
    not a number is refused (naming ``where`` and the measure's ``label_of(name)``); None and NaN are skipped."""
    for name, value in dict(values or {}).items():
        if name not in MEASURE_NAMES:
            raise DataError(f"{where}: unknown geometric measure '{name}'; use {', '.join(MEASURE_NAMES)}")
        if value is None or (isinstance(value, float) and math.isnan(value)):
            continue
        label = label_of(name)
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise DataError(f"{where}: {label} must be a number, got {str(value)[:40]!r}") from None
        yield name, value, v, label


def check_measures(measures: Mapping[str, Any] | None, where: str = "geometric measures") -> dict:
    """Validated measures (finite, positive, in :data:`MEASURE_RANGES`); None values dropped.

    Raises
    ------
    DataError
        Naming the option/column and the fix.
    """
    out = {}
    for name, value, v, _ in _given_numbers(measures, where, lambda name: name):
        lo, hi = MEASURE_RANGES[name]
        if not (math.isfinite(v) and lo <= v <= hi):
            unit = name.rsplit("_", 1)[-1]
            raise DataError(f"{where}: {name} = {value} ({MEASURE_OPTIONS[name]}) is outside the plausible range "
                            f"{lo:g}-{hi:g} {unit}; check the unit ({unit})")
        out[name] = v
    return out


def check_measure_sds(sds: Mapping[str, Any] | None, where: str = "geometric-measure sds",
                      by: str = "option") -> dict:
    """Validated measure standard deviations, keyed by measure name; None/NaN dropped.

    Parameters
    ----------
    sds : mapping
        ``measure name -> sd`` (mL for the volumes, mm for the long axis).
    where : str
        What to name in an error (the file and line, or "options").
    by : {"option", "column"}
        Name the CLI option (``--reference-volume-sd``) or the data column (``reference_volume_ml_sd``).

    Raises
    ------
    DataError
        Naming the option/column, the accepted range and the unit.
    """
    out = {}
    labels = MEASURE_SD_OPTIONS if by == "option" else MEASURE_SD_COLUMNS
    for name, _, v, label in _given_numbers(sds, where, labels.__getitem__):
        lo, hi = MEASURE_SD_RANGES[name]
        unit = {"ml": "mL"}.get(name.rsplit("_", 1)[-1], "mm")
        if not (math.isfinite(v) and lo <= v <= hi):
            raise DataError(f"{where}: {label} = {v:g} is outside {lo:g}-{hi:g} {unit}; give the measurement's "
                            f"standard deviation in {unit} (default {MEASURE_SD[name]:g} {unit})")
        out[name] = v
    return out


@dataclass(frozen=True)
class ShapeMeasures:
    """The geometric measures of ``s * reconstruct(h)`` as JAX functions of ``(h, s)``.

    Built once from a shape model (:func:`shape_measures`); each call is a
    small matrix product and the quadrature of
    :func:`lvcore.geometry.measures.cavity_volume`.
    """

    mean: Any          # (n_nodes * 3,)
    basis: Any         # (k, n_nodes * 3): std_k * component_k
    epi_swap: Any      # node permutation putting the epicardium where the endocardium is
    n_nodes: int

    def nodes(self, h):
        """Template nodes (mm) of the shape with scores ``h`` (unscaled)."""
        return (self.mean + jnp.asarray(h) @ self.basis).reshape(self.n_nodes, 3)

    def unit(self, h) -> dict:
        """Measures of the unscaled shape: cavity and wall volume (mL), long axis (mm)."""
        from lvcore.geometry.measures import cavity_volume
        from lvcore.geometry.template import DEFAULT_TEMPLATE as T

        x = self.nodes(h)
        base_z = jnp.mean(x[T.base_nodes, 2])
        cav = cavity_volume(x, T, base_z) / 1000.0
        outer = cavity_volume(x[self.epi_swap], T, base_z) / 1000.0
        return {"reference_volume_ml": cav, "wall_volume_ml": outer - cav,
                "long_axis_mm": base_z - x[T.apex_epi_node, 2]}

    def __call__(self, h, s) -> dict:
        """Measures of ``s * reconstruct(h)``: volumes x ``s^3``, the long axis x ``s``."""
        u = self.unit(h)
        return {"reference_volume_ml": s ** 3 * u["reference_volume_ml"],
                "wall_volume_ml": s ** 3 * u["wall_volume_ml"], "long_axis_mm": s * u["long_axis_mm"]}


def shape_measures(n_pc: int, model=None) -> ShapeMeasures:
    """:class:`ShapeMeasures` of the first ``n_pc`` modes of ``model`` (default the bundled one)."""
    from lvcore.geometry.shape_model import load_shape_model
    from lvcore.geometry.template import DEFAULT_TEMPLATE as T

    model = load_shape_model() if model is None else model
    if n_pc > model.n_modes:
        raise EmulatorError(f"the emulator uses {n_pc} PC scores, the shape model has {model.n_modes}")
    swap = np.arange(T.n_nodes)
    k0 = T.node_index(T.grid_ijk[:, 0], T.grid_ijk[:, 1], 0)
    kn = T.node_index(T.grid_ijk[:, 0], T.grid_ijk[:, 1], T.nt - 1)
    swap[k0] = kn
    return ShapeMeasures(mean=jnp.asarray(model.mean.ravel()),
                         basis=jnp.asarray(model.std[:n_pc, None] * model.components[:n_pc]),
                         epi_swap=jnp.asarray(swap), n_nodes=int(model.n_nodes))


@dataclass(frozen=True, eq=False)
class InferredGeometryForward:
    """An emulator whose geometry (PC scores and scale) is sampled with theta.

    The numpyro models of :mod:`lvcore.inference.models` call
    :meth:`sample_latents` inside the model (priors of ``h`` and ``s``, and the
    likelihood of the measured geometric measures) and pass the sampled values
    to :meth:`__call__` with theta.

    Parameters
    ----------
    forward : lvcore.core.EmulatorForward
        The emulator with its conditions bound; its PC scores are replaced by
        the sampled ones.
    measures : mapping
        Measured ``reference_volume_ml`` / ``wall_volume_ml`` / ``long_axis_mm`` (any subset, may be empty).
    shape : ShapeMeasures
    scale_bounds : (float, float)
    measure_sd : mapping
        Standard deviation of a measure (mL, mL, mm), overriding :data:`MEASURE_SD`.
    representation : lvcore.inference.representation_error.RepresentationError or None
        The shape model's representation error: a variance floor on the strains, the LVV and the
        measures (:mod:`lvcore.inference.representation_error`); None: no floor.
    """

    forward: Any
    measures: Mapping[str, float] = field(default_factory=dict)
    shape: ShapeMeasures | None = None
    scale_bounds: tuple = None
    measure_sd: Mapping[str, float] = field(default_factory=dict)
    representation: Any = None

    def __post_init__(self):
        from lvcore.geometry.scaling import SCALE_BOUNDS

        emu = self.forward.emulator
        names = tuple(emu.input_names)
        pcs = tuple(n for n in names if is_pc_name(n))
        if not pcs:
            raise EmulatorError(f"emulator '{self.forward.label}' has no PC-score inputs; --geometry infer needs "
                                "an emulator of the shape model's scores (e.g. 'chapter' or 'angles')")
        object.__setattr__(self, "measures", check_measures(self.measures))
        object.__setattr__(self, "measure_sd", check_measure_sds(self.measure_sd))
        if self.representation is not None and int(self.representation.n_pc) != len(pcs):
            raise EmulatorError(f"the representation error is for {self.representation.n_pc} PC scores, the "
                                f"emulator '{self.forward.label}' has {len(pcs)}")
        object.__setattr__(self, "scale_bounds", tuple(self.scale_bounds or SCALE_BOUNDS))
        if self.shape is None:
            object.__setattr__(self, "shape", shape_measures(len(pcs)))

    # --- what the models and the guards read ---------------------------------
    @property
    def pc_names(self) -> tuple:
        return tuple(n for n in self.forward.emulator.input_names if is_pc_name(n))

    @property
    def latent_names(self) -> tuple:
        """Sampled geometry sites: ``h1..hk`` then ``scale``."""
        return self.pc_names + (SCALE_NAME,)

    @property
    def input_names(self) -> tuple:
        return tuple(n for n in self.forward.input_names if not is_pc_name(n))

    @property
    def input_bounds(self) -> dict:
        return {n: b for n, b in self.forward.input_bounds.items() if n in self.input_names}

    @property
    def latent_bounds(self) -> dict:
        """Prior bounds of the latents: the emulator's box for ``h``, :attr:`scale_bounds` for ``s``."""
        emu = self.forward.emulator
        names = tuple(emu.input_names)
        out = {n: (float(emu.lower[names.index(n)]), float(emu.upper[names.index(n)])) for n in self.pc_names}
        out[SCALE_NAME] = tuple(float(v) for v in self.scale_bounds)
        return out

    def _latent_only(self, *args, **kwargs):
        from lvcore.exceptions import ForwardError

        raise ForwardError("an inferred geometry is sampled inside the model: evaluate it at (theta, h, scale) "
                           "with forward(params); batch evaluation over theta alone is undefined")

    # TraceableForward: __call__ traces; batches need the latent geometry, which only the model supplies
    evaluate = jacobian = apply = _latent_only

    @property
    def label(self) -> str:
        return f"{self.forward.label} (geometry inferred)"

    @property
    def emulator(self):
        return self.forward.emulator

    @property
    def base(self) -> str:
        return self.forward.base

    @property
    def conditions(self) -> dict:
        return {k: v for k, v in self.forward.conditions.items() if not is_pc_name(k)}

    @property
    def measure_sds(self) -> dict:
        """Measurement sd of each given measure (mL, mL, mm): the user's, else :data:`MEASURE_SD`."""
        return {k: float(self.measure_sd.get(k, MEASURE_SD[k])) for k in self.measures}

    @property
    def likelihood_sds(self) -> dict:
        """Sd of each measure's likelihood: :attr:`measure_sds` widened by the representation error's
        relative floor at the measured value (equal to :attr:`measure_sds` without one)."""
        sds = self.measure_sds
        if self.representation is None:
            return sds
        return {k: self.representation.measure_sd(k, sd, self.measures[k]) for k, sd in sds.items()}

    # --- numpyro ---------------------------------------------------------------
    def sample_latents(self) -> dict:
        """Sample ``h`` and ``s`` (numpyro sites) and observe the measured geometric measures."""
        import numpyro
        import numpyro.distributions as dist

        out = {}
        for n, (lo, hi) in self.latent_bounds.items():
            if n == SCALE_NAME:
                log_s = numpyro.sample("log_scale", dist.Uniform(math.log(lo), math.log(hi)))
                out[n] = numpyro.deterministic(SCALE_NAME, jnp.exp(log_s))
            else:
                out[n] = numpyro.sample(n, dist.TruncatedNormal(0.0, 1.0, low=lo, high=hi))
        if self.measures:
            pred = self.shape(jnp.stack([out[n] for n in self.pc_names]), out[SCALE_NAME])
            sds = self.likelihood_sds
            for name, value in self.measures.items():
                numpyro.sample(f"{name}_obs", dist.Normal(pred[name], sds[name]), obs=value)
        return out

    def __call__(self, params):
        inner = {n: params[n] for n in self.forward.input_names if not is_pc_name(n)}
        inner.update({n: params[n] for n in self.pc_names})
        y = self.forward(inner)
        return y.at[0].multiply(jnp.asarray(params[SCALE_NAME]) ** 3)

    def measures_of(self, h, s) -> dict:
        """Plain-float geometric measures of ``s * reconstruct(h)``."""
        return {k: float(v) for k, v in self.shape(jnp.asarray(h, dtype=float), float(s)).items()}


def inferred_geometry_forward(emulator, *, name: str | None = None, measures: Mapping | None = None,
                              infer_angles: bool = False, alpha_endo: float | None = None,
                              alpha_epi: float | None = None, edp_mmhg: float | None = None,
                              scale_bounds=None, measure_sd: Mapping | None = None,
                              representation: Any = "bundled") -> InferredGeometryForward:
    """Bind conditions into ``emulator`` and let calibration sample its PC scores and a scale.

    Parameters are those of :func:`lvcore.emulator.forward.emulator_forward`
    (``None``: its defaults), plus ``measures`` (:data:`MEASURE_NAMES`), their
    ``measure_sd`` (default :data:`MEASURE_SD`) and ``representation``: the
    shape model's representation error added as a variance floor
    (``"bundled"``: the asset of the emulator's number of modes,
    :func:`lvcore.inference.representation_error.load_representation_error`;
    None: no floor; or a ``RepresentationError``).
    """
    from lvcore.emulator.forward import EmulatorForward, emulator_forward

    kwargs = {k: v for k, v in (("alpha_endo", alpha_endo), ("alpha_epi", alpha_epi), ("edp_mmhg", edp_mmhg))
              if v is not None}
    names = tuple(emulator.input_names)
    n_pc = sum(1 for n in names if is_pc_name(n))
    bound = emulator_forward(emulator, np.zeros(n_pc), name=name, infer_angles=infer_angles, **kwargs)
    pcs = tuple(n for n in names if is_pc_name(n))
    reads = THETA_NAMES + (ANGLE_NAMES if infer_angles else ()) + pcs
    inner = EmulatorForward(bound.emulator, {k: v for k, v in bound.conditions.items() if k not in pcs}, reads,
                            bound.label)
    if isinstance(representation, str):
        if representation != "bundled":
            raise ValueError(f"representation must be 'bundled', None or a RepresentationError, got {representation!r}")
        from lvcore.inference.representation_error import load_representation_error

        representation = load_representation_error(n_pc)
    return InferredGeometryForward(inner, measures or {}, scale_bounds=scale_bounds, measure_sd=measure_sd or {},
                                   representation=representation)


def geometry_posterior(samples: Mapping, forward: InferredGeometryForward) -> dict:
    """Posterior summary (median, q05, q95) of ``h``, ``s`` and the implied geometric measures."""
    h = np.stack([np.asarray(samples[n], float).reshape(-1) for n in forward.pc_names], axis=-1)
    s = np.asarray(samples[SCALE_NAME], float).reshape(-1)
    idx = np.linspace(0, h.shape[0] - 1, min(h.shape[0], 400)).astype(int)
    import jax

    meas = jax.vmap(lambda hh, ss: forward.shape(hh, ss))(jnp.asarray(h[idx]), jnp.asarray(s[idx]))

    def q(v):
        v = np.asarray(v, float)
        return {"median": float(np.median(v)), "q05": float(np.quantile(v, 0.05)), "q95": float(np.quantile(v, 0.95))}

    out = {n: q(h[:, i]) for i, n in enumerate(forward.pc_names)}
    out[SCALE_NAME] = q(s)
    out.update({f"implied_{k}": q(v) for k, v in meas.items()})
    out["measured"] = dict(forward.measures)
    out["measure_sd"] = forward.measure_sds
    out["likelihood_sd"] = forward.likelihood_sds
    return out


__all__ = ["MEASURE_NAMES", "MEASURE_SD", "MEASURE_OPTIONS", "MEASURE_RANGES", "MEASURE_SD_OPTIONS",
           "MEASURE_SD_COLUMNS", "MEASURE_SD_RANGES", "SCALE_NAME", "NO_MEASURE_WARNING", "check_measure_sds",
           "check_measures", "ShapeMeasures", "shape_measures", "InferredGeometryForward",
           "inferred_geometry_forward", "geometry_posterior"]
