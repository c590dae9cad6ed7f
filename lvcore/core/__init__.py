"""The core layer: the one interface between models and everything that uses them (no implementation).

:mod:`lvcore.core.space`
    :class:`Parameter`, :class:`ParameterSpace`, the chapter's prior box
    (:data:`THETA_BOUNDS`, Table 9.1) and the fibre-angle and EDP ranges
    (the case for named inputs is :func:`lvcore.mechanics.case_inputs.build_case`).
:mod:`lvcore.core.forward`
    The :class:`Forward` protocol (named physical inputs -> the 25 outputs,
    batched) and its capabilities :class:`JacobianForward` and
    :class:`TraceableForward`; :class:`ForwardBatch`. The implementations
    live next to what they wrap: :mod:`lvcore.mechanics.forward` (the
    simulator), :mod:`lvcore.emulator.forward`, :mod:`lvcore.testing.analytic`.
:mod:`lvcore.core.registry`
    The allow-list of named forwards that campaign stores may refer to.

Campaigns, optimisation, inference, studies and the app take a
:class:`Forward`; none of them builds a case dictionary by hand. Names are imported on first use.
"""
from __future__ import annotations

from lvcore._exports import lazy_exports

_EXPORTS = {
    "Forward": "forward", "JacobianForward": "forward", "TraceableForward": "forward", "ForwardBatch": "forward",
    "JaxForward": "forward",
    "register_forward": "registry", "make_forward": "registry", "forward_names": "registry",
    "registered_name": "registry",
    "Parameter": "space", "ParameterSpace": "space", "THETA_BOUNDS": "space",
    "ANGLES_THETA_BOUNDS": "space", "ANGLE_BOUNDS": "space", "EDP_BOUNDS": "space",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS,
                                   moved={"build_case": "lvcore.mechanics.case_inputs:build_case"})
