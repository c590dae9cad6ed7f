"""Neural-network emulators of the simulator (see :mod:`lvcore.emulator.model`)."""
from __future__ import annotations


def load_emulator(name_or_path, *, strict: bool = False):
    """Load an emulator by name or directory; see :func:`lvcore.emulator.io.load_emulator`."""
    from lvcore.emulator.io import load_emulator as _load

    return _load(name_or_path, strict=strict)


__all__ = ["load_emulator"]
