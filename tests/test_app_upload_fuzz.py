"""Property-based fuzzing of the app's uploads through Streamlit's AppTest upload path, under a 4 GB memory cap.

Every upload widget of the Calibration, Geometry & operators and My subject pages gets hypothesis-generated files
(random bytes, random JSON, valid files corrupted by flips, cuts and insertions, valid JSON with one field
replaced, odd file names, wrong contents behind the right extension) and one oversized file. After each upload the
page must show no exception (no traceback), any error it shows must name the user's file and no server path, an
upload without an error must have been used, and what the page showed before from the *other* upload (and the
controls) must still be there. Each page's fuzz runs in a child Python whose address space is capped
(``RLIMIT_AS`` 4 GB, as ``ulimit -v 4000000``), so a reader that allocates wildly, or crashes a native library,
fails the test instead of taking the machine.

Files with a wrong extension never reach a typed widget's reader: Streamlit refuses them itself (in the browser the
file dialog filters them; a forged upload gets Streamlit's "Invalid file extension" exception in that session), so
the typed widgets get their own extensions (in either case) with any contents, and the untyped ones (surfaces and
volume meshes on the Geometry & operators page) any extension.

Examples per widget: ``LVCORE_FUZZ_SCALE`` × a few (``LVCORE_FUZZ_SCALE=10`` for a deeper local run).
"""
from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_fuzz_readers import _paths

ROOT = Path(__file__).resolve().parents[1]
TESTS = Path(__file__).resolve().parent
#: The cap of the child that runs each page's fuzz (bytes): ``ulimit -v 4000000``.
CAP_BYTES = 4_000_000 * 1024
SCALE = float(os.environ.get("LVCORE_FUZZ_SCALE", "1"))


def _examples(n: int):
    return settings(max_examples=max(1, int(n * SCALE)), deadline=None, database=None,
                    suppress_health_check=list(HealthCheck))


# --------------------------------------------------------------------------- generated files
HEADER = "subject,lvv_ml," + ",".join(f"strain_{k:02d}" for k in range(1, 25))
MEASURED_CSV = (HEADER + "\nS1,150," + ",".join(["-0.15"] * 24) + "\n").encode()
MEASURED_JSON = {"subject": "S1", "lvv_ml": 150.0, "strains": [-0.15] * 24}
SCORES_JSON = {"h": [0.1, -0.2, 0.0, 0.3, 0.0], "scale": 1.0}
SCORES_CSV = b"h1,h2,h3,h4,h5\n0.1,-0.2,0,0.3,0\n"
STL = ("solid s\n" + "".join(
    f"facet normal 0 0 1\nouter loop\nvertex {a} 0 0\nvertex 0 {b} 0\nvertex 0 0 {c}\nendloop\nendfacet\n"
    for a, b, c in [(30, 30, 30), (30, 31, 29), (29, 30, 31)]) + "endsolid s\n").encode()
MSH = (b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 10 0 0\n3 0 10 0\n4 0 0 10\n$EndNodes\n"
       b"$Elements\n1\n1 4 2 0 1 1 2 3 4\n$EndElements\n")
INP = b"*NODE\n1, 0, 0, 0\n2, 10, 0, 0\n3, 0, 10, 0\n4, 0, 0, 10\n*ELEMENT, TYPE=C3D4\n1, 1, 2, 3, 4\n"
#: Tokens that upset parsers: huge and non-finite numbers, quotes, separators, NUL, non-ASCII.
NASTY = st.sampled_from([b"nan", b"inf", b"1e400", b"-1e400", b"-", b'"', b"'", b",", b"\n", b"\x00", b"9" * 60,
                         b"<", b">", b"{", b"]", "é".encode(), b"\xff\xfe", b" ", b"1000000000"])

json_scalars = (st.none() | st.booleans() | st.integers(min_value=-10**30, max_value=10**30)
                | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=12))
json_values = st.recursive(json_scalars, lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=6), c,
                                                                                              max_size=4),
                           max_leaves=12)


def _seed(path) -> bytes:
    return Path(path).read_bytes()


