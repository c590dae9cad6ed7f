"""Property-based fuzzing of every reader of user files (issue 15).

Cases, contour JSON, surfaces, measured CSV, geometry scores and campaign
stores get random bytes, random JSON and valid files with one field replaced
by a random value. The property: the input either parses or raises the
package's own error (an :class:`~lvcore.exceptions.LVCoreError`); no other
exception escapes. Bounded to well under 60 s in all (``max_examples`` below,
no deadline).
"""
from __future__ import annotations

import copy
import json
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from lvcore.exceptions import LVCoreError  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: Scale the number of examples for a deeper local run (``LVCORE_FUZZ_SCALE=20 pytest tests/test_fuzz_readers.py``);
#: 1 in CI (about 30 s for the whole module on the 2-core machine).
SCALE = float(os.environ.get("LVCORE_FUZZ_SCALE", "1"))
FUZZ = settings(max_examples=int(40 * SCALE), deadline=None, suppress_health_check=list(HealthCheck), database=None)
FEW = settings(max_examples=int(15 * SCALE), deadline=None, suppress_health_check=list(HealthCheck), database=None)

json_scalars = (st.none() | st.booleans() | st.integers(min_value=-10**40, max_value=10**40)
                | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=20))
json_values = st.recursive(json_scalars, lambda c: st.lists(c, max_size=5) | st.dictionaries(st.text(max_size=8), c,
                                                                                              max_size=5),
                           max_leaves=20)


def _paths(obj, prefix=()):
    """Every path (tuple of keys/indices) into a JSON document."""
    out = [prefix]
    if isinstance(obj, dict):
        for k, v in obj.items():
            out += _paths(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj[:6]):
            out += _paths(v, prefix + (i,))
    return out


def _replace(doc, path, value):
    doc = copy.deepcopy(doc)
    if not path:
        return value
    node = doc
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return doc


@st.composite
def mutated(draw, doc):
    paths = _paths(doc)
    path = paths[draw(st.integers(0, len(paths) - 1))]
    return _replace(doc, path, draw(json_values))


def _text(obj) -> str:
    return json.dumps(obj, allow_nan=True)


def _check(reader, content, suffix):
    """Write ``content`` to a file and read it: success or an LVCoreError, nothing else."""
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / f"input{suffix}"
        p.write_bytes(content if isinstance(content, bytes) else content.encode("utf-8", "surrogatepass"))
        try:
            reader(p)
        except LVCoreError:
            pass


