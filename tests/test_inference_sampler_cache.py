"""Compiled samplers and best-fit programs kept in the process (issue 25: click to results), and their thread safety.

The forward models are the bundled ``chapter`` emulator at two SYNTHETIC geometries; the data are its outputs
plus an offset.
"""
from __future__ import annotations

import dataclasses
import threading

import numpy as np
import pytest

from lvcore.inference import samplers, verdict

THETA = {"a": 0.8, "b": 4.0, "af": 1.2, "bf": 6.0}
CFG = samplers.SamplerConfig(num_warmup=30, num_samples=20, num_chains=2, seed=2)


def _forwards():
    from lvcore.emulator.forward import load_emulator_forward
    from lvcore.geometry.scaling import ScaledForward

    f1 = ScaledForward(load_emulator_forward("chapter", [0.5, -0.4, 0.3, -0.2, 0.1]), 1.1)
    f2 = ScaledForward(load_emulator_forward("chapter", [-1.0, 0.2, 0.0, 0.6, -0.3]), 0.9)  # its own load
    return f1, f2


def _y(fwd, offset=0.01):
    return np.asarray(fwd(THETA)) + offset


class _Traces:
    """Counts how often a run-time-conditioned forward model is bound, i.e. traced into a program."""

    def __init__(self, monkeypatch):
        self.n = 0
        bind = samplers.ConditionedForward.bind

        def counting(template, values):
            self.n += 1
            return bind(template, values)

        monkeypatch.setattr(samplers.ConditionedForward, "bind", counting)


def test_a_new_subject_reuses_the_compiled_sampler_and_draws_what_a_fresh_one_draws(monkeypatch):
    """The second geometry (another load of the emulator) runs without tracing the model again; the cached
    sampler's draws equal those of a sampler built from scratch, and a reused one forgets the last run."""
    samplers.clear_sampler_cache()
    f1, f2 = _forwards()
    assert samplers.emulator_fingerprint(f1.forward.emulator) == samplers.emulator_fingerprint(f2.forward.emulator)
    traces = _Traces(monkeypatch)
    r1 = samplers.run_model("iid", _y(f1), f1, CFG)
    assert traces.n > 0
    n_first = traces.n
    r2 = samplers.run_model("iid", _y(f2), f2, CFG)
    assert traces.n == n_first  # compiled once: no new trace for a new subject
    r1_again = samplers.run_model("iid", _y(f1), f1, CFG)
    np.testing.assert_array_equal(r1_again.samples["a"], r1.samples["a"])  # no state carried over
    samplers.clear_sampler_cache()
    fresh = samplers.run_model("iid", _y(f2), f2, CFG)
    np.testing.assert_array_equal(fresh.samples["a"], r2.samples["a"])
    assert not np.allclose(r1.samples["a"], r2.samples["a"])
    # another setting (draws) is another program
    samplers.run_model("iid", _y(f1), f1, dataclasses.replace(CFG, num_samples=21))
    assert traces.n > n_first


def test_precompile_samples_nothing_and_the_run_after_it_traces_nothing(monkeypatch):
    samplers.clear_sampler_cache()
    f1, f2 = _forwards()
    wall = samplers.precompile("iid", _y(f1), f1, CFG)
    assert wall > 0
    traces = _Traces(monkeypatch)
    run = samplers.run_model("iid", _y(f2), f2, CFG)
    assert traces.n == 0
    assert np.all(run.samples["a"] > 0) and np.std(run.samples["a"]) > 0  # real draws, not the compile-only zeros
    samplers.clear_sampler_cache()
    np.testing.assert_array_equal(samplers.run_model("iid", _y(f2), f2, CFG).samples["a"], run.samples["a"])


def test_best_fit_programs_serve_every_geometry_and_find_what_they_found_before(monkeypatch):
    """The best fit is compiled once per emulator: a second geometry traces nothing; its result equals the
    one found with freshly compiled programs."""
    f1, f2 = _forwards()
    verdict.clear_best_fit_programs()
    c1 = verdict.consistency_check(_y(f1), f1, sigma_v=5.0)
    traces = _Traces(monkeypatch)
    c2 = verdict.consistency_check(_y(f2, 0.0), f2, sigma_v=5.0)
    assert traces.n == 0
    assert list(c2.best_fit) == ["a", "b", "af", "bf"]  # the model's order
    np.testing.assert_allclose(c2.eta, np.asarray(f2({k: c2.best_fit[k] for k in THETA})), rtol=1e-10)
    assert c2.plausible
    verdict.clear_best_fit_programs()
    again = verdict.consistency_check(_y(f1), f1, sigma_v=5.0)
    assert again.best_fit == c1.best_fit
    np.testing.assert_array_equal(again.p_values, c1.p_values)


@pytest.mark.slow
def test_two_likelihoods_and_the_best_fit_in_threads_at_once_equal_them_one_by_one():
    """The app runs iid, discrepancy and the best fit side by side: with cold caches all three trace at once
    (numpyro's global handler stack: they must take turns, samplers.TRACE_LOCK), and each gives what it gives
    alone."""
    f1, _ = _forwards()
    y = _y(f1)
    # CFG's settings (another seed, which is a run-time argument): the iid program XLA compiled for the tests
    # above is loaded from JAX's persistent cache; every model is still traced cold, at once, in the threads
    cfg = dataclasses.replace(CFG, seed=4)
    samplers.clear_sampler_cache()
    verdict.clear_best_fit_programs()
    out, errors = {}, []

    def job(name, fn):
        try:
            out[name] = fn()
        except Exception as err:  # noqa: BLE001 - reported by the assertion below
            errors.append(f"{name}: {type(err).__name__}: {err}")

    jobs = {"iid": lambda: samplers.run_model("iid", y, f1, cfg).samples["a"],
            "discrepancy": lambda: samplers.run_model("discrepancy", y, f1, cfg).samples["a"],
            "best fit": lambda: verdict.consistency_check(y, f1, sigma_v=5.0).eta}
    threads = [threading.Thread(target=job, args=item) for item in jobs.items()]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    samplers.clear_sampler_cache()
    verdict.clear_best_fit_programs()
    for name, fn in jobs.items():
        np.testing.assert_array_equal(fn(), out[name], err_msg=name)


def test_a_sampler_compiled_with_default_settings_serves_a_run_that_names_them():
    """The app's warm-up compiles without model keyword arguments; calibrate() passes sigma_v and
    infer_angles explicitly (sometimes as NumPy numbers). Both must find the same compiled sampler: before
    this key, the click recompiled (first iid run 5.6 CPU-s against 2.6 after the fix, 2026-11-27)."""
    import numpy as np

    from lvcore.domain.conditions import SIGMA_V_ML
    from lvcore.inference import samplers

    cfg = samplers.INTERACTIVE
    warm = samplers._config_key(cfg, {})
    assert samplers._config_key(cfg, {"sigma_v": SIGMA_V_ML, "infer_angles": False}) == warm
    assert samplers._config_key(cfg, {"sigma_v": np.float64(SIGMA_V_ML), "infer_angles": np.bool_(False)}) == warm
    assert samplers._config_key(cfg, {"sigma_v": 2 * SIGMA_V_ML}) != warm  # a different model still differs
    assert samplers._config_key(cfg, {"infer_angles": True}) != warm
