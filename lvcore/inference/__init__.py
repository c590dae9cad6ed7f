"""Bayesian calibration of theta = (a, b, af, bf) from LVV and 24 circumferential strains.

Modules, in the order data flow through them: :mod:`~lvcore.inference.data`
(measured data), :mod:`~lvcore.inference.kernels` (polar GP kernel),
:mod:`~lvcore.inference.models` (numpyro models (i)-(iii)),
:mod:`~lvcore.inference.samplers` (NUTS, HMC-within-Gibbs),
:mod:`~lvcore.inference.diagnostics` (R-hat, ESS, posterior predictive,
InferenceData), :mod:`~lvcore.inference.calibrate` (one calibration end to
end, and every subject x model), :mod:`~lvcore.inference.coverage`
(credible-interval coverage check); around them :mod:`~lvcore.inference.segments`
(AHA <-> lvcore strain segments), :mod:`~lvcore.inference.loaded_states` (further
loaded states of a subject and the Klotz EDPVR prior), :mod:`~lvcore.inference.guards` (what
``lvcore calibrate`` refuses), :mod:`~lvcore.inference.request` (the whole set-up of one calibration, built once
for the CLI and the app) and :mod:`~lvcore.inference.plausibility`
(posterior-predictive check of the data). One calibration is
``lvcore.inference.calibrate.calibrate`` (the name ``calibrate`` here is the
module). Names are imported on first use. The forward model is any JAX-traceable
:class:`lvcore.core.Forward` (the emulator, :class:`lvcore.emulator.EmulatorForward`).
"""
from __future__ import annotations

from lvcore._exports import lazy_exports

_EXPORTS = {
    "calibrate": "calibrate", "CalibrationResult": "calibrate", "SubjectResult": "calibrate",
    "calibrate_subjects": "calibrate", "read_pc_scores": "calibrate", "result_record": "calibrate",
    "write_result": "calibrate",
    "CoverageResult": "coverage", "coverage_study": "coverage", "simulate_data": "coverage",
    "MeasuredData": "data", "read_measured_csv": "data", "read_measurements": "data",
    "validate_measurements": "data", "write_measured_csv": "data", "LoadedState": "data",
    "LoadedStatesForward": "loaded_states", "StateTerm": "loaded_states", "KlotzPrior": "loaded_states",
    "aha_to_lvcore": "segments", "lvcore_to_aha": "segments", "to_lvcore": "segments",
    "GeometrySource": "guards", "resolve_geometry": "guards", "check_conditions": "guards",
    "check_inputs_in_box": "guards",
    "CalibrationRequest": "request", "build_request": "request",
    "PlausibilityCheck": "plausibility", "posterior_predictive_check": "plausibility",
    "Convergence": "diagnostics", "posterior_predictive": "diagnostics", "to_inference_data": "diagnostics",
    "MODEL_NAMES": "models", "get_model": "models", "prior_bounds": "models",
    "SamplerConfig": "samplers", "SamplerRun": "samplers", "run_model": "samplers", "use_host_devices": "samplers",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
