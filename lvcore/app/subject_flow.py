"""The "My subject" flow: one's own geometry and measurements, from upload to a downloadable bundle.

The page ``pages/8_My_subject.py`` only gathers inputs and shows what this
module returns; every step here is Streamlit-free and does what ``lvcore
calibrate`` does for the same inputs (same geometry resolution, box check,
conditions, forward model and plausibility check), so the app and the CLI
give the same answer. The steps live in one module each, and every public
name is importable from here: :mod:`lvcore.app.subject_inputs` (steps 1-2),
:mod:`lvcore.app.subject_prepare` (step 3), :mod:`lvcore.app.subject_results`
(step 4 and the figures), :mod:`lvcore.app.subject_bundle` (step 5) and
:mod:`lvcore.app.subject_build` (the subject-specific emulator).

The steps:

1. :func:`read_geometry` — an uploaded geometry (a volume mesh, a template
   mesh, or PC scores) becomes a :class:`~lvcore.inference.guards.GeometrySource`
   (PC scores ``h`` and the uniform scale ``s``; the fit residual of a mesh).
   Without a mesh (``lvcore calibrate --geometry infer``), :func:`inferred_measures`
   takes the CMR measures (reference volume, wall volume, long axis) and
   :func:`prepare_inferred` samples ``h`` and ``s`` with θ
   (:mod:`lvcore.inference.geometry_prior`).
2. :func:`read_data` — uploaded measurements (24-region or AHA-16 CSV, JSON
   or ``.mat``) become :class:`~lvcore.inference.data.MeasuredData` rows.
3. :func:`prepare` — binds geometry and conditions (EDP) into the emulator,
   checks the PC scores against the emulator's training box and returns the
   forward model with what it used: one
   :class:`~lvcore.inference.request.CalibrationRequest` (:class:`Prepared`),
   made by :func:`lvcore.inference.request.build_request` as ``lvcore
   calibrate`` and the Calibration page make theirs.
4. :func:`calibrate` — runs the chosen likelihoods and checks each result's
   plausibility (:class:`ModelRun`).
5. :func:`bundle` — one zip: InferenceData (netCDF) per likelihood, the
   figures (HTML), ``settings.json``, ``summary.json`` and a one-page
   ``summary.html``.

Optionally, :class:`SubjectBuild` builds a subject-specific emulator on the
loaded geometry as it is (``lvcore emulator build --geometry FILE``,
:func:`lvcore.emulator.subject.build_subject_emulator`) in a background thread,
with progress and a stop request; :func:`prepare` then binds no PC scores
(the geometry is in the emulator), as ``lvcore calibrate --emulator DIR``.
"""
from __future__ import annotations

from lvcore.app.subject_build import BUILD_CACHE, HELD_OUT_TARGETS, SubjectBuild, build_dir, held_out_summary
from lvcore.app.subject_bundle import bundle, summary_html, summary_record
from lvcore.app.subject_inputs import (DATA_TYPES, GEOMETRY_TYPES, MEASURE_LABELS, NO_MEASURE_WARNING,
                                       REFERENCE_VOLUME_TOLERANCE, UNITS_CONTROL, geometry_measures, geometry_nodes,
                                       inferred_measure_sds, inferred_measures, read_data, read_geometry,
                                       template_mesh_file)
from lvcore.app.subject_prepare import (InferredGeometry, Prepared, floor_caption, prepare, prepare_inferred,
                                        subject_emulator_geometry)
from lvcore.app.subject_results import (ModelRun, bound_flags, calibrate, figures, geometry_figure,
                                        geometry_posterior, geometry_posterior_rows, implied_cavity_draws)

__all__ = ["BUILD_CACHE", "DATA_TYPES", "GEOMETRY_TYPES", "HELD_OUT_TARGETS", "MEASURE_LABELS", "NO_MEASURE_WARNING",
           "REFERENCE_VOLUME_TOLERANCE", "UNITS_CONTROL", "InferredGeometry", "ModelRun", "Prepared", "SubjectBuild",
           "bound_flags", "build_dir", "bundle", "calibrate", "figures", "floor_caption", "geometry_figure",
           "geometry_measures", "geometry_nodes", "geometry_posterior", "geometry_posterior_rows", "held_out_summary",
           "implied_cavity_draws", "inferred_measure_sds", "inferred_measures", "prepare", "prepare_inferred",
           "read_data", "read_geometry", "subject_emulator_geometry", "summary_html", "summary_record",
           "template_mesh_file"]
