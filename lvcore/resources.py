"""Where the bundled data lives: one place that finds the data files and the app's page scripts.

The repository keeps them at its top level: ``assets/`` (the SYNTHETIC cohort,
the PCA shape model, the emulators, the below-spec demonstration emulators,
the SYNTHETIC volunteers, example cases, shipped study results) and
``pages/`` (the app's page scripts). The wheel carries them inside the package
as ``lvcore/assets/`` and ``lvcore/app/views/`` (pyproject maps the folders with
setuptools' ``package-dir``). Loaders ask this module for them:

* from a source checkout (an editable install, or the checkout on
  ``PYTHONPATH``) they are the checkout's top-level folders, beside the
  ``lvcore`` package;
* from an installed wheel they are package data, found through
  :func:`importlib.resources.files`, from any working directory.

The layout under ``assets/``::

    cases/                  example case files (docs/case_schema.md), shown by the app
    cohort/                 SYNTHETIC cohort, operator study, contour stacks
    shape_model/            SYNTHETIC PCA shape model (.npz + .json)
    emulators/<name>/       emulators loaded by name ("chapter", "angles"); emulators/edpvr/ the derived EDPVR's
                            emulator (edpvr.json, lvcore.emulator.edpvr), not a calibration emulator
    emulators-below-spec/   demonstration emulators, loaded only by path
    volunteers/             SYNTHETIC volunteers: <name>_measured.csv, <name>_geometry.vtu
    volunteers/truth/       the volunteers' hidden true parameters
    studies/                saved study results read by ``lvcore report`` (scripts/ship_fibre_discrepancy.py)
    real_lv/                a REAL (patient-derived, not synthetic) LV: Dalton et al. 2022, MIT licence, with its
                            upstream licence text (scripts/ship_real_lv.py)

Building these files is a script's job (``scripts/build_cohort.py``,
``scripts/build_volunteers.py``, ``scripts/build_emulators.py``); their
``--out`` defaults point at the checkout's ``assets/``.
"""
from __future__ import annotations

import atexit
import contextlib
from dataclasses import dataclass
from importlib.resources import as_file, files
from pathlib import Path

from lvcore.exceptions import DataError

#: The bundled-data folder: ``assets/`` in a checkout, ``lvcore/assets/`` (package data) in a wheel.
ASSETS = "assets"
#: The app's page scripts: ``pages/`` in a checkout, ``lvcore/app/views/`` (package data) in a wheel.
PAGES = "pages"
#: Where the wheel puts each top-level folder inside the package (pyproject's ``package-dir``).
_IN_PACKAGE = {ASSETS: ("assets",), PAGES: ("app", "views")}

#: The folder holding the ``lvcore`` package: the repository root when running from a checkout.
_ROOT = Path(__file__).resolve().parent.parent

_extracted = contextlib.ExitStack()  # holds files extracted from a zipped install until exit
atexit.register(_extracted.close)


def _checkout_folder(name: str) -> Path | None:
    """``<repository>/<name>`` when lvcore runs from a source checkout, else None.

    A checkout is recognised by its ``pyproject.toml`` beside the package. It is asked first, so a checkout on
    ``PYTHONPATH`` reads its own data even where another checkout is installed editable in the same environment.
    """
    folder = _ROOT / name
    return folder if (_ROOT / "pyproject.toml").is_file() and folder.is_dir() else None


def _data_path(name: str, *parts: str) -> Path:
    folder = _checkout_folder(name)
    if folder is not None:
        return folder.joinpath(*parts)
    resource = files("lvcore").joinpath(*_IN_PACKAGE[name], *parts)
    if isinstance(resource, Path):
        return resource
    return _extracted.enter_context(as_file(resource))  # pragma: no cover (zipimport only)


def asset_path(*parts: str) -> Path:
    """A file system path to ``assets/<parts...>`` (which need not exist).

    A checkout's top-level ``assets/``, else the installed package data ``lvcore/assets/``. A normal install
    (wheel or editable) keeps the files on disk and this is their path. From a zipped install the file or folder
    is extracted to a temporary location that lives until the interpreter exits.
    """
    return _data_path(ASSETS, *parts)


def assets_dir() -> Path:
    """The bundled-data folder (``assets/``)."""
    return asset_path()


def pages_dir() -> Path:
    """The folder of the app's page scripts: a checkout's ``pages/``, else the installed ``lvcore/app/views/``."""
    return _data_path(PAGES)


def example_cases() -> dict[str, Path]:
    """The bundled example case files (``assets/cases/*.json``), file name -> path, sorted."""
    return {p.name: p for p in sorted(asset_path("cases").glob("*.json"))}


