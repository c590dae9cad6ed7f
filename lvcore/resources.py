"""Where the bundled data lives: one place that finds files shipped inside the package.

Everything the package ships (the SYNTHETIC cohort, the PCA shape model, the
emulators, the below-spec demonstration emulators and the SYNTHETIC
volunteers) sits in ``lvcore/assets/`` and is installed with the package as
package data. Loaders ask this module for it, through
:func:`importlib.resources.files`, so a wheel installed into any
environment finds its data from any working directory; nothing reads the
repository checkout.

The layout under ``lvcore/assets/``::

    cases/                  example case files (docs/case_schema.md), shown by the app
    cohort/                 SYNTHETIC cohort, operator study, contour stacks
    shape_model/            SYNTHETIC PCA shape model (.npz + .json)
    emulators/<name>/       emulators loaded by name ("chapter", "angles")
    emulators-below-spec/   demonstration emulators, loaded only by path
    volunteers/             SYNTHETIC volunteers: <name>_measured.csv, <name>_geometry.vtu
    volunteers/truth/       the volunteers' hidden true parameters
    studies/                saved study results read by ``lvcore report`` (scripts/ship_fibre_discrepancy.py)

Building these files is a script's job (``scripts/build_cohort.py``,
``scripts/build_volunteers.py``, ``scripts/build_emulators.py``); their
``--out`` defaults point here.
"""
from __future__ import annotations

import atexit
import contextlib
from dataclasses import dataclass
from importlib.resources import as_file, files
from pathlib import Path

from lvcore.exceptions import DataError

#: The bundled-data folder inside the package.
ASSETS = "assets"

_extracted = contextlib.ExitStack()  # holds files extracted from a zipped install until exit
atexit.register(_extracted.close)


def asset_path(*parts: str) -> Path:
    """A file system path to ``lvcore/assets/<parts...>`` (which need not exist).

    A normal install (wheel, editable or source checkout) keeps the files on
    disk and this is their path. From a zipped install the file or folder is
    extracted to a temporary location that lives until the interpreter exits.
    """
    resource = files("lvcore").joinpath(ASSETS, *parts)
    if isinstance(resource, Path):
        return resource
    return _extracted.enter_context(as_file(resource))  # pragma: no cover (zipimport only)


def assets_dir() -> Path:
    """The bundled-data folder ``lvcore/assets``."""
    return asset_path()


def example_cases() -> dict[str, Path]:
    """The bundled example case files (``lvcore/assets/cases/*.json``), file name -> path, sorted."""
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


__all__ = ["ASSETS", "asset_path", "assets_dir", "example_cases", "VolunteerFiles", "volunteers_dir", "bundled_volunteers",
           "volunteer_files", "volunteer_truth"]
