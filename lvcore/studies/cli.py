"""``lvcore study <name>``: each study with a CLI in the registry (:data:`lvcore.studies.registry.STUDIES`) exposes
``add_study_parser(subparsers)`` in its module."""
from __future__ import annotations

import importlib

from lvcore.studies.registry import STUDIES

#: Study modules with a sub-command, one per study, in the registry's order.
STUDY_MODULES = tuple(s.module_name for s in STUDIES.values() if s.cli)

#: The description of each study's ``--help`` (its registry entry's), where its module gives none.
STUDY_DESCRIPTIONS = {s.name: s.description for s in STUDIES.values() if s.cli and s.description}


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "study", help="run one of the chapter's studies",
        description="Run one of the thesis chapter's studies on SYNTHETIC data; each writes its results (JSON, "
                    "CSV) to --out for `lvcore report --from`.")
    studies = parser.add_subparsers(dest="study", required=True)
    for name in STUDY_MODULES:
        importlib.import_module(name).add_study_parser(studies)
    for name, p in studies.choices.items():
        p.description = p.description or STUDY_DESCRIPTIONS.get(name)
