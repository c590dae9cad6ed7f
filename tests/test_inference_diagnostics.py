"""sample_until_converged's extension rounds (lvcore.inference.diagnostics): a run whose chains miss the thresholds
is continued from where it stopped, without a new warm-up, until they are met or the rounds run out."""
import numpy as np

from lvcore.inference import diagnostics, samplers
from lvcore.testing.analytic import AnalyticForward

FWD = AnalyticForward()
TRUTH = {"a": 0.8, "b": 4.0, "af": 1.2, "bf": 6.0}


def test_unconverged_chains_are_continued_round_by_round_and_a_single_chain_is_not():
    y = np.asarray(FWD(TRUTH)) + 0.01
    cfg = samplers.SamplerConfig(num_warmup=30, num_samples=20, num_chains=2, seed=2)
    said = []
    # an ESS no run of 2 x 20 draws reaches: every round misses it, so all three rounds are drawn
    run, conv = diagnostics.sample_until_converged("volume", y, FWD, cfg, ess_min=1e9, max_rounds=3,
                                                   progress=lambda msg, frac: said.append((msg, frac)))
    assert not conv.converged and conv.rounds == 3 and conv.failing
    assert [m for m, _ in said if "drawing round" in m] == [m for m, _ in said][1:3]
    assert [f for _, f in said] == [0.0, 1 / 3, 2 / 3, 1.0]
    assert run.samples["a"].shape == (2, 20)  # each round's draws replace the last (those are burn-in)
    # a met threshold stops at round 1, whose draws (the same seed) round 3 did not repeat
    first, conv1 = diagnostics.sample_until_converged("volume", y, FWD, cfg, rhat_max=np.inf, ess_min=0.0,
                                                      max_rounds=3)
    assert conv1.converged and conv1.rounds == 1 and first.samples["a"].shape == (2, 20)
    assert not np.allclose(run.samples["a"], first.samples["a"])
    # one chain: R-hat cannot be assessed, so it is reported, not extended
    one = samplers.SamplerConfig(num_warmup=30, num_samples=20, num_chains=1, seed=2)
    _, conv_one = diagnostics.sample_until_converged("volume", y, FWD, one, ess_min=1e9, max_rounds=3)
    assert conv_one.rounds == 1
