"""Simulation campaigns: named design spaces, space-filling designs and crash-safe stores.

The forward model of a campaign is a registered :class:`lvcore.core.Forward`
(see :mod:`lvcore.core.registry`); parameter spaces live in :mod:`lvcore.core.space`; rows run on the
executors of :mod:`lvcore.execution.parallel`. Names are imported on first use.
"""
from __future__ import annotations

from lvcore._exports import lazy_exports

_EXPORTS = {
    "Design": "designs", "load_design": "designs", "make_design": "designs", "save_design": "designs",
    "campaign_status": "runner", "resume_campaign": "runner", "run_campaign": "runner",
    "SPACE_NAMES": "space", "get_space": "space",
    "CampaignStore": "store", "StoreContents": "store", "StoreSummary": "store", "read_store": "store",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