@st.composite
def corrupted(draw, seed: bytes):
    """``seed`` with 1-4 edits: a byte replaced, a cut, an insertion (random or nasty bytes), a slice repeated."""
    data = bytearray(seed)
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["flip", "cut", "insert", "repeat"]))
        pos = draw(st.integers(0, max(len(data) - 1, 0)))
        if op == "flip" and data:
            data[pos] = draw(st.integers(0, 255))
        elif op == "cut":
            data = data[:pos] + data[pos + draw(st.integers(1, 400)):] if draw(st.booleans()) else data[:pos]
        elif op == "insert":
            data[pos:pos] = draw(NASTY | st.binary(min_size=1, max_size=16))
        else:
            data += data[pos:pos + draw(st.integers(1, 400))] * draw(st.integers(1, 3))
    return bytes(data)




@st.composite
def mutated(draw, doc):
    """``doc`` (JSON) with one field, list item or the whole replaced by a random JSON value, as bytes."""
    import copy

    paths = _paths(doc, max_items=4)
    path = paths[draw(st.integers(0, len(paths) - 1))]
    value = draw(json_values)
    if not path:
        return json.dumps(value).encode()
    doc = copy.deepcopy(doc)
    node = doc
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return json.dumps(doc, allow_nan=True).encode("utf-8", "surrogatepass")


def contents(seeds: list[bytes], docs: list = ()):
    """Random bytes, random JSON, and the seeds corrupted (and the JSON docs mutated)."""
    parts = [st.binary(max_size=300), json_values.map(lambda v: json.dumps(v).encode("utf-8", "surrogatepass"))]
    parts += [corrupted(s) for s in seeds] + [mutated(d) for d in docs]
    return st.one_of(*parts)


#: File stems: plain, long, non-ASCII, path-like, spaced (never NUL or a folder separator at the end).
stems = st.one_of(st.sampled_from(["a", "my file", "../../etc/passwd", "名前", "x" * 120, ".hidden", "C:\\data\\m",
                                   "<script>", "a;b"]),
                  st.text(alphabet=st.characters(blacklist_characters="\x00", blacklist_categories=("Cs",)),
                          min_size=1, max_size=20))


def names(suffixes):
    """File names with one of ``suffixes`` (lower or upper case; an empty suffix: no extension)."""
    sfx = st.sampled_from(list(suffixes)).flatmap(lambda s: st.sampled_from([s, s.upper()]) if s else st.just(""))
    return st.tuples(stems, sfx).map(lambda t: f"{t[0]}.{t[1]}" if t[1] else t[0]).filter(lambda n: n.strip(" ."))


def _mat(**arrays) -> bytes:
    from scipy.io import savemat

    buf = io.BytesIO()
    savemat(buf, arrays)
    return buf.getvalue()


def _npy(array) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.asarray(array))
    return buf.getvalue()


# --------------------------------------------------------------------------- the page checks
def _texts(at) -> list[str]:
    out = []
    for kind in ("markdown", "success", "caption", "warning", "info"):
        out += [str(e.value) for e in at.get(kind)]
    return out


def _check(at, name, prefix: str, accepted, kept=(), uploaders=()):
    """After an upload of ``name`` (or of several files, a tuple of names): no exception; errors starting with
    ``prefix`` name a file of the upload and no server path; no such error: the upload was used
    (``accepted(texts)``); the ``kept`` texts and the ``uploaders`` are still on the page."""
    from lvcore.app.uploads import display_name

    shown = [display_name(n) for n in ((name,) if isinstance(name, str) else name)]
    assert not at.exception, (name, [str(e.value)[:500] for e in at.exception])
    errors = [str(e.value) for e in at.error]
    for e in errors:
        assert "Traceback" not in e and "/tmp/" not in e and "lvcore_upload_" not in e, (name, e)
    mine = [e for e in errors if e.startswith(prefix)]
    texts = _texts(at)
    if mine:
        assert any(n in e for e in mine for n in shown), (name, shown, mine)
    else:
        assert accepted(texts), (name, errors, texts[:5])
    for k in kept:
        assert any(k in t for t in texts), (name, k, errors)
    for key in uploaders:
        assert at.file_uploader(key=key) is not None, (name, key)


def _page(fragment: str) -> str:
    from lvcore.app import PAGES_DIR

    return str(sorted(PAGES_DIR.glob(f"*{fragment}*.py"))[0])


