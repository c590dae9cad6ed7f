"""Running work: process pools, continuation chains and the caches that keep compiled work.

* :mod:`lvcore.execution.parallel`: local and Dask process pools, the in-process executor for small jobs,
  and :func:`~lvcore.execution.parallel.pin_threads` (imports neither numpy nor JAX);
* :mod:`lvcore.execution.chains`: continuation chains, a batch of solves ordered so that each one
  warm-starts from a neighbour's solution;
* :mod:`lvcore.execution.jax_cache`: JAX's float64 switch, its persistent compilation cache and the
  exported (traced and lowered) simulator kernels;
* :mod:`lvcore.execution.bounded_cache`: the thread-safe, size-bounded LRU of per-process compiled work.

Importing this package imports none of them (``import lvcore`` imports :mod:`~lvcore.execution.jax_cache`
only, which imports neither numpy nor JAX).
"""
