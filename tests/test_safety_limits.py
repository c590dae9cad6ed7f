"""lvcore.safety.limits: regular files only, size limits, strict JSON, mesh sizes refused before allocation.

Each reader of a user file is checked against a directory, /dev/zero, a FIFO
and an over-size file: it must say "not a regular file" (not "does not
exist") or name the limit, quickly, and raise the package's own error.
"""
from __future__ import annotations

import os
import time

import pytest

from lvcore.safety import limits
from lvcore.exceptions import CampaignError, CaseError, DataError, GeometryError, LimitError, LVCoreError


# --------------------------------------------------------------------------- read_regular_file
def test_read_regular_file_reads_a_file(tmp_path):
    p = tmp_path / "a.txt"
    p.write_bytes(b"hello")
    assert limits.read_regular_file(p, 10, "test file") == b"hello"


def test_directory_is_not_a_regular_file(tmp_path):
    with pytest.raises(LimitError, match="not a regular file.*directory"):
        limits.read_regular_file(tmp_path, 10, "test file")


def test_dev_zero_is_refused_without_reading():
    t0 = time.perf_counter()
    with pytest.raises(LimitError, match="not a regular file.*character device"):
        limits.read_regular_file("/dev/zero", 10, "test file")
    assert time.perf_counter() - t0 < 1.0


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_fifo_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    with pytest.raises(LimitError, match="FIFO"):
        limits.read_regular_file(fifo, 10, "test file")


def test_missing_file_says_does_not_exist(tmp_path):
    with pytest.raises(LimitError, match="does not exist"):
        limits.read_regular_file(tmp_path / "nope", 10, "test file")


def test_oversize_file_is_refused_by_its_size(tmp_path):
    p = tmp_path / "big.json"
    p.write_bytes(b" " * 101)
    with pytest.raises(LimitError, match="larger than the limit of 100 bytes"):
        limits.read_regular_file(p, 100, "test file")


def test_error_factory_is_used(tmp_path):
    with pytest.raises(GeometryError, match="directory"):
        limits.read_regular_file(tmp_path, 10, "mesh", GeometryError)


def test_binary_text_is_refused(tmp_path):
    p = tmp_path / "b.json"
    p.write_bytes(b"\x00\x01\xff\xfe garbage")
    with pytest.raises(LimitError, match="binary"):
        limits.read_text_file(p, 100, "test file")


# --------------------------------------------------------------------------- strict JSON
@pytest.mark.parametrize("text, match", [
    ('{"a": 1, "a": 2}', "duplicate key 'a'"),
    ('{"x": {"b": 1, "b": 1}}', "duplicate key 'b'"),
    ('[1e400]', "too large for a float"),
    ('[-1e400]', "too large for a float"),
    ('[NaN]', "not a number JSON allows"),
    ('[Infinity]', "not a number JSON allows"),
    ("[" + "9" * 5000 + "]", "integer of 5000 digits"),
    ("[" * 200_000 + "]" * 200_000, "nested"),
    ("[" * 100 + "]" * 100, "nested more than 64"),
    ("{", "not valid JSON"),
])
def test_loads_json_refuses(text, match):
    with pytest.raises(LimitError, match=match):
        limits.loads_json(text, "test")


def test_loads_json_accepts_ordinary_json():
    assert limits.loads_json('{"a": [1, 2.5, -3e2, {"b": null}]}', "t") == {"a": [1, 2.5, -300.0, {"b": None}]}


# --------------------------------------------------------------------------- mesh sizes
@pytest.mark.parametrize("counts, kind, match", [
    ((100, 100, 10), "box", "100,000 elements"),
    ((1000, 1000, 1000), "box", "along one direction"),
    ((6, 1000, 1), "lv", "along one direction"),
    ((300, 300, 1), "lv", "elements is more than the limit"),
])
def test_check_mesh_size_refuses_huge_meshes_fast(counts, kind, match):
    t0 = time.perf_counter()
    with pytest.raises(LimitError, match=match):
        limits.check_mesh_size(counts, kind)
    assert time.perf_counter() - t0 < 0.1