OVERSIZED = b"0" * (10 * 1024 * 1024 + 1)  # lvcore.app.uploads.MAX_UPLOAD_MB + 1 byte


# --------------------------------------------------------------------------- the pages (run in capped children)
def _fuzz_slot(at, key: str, mime: str, names_st, contents_st, n: int, prefix: str, used, *, kept, controls) -> int:
    """``n`` hypothesis files through the upload widget ``key`` of the page ``at``, each checked by :func:`_check`
    (``prefix``, ``used``, ``kept``, ``controls`` as there); the number of files sent."""
    count = 0

    @_examples(n)
    @given(name=names_st, content=contents_st)
    def upload(name, content):
        nonlocal count
        at.file_uploader(key=key).upload(name, content, mime)
        at.run()
        count += 1
        _check(at, name, prefix, used, kept=kept, uploaders=controls)

    upload()
    return count


def _oversized(at, key: str, name: str, mime: str, prefix: str, *, kept, controls) -> int:
    """One file of 10 MB + 1 byte through the widget ``key``: refused with the limit named, nothing else lost."""
    at.file_uploader(key=key).upload(name, OVERSIZED, mime)
    at.run()
    _check(at, name, prefix, lambda t: False, kept=kept, uploaders=controls)
    assert any("more than the 10 MB allowed" in str(e.value) for e in at.error)
    return 1


def fuzz_calibration() -> int:
    """Calibration page, 'upload': the measured CSV and the geometry (PC scores .json/.csv or template .vtu)."""
    from streamlit.testing.v1 import AppTest

    from lvcore.resources import bundled_volunteers, volunteer_files

    vtu = _seed(volunteer_files(bundled_volunteers()[0]).geometry)
    at = AppTest.from_file(_page("Calibration"), default_timeout=180).run()
    at.radio[0].set_value("upload").run()
    good_data, good_geo = "LVV = 150.0 mL", "PC scores h = 0.10, -0.20"
    controls = ("up_measured", "up_geometry")
    at.file_uploader(key="up_measured").upload("good.csv", MEASURED_CSV, "text/csv")
    at.file_uploader(key="up_geometry").upload("good.json", json.dumps(SCORES_JSON).encode(), "application/json")
    at.run()
    _check(at, "good.json", "Geometry:", lambda t: True, kept=(good_data, good_geo), uploaders=controls)
    count = _fuzz_slot(at, "up_measured", "text/csv", names(["csv"]), contents([MEASURED_CSV, vtu[:2000]]), 12,
                       "Measured data:", lambda t: any("LVV = " in x for x in t), kept=(good_geo,), controls=controls)
    at.file_uploader(key="up_measured").upload("good.csv", MEASURED_CSV, "text/csv")
    at.run()
    count += _fuzz_slot(at, "up_geometry", "application/octet-stream", names(["json", "csv", "vtu"]),
                        contents([SCORES_CSV, vtu], [SCORES_JSON]), 12, "Geometry:",
                        lambda t: any("PC scores h = " in x for x in t), kept=(good_data,), controls=controls)
    for key, prefix, kept in (("up_measured", "Measured data:", good_geo), ("up_geometry", "Geometry:", good_data)):
        at.file_uploader(key="up_measured").upload("good.csv", MEASURED_CSV, "text/csv")
        at.file_uploader(key="up_geometry").upload("good.json", json.dumps(SCORES_JSON).encode(), "application/json")
        at.run()
        count += _oversized(at, key, "big.csv", "text/csv", prefix, kept=(kept,), controls=controls)
    return count