# --------------------------------------------------------------------------- cases
CASE = {
    "geometry": {"kind": "ellipsoid", "endo": {"rs": 7, "rl": 17}, "epi": {"rs": 10, "rl": 20}, "base_z": 5,
                 "resolution": {"circumferential": 6, "longitudinal": [1, 1, 1, 1], "transmural": 1}},
    "material": {"law": "holzapfel-ogden", "a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6},
    "fibres": {"alpha_endo": -60, "alpha_epi": 90},
    "load": {"pressure": 8, "units": "mmHg"},
    "boundary": {"base": "clamped"},
    "probes": [[0, 0, -17]],
    "outputs": {"strain_layer": "wall"},
}


def _load_case(p):
    from lvcore.mechanics.case import load_case

    load_case(p)


@FUZZ
@given(mutated(CASE))
def test_fuzz_case_fields(doc):
    _check(_load_case, _text(doc), ".json")


@FUZZ
@given(st.binary(max_size=300) | json_values.map(_text))
def test_fuzz_case_bytes(content):
    _check(_load_case, content, ".json")


# --------------------------------------------------------------------------- contours
@pytest.fixture(scope="module")
def contours_doc():
    return json.loads((ROOT / "examples" / "contours" / "SYNTHETIC_example_contours.json").read_text())


def _read_contours(p):
    import warnings

    from lvcore.geometry.contours import read_contours

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        read_contours(p)


@FUZZ
@given(data=st.data())
def test_fuzz_contour_fields(contours_doc, data):
    _check(_read_contours, _text(data.draw(mutated(contours_doc))), ".json")


@FUZZ
@given(st.binary(max_size=300) | json_values.map(_text))
def test_fuzz_contour_bytes(content):
    _check(_read_contours, content, ".json")


# --------------------------------------------------------------------------- surfaces
STL = "solid s\n" + "".join(
    f"facet normal 0 0 1\nouter loop\nvertex {a} 0 0\nvertex 0 {b} 0\nvertex 0 0 {c}\nendloop\nendfacet\n"
    for a, b, c in [(30, 30, 30), (30, 31, 29), (29, 30, 31)]) + "endsolid s\n"


def _read_surface(p):
    from lvcore.geometry.surfaces import read_surface

    read_surface(p, "endo")


@FEW
@given(st.binary(max_size=200), st.sampled_from([".stl", ".vtk", ".ply", ".obj", ".vtp"]))
def test_fuzz_surface_bytes(content, suffix):
    _check(_read_surface, content, suffix)


@FEW
@given(st.lists(st.sampled_from(["nan", "1e400", "-", "facet", "vertex 1 2", "", "0", "endloop", "x"]),
                min_size=1, max_size=6), st.integers(0, 2000))
def test_fuzz_surface_ascii_stl(tokens, pos):
    pos = min(pos, len(STL))
    _check(_read_surface, STL[:pos] + " ".join(tokens) + STL[pos:], ".stl")


# --------------------------------------------------------------------------- measured CSV
HEADER = "subject,lvv_ml," + ",".join(f"strain_{k:02d}" for k in range(1, 25))
ROW = "S1,150," + ",".join(["-0.15"] * 24)


def _read_measured(p):
    from lvcore.inference.data import read_measured_csv

    read_measured_csv(p)


cells = st.sampled_from(["", "nan", "1e400", "-1e400", "abc", '"', "'", "\x00", "9" * 400, "-0.1", "150", "0",
                         "subject", "#", ",", "\n", "é"])


@FUZZ
@given(st.lists(st.tuples(st.integers(0, 1), st.integers(0, 25), cells), min_size=1, max_size=4))
def test_fuzz_measured_cells(edits):
    rows = [HEADER.split(","), ROW.split(",")]
    for r, c, v in edits:
        rows[r][min(c, len(rows[r]) - 1)] = v
    _check(_read_measured, "\n".join(",".join(r) for r in rows) + "\n", ".csv")


@FUZZ
@given(st.binary(max_size=300) | st.text(max_size=300))
def test_fuzz_measured_bytes(content):
    _check(_read_measured, content, ".csv")


# --------------------------------------------------------------------------- geometry scores
def _read_scores(p):
    from lvcore.inference.calibrate import read_pc_scores

    read_pc_scores(p)


@FUZZ
@given(json_values.map(_text) | mutated({"h": [0.1, -0.2, 0.3, 0.0, 1.0]}).map(_text)
       | mutated({"h1": 0, "h2": 1, "h3": 2, "h4": 3, "h5": 4}).map(_text))
def test_fuzz_scores_json(content):
    _check(_read_scores, content, ".json")


@FUZZ
@given(st.binary(max_size=200) | st.text(max_size=200), st.sampled_from([".csv", ".npy", ".npz", ".json", ".vtu"]))
def test_fuzz_scores_bytes(content, suffix):
    _check(_read_scores, content, suffix)


@FEW
@given(st.sampled_from([np.float64, np.int8, np.complex128, np.bool_, "U3", np.float32]),
       st.lists(st.integers(0, 4), min_size=0, max_size=3), st.booleans())
def test_fuzz_scores_arrays(dtype, shape, npz):
    arr = np.zeros(shape, dtype=dtype)
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / ("g.npz" if npz else "g.npy")
        (np.savez(p, arr) if npz else np.save(p, arr))
        try:
            _read_scores(p)
        except LVCoreError:
            pass


# --------------------------------------------------------------------------- campaign stores
@pytest.fixture(scope="module")
def good_store(tmp_path_factory):
    from lvcore.campaigns.designs import make_design
    from lvcore.campaigns.space import get_space
    from lvcore.campaigns.store import CampaignStore

    p = tmp_path_factory.mktemp("store") / "s.h5"
    CampaignStore.create(p, make_design(get_space("material"), "lhs", 3, seed=0), forward="campaign_double:forward",
                         resolution="fast").close()
    return p  # a path: hypothesis prints the arguments of failing examples


def _status(p):
    from lvcore.campaigns.runner import campaign_status

    campaign_status(p).format()


@FEW
@given(st.binary(max_size=300))
def test_fuzz_store_bytes(content):
    _check(_status, content, ".h5")


STORE_EDITS = ["del_attr", "set_attr", "del_dataset", "replace_dataset"]
STORE_KEYS = ["format", "space", "design_seed", "design_method", "resolution", "forward", "inputs", "outputs",
              "state", "seconds", "reason", "version", "worker", "finished_at", "record_count"]


@FEW
@given(st.sampled_from(STORE_EDITS), st.sampled_from(STORE_KEYS),
       st.one_of(st.integers(-5, 5), st.text(max_size=30), st.just("{}"), st.just('{"name": "x"}'),
                 st.lists(st.floats(allow_nan=True), max_size=4)))
def test_fuzz_store_layout(good_store, edit, key, value):
    import h5py

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "s.h5"
        p.write_bytes(good_store.read_bytes())
        with h5py.File(p, "r+") as f:
            if edit == "del_attr" and key in f.attrs:
                del f.attrs[key]
            elif edit == "set_attr":
                f.attrs[key] = value if not isinstance(value, list) else np.asarray(value, dtype=float)
            elif edit == "del_dataset" and key in f:
                del f[key]
            elif edit == "replace_dataset":
                if key in f:
                    del f[key]
                f[key] = np.asarray(value if not isinstance(value, str) else [value.encode("utf-8", "replace")])
        try:
            _status(p)
        except LVCoreError:
            pass
    assert os.path.exists(tempfile.gettempdir())
