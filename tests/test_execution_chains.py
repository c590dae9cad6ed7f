"""Continuation chains (lvcore.execution.chains): order, scheduling, and warm-chained results equal cold ones."""
from concurrent.futures import Future

import numpy as np
import pytest

import campaign_double
from campaign_double import closed_form
from lvcore.execution import chains
from lvcore.campaigns.designs import Design, make_design
from lvcore.campaigns.runner import _drive, execute_chunk, run_campaign
from lvcore.campaigns.space import get_space
from lvcore.campaigns.store import CampaignStore, read_store
from lvcore.mechanics.forward import SimulatorForward
from lvcore.domain.outputs import THETA_NAMES


class _Inline:
    """Runs each task at submission (an executor with the campaign interface)."""

    def __init__(self, workers=1):
        self.workers = workers
        self.submitted = []

    def describe(self):
        return "inline"

    def submit(self, fn, *args):
        self.submitted.append(args)
        f = Future()
        f.set_result(fn(*args))
        return f

    def as_completed(self, futures):
        return iter(futures)


def test_continuation_order_is_a_permutation_that_walks_between_neighbours():
    rng = np.random.default_rng(0)
    U = rng.random((400, 4))
    order = chains.continuation_order(U)
    assert sorted(order.tolist()) == list(range(400))
    walk = np.linalg.norm(np.diff(U[order], axis=0), axis=1)
    random_walk = np.linalg.norm(np.diff(U, axis=0), axis=1)
    # the walk's steps are a few nearest-neighbour distances, several times shorter than a random order's
    assert np.median(walk) < 0.35 * np.median(random_walk)
    # duplicates, two clusters (a disconnected k-NN graph) and tiny batches
    twin = np.vstack([U[:5], U[:5], U[:5] + 100.0])
    assert sorted(chains.continuation_order(twin, k=3).tolist()) == list(range(15))
    assert chains.continuation_order(U[:2]).tolist() == [0, 1] and chains.continuation_order(U[:0]).size == 0


def test_solve_in_order_starts_each_point_from_the_nearest_converged_state():
    U = np.array([[0.0], [1.0], [0.1], [5.0], [1.2]])
    starts = {}

    def solve(key, initial):
        starts[key] = initial
        return key, (None if key == 2 else ("state", key))  # point 2 "fails": never a start

    rows = chains.solve_in_order([0, 1, 2, 3, 4], U, [chains.Seed(np.array([4.9]), ("state", "seed"))], solve)
    assert [r.key for r in rows] == [0, 1, 2, 3, 4]
    assert starts == {0: ("state", "seed"), 1: ("state", 0), 2: ("state", 0), 3: ("state", "seed"),
                      4: ("state", 1)}
    assert rows[2].state is None and all(r.warm for r in rows)


def test_run_chains_solves_every_point_once_on_at_least_two_chains_per_worker():
    rng = np.random.default_rng(1)
    U = rng.random((100, 3))
    ex = _Inline(workers=2)
    seen = []

    def task(positions, units, seeds):
        return chains.solve_in_order(positions, units, seeds, lambda k, init: (k, ("s", k)))

    def submit(positions, seeds):
        return ex.submit(task, positions, U[positions], seeds)

    stats = chains.run_chains(ex, submit, U, workers=2, chunk=7, on_rows=lambda rows: seen.extend(r.key for r in rows))
    assert sorted(seen) == list(range(100))
    assert stats.chains >= 4 and stats.chunks >= 100 // 7
    # only the first chunk of each initial chain starts cold; later chunks get seeds from the driver
    assert stats.cold == 4 and stats.warm == 96
    assert all(len(args[0]) <= 7 for args in ex.submitted)


