"""The app's background warm-up of the Calibration page (lvcore.app.warmup)."""
from __future__ import annotations

import pytest

from lvcore.app import warmup


def test_warmup_is_off_under_the_tests_and_starts_once(monkeypatch):
    monkeypatch.setattr(warmup, "_started", False)
    monkeypatch.setenv(warmup.ENV, "0")
    assert not warmup.enabled()
    assert warmup.start() is False and warmup.STATUS["state"] == "off"
    assert warmup.start() is False  # once per process, whatever the setting
    monkeypatch.setenv(warmup.ENV, "1")
    assert warmup.enabled()


@pytest.mark.slow
def test_warm_compiles_the_pages_default_sampler_and_best_fit():
    """After warm(), the page's default run (shared sidebar subject and emulator, INTERACTIVE) finds its
    compiled sampler and best fit in the process."""
    from lvcore.inference import samplers, verdict

    samplers.clear_sampler_cache()
    verdict.clear_best_fit_programs()
    stages = warmup.warm(models=("iid",))
    assert set(stages) >= {"load", "iid", "best fit"}
    keys = [k for k in samplers._MCMC_CACHE if k[:2] == ("nuts", "iid")]
    assert len(keys) == 1 and keys[0][:2] == ("nuts", "iid") and keys[0][3][0].num_warmup == samplers.INTERACTIVE.num_warmup
    compiled = samplers._MCMC_CACHE[keys[0]].__dict__["_lvcore_compiled"]
    assert len(compiled) == 1
    # the best fit of the same forward model (its template key: emulator, inputs, conditions, scale) is kept;
    # counted by key, not in total: a calibration thread an earlier app test started may add its own
    assert [k for k in verdict._BEST_FIT_PROGRAMS if k[0] == keys[0][2]]


CHILD_EXITS_DURING_WARMUP = r'''
import sys, time
from lvcore.app import warmup

def fake_warm(subject, emulator, models, room, stages):
    """Stages of 0.3 s each (a sampler's compile stands in), checking the room before each, as _warm does."""
    for k in range(100):
        room(f"stage {k}")
        time.sleep(0.3)
        stages[f"stage {k}"] = 0.3


warmup._warm = fake_warm
warmup.check_room = lambda stage, **kw: None   # the machine's memory is not what this test is about
assert warmup.start()
time.sleep(0.5)   # inside its second stage
assert warmup.STATUS["state"] == "running"
print("main done", flush=True)
'''


def test_a_process_that_exits_mid_warmup_stops_it_between_stages_and_exits_cleanly():
    """The interpreter's exit waits for the warm-up to finish its current stage and stop (an exit handler):
    a daemon thread left inside XLA's compile at teardown aborted the process (exit -6) after its work."""
    import os
    import subprocess
    import sys

    env = {**os.environ, warmup.ENV: "1"}
    done = subprocess.run([sys.executable, "-c", CHILD_EXITS_DURING_WARMUP], env=env, capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "main done" in done.stdout
    # the warm-up reported that it stopped, well before its 100 stages (30 s)
    line = next(ln for ln in done.stderr.splitlines() if "lvcore app warm-up" in ln)
    assert line.startswith("lvcore app warm-up stopped in "), line
    assert float(line.split(" in ")[1].split(" s")[0]) < 5.0, line
