"""Moved to :mod:`lvcore.core.forward`; this module re-exports the old names for now."""
from __future__ import annotations

from lvcore.core.forward import AnalyticForward, EmulatorForward, Forward, emulator_forward
from lvcore.core.forward import Forward as ForwardModel  # noqa: F401
from lvcore.core.forward import load_emulator_forward as load_forward

__all__ = ["ForwardModel", "Forward", "EmulatorForward", "emulator_forward", "load_forward", "AnalyticForward"]
