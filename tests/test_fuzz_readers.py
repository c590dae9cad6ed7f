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


def _paths(obj, prefix=(), max_items=6):
    """Every path (tuple of keys/indices) into a JSON document, through the first ``max_items`` of each list."""
    out = [prefix]
    if isinstance(obj, dict):
        for k, v in obj.items():
            out += _paths(v, prefix + (k,), max_items)
    elif isinstance(obj, list):
        for i, v in enumerate(obj[:max_items]):
            out += _paths(v, prefix + (i,), max_items)
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


# several loaded states of one subject (rows with one subject ID, each with its edp_mmhg; strains optional)
STATES_HEADER = "subject,edp_mmhg,lvv_ml," + ",".join(f"strain_{k:02d}" for k in range(1, 25))
STATE_ROWS = ("S1,8,150," + ",".join(["-0.15"] * 24), "S1,20,190," + "," * 23, "S1,14,170," + ",".join(["-0.12"] * 24))


def _read_any(p):
    from lvcore.inference.data import read_measurements

    read_measurements(p)


@FUZZ
@given(st.lists(st.tuples(st.integers(0, 3), st.integers(0, 26), cells | st.sampled_from(["8", "20", "-3"])),
                min_size=1, max_size=5))
def test_fuzz_loaded_state_cells(edits):
    rows = [STATES_HEADER.split(",")] + [r.split(",") for r in STATE_ROWS]
    for r, c, v in edits:
        rows[r][min(c, len(rows[r]) - 1)] = v
    _check(_read_any, "\n".join(",".join(r) for r in rows) + "\n", ".csv")


STATES_JSON = [{"subject": "S1", "edp_mmhg": 8, "lvv_ml": 150, "strains": [-0.15] * 24},
               {"subject": "S1", "edp_mmhg": 20, "lvv_ml": 190}]


@FUZZ
@given(mutated(STATES_JSON).map(_text) | st.lists(mutated(STATES_JSON[1]), max_size=4).map(_text))
def test_fuzz_loaded_state_json(content):
    _check(_read_any, content, ".json")


@FUZZ
@given(st.lists(st.sampled_from(["S1", "S2", ""]), min_size=1, max_size=4),
       st.lists(st.sampled_from([8.0, 20.0, float("nan"), 0.0, 1e9, -1.0]), min_size=1, max_size=4),
       st.lists(st.sampled_from([150.0, float("nan"), 1.5, 0.0]), min_size=1, max_size=4), st.booleans())
def test_fuzz_loaded_state_mat(subjects, edps, lvvs, blank_strains):
    from scipy.io import savemat

    n = len(lvvs)
    strains = np.full((n, 24), np.nan if blank_strains else -0.15)
    strains[0] = -0.15
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "states.mat"
        savemat(p, {"subject": np.array((subjects * n)[:n], dtype=object), "edp_mmhg": np.asarray(edps),
                    "lvv_ml": np.asarray(lvvs), "strains": strains})
        try:
            _read_any(p)
        except LVCoreError:
            pass


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
              "state", "seconds", "reason", "version", "worker", "finished_at", "record_count",
              "format_version", "run", "chain", "chain_position", "seed_row", "start"]  # format version 2


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


# --------------------------------------------------------------------------- binary formats with declared sizes (issue 28)
# Generated headers declare counts from 0 to 10^12; the bodies hold a few items at most. Every reader
# must parse or raise an LVCoreError; the header checks (lvcore.safety.headers) refuse before allocating, and the
# mesh parsers run in a child capped at 1 GB here (lvcore.safety.isolation), so memory stays bounded whatever
# the example declares.
#: The binary-format fuzzers below: 10 examples each in CI (each surface example forks a VTK reader).
BINARY = settings(max_examples=int(10 * SCALE), deadline=None, suppress_health_check=list(HealthCheck), database=None)
counts = st.one_of(st.integers(0, 8), st.integers(9, 10 ** 6), st.sampled_from([10 ** 9, 2 ** 31 - 1, 2 ** 32 + 3,
                                                                                 10 ** 12]))
small_floats = st.lists(st.sampled_from(["0", "1", "-1", "2.5", "30", "nan", "1e400", "x"]), min_size=0, max_size=12)


@pytest.fixture
def capped_reader(monkeypatch):
    from lvcore.safety import limits

    monkeypatch.setattr(limits, "MAX_READER_MEMORY_BYTES", 1024 ** 3)


def _ply(n_vertex, n_face, binary, body):
    fmt = "binary_little_endian" if binary else "ascii"
    head = (f"ply\nformat {fmt} 1.0\nelement vertex {n_vertex}\nproperty float x\nproperty float y\n"
            f"property float z\nelement face {n_face}\nproperty list uchar int vertex_indices\nend_header\n")
    return head.encode() + (body if isinstance(body, bytes) else " ".join(body).encode())