def test_chained_campaign_of_the_double_records_every_row_once_with_warm_starts(tmp_path, monkeypatch):
    log = tmp_path / "exec.log"
    monkeypatch.setenv("LVCORE_TEST_EXEC_LOG", str(log))
    design = make_design(get_space("material"), "sobol", 40, seed=3)
    s = run_campaign(design, tmp_path / "s.h5", executor=_Inline(workers=2), forward=campaign_double.NAME,
                     progress=False)
    assert s.converged == 40
    c = read_store(tmp_path / "s.h5")
    np.testing.assert_allclose(c.outputs, [closed_form(*r) for r in design.points], rtol=1e-12)
    np.testing.assert_array_equal(c.record_count, 1)
    warm = [line.split()[1] for line in log.read_text().splitlines() if line.startswith("warm ")]
    assert len(warm) == 40 - 4  # all but the first row of each of the 2 x 2 chains
    # ... and each start is a near neighbour: closer than the median distance between design points
    U = design.space.to_unit(design.points)
    a = {repr(float(x)): i for i, x in enumerate(design.points[:, 0])}
    d = [np.linalg.norm(U[a[k.split("->")[0]]] - U[a[k.split("->")[1]]]) for k in warm]
    allpairs = np.linalg.norm(U[:, None] - U[None], axis=2)[np.triu_indices(40, 1)]
    assert np.median(d) < 0.5 * np.median(allpairs)


@pytest.fixture(scope="module")
def theta_design():
    """Ten nearby stiffnesses around the reference (a cluster, as a fine design has)."""
    rng = np.random.default_rng(5)
    X = np.array([0.6, 1.3, 1.0, 3.6]) * np.exp(0.15 * rng.standard_normal((10, 4)))
    return Design(get_space("material"), X, "custom", None)


def test_predicted_state_is_exact_for_a_linear_solution_and_falls_back_to_the_nearest():
    from lvcore.mechanics.forward import WarmState

    rng = np.random.default_rng(1)
    G = rng.normal(size=(3, 7))  # u(x) = u0 + x G for x in 3-D, u of 5 dofs + a (1, 2) pressure

    def state(x, tangent=None):
        y = np.ones(7) + x @ G
        return WarmState(y[:5], y[5:].reshape(1, 2), tangent, ("values", tuple(x)))

    X = rng.random((9, 3))
    pool = [chains.Seed(x, state(x, tangent="newest" if i == 8 else None)) for i, x in enumerate(X)]
    target = X[0] + 0.05  # inside the neighbours' cloud
    nearest = pool[int(np.argmin(np.linalg.norm(X - target, axis=1)))].state
    got = chains.predicted_state(target, pool)
    want = state(target)
    np.testing.assert_allclose(got.u, want.u, atol=1e-12)
    np.testing.assert_allclose(got.p, want.p, atol=1e-12)
    # the nearest state's parameters (for a continuation) and the newest factorised tangent (a chord start)
    assert got.values == nearest.values and got.tangent == "newest"
    # too few neighbours for a 3-D plane, a point beyond the cloud, states without arrays: the nearest as it is
    few = pool[:4]
    assert chains.predicted_state(target, few) is few[int(np.argmin(np.linalg.norm(X[:4] - target, axis=1)))].state
    far = X.mean(axis=0) + 10.0
    assert chains.predicted_state(far, pool) is pool[int(np.argmin(np.linalg.norm(X - far, axis=1)))].state
    assert chains.predicted_state(target, [chains.Seed(x, ("state", i)) for i, x in enumerate(X)])[0] == "state"
    assert chains.predicted_state(target, []) is None