def fuzz_geometry_page() -> int:
    """Geometry & operators page, 'Upload my own': operator 1's contours, volume mesh, or endo + epi surfaces (each
    on a fresh page), while operator 2's valid contours stay fitted."""
    from streamlit.testing.v1 import AppTest

    contours = json.loads((ROOT / "examples" / "contours" / "SYNTHETIC_example_contours.json").read_text())
    fitted = "fitted: residual"
    controls = ("c0", "e0", "p0", "m0", "c1")
    prefix = "Cannot use this segmentation:"
    vtk_seed = (b"# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 3 float\n30 0 0 0 30 0 0 0 30\n"
                b"POLYGONS 1 4\n3 0 1 2\n")
    count = 0

    def fresh():
        at = AppTest.from_file(_page("Geometry"), default_timeout=180).run()
        at.radio[0].set_value("Upload my own").run()
        at.file_uploader(key="c1").upload("good.json", json.dumps(contours).encode(), "application/json")
        at.run()
        assert any(fitted in str(s.value) for s in at.success), [str(e.value) for e in at.error]
        return at

    def used(texts):  # operator 1's upload fitted too
        return sum(fitted in x for x in texts) >= 2

    count += _fuzz_slot(fresh(), "c0", "application/json", names(["json"]), contents([], [contours]), 6, prefix, used,
                        kept=(fitted,), controls=controls)
    at = fresh()
    count += _fuzz_slot(at, "m0", "application/octet-stream", names(["vtu", "vtk", "msh", "inp", "stl", "txt", ""]),
                        contents([MSH, INP, vtk_seed, STL]), 6, prefix, used, kept=(fitted,), controls=controls)
    count += _oversized(at, "m0", "big.vtu", "application/octet-stream", prefix, kept=(fitted,), controls=controls)
    at = fresh()

    @_examples(6)
    @given(endo=names(["stl", "vtk", "ply", "obj", "vtp", "png", ""]), endo_content=contents([STL, vtk_seed]),
           epi_content=contents([STL]))
    def surfaces(endo, endo_content, epi_content):
        nonlocal count
        at.file_uploader(key="e0").upload(endo, endo_content, "application/octet-stream")
        at.file_uploader(key="p0").upload("epi.stl", epi_content, "application/octet-stream")
        at.run()
        count += 1
        _check(at, (endo, "epi.stl"), prefix, used, kept=(fitted,), uploaders=controls)

    surfaces()
    return count


def fuzz_my_subject() -> int:
    """My subject page: the geometry (mesh, template, PC scores, arrays) and the measurements (CSV/JSON/.mat)."""
    from streamlit.testing.v1 import AppTest

    from lvcore.app import subject_flow as flow
    from lvcore.resources import bundled_volunteers, volunteer_files

    vtu = _seed(volunteer_files(bundled_volunteers()[0]).geometry)
    at = AppTest.from_file(_page("My_subject"), default_timeout=180).run()
    at.file_uploader(key="my_data").upload("good.csv", MEASURED_CSV, "text/csv")
    at.file_uploader(key="my_geometry").upload("good.json", json.dumps(SCORES_JSON).encode(), "application/json")
    at.run()
    good_geo, good_data = "Read as **scores**", "**S1**: LVV 150.0 mL"
    controls = ("my_data", "my_geometry")
    _check(at, "good.json", "Geometry:", lambda t: True, kept=(good_geo, good_data), uploaders=controls)
    mat = _mat(subject=np.array(["S1"]), lvv_ml=np.array([150.0]), strains=np.full((1, 24), -0.15))
    count = _fuzz_slot(at, "my_data", "application/octet-stream", names(flow.DATA_TYPES),
                       contents([MEASURED_CSV, mat], [MEASURED_JSON]), 6, "Measurements:",
                       lambda t: any(": LVV " in x for x in t), kept=(good_geo,), controls=controls)
    at.file_uploader(key="my_data").upload("good.csv", MEASURED_CSV, "text/csv")
    at.run()
    arrays = [_npy(np.zeros(5)), _npy(np.zeros((3, 3))), _npy(np.array(["a"])), _npy(np.full(5, np.nan))]
    count += _fuzz_slot(at, "my_geometry", "application/octet-stream", names(flow.GEOMETRY_TYPES),
                        contents([vtu, MSH, INP, SCORES_CSV] + arrays, [SCORES_JSON]), 8, "Geometry:",
                        lambda t: any("Read as **" in x for x in t), kept=(good_data,), controls=controls)
    return count + _oversized(at, "my_geometry", "big.vtu", "application/octet-stream", "Geometry:",
                              kept=(good_data,), controls=controls)


