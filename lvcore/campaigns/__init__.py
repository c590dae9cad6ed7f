"""Simulation campaigns: named design spaces, space-filling designs, crash-safe stores and executors.

The forward model of a campaign is a registered :class:`lvcore.core.Forward`
(see :mod:`lvcore.core.registry`); parameter spaces live in :mod:`lvcore.core.space`.
"""
from __future__ import annotations

from lvcore.campaigns.designs import Design, load_design, make_design, save_design
from lvcore.campaigns.executors import DaskExecutor, LocalExecutor, make_executor
from lvcore.campaigns.runner import campaign_status, resume_campaign, run_campaign
from lvcore.campaigns.space import SPACE_NAMES, get_space
from lvcore.campaigns.store import CampaignStore, StoreContents, StoreSummary, read_store

__all__ = [
    "Design", "load_design", "make_design", "save_design", "DaskExecutor", "LocalExecutor", "make_executor",
    "campaign_status", "resume_campaign", "run_campaign", "SPACE_NAMES", "get_space", "CampaignStore",
    "StoreContents", "StoreSummary", "read_store",
]
