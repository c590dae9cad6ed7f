"""Sampler settings and the output of one sampler call: the value objects shared by the runners
(:mod:`lvcore.inference.samplers`), the compiled-program cache (:mod:`lvcore.inference.compiled_samplers`)
and their callers."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class SamplerConfig:
    """MCMC settings.

    Attributes
    ----------
    num_warmup, num_samples, num_chains : int
        Warm-up (adaptation) iterations, kept draws and chains.
    chain_method : str
        ``"auto"`` (parallel when there are enough JAX devices, else
        vectorized), or numpyro's ``"parallel"``, ``"vectorized"``, ``"sequential"``.
    seed : int
        PRNG seed.
    target_accept_prob : float
        NUTS dual-averaging target.
    max_tree_depth : int
        NUTS maximum tree depth.
    dense_mass : bool
        Dense mass matrix for plain NUTS (default: diagonal). Neither wins
        everywhere: over 7 SYNTHETIC iid data sets on the ``chapter``
        emulator (4 x (1000 + 1000)) a dense matrix gave the larger minimum
        ESS on 4 but the two poorest runs (ESS 61 with R-hat 1.05, and 571),
        where the diagonal one's poorest was 1441
        (``benchmarks/bench_calibration.py --runs iid [--dense-mass]``).
    progress_bar : bool
        numpyro's text progress bar.
    discrepancy_block : str
        Block 4 of the discrepancy model's HMC-within-Gibbs, one of :data:`DISCREPANCY_BLOCKS`: ``"marginal"``
        (b integrated out of the NUTS block, then drawn exactly) or ``"chapter"`` (Algorithm 4 as written).
    discrepancy_kernel : str
        The discrepancy model's GP kernel, one of :data:`lvcore.inference.models.KERNEL_KINDS`: ``"additive"``
        (the chapter's, sector profile + level profile) or ``"product"`` (sector × level,
        :func:`lvcore.inference.kernels.polar_product_kernel`). Read by the discrepancy model's samplers only
        (blocked and joint NUTS); being a field, it keys the compiled samplers, so the two kernels never share
        a compiled program.
    """

    num_warmup: int = 1000
    num_samples: int = 1000
    num_chains: int = 4
    chain_method: str = "auto"
    seed: int = 0
    target_accept_prob: float = 0.8
    max_tree_depth: int = 10
    dense_mass: bool = False
    progress_bar: bool = False
    discrepancy_block: str = "marginal"
    discrepancy_kernel: str = "additive"


#: The app's default run: 4 chains x (250 warm-up + 500 draws). Chosen by measured ESS per CPU second
#: (``benchmarks/bench_calibration.py --sweep``, 2 SYNTHETIC data sets, ``chapter`` emulator, docs/calibration.md):
#: the discrepancy sampler (HMC-within-Gibbs) costs ~5 CPU-ms per chain iteration and gives a bulk ESS of theta
#: of 0.35-0.7 per draw, so 4 x (1000 + 1000) (43 CPU-s, ESS 2,500-3,000) spends most of the click on draws
#: nobody needs; 4 x (250 + 500) costs 18 CPU-s and still gives a worst theta ESS of 1,400 (all parameters,
#: GP hyperparameters included: 395) with R-hat <= 1.01; 250 warm-up iterations gave the same ESS per draw as
#: 500. The iid model (NUTS, ~1.2 CPU-ms per iteration) gets the same setting. Four chains keep R-hat
#: meaningful; on 2 cores they run as 4 XLA host devices. (Those figures are the chapter's block 4; the
#: marginal block, the default since, costs ~2.3-3.1 CPU-ms per chain iteration for a larger minimum ESS.)
INTERACTIVE = SamplerConfig(num_warmup=250, num_samples=500, num_chains=4)


@dataclass
class SamplerRun:
    """Output of one sampler call.

    Attributes
    ----------
    method : str
        ``"nuts"`` or ``"hmc_gibbs"``.
    model : str
        ``"volume"``, ``"iid"`` or ``"discrepancy"``.
    samples : dict of ndarray
        Posterior draws, leading axes (chain, draw).
    sample_stats : dict of ndarray
        Per-draw statistics (``diverging``, ``n_steps``), axes (chain, draw).
    wall_s : float
        Wall time of the call, compilation included (s).
    mcmc : numpyro.infer.MCMC
        The MCMC object (for continuing a chain after non-convergence).
    """

    method: str
    model: str
    samples: dict
    sample_stats: dict
    wall_s: float
    mcmc: Any = field(repr=False, default=None)
    run_kwargs: dict = field(repr=False, default_factory=dict)


__all__ = ["SamplerConfig", "INTERACTIVE", "SamplerRun"]
