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
    verdict._BEST_FIT_PROGRAMS.clear()
    stages = warmup.warm(models=("iid",))
    assert set(stages) >= {"load", "iid", "best fit"}
    keys = list(samplers._MCMC_CACHE)
    assert len(keys) == 1 and keys[0][:2] == ("nuts", "iid") and keys[0][3][0].num_warmup == samplers.INTERACTIVE.num_warmup
    compiled = samplers._MCMC_CACHE[keys[0]].__dict__["_lvcore_compiled"]
    assert len(compiled) == 1
    assert len(verdict._BEST_FIT_PROGRAMS) == 1
