"""The campaign store: nothing lost or duplicated across SIGKILL + resume; failed rows kept.

The forward model here is ``tests/campaign_double.py``, a TEST DOUBLE (a cheap
closed-form function with the simulator's return contract), so that the store
and runner are tested in seconds.
"""
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

import campaign_double
from campaign_double import closed_form
from executor_double import InlineExecutor
from lvcore.campaigns.designs import make_design, save_design
from lvcore.campaigns.runner import campaign_status, resume_campaign, run_campaign
from lvcore.campaigns.space import get_space
from lvcore.campaigns.store import CONVERGED, FAILED, PENDING, CampaignStore, RowResult, read_store
from lvcore.exceptions import CampaignError

TESTS = Path(__file__).parent
DOUBLE = campaign_double.NAME  # registered on import


def _env(**extra):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(TESTS), env.get("PYTHONPATH", "")])
    env.update({k: str(v) for k, v in extra.items()})
    return env


def _cli(*args):
    """The lvcore CLI in a program that registered the test double first (as a user registers a forward)."""
    return [sys.executable, "-c", "import sys, campaign_double; from lvcore.cli import main; sys.exit(main())", *args]


def _log_events(path):
    if not path.exists():
        return []
    return [tuple(line.split()[:2]) for line in path.read_text().splitlines() if line.strip()]


