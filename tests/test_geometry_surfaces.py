"""Malformed endo/epi surface input: each gets a GeometryError that says what to fix."""
import pytest

from lvcore.exceptions import GeometryError
from lvcore.geometry.analytic import EllipsoidSurface, TruncatedEllipsoidLV
from lvcore.geometry.fitting import fit_surfaces
from test_geometry_fitting import ellipsoid_surface_mesh

LV = TruncatedEllipsoidLV(EllipsoidSurface(22.0, 60.0), EllipsoidSurface(31.0, 70.0), 8.0)


def _write(tmp_path, name, surf, scale=1.0, fmt="stl"):
    p = tmp_path / f"{name}.{fmt}"
    ellipsoid_surface_mesh(surf, LV.base_z, scale).save(p)
    return p


def test_surfaces_in_metres_are_detected(tmp_path):
    endo = _write(tmp_path, "endo", LV.endo, scale=1e-3)
    epi = _write(tmp_path, "epi", LV.epi, scale=1e-3)
    with pytest.raises(GeometryError, match="metres"):
        fit_surfaces(endo, epi)


def test_surfaces_in_centimetres_are_detected(tmp_path):
    endo = _write(tmp_path, "endo", LV.endo, scale=0.1)
    epi = _write(tmp_path, "epi", LV.epi, scale=0.1)
    with pytest.raises(GeometryError, match="centimetres"):
        fit_surfaces(endo, epi)


def test_swapped_surfaces_are_detected(tmp_path):
    endo = _write(tmp_path, "endo", LV.endo)
    epi = _write(tmp_path, "epi", LV.epi)
    with pytest.raises(GeometryError, match="swapped"):
        fit_surfaces(epi, endo)


def test_empty_and_missing_surface_files(tmp_path):
    epi = _write(tmp_path, "epi", LV.epi)
    empty = tmp_path / "empty.stl"
    empty.write_bytes(b"")
    with pytest.raises(GeometryError, match="empty"):
        fit_surfaces(empty, epi)
    with pytest.raises(GeometryError, match="does not exist"):
        fit_surfaces(tmp_path / "nope.stl", epi)


def test_unreadable_surface_file(tmp_path):
    epi = _write(tmp_path, "epi", LV.epi)
    junk = tmp_path / "junk.vtp"
    junk.write_text("this is not a mesh")
    with pytest.raises(GeometryError, match="cannot read"):
        fit_surfaces(junk, epi)