@BINARY
@given(counts, counts, st.booleans(), small_floats | st.binary(max_size=64))
def test_fuzz_ply_declared_counts(capped_reader, n_vertex, n_face, binary, body):
    _check(_read_surface, _ply(n_vertex, n_face, binary, body), ".ply")


@BINARY
@given(st.lists(st.tuples(st.sampled_from(["v", "f", "vn", "l", "#"]),
                          st.lists(st.one_of(st.integers(-10 ** 10, 10 ** 10).map(str),
                                             st.sampled_from(["1/1", "2//3", "-1", "0", "x", "1e3"])),
                                   min_size=0, max_size=4)), min_size=0, max_size=8))
def test_fuzz_obj_face_indices(capped_reader, lines):
    text = "v 0 0 0\nv 30 0 0\nv 0 30 0\nv 0 0 30\n" + "".join(f"{k} {' '.join(t)}\n" for k, t in lines)
    _check(_read_surface, text, ".obj")


@BINARY
@given(counts, counts, st.sampled_from(["ASCII", "BINARY"]), st.sampled_from(["float", "double", "int"]),
       small_floats)
def test_fuzz_vtk_declared_counts(capped_reader, n_points, n_cells, mode, dtype, body):
    text = (f"# vtk DataFile Version 3.0\nfuzz\n{mode}\nDATASET POLYDATA\nPOINTS {n_points} {dtype}\n"
            f"{' '.join(body)}\nPOLYGONS {n_cells} {4 * n_cells}\n3 0 1 2\n")
    _check(_read_surface, text, ".vtk")


def _read_volume(p):
    from lvcore.geometry.volume_mesh import read_volume_cells

    read_volume_cells(p)


@BINARY
@given(counts, counts, counts, st.sampled_from(["2.2", "4.1"]), small_floats)
def test_fuzz_msh_declared_counts(capped_reader, n_nodes, n_elements, max_tag, version, body):
    if version == "2.2":
        nodes = f"$Nodes\n{n_nodes}\n1 {' '.join(body[:3])}\n$EndNodes\n"
        elements = f"$Elements\n{n_elements}\n1 4 2 0 1 1 1 1 1\n$EndElements\n"
    else:
        nodes = f"$Nodes\n1 {n_nodes} 1 {max_tag}\n3 1 0 1\n1\n{' '.join(body[:3])}\n$EndNodes\n"
        elements = f"$Elements\n1 {n_elements} 1 {max_tag}\n3 1 4 1\n1 1 1 1 1\n$EndElements\n"
    text = f"$MeshFormat\n{version} 0 8\n$EndMeshFormat\n{nodes}{elements}"
    _check(_read_volume, text, ".msh")


@BINARY
@given(st.lists(st.one_of(st.integers(0, 8), st.sampled_from([10 ** 5, 10 ** 9, 2 ** 40])), min_size=0, max_size=3),
       st.sampled_from(["<f8", "<f4", "<i8", "|u1", "<c16", "|O", "<U5"]), st.integers(0, 64), st.booleans())
def test_fuzz_npy_npz_declared_shapes(shape, dtype, n_data, npz):
    import hostile_files as hf

    header = hf.npy_header(shape, dtype)[:-16] + b"\x00" * n_data
    content = hf.npz_of({"nodes": header}) if npz else header
    _check(_read_scores, content, ".npz" if npz else ".npy")


def _load_shape_model_npz(p):
    from lvcore.geometry.shape_model import BUNDLED_MODEL, load_shape_model

    p.with_suffix(".json").write_text(BUNDLED_MODEL.with_suffix(".json").read_text())
    load_shape_model(p)


@BINARY
@given(st.dictionaries(st.sampled_from(["mean", "components", "std", "explained_variance_ratio", "x"]),
                       st.lists(st.sampled_from([0, 3, 10 ** 6, 10 ** 9]), min_size=0, max_size=2),
                       min_size=0, max_size=5))
def test_fuzz_shape_model_npz_shapes(members):
    import hostile_files as hf

    content = hf.npz_of({k: hf.npy_header(v) for k, v in members.items()})
    _check(_load_shape_model_npz, content, ".npz")


@BINARY
@given(st.sampled_from(["inputs", "outputs", "state", "record_count", "seconds"]),
       st.sampled_from([0, 1, 5, 10 ** 6, 10 ** 9]), st.integers(-3, 9), st.floats(allow_nan=True))
