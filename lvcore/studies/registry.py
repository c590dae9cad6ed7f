"""The one list of the chapter's studies: each study's name, result file, module (load, tables, figures), CLI,
report section and Studies page tab.

Everything that lists the studies is derived from :data:`STUDIES`: ``lvcore study``'s sub-commands
(:data:`lvcore.studies.cli.STUDY_MODULES`), the result files the app and the report look for
(:data:`lvcore.studies.results.RESULT_FILES`), the inputs of the findings table
(:data:`lvcore.studies.findings.SOURCES`), the report's sections (:data:`lvcore.report.build.SECTIONS`) and the
Studies page's tabs. A result file's name is written here only: each study module reads its own from its entry
(:func:`result_file`).

A study module is the interface :class:`StudyModule` describes; its entry names it, and any helper modules it is
split into (:attr:`Study.parts`). ``tests/test_studies_registry.py`` fails when a module of ``lvcore/studies`` is
in no entry, or when a result file's name is written outside this module.

Examples
--------
>>> from lvcore.studies.registry import STUDIES, result_file
>>> result_file("operators")
'operators.json'
>>> [s.name for s in STUDIES.values() if s.cli][:3]
['fibre-discrepancy', 'geometry-operators', 'bo-fibres']
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from types import ModuleType
from typing import Any, Mapping, Protocol, runtime_checkable

#: The package the study modules live in.
PACKAGE = "lvcore.studies"


@runtime_checkable
class StudyModule(Protocol):
    """What every study module provides (a module is checked with ``isinstance(module, StudyModule)``).

    Attributes
    ----------
    TITLES : dict
        Figure or table name -> its title, for every item :func:`figures` can draw.

    Notes
    -----
    ``tables(result)`` and ``figures(result)`` map names of :data:`TITLES` to data frames and Plotly figures;
    ``source_line(result)`` says where the numbers come from. A study with a result file also has
    ``load(folder) -> dict`` (the result read from ``folder``) and ``COMMAND`` (the command that makes it); a study
    computed on demand has ``compute(...)`` instead; a study with a CLI has ``add_study_parser(subparsers)``.
    """

    TITLES: Mapping[str, str]

    def tables(self, result: Any) -> dict: ...

    def figures(self, result: Any) -> dict: ...

    def source_line(self, result: Any) -> str: ...


@dataclass(frozen=True)
class Study:
    """One study of the registry.

    Parameters
    ----------
    name : str
        The study's name, as ``lvcore study <name>`` and the app write it (e.g. ``"bo-fibres"``).
    module : str
        Its module in :mod:`lvcore.studies` (e.g. ``"bo_fibres"``), a :class:`StudyModule`.
    result_file : str or None
        The result file its run writes and ``load`` reads (the shipped one is under ``assets/studies/``); None for a
        study computed on demand (``compute``) or read from other studies' results (:attr:`inputs`).
    cli : bool
        Whether it has a sub-command ``lvcore study <name>`` (its module's ``add_study_parser``).
    description : str
        The ``--help`` description of that sub-command ("" : the module's own).
    report : str or None
        Its section's label in ``lvcore report`` (None: not in the report), with the items it draws there,
        :attr:`report_items` (names of the module's ``TITLES``).
    tab : str or None
        The Studies page tab it is shown on (None: not on that page); studies with the same tab share it.
    inputs : tuple of str
        Names of the studies whose results it reads (the findings table).
    parts : tuple of str
        Helper modules of :mod:`lvcore.studies` the study is split into (no study interface of their own).
    """

    name: str
    module: str
    result_file: str | None = None
    cli: bool = True
    description: str = ""
    report: str | None = None
    report_items: tuple[str, ...] = ()
    tab: str | None = None
    inputs: tuple[str, ...] = ()
    parts: tuple[str, ...] = ()

    @property
    def module_name(self) -> str:
        """The module's full name, e.g. ``lvcore.studies.bo_fibres``."""
        return f"{PACKAGE}.{self.module}"

    def load_module(self) -> ModuleType:
        """The study's module (imported on first use)."""
        return importlib.import_module(self.module_name)

    @property
    def report_file(self) -> str | None:
        """The result file the report looks for: its own, else its first input's (None: computed)."""
        if self.result_file:
            return self.result_file
        return STUDIES[self.inputs[0]].result_file if self.inputs else None

    def load(self, folder=None) -> dict:
        """The study's result read from ``folder`` (its module's ``load``)."""
        return self.load_module().load(folder)

    def tables(self, result) -> dict:
        """The data behind each figure, by name (its module's ``tables``)."""
        return self.load_module().tables(result)

    def figures(self, result) -> dict:
        """The study's figures by name (its module's ``figures``)."""
        return self.load_module().figures(result)


_STUDIES = (
    Study("fibre-angles", "fibre_angles", cli=False, report="Fig 9.5 angle sweep",
          report_items=("fig9_5_angle_sweep", "fig9_5_angle_map")),
    Study("fibre-discrepancy", "fibre_discrepancy", "fibre_discrepancy.json",
          description="Sections 9.3.2 and 9.4.3: fit data simulated at wrong fibre angles with the volume-only, "
                      "iid and polar-GP discrepancy likelihoods and compare each posterior with the benchmark.",
          report="Figs 9.6-9.9 fibre discrepancy",
          report_items=("fig9_6_strain_predictive", "fig9_7_sigma_s", "fig9_7_sigma_s_all_sets",
                        "fig9_8_eta_vs_benchmark", "fig9_9_error_violins", "table_fibre_discrepancy_findings"),
          tab="Fibre discrepancy (Figs 9.6–9.9)"),
    Study("fibre-discrepancy-real-lv", "fibre_discrepancy_real_lv", "fibre_discrepancy_real_lv.json", cli=False,
          report="Fibre discrepancy on the real LV, per strain layer",
          report_items=("fig_real_lv_regional_pattern", "fig_real_lv_regional_spread",
                        "fig_real_lv_sigma_s_inflation", "table_real_lv_findings"),
          tab="Fibre discrepancy (Figs 9.6–9.9)"),
    Study("geometry-operators", "geometry_operators",
          description="Table 9.4 on the SYNTHETIC cohort: how far the operators' geometries lie from each other "
                      "against the error of 5- to 10-mode PCA reconstructions (node MSE, cm²).",
          report="Table 9.4 / Fig 9.10 operators and PCA",
          report_items=("table9_4_operators_pca", "fig_pca_vs_operators", "fig9_10_geometry_effect"),
          tab="Operators, geometry (Table 9.4)"),
    Study("volunteer-calibration", "volunteer_calibration", cli=False, report="calibration posterior",
          report_items=("fig_calibration_posterior", "table_calibration_summary", "fig_calibration_edpvr",
                        "table_calibration_derived")),
    Study("bo-fibres", "bo_fibres", "bo_fibres.json",
          description="Section 9.3.1: Bayesian optimisation of theta with the fibre angles fixed or free, with the "
                      "FE simulator on the SYNTHETIC volunteers (Tables 9.2 and 9.3).",
          report="Tables 9.2/9.3 BO of fibre angles",
          report_items=("table9_2_bo_fixed_angles", "table9_3_bo_free_angles", "fig_bo_lvv_error"),
          tab="Fibre-angle BO (Tables 9.2/9.3)"),
    Study("operators", "operators", "operators.json",
          description="Section 9.3.3: SQP refits of theta on the other operators' geometries and on 5- and 10-mode "
                      "PCA reconstructions, with adjoint gradients (Figs 9.11-9.14, SYNTHETIC).",
          report="Figs 9.11-9.14 operator study",
          report_items=("fig9_11_forward_strain_error", "fig9_12_parameter_error", "fig9_13_rss_surface",
                        "fig9_14_output_error"),
          tab="Operators (Figs 9.11–9.14)", parts=("operators_fit",)),
    Study("mismatch", "mismatch", "mismatch.json",
          description="Model-data mismatch as a dose-response: sigma_S inflation, output error and theta coverage "
                      "of each likelihood as one source of mismatch grows (SYNTHETIC; resumable).",
          report="Model-data mismatch dose-response",
          report_items=("fig_mismatch_sigma_s_inflation", "fig_mismatch_discrepancy_sigma_s",
                        "fig_mismatch_output_error", "table_mismatch_doses", "table_mismatch_real_lv"),
          tab="Mismatch dose–response and findings", parts=("mismatch_sim", "mismatch_fit", "mismatch_docs")),
    Study("findings", "findings", cli=False, report="Findings F1-F6 with verdicts",
          report_items=("table_findings", "table_findings_doses"), tab="Mismatch dose–response and findings",
          inputs=("mismatch", "fibre-discrepancy", "operators", "bo-fibres", "operators-realistic", "bo-mismatch"),
          parts=("findings_rule", "findings_tests", "findings_docs")),
    Study("sbc", "sbc", "sbc.json", report="Simulation-based calibration of the pipeline",
          report_items=("fig_sbc_rank_histograms", "fig_sbc_coverage", "table_sbc_summary"), tab="SBC",
          parts=("sbc_runner", "sbc_stats")),
    Study("information", "information", "information.json",
          description="Information that pins the stiffness: how much a second and third loaded state, the Klotz "
                      "EDPVR prior and a hierarchical cohort fit narrow a's 90 % interval, with the coverage of the "
                      "truth, on SYNTHETIC subjects (FE-simulated default LV; cohorts from the chapter emulator; "
                      "resumable parts, then --summarise).",
          report="Information that pins the stiffness (SYNTHETIC)",
          report_items=("fig_information_a_ratio", "table_information_variants", "verdicts"), tab="Information",
          parts=("information_runner", "information_summary")),
    Study("operators-realistic", "operators_realistic", "operators_realistic.json",
          description="Findings F4/F5 with realistic imitation operators (whole-slice choices, trabeculae, "
                      "breath-hold shifts) on 20 or more SYNTHETIC patients, with bootstrap intervals.",
          tab="Operators (Figs 9.11–9.14)"),
    Study("bo-mismatch", "bo_mismatch", "bo_mismatch.json",
          description="Finding F6 as a real test: Bayesian optimisation with fixed or free fibre angles on SYNTHETIC "
                      "volunteer data with a known kind of model-data mismatch.",
          tab="Fibre-angle BO (Tables 9.2/9.3)"),
    Study("cohort", "cohort", "cohort.json", cli=False, report="Hierarchical calibration of a SYNTHETIC cohort",
          report_items=("fig_cohort_a", "table_cohort_population")),
)

#: Every study by name, in the report's (the chapter's) order.
STUDIES: dict[str, Study] = {s.name: s for s in _STUDIES}
#: Modules of :mod:`lvcore.studies` that serve every study (no study of their own).
SHARED = ("__init__", "_common", "cli", "registry", "results")


def study(name: str) -> Study:
    """The registry entry of ``name`` (``"bo-fibres"``) or of its module (``"bo_fibres"``); KeyError naming the
    registered studies otherwise."""
    for s in STUDIES.values():
        if name in (s.name, s.module):
            return s
    raise KeyError(f"no study {name!r}; registered: {', '.join(STUDIES)}")


def result_file(name: str) -> str:
    """The result file of study ``name`` (its registry entry's, the only place the name is written)."""
    s = study(name)
    if s.result_file is None:
        raise KeyError(f"study {s.name!r} has no result file of its own")
    return s.result_file


def tabs() -> dict[str, tuple[Study, ...]]:
    """The Studies page's tabs in order of first appearance: tab label -> its studies, in registry order."""
    out: dict[str, list[Study]] = {}
    for s in STUDIES.values():
        if s.tab:
            out.setdefault(s.tab, []).append(s)
    return {k: tuple(v) for k, v in out.items()}


def modules() -> dict[str, str]:
    """Every module of :mod:`lvcore.studies` the registry accounts for: module -> what it is (a study's name, the
    study a part belongs to, or ``shared``)."""
    out = dict.fromkeys(SHARED, "shared")
    for s in STUDIES.values():
        out[s.module] = s.name
        out.update(dict.fromkeys(s.parts, f"part of {s.name}"))
    return out


__all__ = ["PACKAGE", "SHARED", "STUDIES", "Study", "StudyModule", "modules", "result_file", "study", "tabs"]