# ----------------------------------------------------------------------------- volunteers
@dataclass(frozen=True)
class VolunteerFiles:
    """The files of one bundled volunteer (SYNTHETIC: generated, not a real subject)."""

    name: str
    measured: Path  #: CSV: subject, lvv_ml, strain_01..strain_24
    geometry: Path  #: early-diastolic template mesh (.vtu)


def volunteers_dir() -> Path:
    """Folder of the bundled SYNTHETIC volunteers."""
    return asset_path("volunteers")


def bundled_volunteers() -> list[str]:
    """Names of the bundled volunteers (e.g. ``SYNTHETIC_HV1``), sorted."""
    d = volunteers_dir()
    if not d.is_dir():
        return []
    return sorted(p.name[: -len("_measured.csv")] for p in d.glob("*_measured.csv"))


def volunteer_files(name: str) -> VolunteerFiles:
    """The measured-data CSV and geometry of bundled volunteer ``name``.

    Raises
    ------
    DataError
        If there is no such volunteer (the message lists the bundled ones).
    """
    d = volunteers_dir()
    files_ = VolunteerFiles(name=name, measured=d / f"{name}_measured.csv", geometry=d / f"{name}_geometry.vtu")
    if not (files_.measured.is_file() and files_.geometry.is_file()):
        known = ", ".join(bundled_volunteers()) or "none"
        raise DataError(f"volunteer '{name}': not bundled with lvcore (bundled: {known})")
    return files_


def volunteer_truth(subject: str) -> dict[str, float] | None:
    """The hidden generating parameters of a SYNTHETIC volunteer (θ and fibre angles), for display only.

    ``subject`` is the measured CSV's subject (``SYNTHETIC-HV1``) or the bundled name (``SYNTHETIC_HV1``).
    Returns None for a subject without a recorded truth (a real subject, an upload). The truth scores a fit;
    it must never enter one.
    """
    import json

    path = volunteers_dir() / "truth" / "SYNTHETIC_volunteers_truth.json"
    if not path.is_file():
        return None
    key = subject.replace("_", "-")
    for t in json.loads(path.read_text()).get("volunteers", []):
        if str(t.get("subject", "")).replace("_", "-") == key:
            return {**{k: float(v) for k, v in t.get("theta", {}).items()},
                    **{k: float(v) for k, v in t.get("fibres_deg", {}).items()}}
    return None


# ----------------------------------------------------------------------------- the real LV
#: The shipped real LV's folder under ``assets/``.
REAL_LV_DIR = "real_lv"
#: Its fitted template mesh (27-node hexahedra, mm).
REAL_LV_TEMPLATE = "real_lv_dalton2022_template.vtu"
#: How it is labelled everywhere: real, patient-derived, with its source.
REAL_LV_LABEL = ("REAL patient-derived LV (not synthetic): Dalton et al. 2022, dodaltuin/passive-lv-gnn-emul, "
                 "MIT licence")


@dataclass(frozen=True)
class RealLVFiles:
    """The shipped real LV (patient-derived, not synthetic; Dalton et al. 2022, MIT licence)."""

    template: Path     #: fitted template mesh (.vtu, mm)
    fit_summary: Path  #: the fit's summary (JSON: cavity volume mL, residual mm, source)
    licence: Path      #: the upstream licence text
    readme: Path       #: attribution and how the files were made
    label: str = REAL_LV_LABEL


def real_lv_files() -> RealLVFiles:
    """The files of the shipped real LV (``assets/real_lv/``; made by ``scripts/ship_real_lv.py``).

    Raises
    ------
    DataError
        If the folder is not shipped (a checkout without the asset).
    """
    d = asset_path(REAL_LV_DIR)
    out = RealLVFiles(d / REAL_LV_TEMPLATE, d / "fit_summary.json", d / "LICENSE-upstream.md", d / "README.md")
    missing = [p.name for p in (out.template, out.fit_summary, out.licence, out.readme) if not p.is_file()]
    if missing:
        raise DataError(f"the real LV is not shipped: {', '.join(missing)} missing in {d} (python scripts/ship_real_lv.py)")
    return out


__all__ = ["ASSETS", "PAGES", "asset_path", "assets_dir", "pages_dir", "example_cases", "VolunteerFiles",
           "volunteers_dir", "bundled_volunteers", "volunteer_files", "volunteer_truth", "REAL_LV_DIR", "REAL_LV_TEMPLATE",
           "REAL_LV_LABEL", "RealLVFiles", "real_lv_files"]