def test_check_mesh_size_refuses_by_memory_estimate(monkeypatch):
    monkeypatch.setattr(limits, "memory_budget_bytes", lambda: 100 * limits.MiB)
    with pytest.raises(LimitError, match="GB of memory"):
        limits.check_mesh_size((24, 16, 2), "lv")  # 768 elements ~ 0.75 GB > 100 MB


def test_presets_pass_the_limits():
    from lvcore.mechanics.resolution import RESOLUTION_PRESETS

    for res in RESOLUTION_PRESETS.values():
        limits.check_mesh_size(res.counts, "lv", 9 * res.transmural_gauss_points)
    limits.check_mesh_size((24, 12, 3), "lv")  # Land et al. 2015 problem 2 in the tests


# --------------------------------------------------------------------------- every reader
def _non_regular(tmp_path):
    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)
    return [tmp_path, "/dev/zero", fifo]


def _readers():
    from lvcore.campaigns.store import CampaignStore
    from lvcore.geometry.contours import read_contours
    from lvcore.geometry.io import read_template_mesh
    from lvcore.geometry.surfaces import read_surface
    from lvcore.inference.calibrate import read_pc_scores
    from lvcore.inference.data import read_measured_csv
    from lvcore.mechanics.case import load_case

    return {
        "case": (load_case, CaseError),
        "contours": (read_contours, GeometryError),
        "mesh": (read_template_mesh, GeometryError),
        "surface": (read_surface, GeometryError),
        "measured": (read_measured_csv, DataError),
        "scores": (read_pc_scores, GeometryError),
        "store": (CampaignStore.open, CampaignError),
    }


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
@pytest.mark.parametrize("reader", ["case", "contours", "mesh", "surface", "measured", "scores", "store"])
def test_every_reader_refuses_non_regular_files(tmp_path, reader):
    fn, err = _readers()[reader]
    if reader == "surface":
        import pyvista  # noqa: F401 - imported lazily by the reader; not part of the timing
    for target in _non_regular(tmp_path):
        t0 = time.perf_counter()
        with pytest.raises(err, match="not a regular file") as info:
            fn(target)
        assert "does not exist" not in str(info.value)
        assert time.perf_counter() - t0 < 2.0


@pytest.mark.parametrize("reader, limit, suffix", [
    ("case", "MAX_CASE_BYTES", ".json"),
    ("contours", "MAX_CONTOUR_BYTES", ".json"),
    ("measured", "MAX_MEASURED_BYTES", ".csv"),
    ("scores", "MAX_SCORES_BYTES", ".json"),
    ("mesh", "MAX_MESH_BYTES", ".vtu"),
    ("surface", "MAX_SURFACE_BYTES", ".stl"),
])
def test_every_reader_refuses_oversize_files(tmp_path, monkeypatch, reader, limit, suffix):
    monkeypatch.setattr(limits, limit, 1000)
    p = tmp_path / f"big{suffix}"
    p.write_text(" " * 2000)
    fn, err = _readers()[reader]
    with pytest.raises(err, match="larger than the limit"):
        fn(p)


def test_scores_json_refuses_dev_zero_style_paths(tmp_path):
    from lvcore.inference.calibrate import read_pc_scores

    d = tmp_path / "dir.json"
    d.mkdir()
    with pytest.raises(GeometryError, match="not a regular file"):
        read_pc_scores(d)


def test_limit_errors_are_lvcore_errors():
    assert issubclass(LimitError, LVCoreError)


def test_limits_are_documented():
    from pathlib import Path

    docs = (Path(__file__).resolve().parents[1] / "docs" / "case_schema.md").read_text()
    rel = (Path(__file__).resolve().parents[1] / "docs" / "reliability.md").read_text()
    for name in ("MAX_CASE_BYTES", "MAX_ELEMENTS", "MAX_DOFS", "MAX_PROBES", "MAX_ELEMENTS_PER_DIRECTION"):
        assert name in docs, name
    for name in [n for n in dir(limits) if n.startswith(("MAX_", "MIN_", "PLAUSIBLE_"))]:
        assert name in rel, name
