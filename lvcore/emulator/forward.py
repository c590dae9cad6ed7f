"""The emulator adapter: a trained emulator as a forward model of :mod:`lvcore.core.forward`.

:class:`EmulatorForward` binds fixed conditions (PC scores, fibre angles,
EDP) into an :class:`~lvcore.emulator.model.Emulator` and reads the rest at
call time; it is a pure JAX function (a
:class:`~lvcore.core.forward.TraceableForward`), so NUTS and ``jax.grad`` trace
it. :func:`emulator_forward` binds a geometry and conditions for calibration;
:func:`load_emulator_forward` loads a bundled emulator by name first.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import jax.numpy as jnp
import numpy as np

from lvcore.domain.conditions import SIMULATOR_DEFAULT_ANGLES, SIMULATOR_DEFAULT_EDP_MMHG
from lvcore.core.forward import JaxForward
from lvcore.emulator.io import load_emulator
from lvcore.exceptions import EmulatorError
from lvcore.domain.outputs import ANGLE_NAMES, EDP_NAME, N_OUTPUTS, THETA_NAMES, is_pc_name, pc_names


@dataclass(frozen=True, eq=False)
class EmulatorForward(JaxForward):
    """A trained emulator with fixed conditions bound in: a :class:`~lvcore.core.forward.TraceableForward`.

    Parameters
    ----------
    emulator : lvcore.emulator.model.Emulator
        From :func:`lvcore.emulator.load_emulator`. Its one calling convention
        is used: ``emulator.apply(x)`` with ``x`` of shape ``(..., d)`` in the
        order of ``emulator.input_names`` (physical units), a pure, jittable
        JAX function returning ``(..., 25)``.
    conditions : mapping
        Fixed inputs by name (``h1..hk``; ``edp`` in mmHg and fibre angles in
        degrees for emulators that take them).
    input_names : tuple of str
        Inputs read at call time.
    label : str
    """

    emulator: Any
    conditions: Mapping[str, float]
    input_names: tuple[str, ...] = THETA_NAMES
    label: str = "emulator"

    def __post_init__(self):
        names = tuple(getattr(self.emulator, "input_names", ()) or ())
        if not names or not callable(getattr(self.emulator, "apply", None)):
            raise EmulatorError(f"{type(self.emulator).__name__} is not an emulator (needs input_names and apply); "
                                "load one with lvcore.emulator.load_emulator(name)")
        object.__setattr__(self, "input_names", tuple(self.input_names))
        object.__setattr__(self, "conditions", {str(k): float(v) for k, v in dict(self.conditions).items()})
        missing = [n for n in names if n not in self.input_names and n not in self.conditions]
        if missing:
            raise EmulatorError(f"emulator '{self.label}' needs inputs {missing} that are neither read nor fixed")
        extra = [n for n in self.input_names if n not in names]
        if extra:
            raise EmulatorError(f"emulator '{self.label}' has no input(s) {extra}; its inputs: {list(names)}")

    @property
    def base(self) -> str:
        """Basal boundary condition of the simulations the emulator was trained on."""
        return str(getattr(self.emulator, "base", "clamped"))

    @property
    def input_bounds(self) -> dict[str, tuple[float, float]]:
        """The emulator's training box over ``input_names`` (physical units).

        Calibration narrows its uniform priors to this box
        (:func:`lvcore.inference.models.prior_bounds`), so NUTS never asks
        the emulator to extrapolate.
        """
        names = tuple(self.emulator.input_names)
        return {n: (float(self.emulator.lower[names.index(n)]), float(self.emulator.upper[names.index(n)]))
                for n in self.input_names}

    def _vector(self, params):
        return jnp.stack([jnp.asarray(params[n] if n in self.input_names else self.conditions[n], dtype=jnp.float64)
                          for n in self.emulator.input_names], axis=-1)

    def __call__(self, params):
        return jnp.reshape(self.emulator.apply(self._vector(params)), (N_OUTPUTS,))

    def _check_box(self, x: np.ndarray) -> None:
        full = np.stack([x[:, self.input_names.index(n)] if n in self.input_names
                         else np.full(x.shape[0], self.conditions[n]) for n in self.emulator.input_names], axis=-1)
        check = getattr(self.emulator, "check_inputs", None)
        if check is not None:
            check(full)


def emulator_forward(
    emulator,
    h,
    *,
    infer_angles: bool = False,
    alpha_endo: float = SIMULATOR_DEFAULT_ANGLES[0],
    alpha_epi: float = SIMULATOR_DEFAULT_ANGLES[1],
    edp_mmhg: float = SIMULATOR_DEFAULT_EDP_MMHG,
    name: str | None = None,
) -> EmulatorForward:
    """Bind a geometry (PC scores) and conditions into an emulator for calibration.

    Parameters
    ----------
    emulator : lvcore.emulator.model.Emulator
    h : array_like
        PC scores of the geometry; at least as many as the emulator uses.
    infer_angles : bool
        If True the fibre angles are inputs (read at call time); the emulator
        must take ``alpha_endo`` and ``alpha_epi``.
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
    input_names = THETA_NAMES + (ANGLE_NAMES if infer_angles else ())
    missing = [n for n in names if n not in input_names and n not in cond]
    if missing:
        raise EmulatorError(f"emulator '{label}' needs inputs {missing} that calibration cannot supply")
    cond = {k: v for k, v in cond.items() if k in names and k not in input_names}
    return EmulatorForward(emulator, cond, input_names, label)


def load_emulator_forward(name: str, h, **kwargs) -> EmulatorForward:
    """Load emulator ``name`` (:func:`lvcore.emulator.load_emulator`) and bind ``h`` and conditions.

    Never substitutes a stand-in: a missing emulator is an :class:`EmulatorError`
    telling how to build it. ``kwargs`` go to :func:`emulator_forward`.

    Examples
    --------
    A :class:`lvcore.core.forward.Forward` of the mean shape (all five PC scores 0): θ in, 25 outputs out.

    >>> from lvcore.domain.conditions import THETA_TILDE
    >>> from lvcore.emulator.forward import load_emulator_forward
    >>> forward = load_emulator_forward("chapter", [0.0, 0.0, 0.0, 0.0, 0.0])
    >>> forward.input_names
    ('a', 'b', 'af', 'bf')
    >>> forward(THETA_TILDE).shape
    (25,)
    >>> batch = forward.evaluate({"a": [0.6, 1.2], "b": 1.3, "af": 1.0, "bf": 3.6})
    >>> batch.outputs.shape                      # one row per point
    (2, 25)
    """
    try:
        emulator = load_emulator(name)
    except EmulatorError:
        raise
    except (FileNotFoundError, OSError, KeyError) as err:
        raise EmulatorError(
            f"emulator '{name}' not found; build it with python scripts/build_emulators.py ({err})"
        ) from err
    return emulator_forward(emulator, h, name=name, **kwargs)


__all__ = ["EmulatorForward", "emulator_forward", "load_emulator_forward"]
