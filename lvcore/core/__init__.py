"""The core layer: one interface between models and everything that uses them.

:mod:`lvcore.core.space`
    :class:`Parameter`, :class:`ParameterSpace`, the chapter's prior box
    (:data:`THETA_BOUNDS`, Table 9.1), the fibre-angle and EDP ranges and
    :func:`build_case` (named inputs -> simulator case).
:mod:`lvcore.core.forward`
    The :class:`Forward` protocol (named physical inputs -> the 25 outputs,
    batched, optional Jacobian) and its implementations
    :class:`SimulatorForward`, :class:`EmulatorForward` and the SYNTHETIC
    :class:`AnalyticForward`.
:mod:`lvcore.core.registry`
    The allow-list of named forwards that campaign stores may refer to.

Campaigns, optimisation, inference, studies and the app take a
:class:`Forward`; none of them builds a case dictionary by hand.
"""
from __future__ import annotations

from lvcore.core.forward import (
    AnalyticForward,
    EmulatorForward,
    Forward,
    ForwardBatch,
    SimulatorForward,
    emulator_forward,
    load_emulator_forward,
)
from lvcore.core.registry import forward_names, make_forward, register_forward, registered_name
from lvcore.core.space import (
    ANGLE_BOUNDS,
    ANGLES_THETA_BOUNDS,
    CHAPTER_ANGLES,
    CHAPTER_EDP,
    EDP_BOUNDS,
    SIGMA_V_ML,
    THETA_BOUNDS,
    Parameter,
    ParameterSpace,
    build_case,
)

__all__ = [
    "Forward", "ForwardBatch", "SimulatorForward", "EmulatorForward", "AnalyticForward", "emulator_forward",
    "load_emulator_forward", "register_forward", "make_forward", "forward_names", "registered_name",
    "Parameter", "ParameterSpace", "build_case", "THETA_BOUNDS", "ANGLES_THETA_BOUNDS", "ANGLE_BOUNDS",
    "EDP_BOUNDS", "CHAPTER_ANGLES", "CHAPTER_EDP", "SIGMA_V_ML",
]