def test_fuzz_store_declared_rows_and_values(good_store, name, rows, state, value):
    """HDF5 stores whose datasets declare many rows (chunked, nothing written) or hold odd values."""
    import h5py

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "s.h5"
        p.write_bytes(good_store.read_bytes())
        with h5py.File(p, "r+") as f:
            f["state"][0] = state
            f["outputs"][1, 0] = value
            if rows != 3:
                tail, dtype = f[name].shape[1:], f[name].dtype
                del f[name]
                f.create_dataset(name, shape=(rows,) + tail, dtype=dtype, chunks=(1,) + tail if rows else None)
        try:
            s = None
            from lvcore.campaigns.runner import campaign_status

            s = campaign_status(p)
        except LVCoreError:
            pass
        if s is not None:  # the counts always add up; an inconsistent row is never converged
            assert s.converged + s.failed + s.pending + s.inconsistent == s.n


# --------------------------------------------------------------------------- an emulator directory's prior record
@pytest.fixture(scope="module")
def prior_emulator_dir(tmp_path_factory):
    """A subject-style emulator directory with a prior mean (UNTRAINED random networks: the reader only)."""
    from lvcore.emulator.io import save_emulator
    from lvcore.emulator.model import Emulator, PriorMean
    from lvcore.emulator.network import MLP
    from lvcore.domain.outputs import THETA_NAMES, pc_names

    def emulator(name, names, fixed, prior=None):
        d = len(names)
        lower = np.array([0.05, 0.1, 0.05, 0.1] + [-2.0] * (d - 4))
        upper = np.array([10.0, 30.0, 10.0, 30.0] + [2.0] * (d - 4))
        return Emulator(name=name, input_names=names, lower=lower, upper=upper,
                        log_inputs=tuple(n in THETA_NAMES for n in names), x_mean=np.zeros(d), x_sd=np.ones(d),
                        y_mean=np.r_[140.0, np.full(24, -0.15)], y_sd=np.r_[20.0, np.full(24, 0.03)],
                        network=MLP(d, 25, (8, 8), seed=1), fixed=fixed,
                        log_outputs=(True,) + (False,) * 24, prior=prior)

    fixed = {"alpha_endo": -60.0, "alpha_epi": 60.0, "edp": 8.0}
    prior = PriorMean(emulator("chapter", THETA_NAMES + pc_names(5), fixed), {f"h{k}": 0.1 * k for k in range(1, 6)},
                      1.1)
    out = tmp_path_factory.mktemp("prior") / "emu"
    save_emulator(emulator("subject", THETA_NAMES, fixed, prior), out)
    return out


@FUZZ
@given(data=st.data())
def test_fuzz_emulator_prior_record(prior_emulator_dir, data):
    import shutil

    from lvcore.emulator.io import load_emulator

    meta = json.loads((prior_emulator_dir / "metadata.json").read_text())
    record = data.draw(mutated(meta["prior"]) | json_values)
    with tempfile.TemporaryDirectory() as d:
        copy_dir = Path(d) / "emu"
        shutil.copytree(prior_emulator_dir, copy_dir)
        (copy_dir / "metadata.json").write_text(_text({**meta, "prior": record}), encoding="utf-8")
        try:
            emu = load_emulator(copy_dir)
        except LVCoreError:
            return
        if record is not None:  # loaded: the prior's inputs complete the subject's and its scale is usable
            assert emu.prior is not None and emu.prior.scale > 0 and np.all(np.isfinite(list(emu.prior.inputs.values())))
            # strains do not depend on the scale (LVV x scale^3 may overflow for an absurd recorded scale)
            assert np.all(np.isfinite(np.asarray(emu.apply(np.array([0.7, 1.4, 1.1, 3.0])))[1:]))


# --------------------------------------------------------------------------- an EDPVR emulator's folder (edpvr.json)
@FEW
@given(data=st.data())
def test_fuzz_edpvr_emulator_metadata(data):
    """``edpvr.json`` with one field replaced (or random JSON, or bytes): ``load_emulator`` of the folder (the EDPVR
    emulator composed with chapter, lvcore.emulator.edpvr_states) loads it or raises the package's error; a loaded
    one evaluates to finite outputs inside its box."""
    import shutil

    from lvcore.emulator.edpvr import METADATA_FILE, find_edpvr_emulator
    from lvcore.emulator.io import load_emulator

    src = find_edpvr_emulator()
    meta = json.loads((src / METADATA_FILE).read_text())
    content = data.draw(mutated(meta).map(_text) | json_values.map(_text) | st.binary(max_size=200))
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d) / "edpvr"
        shutil.copytree(src, folder)
        (folder / METADATA_FILE).write_bytes(content if isinstance(content, bytes) else content.encode("utf-8"))
        try:
            emu = load_emulator(folder)
        except LVCoreError:
            return
        x = (emu.lower + emu.upper) / 2.0
        assert np.all(np.isfinite(np.asarray(emu.apply(x))))
