"""A campaign's rows do not depend on the order of the work (the real simulator, ``fast`` mesh).

One 64-row design over the ``material`` space (24 rows in the soft corner), run three ways
through :func:`run_campaign` / :func:`resume_campaign`: straight (warm-started continuation chains, one
worker), killed half-way and resumed with two workers (four chains for the pending rows: another order,
other seeds), and cold (every row from zero load). Every row of every way equals the cold row within 1e-6 relative in LVV and the 24
strains. The design includes soft rows, where the equilibrium is not unique and a warm start can
converge to another equilibrium than the cold load path: those in the simulator's soft corner
(:func:`lvcore.mechanics.forward.soft_corner`) are solved cold whatever their start, in every way
(``start`` 0), so the test does not depend on how the rounding of a machine sends a warm start. The
store's provenance (run, chain, place in the chain, seed row) is checked against the order the rows
were solved in.

The workers are an in-process executor (tests/executor_double.py): a chain plan for ``workers=2`` runs
its chunks one after another here, so the order differs from one worker's but not with the timing.
Cost (2026-12-02, 2-core machine at load average 36-38, PARDISO): 100 CPU-s (user + sys) for both tests,
547 s wall, with 120 rows (96 moderate); with a separate fourth run on the two-worker plan it was 122 CPU-s, so
that run was folded into the resume. The moderate rows were then cut to the first 40 of the same Sobol sequence
(every soft row kept: they are the ones the guard is for), about half the solves of the four runs.
"""
import numpy as np
import pytest

from executor_double import InlineExecutor
from lvcore.campaigns.designs import Design
from lvcore.campaigns.runner import campaign_status, resume_campaign, run_campaign
from lvcore.campaigns.space import get_space
from lvcore.campaigns.store import PENDING, START_COLD, START_RESOLVED, START_WARM, CampaignStore, read_store
from lvcore.execution import chains
from lvcore.mechanics import forward

N_ROWS = 64
KILL_AFTER = 32


class _Inline(InlineExecutor):
    def __init__(self, workers=1):
        self.workers = workers


#: The soft corner of the ``material`` space (a kPa, b, af kPa, bf), where equilibria are not unique ...
SOFT_BOX = ((0.05, 0.15), (1.0, 3.0), (0.05, 0.12), (0.1, 1.5))
#: ... and typical materials (the ``moderate`` box of benchmarks/bench_campaign.py), where they are.
MODERATE_BOX = ((0.3, 1.5), (1.0, 5.0), (0.3, 1.5), (1.0, 5.0))
N_SOFT = 24


def _sobol(box, n):
    from scipy.stats import qmc

    lo, hi = np.log(np.array(box)).T
    m = int(np.ceil(np.log2(n)))
    return np.exp(lo + qmc.Sobol(4, scramble=True, seed=1).random_base2(m)[:n] * (hi - lo))


@pytest.fixture(scope="module")
def design():
    """24 Sobol rows in the soft corner (:data:`SOFT_BOX`, log-uniform), then 40 in :data:`MODERATE_BOX`.

    Without the guard, 4 of the soft rows alone, chained, were solved to another equilibrium than the cold
    one (3.7–7.7 % in strain), or converged where the cold load path stops at load factor 0.9994.
    """
    return Design(get_space("material"), np.vstack([_sobol(SOFT_BOX, N_SOFT), _sobol(MODERATE_BOX, N_ROWS - N_SOFT)]),
                  "custom", 1)


@pytest.fixture(scope="module")
def cold(design, tmp_path_factory):
    """The design run cold (every row from zero load): the reference."""
    path = tmp_path_factory.mktemp("cold") / "cold.h5"
    run_campaign(design, path, executor=_Inline(1), resolution="fast", progress=False, chained=False)
    return read_store(path)


class _Killed(Exception):
    pass


def _same(a, b):
    np.testing.assert_allclose(a.outputs, b.outputs, rtol=1e-6, atol=1e-9)


