"""Bayesian calibration of theta = (a, b, af, bf) from LVV and 24 circumferential strains.

Modules, in the order data flow through them: :mod:`~lvcore.inference.data`
(measured data), :mod:`~lvcore.inference.kernels` (polar GP kernel),
:mod:`~lvcore.inference.models` (numpyro models (i)-(iii)),
:mod:`~lvcore.inference.samplers` (NUTS, HMC-within-Gibbs),
:mod:`~lvcore.inference.diagnostics` (R-hat, ESS, posterior predictive,
InferenceData), :mod:`~lvcore.inference.calibrate` (one calibration end to
end, and every subject x model), :mod:`~lvcore.inference.coverage`
(credible-interval coverage check). One calibration is
``lvcore.inference.calibrate.calibrate`` (the name ``calibrate`` here is the
module). The forward model is any JAX-traceable
:class:`lvcore.core.Forward` (the emulator, :class:`lvcore.core.EmulatorForward`).
"""
from __future__ import annotations

from lvcore.inference.calibrate import (
    CalibrationResult,
    SubjectResult,
    calibrate_subjects,
    read_pc_scores,
    result_record,
    write_result,
)
from lvcore.inference.coverage import CoverageResult, coverage_study, simulate_data
from lvcore.inference.data import MeasuredData, read_measured_csv, validate_measurements, write_measured_csv
from lvcore.inference.diagnostics import Convergence, posterior_predictive, to_inference_data
from lvcore.inference.models import MODEL_NAMES, get_model, prior_bounds
from lvcore.inference.samplers import SamplerConfig, SamplerRun, run_model, use_host_devices

__all__ = [
    "CalibrationResult", "SubjectResult", "calibrate_subjects", "read_pc_scores", "result_record",
    "write_result", "CoverageResult", "coverage_study", "simulate_data", "MeasuredData", "read_measured_csv",
    "validate_measurements", "write_measured_csv", "Convergence", "posterior_predictive", "to_inference_data",
    "MODEL_NAMES", "get_model", "prior_bounds", "SamplerConfig", "SamplerRun", "run_model", "use_host_devices",
]
