"""Campaign runner on executors: a Dask LocalCluster campaign, and real simulator rows."""
import numpy as np
import pytest

import lvcore

import campaign_double
from campaign_double import closed_form
from executor_double import InlineExecutor
from lvcore.campaigns.designs import make_design
from lvcore.campaigns.runner import execute_row, resume_campaign, run_campaign
from lvcore.campaigns.space import get_space
from lvcore.campaigns.store import CampaignStore, read_store
from lvcore.core.registry import registered_name
from lvcore.exceptions import CampaignError
from lvcore.execution.parallel import DaskExecutor, default_workers


def test_dask_localcluster_campaign_of_20_rows(tmp_path):
    design = make_design(get_space("material"), "sobol", 20, seed=4)
    with DaskExecutor(workers=2, processes=False) as ex:
        assert ex.workers == 2
        summary = run_campaign(design, tmp_path / "s.h5", executor=ex, forward=campaign_double.NAME, progress=False)
    assert summary.converged == 20 and summary.pending == 0
    c = read_store(tmp_path / "s.h5")
    np.testing.assert_allclose(c.outputs, [closed_form(*r) for r in design.points], rtol=1e-12)
    np.testing.assert_array_equal(c.record_count, 1)


def test_dask_executor_connects_to_a_scheduler_address(tmp_path):
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        with DaskExecutor(scheduler=cluster.scheduler_address) as ex:
            assert cluster.scheduler_address in ex.describe()
            s = run_campaign(make_design(get_space("material"), "lhs", 5, seed=1), tmp_path / "s.h5", executor=ex,
                             forward=campaign_double.NAME, progress=False)
    assert s.converged == 5


def test_bad_forward_and_scheduler_are_clear_errors(tmp_path):
    with pytest.raises(CampaignError, match="unknown forward model 'nocolon'"):
        registered_name("nocolon")
    with pytest.raises(CampaignError, match="no longer imported.*register_forward"):
        registered_name("lvcore:no_such_function")
    with pytest.raises(CampaignError, match="unknown forward model"):
        run_campaign(make_design(get_space("material"), "lhs", 2, seed=0), tmp_path / "x.h5", executor=InlineExecutor(),
                     forward="campaign_double:forward", progress=False)
    assert not (tmp_path / "x.h5").exists()
    with pytest.raises(CampaignError, match="tcp://"):
        DaskExecutor(scheduler="localhost:1234")
    assert default_workers() >= 1


class _Raises:
    input_names = ("a",)

    def evaluate(self, inputs):
        raise ImportError("cannot import the model's data")


def test_forward_exceptions_become_failed_rows():
    r = execute_row(_Raises(), 3, {"a": 1.0})
    assert not r.converged and "cannot import" in r.reason and r.index == 3


def test_a_store_naming_code_is_refused_and_nothing_runs(tmp_path, monkeypatch):
    """A data file never chooses code: a store whose forward is 'builtins:print' is refused before any row runs."""
    import builtins

    path = tmp_path / "s.h5"
    with CampaignStore.create(path, make_design(get_space("material"), "lhs", 3, seed=0),
                              forward="builtins:print", resolution="fast"):
        pass
    calls = []
    monkeypatch.setattr(builtins, "print", lambda *a, **k: calls.append(a))
    with pytest.raises(CampaignError, match="unknown forward model 'builtins:print'"):
        resume_campaign(path, executor=InlineExecutor(), progress=True)
    monkeypatch.undo()
    assert calls == []
    assert read_store(path).state.tolist() == [0, 0, 0] and read_store(path).record_count.sum() == 0


def test_real_simulator_rows_at_fast_resolution(tmp_path):
    from lvcore.campaigns.designs import Design

    # the reference material and the same with every stiffness doubled
    ref = np.array([0.6, 1.3, 1.0, 3.6])
    design = Design(get_space("material"), np.array([ref, ref * [2, 1, 2, 1]]), "custom", None)
    summary = run_campaign(design, tmp_path / "s.h5", executor=InlineExecutor(), resolution="fast", progress=False)
    c = read_store(tmp_path / "s.h5")
    assert summary.pending == 0 and summary.n == 2
    assert summary.converged == 2, summary.format()
    assert np.all((c.outputs[:, 0] > 20) & (c.outputs[:, 0] < 400))      # LVV in mL
    assert np.all((c.outputs[:, 1:] < 0) & (c.outputs[:, 1:] > -0.5))    # filling: negative strains
    assert c.outputs[1, 0] < c.outputs[0, 0]                              # stiffer -> smaller end-diastolic volume
    assert np.all(np.abs(c.outputs[1, 1:]) < np.abs(c.outputs[0, 1:]))    # ... and smaller strains
    assert np.all(c.seconds > 0) and len(set(c.versions)) == 1 and c.versions[0].startswith(lvcore.__version__ + "+src.")



def test_small_campaigns_run_in_this_process_unless_workers_are_given():
    from lvcore.campaigns.runner import IN_PROCESS_MAX_ROWS, choose_executor
    from lvcore.execution.parallel import InProcessExecutor, LocalExecutor

    assert isinstance(choose_executor(IN_PROCESS_MAX_ROWS), InProcessExecutor)
    for n, workers in ((IN_PROCESS_MAX_ROWS + 1, None), (1, 2), (1, 1)):  # more rows, or --workers given
        with choose_executor(n, workers) as ex:  # no worker starts before a task is submitted
            assert isinstance(ex, LocalExecutor) and ex.workers == (workers or default_workers())


@pytest.mark.parametrize("chained, rows, expect_chains", [(None, 6, False), (None, 8, True), (True, 6, True),
                                                          (False, 8, False)])
def test_chains_from_chain_min_rows_when_not_chosen(tmp_path, monkeypatch, chained, rows, expect_chains):
    from lvcore.campaigns import runner

    monkeypatch.setattr(runner, "CHAIN_MIN_ROWS", 8)  # the rule, on the test double's cheap rows
    design = make_design(get_space("material"), "sobol", rows, seed=3)
    s = run_campaign(design, tmp_path / "s.h5", forward=campaign_double.NAME, progress=False, chained=chained)
    c = read_store(tmp_path / "s.h5")
    assert s.converged == rows  # ran in this process (at most IN_PROCESS_MAX_ROWS rows, no workers given)
    assert bool(np.all(c.chain >= 0)) == expect_chains and bool(np.all(c.chain == -1)) == (not expect_chains)
    np.testing.assert_allclose(c.outputs, [closed_form(*r) for r in design.points], rtol=1e-12)