@pytest.mark.slow
def test_sigkill_then_resume_loses_nothing_and_runs_nothing_twice(tmp_path):
    design = make_design(get_space("material"), "sobol", 32, seed=2)
    dpath = save_design(design, tmp_path / "d.csv")
    store_path, log = tmp_path / "s.h5", tmp_path / "exec.log"
    env = _env(LVCORE_TEST_EXEC_LOG=log, LVCORE_TEST_SLEEP=0.15)
    proc = subprocess.Popen(
        _cli("campaign", "run", str(dpath), "--out", str(store_path), "--workers", "2", "--chained",
             "--forward", DOUBLE, "--no-progress"),
        env=env, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
    )
    # wait until a few rows are committed, then kill -9 the campaign and its workers
    deadline = time.time() + 90
    done = 0
    while time.time() < deadline and proc.poll() is None:
        if store_path.exists():
            try:
                done = int(np.sum(read_store(store_path).state != PENDING))
            except CampaignError:
                done = 0
            if done >= 6:
                break
        time.sleep(0.05)
    assert proc.poll() is None, f"campaign ended before it could be killed: {proc.stderr.read().decode()[-2000:]}"
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()

    before = read_store(store_path)
    done_before = np.flatnonzero(before.state != PENDING)
    pending_before = np.flatnonzero(before.state == PENDING)
    assert 6 <= done_before.size < design.n, "the kill must land mid-campaign"
    n_log_before = len(_log_events(log))

    res = subprocess.run(_cli("campaign", "resume", str(store_path), "--workers", "2", "--chained", "--no-progress"),
                         env=env, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "pending 0" in res.stdout

    after = read_store(store_path)
    # every row recorded exactly once, with the right numbers
    assert np.all(after.state == CONVERGED)
    np.testing.assert_array_equal(after.record_count[done_before], 1)
    expected = np.array([closed_form(*row) for row in design.points])
    np.testing.assert_allclose(after.outputs, expected, rtol=1e-12)
    # rows finished before the kill are untouched ...
    np.testing.assert_array_equal(after.outputs[done_before], before.outputs[done_before])
    np.testing.assert_array_equal(after.finished_at[done_before], before.finished_at[done_before])
    # ... and were not run again; each row pending at the kill ran exactly once on resume
    keys = [repr(float(a)) for a in design.points[:, 0]]
    started_after = Counter(k for ev, k in _log_events(log)[n_log_before:] if ev == "start")
    assert not set(started_after) & {keys[i] for i in done_before}
    assert started_after == Counter(keys[i] for i in pending_before)
    # both runs were warm-started continuation chains (--chained): rows started from neighbours' states
    events = [ev for ev, _ in _log_events(log)]
    assert events[:n_log_before].count("warm") > 0 and events[n_log_before:].count("warm") > 0


def test_failed_rows_are_kept_and_reported(tmp_path, monkeypatch):
    import campaign_double

    monkeypatch.setattr(campaign_double, "FAIL_ABOVE_A", 3.0)
    monkeypatch.setattr(campaign_double, "RAISE_ABOVE_B", 20.0)
    design = make_design(get_space("material"), "sobol", 32, seed=1)
    n_nonconv = int(np.sum((design.points[:, 0] > 3.0) & (design.points[:, 1] <= 20.0)))
    n_raise = int(np.sum(design.points[:, 1] > 20.0))
    assert n_nonconv > 0 and n_raise > 0
    summary = run_campaign(design, tmp_path / "s.h5", executor=InlineExecutor(), forward=DOUBLE, progress=False)
    assert summary.n == 32 and summary.pending == 0
    assert summary.failed == n_nonconv + n_raise and summary.converged == 32 - summary.failed
    reasons = dict(summary.reasons)
    assert reasons["test double: line search failed"] == n_nonconv
    assert sum(c for r, c in reasons.items() if r.startswith("SolverError: test double")) == n_raise
    c = read_store(tmp_path / "s.h5")
    assert np.all(np.isnan(c.outputs[c.failed])) and np.all(np.isfinite(c.outputs[c.converged]))
    np.testing.assert_array_equal(c.inputs, design.points)  # no row dropped
    text = campaign_status(tmp_path / "s.h5").format()
    assert "failed %d" % summary.failed in text and "line search failed" in text

    # the CLI status shows the same
    from lvcore.cli import main
    assert main(["campaign", "status", str(tmp_path / "s.h5")]) == 0

    # --retry-failed reruns only the failed rows
    monkeypatch.setattr(campaign_double, "FAIL_ABOVE_A", float("inf"))
    monkeypatch.setattr(campaign_double, "RAISE_ABOVE_B", float("inf"))
    s2 = resume_campaign(tmp_path / "s.h5", retry_failed=True, executor=InlineExecutor(), progress=False)
    assert s2.converged == 32


def test_store_refuses_duplicates_and_concurrent_writers(tmp_path):
    design = make_design(get_space("material"), "lhs", 4, seed=0)
    path = tmp_path / "s.h5"
    with CampaignStore.create(path, design, forward=DOUBLE, resolution="fast") as store:
        store.record(RowResult(1, np.arange(25.0), True, seconds=0.1, worker="w"))
        with pytest.raises(CampaignError, match="twice"):
            store.record(RowResult(1, np.arange(25.0), True))
        with pytest.raises(CampaignError, match="expected 25"):
            store.record(RowResult(2, np.arange(3.0), True))
        with pytest.raises(CampaignError, match="another process"):
            CampaignStore.open(path, "r+")
        store.record(RowResult(3, np.full(25, np.nan), True))  # NaN outputs -> failed, not filled
        np.testing.assert_array_equal(store.pending_rows(), [0, 2])
    c = read_store(path)
    assert list(c.state) == [PENDING, CONVERGED, PENDING, FAILED]
    assert c.reasons[3] == "non-finite outputs"
    with pytest.raises(CampaignError, match="already exists"):
        CampaignStore.create(path, design, forward=DOUBLE, resolution="fast")
    (tmp_path / "junk.h5").write_bytes(b"not hdf5")
    with pytest.raises(CampaignError, match="not a readable HDF5"):
        read_store(tmp_path / "junk.h5")


# ----------------------------------------------------------------------------- hostile stores (issue 15)
def test_plain_hdf5_and_broken_layouts_are_not_stores(tmp_path):
    import h5py

    plain = tmp_path / "plain.h5"
    with h5py.File(plain, "w") as f:
        f["x"] = np.arange(3)
    with pytest.raises(CampaignError, match="not an lvcore campaign store"):
        campaign_status(plain)
    design = make_design(get_space("material"), "lhs", 4, seed=0)
    good = tmp_path / "good.h5"
    CampaignStore.create(good, design, forward=DOUBLE, resolution="fast").close()
    for damage in ("del space", "del state", "bad space", "short outputs", "scalar state"):
        p = tmp_path / f"{damage.replace(' ', '_')}.h5"
        p.write_bytes(good.read_bytes())
        with h5py.File(p, "r+") as f:
            if damage == "del space":
                del f.attrs["space"]
            elif damage == "del state":
                del f["state"]
            elif damage == "bad space":
                f.attrs["space"] = "{not json"
            elif damage == "short outputs":
                del f["outputs"]
                f["outputs"] = np.zeros((4, 3))
            else:
                del f["state"]
                f["state"] = 1
        with pytest.raises(CampaignError, match="not an lvcore campaign store"):
            campaign_status(p)
    with pytest.raises(CampaignError, match="not a regular file"):
        campaign_status(tmp_path)


HOLDER = """
import sys, time
from lvcore.campaigns.store import CampaignStore
store = CampaignStore.open(sys.argv[1], "r+")
print("held", flush=True)
time.sleep(60)
"""


def test_store_opened_through_a_hard_link_says_locked(tmp_path):
    design = make_design(get_space("material"), "lhs", 4, seed=0)
    path, link = tmp_path / "s.h5", tmp_path / "link.h5"
    CampaignStore.create(path, design, forward=DOUBLE, resolution="fast").close()
    os.link(path, link)
    holder = subprocess.Popen([sys.executable, "-c", HOLDER, str(path)], env=_env(), stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(CampaignError, match="locked") as info:
            CampaignStore.open(link, "r+")
        assert "not a readable HDF5" not in str(info.value)
        assert campaign_status(link).n == 4  # reading needs no lock
    finally:
        holder.kill()
        holder.wait()


# ----------------------------------------------------------------------------- the store check (issue 28, finding 4)
def _tampered_store(tmp_path, edit):
    import h5py

    design = make_design(get_space("material"), "lhs", 4, seed=0)
    path = tmp_path / "t.h5"
    with CampaignStore.create(path, design, forward=DOUBLE, resolution="fast") as store:
        for i in range(3):
            store.record(RowResult(i, closed_form(*design.points[i]), True, seconds=0.1, worker="w"))
    with h5py.File(path, "r+") as f:
        edit(f)
    return path


@pytest.mark.parametrize("value", [7, -3])
def test_a_state_outside_0_1_2_is_reported_and_the_counts_add_up(tmp_path, value):
    def edit(f):
        f["state"][1] = value
    path = _tampered_store(tmp_path, edit)
    s = campaign_status(path)
    assert s.converged + s.failed + s.pending + s.inconsistent == s.n == 4
    assert s.inconsistent == 1 and s.converged == 2
    assert f"row 1: state value {value}" in s.format()


@pytest.mark.parametrize("value", [1.5, 0.5, float("nan"), 2.0000001])
def test_a_float_state_that_is_not_0_1_2_is_reported_and_the_counts_add_up(tmp_path, value):
    """A state dataset stored as floats: 1.5 was cast to 1 by the check and counted by nobody (2 + 1 + 0 of 4)."""
    def edit(f):
        state = f["state"][...].astype(float)
        state[1] = value
        del f["state"]
        f["state"] = state
    path = _tampered_store(tmp_path, edit)
    s = campaign_status(path)
    assert s.converged + s.failed + s.pending + s.inconsistent == s.n == 4
    assert s.inconsistent == 1 and s.converged == 2 and s.pending == 1
    assert f"row 1: state value {value}" in s.format()
    assert read_store(path).inconsistent.tolist() == [False, True, False, False]


def test_record_many_writes_a_batch_like_single_records_or_nothing(tmp_path):
    design = make_design(get_space("material"), "lhs", 6, seed=0)
    rows = [RowResult(4, np.arange(25.0) + 4, True, seconds=0.4, worker="w1", version="v"),
            RowResult(1, np.arange(25.0) + 1, True, seconds=0.1, worker="w2", version="v"),
            RowResult(2, np.full(25, np.nan), False, "line search failed", seconds=0.2, worker="w1", version="v")]
    with CampaignStore.create(tmp_path / "one.h5", design, forward=DOUBLE, resolution="fast") as store:
        for r in rows:
            store.record(r)
    with CampaignStore.create(tmp_path / "many.h5", design, forward=DOUBLE, resolution="fast") as store:
        store.record_many(rows)  # unsorted rows: written in order
        # a bad batch writes nothing: a committed row, a duplicate, a row outside the store, wrong outputs
        for bad, match in (([RowResult(0, np.arange(25.0), True), rows[0]], "twice"),
                           ([RowResult(0, np.arange(25.0), True), RowResult(0, np.arange(25.0), True)], "twice"),
                           ([RowResult(0, np.arange(25.0), True), RowResult(6, np.arange(25.0), True)], "outside"),
                           ([RowResult(0, np.arange(25.0), True), RowResult(3, np.arange(3.0), True)], "expected 25")):
            with pytest.raises(CampaignError, match=match):
                store.record_many(bad)
            np.testing.assert_array_equal(store.pending_rows(), [0, 3, 5])
    one, many = read_store(tmp_path / "one.h5"), read_store(tmp_path / "many.h5")
    for field in ("outputs", "state", "seconds", "record_count"):
        np.testing.assert_array_equal(getattr(one, field), getattr(many, field))
    assert one.reasons == many.reasons and one.workers == many.workers and one.versions == many.versions
    assert list(many.state) == [PENDING, CONVERGED, FAILED, PENDING, CONVERGED, PENDING]


def test_converged_rows_with_nan_outputs_or_record_count_5_are_not_healthy(tmp_path):
    from lvcore.cli import main

    def edit(f):
        f["outputs"][0, 3] = np.nan
        f["record_count"][2] = 5
    path = _tampered_store(tmp_path, edit)
    s = campaign_status(path)
    assert s.converged == 1 and s.inconsistent == 2
    text = s.format()
    assert "row 0: converged but its outputs contain NaN" in text and "row 2: converged but recorded 5 times" in text
    c = read_store(path)
    assert c.converged.tolist() == [False, True, False, False]  # what emulator training takes
    assert main(["campaign", "status", str(path), "--check"]) == 2
    assert main(["campaign", "status", str(path)]) == 0


def test_emulator_training_data_exclude_inconsistent_rows(tmp_path):
    from lvcore.emulator.training import load_store_data

    def edit(f):
        f["outputs"][0, 3] = np.inf
        f["inputs"][1, 0] = 1e9  # outside the space
    path = _tampered_store(tmp_path, edit)
    data = load_store_data([path])
    assert data.inputs.shape[0] == 1 and data.n_inconsistent == 2
    assert np.all(np.isfinite(data.outputs))
    assert any("row 1" in p and "outside" in p for p in data.problems)


def test_resume_reports_inconsistent_rows_and_never_runs_them(tmp_path, capsys):
    def edit(f):
        f["state"][1] = 7
    path = _tampered_store(tmp_path, edit)
    s = resume_campaign(path, executor=InlineExecutor(), progress=True)
    assert "row 1: state value 7" in capsys.readouterr().err
    c = read_store(path)
    assert c.state.tolist() == [CONVERGED, 7, CONVERGED, CONVERGED] and s.inconsistent == 1 and s.converged == 3


def test_a_clean_store_passes_the_check(tmp_path):
    from lvcore.cli import main

    path = _tampered_store(tmp_path, lambda f: None)
    assert campaign_status(path).inconsistent == 0 and read_store(path).check() == ()
    assert main(["campaign", "status", str(path), "--check"]) == 0


def test_a_store_declaring_a_billion_rows_is_refused_before_reading(tmp_path):
    """HDF5 dataset shapes are checked on opening (a chunked store of 10^9 rows is a few kB on disk)."""
    import h5py

    good = _tampered_store(tmp_path, lambda f: None)
    p = tmp_path / "huge.h5"
    with h5py.File(good, "r") as src, h5py.File(p, "w") as f:
        for k, v in src.attrs.items():
            f.attrs[k] = v
        n = 10 ** 9
        for name in ("inputs", "outputs", "state", "seconds", "reason", "version", "worker", "finished_at",
                     "record_count"):
            shape = (n,) + src[name].shape[1:]
            f.create_dataset(name, shape=shape, dtype=src[name].dtype, chunks=(1024,) + src[name].shape[1:])
    assert p.stat().st_size < 100_000
    with pytest.raises(CampaignError, match="1,000,000,000 rows"):
        campaign_status(p)


def _version_1(path):
    """Turn a store into the layout of format version 1 (no provenance datasets)."""
    import h5py

    from lvcore.campaigns.store import PROVENANCE

    with h5py.File(path, "r+") as f:
        for key in PROVENANCE:
            del f[key]
        f.attrs["format_version"] = 1


def test_a_version_1_store_is_read_and_migrated_to_version_2_on_resume(tmp_path):
    design = make_design(get_space("material"), "sobol", 8, seed=5)
    path = tmp_path / "s.h5"
    with CampaignStore.create(path, design, forward=DOUBLE, resolution="fast") as store:
        for i in range(3):
            store.record(RowResult(i, closed_form(*design.points[i]), True, seconds=0.1, worker="w"))
    _version_1(path)
    old = read_store(path)  # read as it is: provenance "not recorded"
    assert old.attrs["format_version"] == 1 and np.all(old.run == -1) and np.all(old.seed_row == -1)
    assert campaign_status(path).converged == 3
    resume_campaign(path, executor=InlineExecutor(), progress=False)
    new = read_store(path)
    assert new.attrs["format_version"] == 2 and new.attrs["migrated_from_version"] == 1
    assert np.all(new.state == CONVERGED)
    np.testing.assert_array_equal(new.outputs[:3], old.outputs[:3])
    np.testing.assert_array_equal(new.finished_at[:3], old.finished_at[:3])
    # the rows of the version-1 run keep "not recorded"; the resume is run 1, chained
    np.testing.assert_array_equal(new.run, [-1] * 3 + [1] * 5)
    assert np.all(new.chain[3:] >= 0) and np.all(new.chain[:3] == -1)
    assert not (tmp_path / "s.h5.migrating").exists()


def test_a_store_of_a_newer_format_version_is_refused_with_a_message(tmp_path):
    import h5py

    design = make_design(get_space("material"), "sobol", 4, seed=5)
    path = tmp_path / "s.h5"
    CampaignStore.create(path, design, forward=DOUBLE, resolution="fast").close()
    with h5py.File(path, "r+") as f:
        f.attrs["format_version"] = 3
    with pytest.raises(CampaignError, match="format version 3 is newer than this lvcore"):
        read_store(path)
    with h5py.File(path, "r+") as f:
        f.attrs["format_version"] = "two"
    with pytest.raises(CampaignError, match="'format_version' is 'two'"):
        read_store(path)


def test_a_chained_run_records_its_order_and_seeds(tmp_path):
    from lvcore.campaigns.store import START_COLD, START_WARM

    design = make_design(get_space("material"), "sobol", 30, seed=1)
    path = tmp_path / "s.h5"

    class TwoWorkers(InlineExecutor):
        workers = 2

    run_campaign(design, path, executor=TwoWorkers(), forward=DOUBLE, progress=False)
    s = read_store(path)
    assert np.all(s.run == 0) and set(s.chain.tolist()) == {0, 1, 2, 3}  # two chains per worker
    # each chain's places are 0..len-1, and its first row (no seeds yet) is cold, the others warm from a row
    # solved before them
    for ch in range(4):
        rows = np.flatnonzero(s.chain == ch)
        assert sorted(s.chain_position[rows].tolist()) == list(range(rows.size))
    first = s.chain_position == 0
    assert np.all(s.start[first] == START_COLD) and np.all(s.seed_row[first] == -1)
    assert np.all(s.start[~first] == START_WARM)
    rank = {int(i): n for n, i in enumerate(s.solve_order())}
    for i in np.flatnonzero(~first):
        j = int(s.seed_row[i])
        assert 0 <= j < 30 and j != i
        if s.chain[j] == s.chain[i]:
            assert rank[j] < rank[i]
    assert "warm-started 26, re-solved cold 0" in campaign_status(path).format()
