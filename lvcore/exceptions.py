"""Exceptions raised by :mod:`lvcore`. Each message says what to fix."""
from __future__ import annotations


class LVCoreError(Exception):
    """Base class of every error raised on purpose by lvcore."""


class CaseError(LVCoreError, ValueError):
    """A simulation case is malformed: the message names the field."""

    def __init__(self, field: str, problem: str):
        self.field = field
        self.problem = problem
        super().__init__(f"case field '{field}': {problem}")


class GeometryError(LVCoreError, ValueError):
    """A geometry or segmentation file cannot be used as given."""


class SolverError(LVCoreError, RuntimeError):
    """The nonlinear solve failed (diverged, inverted elements, too many step cuts)."""


class DataError(LVCoreError, ValueError):
    """Measured data (volumes, strains) are malformed or in the wrong units."""


class EmulatorError(LVCoreError, ValueError):
    """An emulator file is malformed or an input is outside the training box in strict mode."""


class CampaignError(LVCoreError, RuntimeError):
    """A campaign store or design cannot be used as given."""


class ForwardError(LVCoreError, ValueError):
    """A forward model was called with inputs it does not read, or in a way it does not support."""


class LimitError(LVCoreError, ValueError):
    """An input exceeds a limit of :mod:`lvcore.safety.limits` (size, count, memory) or is not a regular file."""
