"""Each subpackage exports its public API with ``__all__``; every name resolves, lazily."""
from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

PACKAGES = ("lvcore.mechanics", "lvcore.geometry", "lvcore.emulator", "lvcore.viz", "lvcore.studies",
            "lvcore.core", "lvcore.campaigns", "lvcore.inference", "lvcore.optimise")


@pytest.mark.parametrize("package", PACKAGES)
def test_all_names_resolve(package):
    mod = importlib.import_module(package)
    assert mod.__all__ and len(set(mod.__all__)) == len(mod.__all__)
    for name in mod.__all__:
        assert getattr(mod, name) is not None, name
    assert set(mod.__all__) <= set(dir(mod))
    with pytest.raises(AttributeError, match="no attribute"):
        getattr(mod, "no_such_name")


def test_exports_are_the_defining_objects():
    from lvcore.geometry import geometry_info
    from lvcore.geometry.measures import geometry_info as defined
    from lvcore.mechanics import HolzapfelOgden, format_summary
    from lvcore.mechanics.materials import HolzapfelOgden as law
    from lvcore.mechanics.summary import format_summary as summary

    assert geometry_info is defined and HolzapfelOgden is law and format_summary is summary


def test_importing_a_package_is_lazy():
    """``import lvcore.viz`` / ``lvcore.mechanics`` load no submodule (no Plotly, PyVista or solver) until used.
    ``lvcore.studies`` loads only its registry (frozen dataclasses and the standard library: its exports are the
    registry's study modules), no study."""
    code = ("import sys, lvcore.viz, lvcore.mechanics, lvcore.geometry, lvcore.emulator, lvcore.studies; "
            "print(sorted(m for m in sys.modules if m.startswith(('plotly', 'pyvista', 'numpy', 'lvcore.viz.', "
            "'lvcore.mechanics.', 'lvcore.studies.', 'lvcore.emulator.'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "['lvcore.studies.registry']"
