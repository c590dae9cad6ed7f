"""The trained emulator η(inputs) -> 25 outputs, as used by the app and calibration.

An :class:`Emulator` bundles the network with its input transform
(log of the material parameters, then standardisation), its output scaling
and its training box. Two ways to call it:

``Emulator.apply(x)``
    pure, jit-compiled JAX function: ``x`` of shape ``(..., d)`` in the order
    of :attr:`Emulator.input_names` (physical units) to ``(..., 25)``
    [LVV mL, 24 strains]. Differentiable; safe inside ``jax.grad``,
    ``vmap`` and numpyro models. It does **not** check the training box
    (it cannot raise on traced values): use :meth:`Emulator.in_box`.
``Emulator.predict(x=None, *, strict=None, **named)``
    convenience front end: accepts an array ``(..., d)``, a mapping of input
    name to values, or keyword arguments (``predict(a=..., b=..., ...)``),
    broadcasts them, checks the training box and calls :meth:`apply`.
    Outside the box it warns (:class:`ExtrapolationWarning`) or, in strict
    mode, raises :class:`~lvcore.exceptions.EmulatorError`; it never
    extrapolates silently. Inputs the emulator was trained at a fixed value
    for (e.g. the fibre angles of ``chapter``) may be passed and must equal
    that value.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from lvcore.emulator.network import MLP
from lvcore.exceptions import EmulatorError
from lvcore.domain.outputs import N_OUTPUTS, OUTPUT_COLUMNS, THETA_NAMES

#: Inputs that are log-transformed before standardisation (positive, scale-like).
LOG_INPUTS = THETA_NAMES
#: Batches up to this many rows are padded to the next power of two, larger ones to a multiple of it.
PAD_ROWS = 4096


class ExtrapolationWarning(UserWarning):
    """An emulator was asked for a prediction outside its training box."""


#: The prior mean's size factor: an LV between a tenth and ten times the shape model's size (subjects lie near 1).
PRIOR_SCALE_RANGE = (0.1, 10.0)


@dataclass(frozen=True, eq=False)
class PriorMean:
    """A bundled emulator at one subject's shape: the baseline a subject emulator's network corrects.

    A subject emulator with a prior mean predicts
    ``LVV = r_V(x) * s^3 * LVV_prior`` and ``strain = r_S(x) + strain_prior``,
    where the network gives the ratio ``r_V`` and the differences ``r_S``, and
    the prior is ``emulator`` evaluated at the subject's inputs ``x`` and at
    ``inputs`` for what the subject emulator does not vary (the PC scores of
    the subject's size-normalised shape and fixed conditions). The correction
    is smoother and smaller than the whole map, so fewer FE runs learn it
    (:mod:`lvcore.emulator.subject`).

    Parameters
    ----------
    emulator : Emulator
        An emulator over PC scores (e.g. ``chapter``), with the same base
        condition as the subject's FE runs.
    inputs : dict
        Values (physical units) of the prior's inputs that the subject
        emulator does not take, e.g. ``{"h1": 0.3, ..., "h5": -1.2}``.
    scale : float
        Uniform size factor ``s`` of the subject relative to the shape with
        those scores (:func:`lvcore.geometry.scaling.size_normalised_scores`).
    """

    emulator: "Emulator"
    inputs: dict
    scale: float = 1.0

    def __post_init__(self):
        object.__setattr__(self, "inputs", {str(k): float(v) for k, v in self.inputs.items()})
        object.__setattr__(self, "scale", float(self.scale))
        lo, hi = PRIOR_SCALE_RANGE
        if not (np.isfinite(self.scale) and lo <= self.scale <= hi):
            raise EmulatorError(f"prior mean: scale must be the subject's size factor relative to the shape model, "
                                f"between {lo:g} and {hi:g}, got {self.scale:g}; build the subject emulator again")

    def columns(self, input_names) -> tuple:
        """Per prior input: the column of ``input_names`` it is read from, or its fixed value (float)."""
        names = tuple(input_names)
        cols = []
        for n in self.emulator.input_names:
            if n in names:
                cols.append(names.index(n))
            elif n in self.inputs:
                cols.append(float(self.inputs[n]))
            else:
                raise EmulatorError(f"prior mean '{self.emulator.name}' needs input '{n}', which the subject "
                                    f"emulator neither takes ({list(names)}) nor fixes ({sorted(self.inputs)})")
        return tuple(cols)


@dataclass(frozen=True, eq=False)
class Emulator:
    """A trained emulator; build with :func:`lvcore.emulator.training.train_emulator`
    or :func:`lvcore.emulator.io.load_emulator`.

    Parameters
    ----------
    name : str
        Short name (e.g. ``"chapter"``).
    input_names : tuple of str
        Varied inputs, in the column order of ``x``.
    lower, upper : np.ndarray
        Training box (physical units), ``(d,)``.
    log_inputs : tuple of bool
        Per input: transformed by ``log`` before standardisation.
    x_mean, x_sd : np.ndarray
        Standardisation of the (log-)transformed inputs.
    y_mean, y_sd : np.ndarray
        Standardisation of the 25 outputs.
    network : MLP
        Acts on standardised inputs, returns standardised outputs.
    fixed : dict
        Inputs held fixed in the training set (name -> value).
    metadata : dict
        Everything else recorded at training (see :mod:`lvcore.emulator.io`).
    strict : bool
        Default for :meth:`predict`: raise instead of warn outside the box.
    log_outputs : tuple of bool
        Per output: the network predicts the standardised ``log`` of it
        (used for the LVV, which spans an order of magnitude).
    prior : PriorMean, optional
        A baseline the network corrects (subject emulators): the network's
        LVV is a ratio to the prior's, its strains differences from the
        prior's (:class:`PriorMean`).
    """

    name: str
    input_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    log_inputs: tuple[bool, ...]
    x_mean: np.ndarray
    x_sd: np.ndarray
    y_mean: np.ndarray
    y_sd: np.ndarray
    network: MLP
    fixed: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)
    strict: bool = False
    log_outputs: tuple[bool, ...] = (False,) * N_OUTPUTS
    prior: PriorMean | None = None

    def __post_init__(self):
        d = len(self.input_names)
        for attr in ("lower", "upper", "x_mean", "x_sd"):
            if np.shape(getattr(self, attr)) != (d,):
                raise EmulatorError(f"emulator '{self.name}': {attr} must have {d} entries, got shape {np.shape(getattr(self, attr))}")
        for attr in ("y_mean", "y_sd"):
            if np.shape(getattr(self, attr)) != (N_OUTPUTS,):
                raise EmulatorError(f"emulator '{self.name}': {attr} must have {N_OUTPUTS} entries")
        if len(self.log_outputs) != N_OUTPUTS:
            raise EmulatorError(f"emulator '{self.name}': log_outputs must have {N_OUTPUTS} entries")
        if len(self.log_inputs) != d:
            raise EmulatorError(f"emulator '{self.name}': log_inputs must have {d} entries")
        if np.any(np.asarray(self.x_sd) <= 0) or np.any(np.asarray(self.y_sd) <= 0):
            raise EmulatorError(f"emulator '{self.name}': scaler standard deviations must be positive")
        if np.any(np.asarray(self.lower)[np.asarray(self.log_inputs, dtype=bool)] <= 0):
            raise EmulatorError(f"emulator '{self.name}': log-scaled inputs need a positive lower bound")
        n_in, n_out = self.network.in_size, self.network.out_size
        if (n_in, n_out) != (d, N_OUTPUTS):
            raise EmulatorError(f"emulator '{self.name}': network maps {n_in} -> {n_out}, expected {d} -> {N_OUTPUTS}")
        # _make_apply resolves the prior's columns now: a prior needing an input nobody gives raises here
        object.__setattr__(self, "_apply", jax.jit(_make_apply(self)))

    # ----- the pure function ------------------------------------------------
    def apply(self, x):
        """Pure JAX prediction: ``(..., d)`` physical inputs -> ``(..., 25)`` outputs.

        Jit-compiled, batched over leading axes, differentiable. No box check.
        """
        return self._apply(jnp.asarray(x, dtype=jnp.float64))

    def __call__(self, x):
        return self.apply(x)

    @property
    def dim(self) -> int:
        return len(self.input_names)

    @property
    def output_names(self) -> tuple[str, ...]:
        return OUTPUT_COLUMNS

    # ----- what it emulates -------------------------------------------------
    @property
    def training_space(self):
        """The :class:`~lvcore.core.space.ParameterSpace` of the campaigns it was
        trained on (from ``metadata["source"]["space"]``), or None if unrecorded."""
        from lvcore.core.space import ParameterSpace

        d = (self.metadata.get("source") or {}).get("space")
        return None if d is None else ParameterSpace.from_dict(d)

    @property
    def base(self) -> str:
        """Basal boundary condition of the training simulations, ``"clamped"`` or
        ``"sliding"`` (emulators built before it was recorded: ``"clamped"``)."""
        space = self.training_space
        return "clamped" if space is None else space.base

    @property
    def resolution(self) -> str:
        """Mesh preset that reproduces the training simulations (lvcore 0.1's
        ``"default"`` is today's ``"coarse"``)."""
        from lvcore.mechanics.resolution import recorded_resolution

        source = self.metadata.get("source") or {}
        return recorded_resolution(str((source.get("resolution") or ["default"])[0]), source.get("simulator_versions"))

    @property
    def strain_layer(self) -> str:
        """The wall layer of the strains it was trained on (``metadata["strain_layer"]``, a name of
        :data:`lvcore.domain.outputs.STRAIN_LAYERS`); emulators built before it was recorded were all trained on
        the simulator's default, the inner half."""
        from lvcore.domain.outputs import DEFAULT_STRAIN_LAYER, strain_layer

        try:
            return strain_layer(self.metadata.get("strain_layer", DEFAULT_STRAIN_LAYER), "emulator metadata")
        except ValueError as err:
            raise EmulatorError(f"emulator '{self.name}': {err}") from None

    @property
    def is_subject(self) -> bool:
        """True for a subject-specific emulator (:mod:`lvcore.emulator.subject`): its
        geometry is fixed and bound in, so it takes no PC scores."""
        return bool((self.metadata.get("subject") or {}).get("geometry"))

    @property
    def subject_geometry(self) -> dict | None:
        """The case ``geometry`` section a subject emulator was trained on (a ``mesh``
        path resolved against the emulator directory by :func:`~lvcore.emulator.io.load_emulator`),
        or None for emulators over PC scores."""
        g = (self.metadata.get("subject") or {}).get("geometry")
        return None if not g else dict(g)

    def simulator(self, geometry=None):
        """The FE forward model this emulator emulates, for checking it against a live solve.

        Parameters
        ----------
        geometry : mapping, optional
            Geometry description for :func:`lvcore.mechanics.case_inputs.build_case`;
            default: the subject geometry of a subject emulator, else the
            PC-score geometry of the training space.

        Returns
        -------
        lvcore.mechanics.forward.SimulatorForward
            Over the training space's inputs and fixed conditions, at the
            training resolution, base condition and strain layer.

        Raises
        ------
        EmulatorError
            If the emulator does not record its training space.
        """
        from lvcore.mechanics.forward import SimulatorForward

        space = self.training_space
        if space is None:
            raise EmulatorError(f"emulator '{self.name}' does not record the parameter space it was trained on")
        geometry = self.subject_geometry if geometry is None else geometry
        kwargs = {} if geometry is None else {"geometry": dict(geometry)}
        return SimulatorForward(input_names=space.names, conditions=space.fixed_dict(), resolution=self.resolution,
                                base=space.base, strain_layer=self.strain_layer, **kwargs)

    # ----- inputs -----------------------------------------------------------
    def as_array(self, x=None, **named) -> np.ndarray:
        """Assemble ``(..., d)`` inputs from an array, a mapping or keywords.

        Fixed inputs may be passed; they are checked by :meth:`predict`, not used.
        """
        if x is not None and named:
            raise EmulatorError("pass inputs either as one array/mapping or as keywords, not both")
        if x is None:
            x = named
        if isinstance(x, Mapping):
            unknown = [k for k in x if k not in self.input_names and k not in self.fixed]
            if unknown:
                raise EmulatorError(
                    f"emulator '{self.name}' has no input(s) {unknown}; inputs: {list(self.input_names)}"
                    + (f", fixed at training: {self.fixed}" if self.fixed else "")
                )
            missing = [k for k in self.input_names if k not in x]
            if missing:
                raise EmulatorError(f"emulator '{self.name}' needs input(s) {missing}")
            cols = [x[k] for k in self.input_names]
            if any(isinstance(c, jax.core.Tracer) for c in cols):
                cols = jnp.broadcast_arrays(*[jnp.asarray(c, dtype=jnp.float64) for c in cols])
                return jnp.stack(cols, axis=-1)
            cols = np.broadcast_arrays(*[np.asarray(c, dtype=float) for c in cols])
            return np.stack(cols, axis=-1)
        if isinstance(x, jax.core.Tracer):
            arr = x
        else:
            arr = np.asarray(x, dtype=float)
        if arr.ndim == 0 or arr.shape[-1] != self.dim:
            raise EmulatorError(
                f"emulator '{self.name}' takes arrays of shape (..., {self.dim}) with columns {list(self.input_names)}; got {arr.shape}"
            )
        return arr

    def in_box(self, x) -> np.ndarray:
        """Boolean ``(...)``: inside the training box (relative tolerance 1e-9)."""
        x = np.asarray(x, dtype=float)
        span = self.upper - self.lower
        return np.all((x >= self.lower - 1e-9 * span) & (x <= self.upper + 1e-9 * span), axis=-1)

    def check_inputs(self, x, strict: bool | None = None, given_fixed: Mapping | None = None) -> None:
        """Warn (or raise in strict mode) for rows outside the training box."""
        strict = self.strict if strict is None else strict
        problems = []
        for k, v in (given_fixed or {}).items():
            v = np.asarray(v, dtype=float)
            if not np.allclose(v, self.fixed[k], rtol=0, atol=1e-9 * max(1.0, abs(self.fixed[k]))):
                problems.append(f"{k} was fixed at {self.fixed[k]:g} in training, got {np.unique(v)[:5]}")
        x = np.asarray(x, dtype=float)
        if not np.all(np.isfinite(x)):
            problems.append("inputs contain NaN or inf")
        inside = self.in_box(x)
        if not np.all(inside):
            flat = x.reshape(-1, self.dim)
            bad = np.flatnonzero(~inside.reshape(-1))
            row = flat[bad[0]]
            cols = [f"{n}={v:.4g} not in [{lo:.4g}, {hi:.4g}]" for n, v, lo, hi in zip(self.input_names, row, self.lower, self.upper)
                    if not (lo - 1e-9 * (hi - lo) <= v <= hi + 1e-9 * (hi - lo))]
            problems.append(f"{bad.size} of {flat.shape[0]} row(s) outside the training box, e.g. {'; '.join(cols)}")
        if problems:
            msg = f"emulator '{self.name}': " + "; ".join(problems)
            if strict:
                raise EmulatorError(msg + " (strict mode: no extrapolation)")
            warnings.warn(msg + "; predictions there are extrapolations", ExtrapolationWarning, stacklevel=3)

    # ----- the front end ----------------------------------------------------
    def predict(self, x=None, /, *, strict: bool | None = None, **named):
        """Predict the 25 outputs ``[LVV mL, 24 strains]``.

        Parameters
        ----------
        x : array_like or mapping, optional
            ``(..., d)`` inputs in :attr:`input_names` order (physical units:
            kPa, -, deg, mmHg, scores), or a mapping name -> values.
        strict : bool, optional
            Raise :class:`EmulatorError` instead of warning outside the
            training box (default: the emulator's ``strict``).
        **named
            Inputs by name, e.g. ``predict(a=0.6, b=1.3, af=1.0, bf=3.6, h1=0, ...)``;
            arrays broadcast against each other.

        Returns
        -------
        jax.Array
            ``(..., 25)``; a single point gives shape ``(25,)``.

        Notes
        -----
        The compiled function is specialised to the batch shape, and a new
        shape costs a compilation (about 0.3 s). Concrete batches are therefore
        padded to a few row counts (:func:`padded_rows`) and the padding is cut
        off again, so a live view whose grid size changes compiles a handful of
        times, not once per size.

        Examples
        --------
        >>> from lvcore.emulator.io import load_emulator
        >>> emulator = load_emulator("chapter")
        >>> y = emulator.predict(a=0.6, b=1.3, af=1.0, bf=3.6, h1=0, h2=0, h3=0, h4=0, h5=0)
        >>> y.shape                                  # [LVV (mL), 24 strains]
        (25,)
        >>> stiffer = emulator.predict(a=1.2, b=1.3, af=1.0, bf=3.6, h1=0, h2=0, h3=0, h4=0, h5=0)
        >>> bool(stiffer[0] < y[0])                  # a stiffer matrix inflates less
        True
        """
        mapping = named if x is None else x
        given_fixed = {k: v for k, v in mapping.items() if k in self.fixed} if isinstance(mapping, Mapping) else {}
        arr = self.as_array(x, **named)
        traced = isinstance(arr, jax.core.Tracer) or any(isinstance(v, jax.core.Tracer) for v in given_fixed.values())
        if traced:
            return self.apply(arr)
        self.check_inputs(arr, strict, given_fixed)
        if np.ndim(arr) < 2:
            return self.apply(arr)
        lead = np.shape(arr)[:-1]
        rows = np.reshape(np.asarray(arr, dtype=float), (-1, self.dim))
        n = rows.shape[0]
        if n == 0:
            return self.apply(arr)
        padded = np.concatenate([rows, np.repeat(rows[:1], padded_rows(n) - n, axis=0)])
        return self.apply(padded)[:n].reshape(*lead, N_OUTPUTS)


def padded_rows(n: int) -> int:
    """Row count a batch of ``n`` rows is padded to before the compiled prediction.

    The next power of two up to :data:`PAD_ROWS`, above it the next multiple
    of :data:`PAD_ROWS` (at most 4 % extra work from 100,000 rows up).
    """
    n = int(n)
    if n <= 1:
        return max(n, 1)
    if n <= PAD_ROWS:
        return 1 << (n - 1).bit_length()
    return -(-n // PAD_ROWS) * PAD_ROWS


def _make_apply(emu: Emulator):
    log_mask = jnp.asarray(np.asarray(emu.log_inputs, dtype=bool))
    x_mean, x_sd = jnp.asarray(emu.x_mean), jnp.asarray(emu.x_sd)
    y_mean, y_sd = jnp.asarray(emu.y_mean), jnp.asarray(emu.y_sd)
    log_out = jnp.asarray(np.asarray(emu.log_outputs, dtype=bool))
    net = emu.network
    baseline = None if emu.prior is None else _prior_apply(emu.prior, emu.input_names)

    # log only where asked; the where-guard keeps gradients finite for linear inputs
    def apply(x):
        safe = jnp.where(log_mask, jnp.where(x > 0, x, 1.0), 1.0)
        z = jnp.where(log_mask, jnp.log(safe), x)
        z = jnp.where(log_mask & (x <= 0), jnp.nan, z)
        y = net((z - x_mean) / x_sd) * y_sd + y_mean
        y = jnp.where(log_out, jnp.exp(jnp.where(log_out, y, 0.0)), y)
        if baseline is None:
            return y
        return combine_with_prior(y, baseline(x))

    return apply


def combine_with_prior(correction, prior_outputs):
    """Outputs from a network's correction and the prior mean's outputs (``(..., 25)`` each).

    LVV: the correction is a ratio (``LVV = r_V * LVV_prior``); strains: differences (``r_S + strain_prior``).
    NumPy or JAX arrays; differentiable.
    """
    xp = jnp if isinstance(correction, jax.Array) or isinstance(prior_outputs, jax.Array) else np
    return xp.concatenate([correction[..., :1] * prior_outputs[..., :1],
                           correction[..., 1:] + prior_outputs[..., 1:]], axis=-1)


def correction_targets(outputs, prior_outputs) -> np.ndarray:
    """The inverse of :func:`combine_with_prior`: the network's training targets (LVV ratio, strain differences)."""
    y, p = np.asarray(outputs, dtype=float), np.asarray(prior_outputs, dtype=float)
    return np.concatenate([y[..., :1] / p[..., :1], y[..., 1:] - p[..., 1:]], axis=-1)


def prior_outputs(prior: PriorMean, input_names, x) -> np.ndarray:
    """The prior mean's ``(n, 25)`` outputs (LVV at the subject's size) at inputs ``x`` ``(n, d)`` named ``input_names``."""
    return np.asarray(_prior_apply(prior, tuple(input_names))(jnp.asarray(np.asarray(x, dtype=float))))


def _prior_apply(prior: PriorMean, input_names):
    """``x (..., d)`` of the subject emulator -> the prior's ``(..., 25)`` outputs at the subject's size."""
    cols = prior.columns(input_names)
    inner = prior.emulator.apply
    s3 = float(prior.scale) ** 3

    def baseline(x):
        parts = [x[..., c] if isinstance(c, int) else jnp.full(x.shape[:-1], c, dtype=x.dtype) for c in cols]
        y = inner(jnp.stack(parts, axis=-1))
        return y.at[..., 0].multiply(s3)

    return baseline
