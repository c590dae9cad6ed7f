"""Neural-network emulators of the simulator (see :mod:`lvcore.emulator.model`).

Names are imported from their submodules on first use.
"""
from __future__ import annotations

from lvcore._exports import lazy_exports

_EXPORTS = {
    "Emulator": "model", "ExtrapolationWarning": "model", "PriorMean": "model",
    "load_emulator": "io", "save_emulator": "io", "available_emulators": "io", "below_spec_emulators": "io",
    "TrainingConfig": "training", "train_emulator": "training",
    "EmulatorForward": "forward", "emulator_forward": "forward", "load_emulator_forward": "forward",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
