"""Bayesian calibration of theta = (a, b, af, bf) from LVV and 24 circumferential strains.

Modules, in the order data flow through them: :mod:`~lvcore.inference.data`
(measured data), :mod:`~lvcore.inference.forward` (forward-model protocol,
emulator adapter), :mod:`~lvcore.inference.kernels` (polar GP kernel),
:mod:`~lvcore.inference.models` (numpyro models (i)-(iii)),
:mod:`~lvcore.inference.samplers` (NUTS, HMC-within-Gibbs),
:mod:`~lvcore.inference.diagnostics` (R-hat, ESS, InferenceData),
:mod:`~lvcore.inference.calibrate` (one calibration end to end),
:mod:`~lvcore.inference.coverage` (credible-interval coverage check).
"""