def test_predicted_state_is_exact_for_a_quadratic_solution_given_enough_neighbours():
    from lvcore.mechanics.forward import WarmState

    rng = np.random.default_rng(2)
    d = 3
    n_quad = 2 * (1 + d + d * (d + 1) // 2)  # 20 neighbours for a full quadratic in 3-D
    G, H = rng.normal(size=(d, 7)), rng.normal(size=(d, d, 7))

    def state(x, tangent=None):  # u(x) = 1 + x G + x H x: a quadratic the plane cannot follow
        y = np.ones(7) + x @ G + np.einsum("i,ijn,j->n", x, H, x)
        return WarmState(y[:5], y[5:].reshape(1, 2), tangent, None)

    X = 0.2 * rng.random((n_quad + 5, d))
    target = X.mean(axis=0) + 0.01
    want = state(target)
    got = chains.predicted_state(target, [chains.Seed(x, state(x, "newest" if i == len(X) - 1 else None))
                                          for i, x in enumerate(X)])
    np.testing.assert_allclose(got.u, want.u, atol=1e-10)
    np.testing.assert_allclose(got.p, want.p, atol=1e-10)
    assert got.tangent is None  # a design-filling neighbourhood: Newton takes a fresh tangent, no chord start
    # one neighbour short of the quadratic's: the plane, exact to first order only (error of order h²)
    near = np.argsort(np.linalg.norm(X - target, axis=1))[:n_quad - 1]
    plane = chains.predicted_state(target, [chains.Seed(X[i], state(X[i], "newest" if k == n_quad - 2 else None))
                                            for k, i in enumerate(near)])
    err = np.abs(plane.u - want.u).max()
    assert 1e-6 < err < 0.2
    assert plane.tangent == "newest"  # the plane keeps the chord start on the newest tangent
    # an explicit k asks for the plane
    fixed = chains.predicted_state(target, [chains.Seed(x, state(x)) for x in X], k=8)
    assert np.abs(fixed.u - want.u).max() > 1e-6


def test_spline_weights_interpolate_reproduce_quadratics_and_beat_the_least_squares_quadratic():
    rng = np.random.default_rng(5)
    d, m = 4, 30
    Z = rng.uniform(-1, 1, (m, d))
    for i in (0, 7, 29):  # through every node: the weights at a node pick that node
        np.testing.assert_allclose(chains._spline_weights(Z, Z[i]), np.eye(m)[i], atol=1e-9)
    z = np.array([0.1, -0.2, 0.05, 0.3])
    w = chains._spline_weights(Z, z)
    F = chains._quadratic_features(Z)
    np.testing.assert_allclose(w @ F, chains._quadratic_features(z[None])[0], atol=1e-10)  # quadratics exact
    # a smooth solution that is not a quadratic: the spline's error is well below the least-squares quadratic's
    errs = []
    for t in rng.uniform(-0.5, 0.5, (20, d)):
        f = np.exp(0.8 * Z @ np.array([1.0, -0.5, 0.7, 0.3]))
        want = np.exp(0.8 * t @ np.array([1.0, -0.5, 0.7, 0.3]))
        ls = chains._quadratic_features(t[None])[0] @ np.linalg.pinv(F) @ f
        errs.append((abs(chains._spline_weights(Z, t) @ f - want), abs(ls - want)))
    spline, ls = np.median(np.array(errs), axis=0)
    assert spline < 0.5 * ls
    # a repeated design point (states equal to round-off) is used once, not amplified
    Zr = np.vstack([Z, Z[3] + 1e-12])
    wr = chains._spline_weights(Zr, z)
    assert wr[-1] == 0.0 and np.abs(wr).max() < 10
    np.testing.assert_allclose(wr[:-1], w, atol=1e-12)


def test_warm_chained_simulator_rows_equal_cold_ones(tmp_path, theta_design):
    """The real simulator (``fast`` mesh): a chained campaign gives the cold campaign's numbers within tolerance."""
    ex = _Inline(workers=1)
    out = {}
    for chained in (True, False):
        path = tmp_path / f"{chained}.h5"
        run_campaign(theta_design, path, executor=ex, resolution="fast", progress=False, chained=chained)
        out[chained] = read_store(path)
    assert out[True].converged.all() and out[False].converged.all()
    # solver tolerance: ||r|| <= 1e-9 ||f_ext||; volumes and strains agree to ~1e-8 relative
    np.testing.assert_allclose(out[True].outputs, out[False].outputs, rtol=1e-7, atol=1e-9)
    # the chained rows really were warm-started: the same chunk solved again reports its starts
    fwd = SimulatorForward(resolution="fast")
    U = theta_design.space.to_unit(theta_design.points)
    order = chains.continuation_order(U).tolist()
    rows = execute_chunk(fwd, order, order, [dict(zip(THETA_NAMES, theta_design.points[i])) for i in order],
                         U[order], [])
    assert [r.warm for r in rows] == [False] + [True] * 9 and all(r.result.converged for r in rows)
    np.testing.assert_allclose([r.result.outputs for r in sorted(rows, key=lambda r: r.key)], out[False].outputs,
                               rtol=1e-7, atol=1e-9)


def test_warm_started_simulator_forward_batch_equals_cold_and_keeps_states(theta_design):
    X = theta_design.points[:6]
    cols = dict(zip(THETA_NAMES, X.T))
    cold = SimulatorForward(resolution="fast").evaluate(cols)
    warm_fwd = SimulatorForward(resolution="fast", warm_start=True)
    warm = warm_fwd.evaluate(cols)
    assert warm.converged.all()
    assert sum(m == "converged (warm start)" for m in warm.messages) == 5  # all but the first point of the chain
    np.testing.assert_allclose(warm.outputs, cold.outputs, rtol=1e-7, atol=1e-9)
    again = warm_fwd.evaluate({k: v[:1] for k, v in cols.items()})  # a later batch starts from the kept states
    assert again.messages == ("converged (warm start)",)
    # on an executor: chunks of chains, same numbers
    ex = _Inline(workers=2)
    pooled = SimulatorForward(resolution="fast", warm_start=True).evaluate(cols, executor=ex)
    np.testing.assert_allclose(pooled.outputs, cold.outputs, rtol=1e-7, atol=1e-9)
    assert len(ex.submitted) >= 2  # split across chains for the two workers
    import pickle

    assert pickle.loads(pickle.dumps(warm_fwd))._warm == {}  # kept states never travel to workers


def test_drive_reports_chain_statistics(tmp_path):
    design = make_design(get_space("material"), "sobol", 30, seed=1)
    with CampaignStore.create(tmp_path / "s.h5", design, forward=campaign_double.NAME, resolution="fast") as store:
        stats = _drive(store, store.pending_rows(), _Inline(workers=3),
                       forward=campaign_double.DoubleForward(tuple(design.space.names)), progress=False, chunk=4)
        assert store.summary().converged == 30
    assert stats.chains >= 6 and stats.warm + stats.cold == 30 and stats.cold == 6


def test_seed_pool_stacks_solutions_and_combines_them_like_the_states():
    """Growth past its first capacity, seeds without a solution (or of another shape) among solved ones, and
    both ways of combining (the whole stack, or a gather of a few rows) give what the states themselves give."""
    from lvcore.mechanics.forward import WarmState

    rng = np.random.default_rng(4)
    seeds = []
    for i in range(21):
        if i % 5 == 3:
            state = ("no solution", i)
        elif i == 7:
            state = WarmState(np.ones(3), np.ones((1, 2)))  # another shape: offered, never combined
        else:
            state = WarmState(rng.normal(size=6), rng.normal(size=(2, 2)))
        seeds.append(chains.Seed(rng.random(2), state))
    pool = chains.SeedPool(seeds[:4])
    for s in seeds[4:]:
        pool.append(s)
    assert len(pool) == 21 and pool[5] is seeds[5] and list(pool) == seeds
    np.testing.assert_array_equal(pool.units, np.array([s.unit for s in seeds]))
    solved = [i for i in range(21) if i % 5 != 3 and i != 7]
    np.testing.assert_array_equal(np.flatnonzero(pool.solved), solved)
    for rows in (np.array(solved[:-1]), np.array(solved[2:5])):  # most of the pool, then a few rows
        w = rng.normal(size=rows.size)
        u, p = pool.combine(rows, w)
        np.testing.assert_allclose(u, sum(wj * seeds[j].state.u for wj, j in zip(w, rows)), rtol=1e-13)
        np.testing.assert_allclose(p, sum(wj * seeds[j].state.p.ravel() for wj, j in zip(w, rows)), rtol=1e-13)
    pool[-1] = chains.Seed(seeds[-1].unit, chains.light_state(seeds[-1].state))
    assert pool[-1].state.tangent is None and len(pool) == 21
