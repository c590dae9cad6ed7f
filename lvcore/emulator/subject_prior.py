"""The prior mean of a subject emulator: a bundled emulator over PC scores at the subject's size-normalised shape.

:func:`choose_prior` picks the emulator (or none) whose box, base and fixed conditions match the FE runs and
evaluates it at the subject's shape; :func:`describe_prior` says in one sentence what was chosen. Used by
:mod:`lvcore.emulator.subject` (which re-exports these names).
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from lvcore.core.space import ParameterSpace
from lvcore.domain.outputs import DEFAULT_STRAIN_LAYER
from lvcore.emulator.subject_geometry import subject_template_nodes
from lvcore.exceptions import EmulatorError


def _prior_mismatch(emu, space: ParameterSpace, strain_layer: str = DEFAULT_STRAIN_LAYER) -> str | None:
    """Why ``emu`` cannot be the prior mean of a subject emulator over ``space`` with strains of ``strain_layer``
    (None: it can)."""
    if emu.is_subject or emu.prior is not None:
        return "it is itself a subject emulator"
    if emu.strain_layer != strain_layer:
        return f"its strains are {emu.strain_layer}, the FE runs' {strain_layer}"
    if emu.base != space.base:
        return f"its base is {emu.base}, the FE runs' is {space.base}"
    def inside(name, lo, hi) -> bool:  # [lo, hi] within the emulator's box of input `name` (Emulator.in_box's tolerance)
        rows = np.tile(np.asarray(emu.lower, dtype=float), (2, 1))
        rows[:, emu.input_names.index(name)] = (lo, hi)
        return bool(emu.in_box(rows).all())

    def box(name) -> str:
        i = emu.input_names.index(name)
        return f"[{emu.lower[i]:g}, {emu.upper[i]:g}]"

    for n, lo, hi in zip(space.names, space.lower, space.upper):
        if n not in emu.input_names:
            return f"it does not take {n}" + (f" (fixed at {emu.fixed[n]:g})" if n in emu.fixed else "")
        if not inside(n, lo, hi):
            return f"{n}'s range [{lo:g}, {hi:g}] leaves its box {box(n)}"
    for k, v in space.fixed_dict().items():
        if k in emu.fixed and abs(float(emu.fixed[k]) - float(v)) > 1e-9 * max(1.0, abs(float(v))):
            return f"it was trained at {k} = {emu.fixed[k]:g}, the FE runs use {v:g}"
        if k in emu.input_names and not inside(k, v, v):
            return f"{k} = {v:g} is outside its box {box(k)}"
    if any(_score_index(n) is None for n in _score_inputs(emu, space)):
        return f"it takes inputs the subject emulator neither varies nor fixes: {_score_inputs(emu, space)}"
    return None


def _score_inputs(emu, space: ParameterSpace) -> list[str]:
    """The emulator's inputs that the subject's space neither varies nor fixes (PC scores ``h1``, ``h2``, ...)."""
    return [n for n in emu.input_names if n not in space.names and n not in space.fixed_dict()]


def _score_index(name: str) -> int | None:
    """0-based mode of a PC-score input name (``h3`` -> 2), or None for another name."""
    return int(name[1:]) - 1 if name.startswith("h") and name[1:].isdigit() and int(name[1:]) > 0 else None


def choose_prior(space: ParameterSpace, section: Mapping, choice: str = "auto",
                 strain_layer: str = DEFAULT_STRAIN_LAYER):
    """The prior mean of a subject emulator over ``space`` on geometry ``section``.

    The subject's template mesh is split into a size ``s`` and PC scores
    ``h`` of its size-normalised shape
    (:func:`lvcore.geometry.scaling.size_normalised_scores`); the prior is an
    emulator over PC scores (``chapter``, ``angles``, or one on
    ``$LVCORE_EMULATORS``) evaluated there, with LVV times ``s^3``. It must
    match the FE runs: the same base condition and strain layer, every varied input within its
    box, the same fixed conditions. ``auto`` takes the matching emulator with
    the fewest inputs; scores outside its box are clipped to it (recorded;
    the network corrects the rest).

    Parameters
    ----------
    choice : str
        ``auto``, ``none``, or an emulator name or directory.

    Returns
    -------
    (PriorMean or None, dict)
        The prior (None for ``none`` or when no emulator matches under
        ``auto``) and a JSON-ready record of the choice.

    Raises
    ------
    EmulatorError
        When a named emulator does not match (saying why).
    """
    from lvcore.emulator.io import available_emulators, load_emulator
    from lvcore.emulator.model import PriorMean
    from lvcore.geometry.scaling import size_normalised_scores

    choice = str(choice or "auto").strip()
    if choice == "none":
        return None, {"used": False, "reason": "not asked for (--prior none)"}
    names = available_emulators() if choice == "auto" else [choice]
    rejected, candidates = {}, []
    for name in names:
        try:
            emu = load_emulator(name)
        except EmulatorError as err:
            if choice != "auto":
                raise
            rejected[name] = str(err)
            continue
        why = _prior_mismatch(emu, space, strain_layer)
        if why is None:
            candidates.append(emu)
        elif choice != "auto":
            raise EmulatorError(f"--prior {choice}: cannot be the prior mean of this build: {why}; give another "
                                f"emulator, 'auto' or 'none'")
        else:
            rejected[name] = why
    if not candidates:
        return None, {"used": False, "reason": "no emulator matches the FE runs", "rejected": rejected}
    emu = min(candidates, key=lambda e: (len(e.input_names), e.name))
    fixed = space.fixed_dict()
    scores = _score_inputs(emu, space)
    split = size_normalised_scores(subject_template_nodes(section), max([_score_index(n) + 1 for n in scores] or [1]))
    inputs, clipped = {}, []
    for i, n in enumerate(emu.input_names):
        if n in space.names:
            continue
        if n in fixed:
            inputs[n] = float(fixed[n])
            continue
        h = float(split.h[_score_index(n)])
        inputs[n] = float(np.clip(h, emu.lower[i], emu.upper[i]))
        if inputs[n] != h:
            clipped.append(f"{n} {h:.3g} -> {inputs[n]:g}")
    prior = PriorMean(emu, inputs, split.scale)
    record = {"used": True, "name": emu.name, "inputs": inputs, "scale": float(split.scale),
              "projection_mse_cm2": float(split.projection_mse_cm2), "clipped": clipped, "rejected": rejected}
    return prior, record


def describe_prior(record) -> str:
    """One sentence on a subject emulator's prior mean (``metadata["subject"]["prior"]``), for the app and the CLI."""
    rec = dict(record or {})
    if rec.get("used"):
        return (f"The network corrects the bundled `{rec.get('name')}` emulator at this geometry's size-normalised "
                f"shape (scale {float(rec.get('scale', 1.0)):.3f}"
                + (f"; scores clipped to its box: {', '.join(rec['clipped'])}" if rec.get("clipped") else "") + ").")
    if rec:
        return f"No prior mean: {rec.get('reason')}; the network learns the whole map."
    return "Built before prior means were recorded: the network learns the whole map."



__all__ = ["choose_prior", "describe_prior"]
