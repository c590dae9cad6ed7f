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
