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
    "lvcore.studies.sbc",                  # lvcore study sbc
)


#: The description of each study's ``--help`` (its one-line summary), where its module gives none.
STUDY_DESCRIPTIONS = {
    "geometry-operators": "Table 9.4 on the SYNTHETIC cohort: how far the operators' geometries lie from each "
                          "other against the error of 5- to 10-mode PCA reconstructions (node MSE, cm²).",
    "fibre-discrepancy": "Sections 9.3.2 and 9.4.3: fit data simulated at wrong fibre angles with the volume-only, "
                         "iid and polar-GP discrepancy likelihoods and compare each posterior with the benchmark.",
    "bo-fibres": "Section 9.3.1: Bayesian optimisation of theta with the fibre angles fixed or free, with the FE "
                 "simulator on the SYNTHETIC volunteers (Tables 9.2 and 9.3).",
    "operators": "Section 9.3.3: SQP refits of theta on the other operators' geometries and on 5- and 10-mode PCA "
                 "reconstructions, with adjoint gradients (Figs 9.11-9.14, SYNTHETIC).",
    "mismatch": "Model-data mismatch as a dose-response: sigma_S inflation, output error and theta coverage of "
                "each likelihood as one source of mismatch grows (SYNTHETIC; resumable).",
    "operators-realistic": "Findings F4/F5 with realistic imitation operators (whole-slice choices, trabeculae, "
                           "breath-hold shifts) on 20 or more SYNTHETIC patients, with bootstrap intervals.",
    "bo-mismatch": "Finding F6 as a real test: Bayesian optimisation with fixed or free fibre angles on SYNTHETIC "
                   "volunteer data with a known kind of model-data mismatch.",
}


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
