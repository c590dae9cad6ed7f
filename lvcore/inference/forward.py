"""The forward-model protocol used by calibration, and the emulator adapter.

A *forward model* is any JAX-differentiable callable mapping a parameter
dict to the 25 outputs ``[LVV (mL), 24 circumferential strains]`` in the order
of :mod:`lvcore.outputs`. Fixed physiological conditions (PC scores ``h``,
EDP, fixed fibre angles) are bound into the callable, so the statistical
models in :mod:`lvcore.inference.models` never see them and never care
whether they are given an emulator, the simulator or a closed-form stand-in.

Parameter dict keys: ``a, b, af, bf`` (kPa, -, kPa, -) and, when a model
infers fibre angles, ``alpha_endo, alpha_epi`` (degrees).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Protocol, runtime_checkable

import jax.numpy as jnp
import numpy as np

from lvcore.exceptions import EmulatorError
from lvcore.outputs import ANGLE_NAMES, EDP_NAME, N_OUTPUTS, THETA_NAMES, is_pc_name, pc_names
from lvcore.units import DEFAULT_ALPHA_ENDO_DEG, DEFAULT_ALPHA_EPI_DEG, DEFAULT_EDP_MMHG


@runtime_checkable
class ForwardModel(Protocol):
    """Protocol: ``forward(params) -> y`` with ``y.shape == (25,)``.

    Attributes
    ----------
    param_names : tuple of str
        Keys read from ``params`` (``THETA_NAMES`` and optionally ``ANGLE_NAMES``).
    label : str
        Human-readable description (shown in summaries; says "synthetic" for
        stand-ins).
    """

    param_names: tuple[str, ...]
    label: str

    def __call__(self, params: Mapping[str, Any]) -> Any:  # pragma: no cover - protocol
        ...


# --------------------------------------------------------------------------- emulator adapter
def _emulator_call(emulator) -> Callable:
    """Return ``f(x) -> y`` for a loaded emulator, ``x`` of shape (n_inputs,) in its input order."""
    for attr in ("apply", "predict"):
        fn = getattr(emulator, attr, None)
        if callable(fn):
            return fn
    if callable(emulator):
        return emulator
    raise EmulatorError(
        f"emulator object {type(emulator).__name__} has neither apply() nor predict(); "
        "load it with lvcore.emulator.load_emulator(name)"
    )


@dataclass(frozen=True)
class EmulatorForward:
    """Adapter: a loaded emulator with fixed conditions bound in, as a :class:`ForwardModel`.

    Parameters
    ----------
    emulator : object
        From ``lvcore.emulator.load_emulator(name)``: has ``input_names`` and a
        pure, jittable ``apply``/``predict`` taking an input vector (or a
        mapping of named inputs) and returning the 25 outputs.
    conditions : mapping
        Fixed inputs by name (``h1..h5``; ``edp`` in mmHg and fibre angles in
        degrees for emulators that take them).
    param_names : tuple of str
        Inputs taken from the parameter dict at call time.
    label : str
        Description used in summaries.
    """

    emulator: Any
    conditions: Mapping[str, float]
    param_names: tuple[str, ...] = THETA_NAMES
    label: str = "emulator"
    _named: bool = field(default=False, repr=False)

    @property
    def param_bounds(self) -> dict[str, tuple[float, float]]:
        """The emulator's training box over ``param_names`` (physical units).

        Calibration narrows its uniform priors to this box
        (:func:`lvcore.inference.models.prior_bounds`), so NUTS never asks
        the emulator to extrapolate.
        """
        names = tuple(self.emulator.input_names)
        lower, upper = getattr(self.emulator, "lower", None), getattr(self.emulator, "upper", None)
        if lower is None or upper is None:
            return {}
        return {n: (float(lower[names.index(n)]), float(upper[names.index(n)]))
                for n in self.param_names if n in names}

    def __call__(self, params):
        names = tuple(self.emulator.input_names)
        values = [params[n] if n in self.param_names else self.conditions[n] for n in names]
        fn = _emulator_call(self.emulator)
        if self._named:
            y = fn({n: jnp.asarray(v) for n, v in zip(names, values)})
        else:
            y = fn(jnp.stack([jnp.asarray(v, dtype=jnp.float64) for v in values]))
        return jnp.reshape(jnp.asarray(y), (N_OUTPUTS,))


def emulator_forward(
    emulator,
    h,
    *,
    infer_angles: bool = False,
    alpha_endo: float = DEFAULT_ALPHA_ENDO_DEG,
    alpha_epi: float = DEFAULT_ALPHA_EPI_DEG,
    edp_mmhg: float = DEFAULT_EDP_MMHG,
    name: str | None = None,
) -> EmulatorForward:
    """Bind a geometry (PC scores) and conditions into an emulator.

    Parameters
    ----------
    emulator : object
        A loaded emulator (see :class:`EmulatorForward`).
    h : array_like
        PC scores of the geometry; at least as many as the emulator uses.
    infer_angles : bool
        If True the fibre angles are read from the parameter dict; the
        emulator must take ``alpha_endo`` and ``alpha_epi`` as inputs.
    alpha_endo, alpha_epi : float
        Fixed fibre angles (deg), used when the emulator takes them and
        ``infer_angles`` is False. Ignored by emulators trained at fixed angles.
    edp_mmhg : float
        End-diastolic pressure (mmHg), used when the emulator takes ``edp``.

    Raises
    ------
    EmulatorError
        If angles are to be inferred but the emulator was trained at fixed
        angles, if ``h`` is too short, or if the emulator lacks an input.
    """
    names = tuple(getattr(emulator, "input_names", ()))
    if not names:
        raise EmulatorError("emulator has no input_names; cannot bind conditions")
    label = name or getattr(emulator, "name", "emulator")
    if infer_angles and not set(ANGLE_NAMES) <= set(names):
        raise EmulatorError(
            f"emulator '{label}' was trained at fixed fibre angles (inputs {names}); "
            "use --angles fixed or an emulator with alpha_endo/alpha_epi inputs (e.g. 'angles')"
        )
    h = np.atleast_1d(np.asarray(h, dtype=float))
    n_pc = sum(1 for n in names if is_pc_name(n))
    if h.size < n_pc:
        raise EmulatorError(f"emulator '{label}' needs {n_pc} PC scores, got {h.size}")
    cond = {n: float(v) for n, v in zip(pc_names(n_pc), h[:n_pc])}
    cond.update({ANGLE_NAMES[0]: float(alpha_endo), ANGLE_NAMES[1]: float(alpha_epi), EDP_NAME: float(edp_mmhg)})
    param_names = THETA_NAMES + (ANGLE_NAMES if infer_angles else ())
    missing = [n for n in names if n not in param_names and n not in cond]
    if missing:
        raise EmulatorError(f"emulator '{label}' needs inputs {missing} that calibration cannot supply")
    fwd = EmulatorForward(emulator, cond, param_names, label)
    # Decide once whether the emulator takes a vector or a mapping of named inputs.
    probe = {"a": 1.0, "b": 5.0, "af": 1.0, "bf": 5.0, "alpha_endo": -60.0, "alpha_epi": 60.0}
    try:
        y = fwd(probe)
    except (TypeError, KeyError, IndexError, ValueError, AttributeError):
        fwd = EmulatorForward(emulator, cond, param_names, label, _named=True)
        try:
            y = fwd(probe)
        except Exception as err:  # noqa: BLE001 - re-raised with context
            raise EmulatorError(f"cannot evaluate emulator '{label}': {err}") from err
    if np.asarray(y).shape != (N_OUTPUTS,):
        raise EmulatorError(f"emulator '{label}' returned shape {np.asarray(y).shape}, expected ({N_OUTPUTS},)")
    return fwd


def load_forward(name: str, h, **kwargs) -> EmulatorForward:
    """Load emulator ``name`` via :func:`lvcore.emulator.load_emulator` and bind ``h`` and conditions.

    Never substitutes a stand-in: a missing emulator is an :class:`EmulatorError`
    telling how to build it.
    """
    try:
        from lvcore.emulator import load_emulator
    except ImportError as err:
        raise EmulatorError(
            f"emulator '{name}' not available: lvcore.emulator.load_emulator is missing ({err}); "
            "build emulators with python scripts/build_emulators.py"
        ) from err
    try:
        emulator = load_emulator(name)
    except EmulatorError:
        raise
    except (FileNotFoundError, OSError, KeyError) as err:
        raise EmulatorError(
            f"emulator '{name}' not found in assets/emulators; build it with python scripts/build_emulators.py ({err})"
        ) from err
    return emulator_forward(emulator, h, name=name, **kwargs)


# --------------------------------------------------------------------------- closed-form stand-in
def _analytic_matrix() -> np.ndarray:
    """Fixed smooth loading of the 4 log-parameters onto the 24 regions (deterministic)."""
    r = np.arange(24)
    gamma = (r % 6) * np.pi / 3
    z = (r // 6) / 3.0
    m = np.stack([
        1.0 + 0.3 * z,
        0.6 + 0.4 * np.cos(gamma),
        0.8 * np.sin(gamma + 0.5) + 0.3 * z,
        0.5 - 0.6 * z + 0.3 * np.cos(2 * gamma),
    ], axis=1)
    return m


@dataclass(frozen=True)
class AnalyticForward:
    """SYNTHETIC closed-form stand-in forward model, for tests and benchmarks only.

    Smooth, differentiable and identifiable from 25 noisy outputs; it is not a
    model of the heart. With ``u = log(theta / theta_ref)``:
    ``LVV = 140 - 25 tanh(0.5 u_a + 0.3 u_b + 0.3 u_af + 0.2 u_bf)`` (mL) and
    ``strain_r = -0.15 + 0.04 sum_j M_rj u_j + 0.004 |u|^2`` with ``M`` a fixed
    smooth map over (sector, level). If ``alpha_endo``/``alpha_epi`` are in
    ``param_names`` they shift the strains linearly, by 0.02 per 30 degrees
    times fixed sector (alpha_endo) and level (alpha_epi) patterns that no
    change of theta can mimic.
    """

    theta_ref: tuple[float, float, float, float] = (0.6, 5.0, 1.5, 5.0)
    param_names: tuple[str, ...] = THETA_NAMES
    label: str = "analytic stand-in (SYNTHETIC, tests only)"

    def __call__(self, params):
        u = jnp.stack([jnp.log(jnp.asarray(params[n]) / r) for n, r in zip(THETA_NAMES, self.theta_ref)])
        lvv = 140.0 - 25.0 * jnp.tanh(0.5 * u[0] + 0.3 * u[1] + 0.3 * u[2] + 0.2 * u[3])
        m = jnp.asarray(_analytic_matrix())
        strains = -0.15 + 0.04 * (m @ u) + 0.004 * jnp.sum(u**2)
        if ANGLE_NAMES[0] in self.param_names:
            r = jnp.arange(24)
            zz = (r // 6) / 3.0
            gg = (r % 6) * jnp.pi / 3
            # patterns orthogonal to every column of M and to a constant, so the angles are identifiable
            endo_pattern = jnp.sin(2.0 * gg)                 # sectors
            epi_pattern = 9.0 * (zz - 0.5) ** 2 - 1.25       # levels: +1, -1, -1, +1
            strains = strains + 0.02 * (params["alpha_endo"] + 60.0) / 30.0 * endo_pattern \
                + 0.02 * (params["alpha_epi"] - 60.0) / 30.0 * epi_pattern
        return jnp.concatenate([lvv[None], strains])


__all__ = ["ForwardModel", "EmulatorForward", "emulator_forward", "load_forward", "AnalyticForward"]