# --------------------------------------------------------------------------- the tests
def _capped(functions: tuple[str, ...], timeout: float = 900, warmup: bool = False) -> dict[str, int]:
    """Run ``functions`` of this module, one after the other, in one child Python capped at :data:`CAP_BYTES`;
    returns each one's example count.

    With ``warmup`` the app's background warm-up (:mod:`lvcore.app.warmup`, what ``lvcore app`` starts once per
    server: the Calibration page's samplers and best fit compiled) runs in that child while the uploads are fuzzed,
    as on a server just started (the child sets itself up as the app's entry script does, with the environment
    ``lvcore app`` gives a capped server); the child then waits for it and reports its state, which must be
    ``done`` or ``partial`` (a stage skipped for short memory, with its note), never ``failed`` or ``skipped``."""
    code = ("import resource, sys, time\n"
            f"resource.setrlimit(resource.RLIMIT_AS, ({CAP_BYTES}, resource.getrlimit(resource.RLIMIT_AS)[1]))\n"
            "from lvcore.app.process import setup_process\n"
            "setup_process()\n"   # as the app's entry script does first (under the cap: its memory economies)
            f"sys.path.insert(0, {str(TESTS)!r})\n"
            "import test_app_upload_fuzz as fuzz\n"
            "import streamlit.testing.v1\n"   # a server has Streamlit (plotly, pandas) imported before it warms up
            "from lvcore.app import warmup\n"
            f"started = warmup.start() if {warmup!r} else False\n"
            f"for name in {tuple(functions)!r}:\n"
            "    print('FUZZED', name, getattr(fuzz, name)(), flush=True)\n"
            "t0 = time.perf_counter()\n"
            "while warmup.STATUS['state'] == 'running' and time.perf_counter() - t0 < 300:\n"
            "    time.sleep(0.5)\n"
            "print('WARMUP', started, warmup.STATUS['state'], warmup.STATUS['error'], flush=True)\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    # what `lvcore app` puts in a capped server's environment (lvcore.app.memory.launch_environment)
    from lvcore.app import memory

    env.setdefault("MALLOC_ARENA_MAX", str(memory.LEAN_MALLOC_ARENAS))
    env.setdefault("ARROW_DEFAULT_MEMORY_POOL", "system")
    if warmup:
        from lvcore.app import warmup as app_warmup

        env[app_warmup.ENV] = "1"
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, timeout=timeout, capture_output=True,
                          encoding="utf-8", errors="replace")  # a reader's stderr may echo the file's bytes
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith(("FUZZED ", "WARMUP "))]
    assert proc.returncode == 0 and lines and lines[-1].startswith("WARMUP "), (
        f"{functions} exited {proc.returncode} under the {CAP_BYTES / 2**30:.1f} GB cap:\n{proc.stdout[-3000:]}\n"
        f"{proc.stderr[-6000:]}")
    state = lines[-1]
    print(state)
    if warmup:
        # it compiled at least one stage beside the fuzz (with the app's memory economies it did all of them)
        assert state.split()[1] == "True" and state.split()[2] in ("done", "partial"), state
    counts = {ln.split()[1]: int(ln.split()[2]) for ln in lines if ln.startswith("FUZZED ")}
    assert set(counts) == set(functions), (functions, lines)
    return counts


@pytest.fixture(scope="module")
def fuzzed_with_the_warmup():
    """The Calibration page (whose samplers the warm-up compiles), fuzzed while the warm-up compiles them (the most
    memory at once), then the My subject page, in one capped child (one warm-up, not one per page: each is
    minutes of compiling on a cold cache, and the second child's warm-up was mostly tracing again)."""
    return _capped(("fuzz_calibration", "fuzz_my_subject"), warmup=True)


def test_calibration_page_uploads_fuzzed_under_a_4gb_cap_with_the_warmup_on(fuzzed_with_the_warmup):
    assert fuzzed_with_the_warmup["fuzz_calibration"] >= 2


def test_geometry_page_uploads_fuzzed_under_a_4gb_cap():
    assert _capped(("fuzz_geometry_page",))["fuzz_geometry_page"] >= 2


def test_my_subject_uploads_fuzzed_under_a_4gb_cap_with_the_warmup_on(fuzzed_with_the_warmup):
    """After the Calibration page's fuzz, in the same capped child: the warm-up's programs are held (or still being
    compiled) while the My subject page reads its uploads."""
    assert fuzzed_with_the_warmup["fuzz_my_subject"] >= 2
