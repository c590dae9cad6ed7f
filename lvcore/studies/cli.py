"""``lvcore study <name>``: each study module exposes ``add_study_parser(subparsers)``."""
from __future__ import annotations

import importlib

#: Study modules, one per study.
STUDY_MODULES = (
    "lvcore.studies.geometry_operators",   # lvcore study geometry-operators
    "lvcore.studies.fibre_discrepancy",    # lvcore study fibre-discrepancy
    "lvcore.studies.bo_fibres",            # lvcore study bo-fibres
    "lvcore.studies.operators",            # lvcore study operators
    "lvcore.studies.mismatch",             # lvcore study mismatch
    "lvcore.studies.operators_realistic",  # lvcore study operators-realistic
    "lvcore.studies.bo_mismatch",          # lvcore study bo-mismatch
)


def register(subparsers) -> None:
    parser = subparsers.add_parser("study", help="run one of the chapter's studies")
    studies = parser.add_subparsers(dest="study", required=True)
    for name in STUDY_MODULES:
        importlib.import_module(name).add_study_parser(studies)