@pytest.mark.slow
def test_rows_equal_cold_ones_straight_and_killed_then_resumed_on_two_workers(design, cold, tmp_path, monkeypatch):
    ex = _Inline(1)
    paths = {k: tmp_path / f"{k}.h5" for k in ("straight", "killed")}
    run_campaign(design, paths["straight"], executor=ex, resolution="fast", progress=False)

    # a run stopped once KILL_AFTER rows are committed (what a SIGKILL leaves: committed rows and pending ones)
    record_many = CampaignStore.record_many

    def dying(self, results, **kw):
        if int(np.sum(self.state() != PENDING)) >= KILL_AFTER:
            raise _Killed
        record_many(self, results, **kw)

    monkeypatch.setattr(CampaignStore, "record_many", dying)
    with pytest.raises(_Killed):
        run_campaign(design, paths["killed"], executor=ex, resolution="fast", progress=False)
    monkeypatch.setattr(CampaignStore, "record_many", record_many)
    before = read_store(paths["killed"])
    assert KILL_AFTER <= int(np.sum(before.state != PENDING)) < N_ROWS
    resume_campaign(paths["killed"], executor=_Inline(2), progress=False)

    c = {k: read_store(p) for k, p in paths.items()}
    c["cold"] = cold
    for k in ("straight", "killed"):
        np.testing.assert_array_equal(c[k].state, cold.state, err_msg=k)  # the same rows converged, the same failed
        _same(c[k], cold)
    # rows committed before the kill were not touched by the resume
    done = np.flatnonzero(before.state != PENDING)
    np.testing.assert_array_equal(c["killed"].outputs[done], before.outputs[done])

    # provenance: the cold run is cold; chained runs warm-start from rows of the same store, in chain order
    assert cold.converged.sum() >= N_ROWS - 2  # a soft row's cold load path may stop short: failed in every way
    assert np.all(c["cold"].start == START_COLD) and np.all(c["cold"].chain == -1) and np.all(c["cold"].run == 0)
    for k in ("straight", "killed"):
        s = c[k]
        assert np.sum(s.start != START_COLD) > N_ROWS // 2 and np.sum(s.start == START_WARM) >= 10, k
        warm = s.start != START_COLD
        assert np.all(s.seed_row[warm] >= 0) and np.all(s.seed_row[~warm] == -1), k
        # a seed was solved before the row it started: earlier in the same chain, or in an earlier chunk
        order = {int(i): n for n, i in enumerate(s.solve_order())}
        assert len(order) == N_ROWS
        for i in np.flatnonzero(warm):
            j = int(s.seed_row[i])
            assert s.run[j] <= s.run[i]
            if s.chain[j] == s.chain[i] and s.run[j] == s.run[i]:
                assert s.chain_position[j] < s.chain_position[i]
    assert set(c["killed"].run.tolist()) == {0, 1} and set(c["straight"].run.tolist()) == {0}
    resumed = c["killed"].run == 1
    assert c["straight"].chain.max() >= 1 and c["killed"].chain[resumed].max() >= 3  # two chains per worker
    # the rows of the soft corner were solved cold, in every chained way; the status counts the re-solved ones
    fwd = forward.SimulatorForward(resolution="fast")
    corner = np.array([bool(forward.soft_corner(fwd.case(dict(zip(design.space.names, x))))) for x in design.points])
    assert corner[:N_SOFT].sum() >= N_SOFT // 2 and not corner[N_SOFT:].any()
    for k in ("straight", "killed"):
        assert np.all(c[k].start[corner] == START_COLD), k
        resolved = int(np.sum(c[k].start == START_RESOLVED))
        assert f"re-solved cold {resolved}" in campaign_status(paths[k]).format()


@pytest.mark.slow
def test_without_the_guard_chained_rows_differ_from_their_cold_solves(design, cold, tmp_path, monkeypatch):
    """What the guard is for: warm results left alone (no soft corner, no judgement of the Newton path) are
    another equilibrium on some soft rows."""
    monkeypatch.setattr(forward, "soft_corner", lambda case: "")
    monkeypatch.setattr(chains, "warm_path_problem", lambda log: "")
    run_campaign(design, tmp_path / "chained.h5", executor=_Inline(1), resolution="fast", progress=False)
    chained = read_store(tmp_path / "chained.h5")
    off = ~np.isclose(chained.outputs, cold.outputs, rtol=1e-6, atol=1e-9, equal_nan=True).all(axis=1)
    assert off.sum() >= 1 and np.all(np.flatnonzero(off) < N_SOFT)  # soft rows only
