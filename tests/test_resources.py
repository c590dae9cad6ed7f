"""Bundled data is package data: every loader finds it through importlib.resources, from any working directory."""
import importlib.resources
import tomllib
from pathlib import Path

import numpy as np
import pytest

from lvcore import resources
from lvcore.exceptions import DataError


ROOT = Path(__file__).resolve().parents[1]


def test_a_checkout_reads_its_top_level_assets_and_pages():
    assert resources.assets_dir() == ROOT / "assets"
    assert resources.pages_dir() == ROOT / "pages"
    assert resources.asset_path("shape_model", "SYNTHETIC_shape_model.json").is_file()
    assert not (ROOT / "lvcore" / "assets").exists() and not (ROOT / "lvcore" / "app" / "views").exists()


def test_an_install_without_a_checkout_reads_the_package_data(monkeypatch, tmp_path):
    """Outside a checkout (a wheel) the folders are package data: lvcore/assets and lvcore/app/views."""
    monkeypatch.setattr(resources, "_ROOT", tmp_path)  # no pyproject.toml, no assets/ beside the package
    pkg = importlib.resources.files("lvcore")
    assert resources.assets_dir() == pkg / "assets"
    assert resources.pages_dir() == pkg / "app" / "views"


def test_pyproject_ships_every_package_and_maps_the_top_level_folders():
    """pyproject lists the packages by hand (find cannot see mapped folders): the list must match the tree."""
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    tree = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "lvcore").rglob("__init__.py")}
    assert set(cfg["packages"]) == tree | {"lvcore.assets", "lvcore.app.views"}
    assert cfg["package-dir"] == {"lvcore.assets": "assets", "lvcore.app.views": "pages"}


def test_loaders_find_bundled_data_from_a_foreign_working_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # nothing of the checkout is reachable by a relative path
    monkeypatch.delenv("LVCORE_EMULATORS", raising=False)
    from lvcore.emulator.io import available_emulators, below_spec_emulators, load_emulator
    from lvcore.geometry.cohort import load_cohort, load_operator_geometries
    from lvcore.geometry.shape_model import load_shape_model
    from lvcore.inference.data import read_measured_csv

    model = load_shape_model()
    assert model.n_modes > 5 and np.isfinite(model.reconstruct([0.5])).all()
    cohort = load_cohort()
    assert len(cohort.ids) == cohort.nodes.shape[0] > 0
    ops = load_operator_geometries()
    assert ops.contour_path(ops.patients[0], ops.operators[0]).is_file()
    assert {"chapter", "angles"} <= set(available_emulators())
    emu = load_emulator("chapter")
    assert emu.name == "chapter"
    assert "chapter (below spec, demonstration)" in below_spec_emulators()
    names = resources.bundled_volunteers()
    assert len(names) == 8 and all(n.startswith("SYNTHETIC_") for n in names)
    vol = resources.volunteer_files(names[0])
    assert read_measured_csv(vol.measured)[0].y.shape == (25,) and vol.geometry.suffix == ".vtu"
    assert set(resources.example_cases()) >= {"default_lv.json", "land2015_problem1.json"}


def test_unknown_volunteer_names_the_bundled_ones():
    with pytest.raises(DataError, match="SYNTHETIC_HV1"):
        resources.volunteer_files("HV99")


def test_volunteer_truth_for_synthetic_subjects_only():
    from lvcore.resources import bundled_volunteers, volunteer_truth

    name = bundled_volunteers()[0]
    t = volunteer_truth(name)
    assert t is not None and {"a", "b", "af", "bf"} <= set(t)
    assert volunteer_truth(name.replace("_", "-")) == t  # the CSV's subject spelling
    assert volunteer_truth("real-subject-7") is None
