"""Test and benchmark tooling that is not science: a real-browser driver for the app
(:mod:`lvcore.testing.browser`) and a SYNTHETIC closed-form forward model
(:class:`lvcore.testing.analytic.AnalyticForward`). Names are imported on first use."""
from __future__ import annotations

from lvcore._exports import lazy_exports

_EXPORTS = {"AnalyticForward": "analytic"}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
