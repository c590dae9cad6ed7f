"""``lvcore calibrate``: Bayesian calibration of theta from measured data and a geometry.

Guards (exit code 2, see :mod:`lvcore.inference.guards`): ``--geometry`` is
required: PC scores or a mesh (size-normalised: scores plus a scale whose cube
multiplies the emulated LVV, :mod:`lvcore.geometry.scaling`), ``infer`` (the
scores and scale sampled with theta, informed by ``--reference-volume``,
``--wall-volume``, ``--long-axis`` or the data's columns of the same names,
:mod:`lvcore.inference.geometry_prior`), or ``mean`` (allowed with a bias
warning); PC scores and conditions outside the emulator's training box are
refused unless ``--allow-extrapolation``; ``--edp``/angles given to an
emulator trained at fixed values, a data ``edp_mmhg`` that differs from a
fixed-EDP emulator's, or an EDP outside 2-40 mmHg, are refused.

After sampling, :mod:`lvcore.inference.verdict` gives one verdict per
subject: consistency of volume and strains at the best fit (the same for
every model), posterior mass on a prior bound, intervals as wide as the
prior's, divergences. A run with any flag exits with :data:`EXIT_FLAGGED`
(4, "ran, results flagged"); the flags are printed and listed in ``summary.json``.
"""
from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lvcore import cli_args
from lvcore.domain.conditions import SIGMA_V_ML
from lvcore.domain.outputs import DEFAULT_STRAIN_LAYER, STRAIN_LAYERS

#: Range of ``--sigma-v`` (LVV noise sd, mL): echocardiographic/MRI volume errors are 2-15 mL; outside
#: this range the likelihood either ignores the volume (the posterior is the prior) or is degenerate.
SIGMA_V_RANGE_ML = (0.1, 50.0)
#: Range of ``--strain-noise`` (strain sd): measured strain errors are 0.01-0.1.
STRAIN_NOISE_RANGE = (0.001, 0.5)

#: The emulator ``lvcore calibrate`` and the app use unless told otherwise: the chapter's, trained with the
#: sliding base (docs/simulator.md's decision) at fixed fibre angles (-60/60 deg) and EDP (8 mmHg).
DEFAULT_EMULATOR = "chapter"
#: Exit code of a run whose results are flagged by the verdict (docs/reliability.md).
EXIT_FLAGGED = 4


def register(subparsers) -> None:
    """Add the ``calibrate`` sub-command."""
    p = subparsers.add_parser(
        "calibrate",
        help="infer theta = (a, b, af, bf) from measured LVV + 24 strains",
        description="Bayesian calibration with an emulator: volume-only, iid or polar-GP discrepancy likelihood. "
                    "Writes ArviZ InferenceData (netCDF) and summary tables.",
    )
    p.add_argument("--data",
                   help="measured data: CSV (lvv_ml, strain_01..strain_24 or aha_01..aha_16; optional subject "
                        "column; several rows of one subject with their own edp_mmhg are its loaded states), JSON or "
                        "MATLAB .mat (see docs/calibration.md); default: none, give it or --volunteer")
    p.add_argument("--segments", choices=("lvcore", "aha"), default=None,
                   help="segment convention of the strains (default: what the file says, else lvcore)")
    p.add_argument("--segment-offset", type=float, default=None, metavar="DEG",
                   help="lvcore angle (deg, counter-clockwise seen from the base) of the data's septal centre "
                        "(aha) or sector-0 start (lvcore); default 0")
    p.add_argument("--strain-layer", choices=tuple(STRAIN_LAYERS), default=None, help="wall layer of the strains; "
                   "another layer than the emulator's is refused (default: what the file declares in a strain_layer "
                   "column or key, else the emulator's own: inner_half for the bundled ones)")
    p.add_argument("--geometry",
                   help="(required with --data, unless --emulator is a subject-specific one from `lvcore emulator "
                        "build`, whose geometry is bound in) the subject's geometry: PC scores (.json/.csv, "
                        "optional 'scale'), a template mesh (.vtu/.npy/.npz) or a volumetric mesh (.inp/.msh/.vtu) "
                        "to fit and project (size-normalised: scores plus a scale); 'infer' (no mesh: PC scores and "
                        "scale sampled with theta, give --reference-volume); or 'mean' (warned: biased estimates "
                        "when the subject's shape or size differs); default: none, give it or --volunteer")
    p.add_argument("--reference-volume", type=float, default=None, metavar="ML",
                   help="with --geometry infer: the subject's early-diastolic (reference) cavity volume in mL; "
                        "also a data column reference_volume_ml (default: none, size and stiffness trade off)")
    p.add_argument("--wall-volume", type=float, default=None, metavar="ML",
                   help="with --geometry infer: myocardial volume in mL (LV mass in g / 1.05); also a data column "
                        "wall_volume_ml (default: none)")
    p.add_argument("--long-axis", type=float, default=None, metavar="MM",
                   help="with --geometry infer: base plane to epicardial apex in mm; also a data column long_axis_mm "
                        "(default: none)")
    p.add_argument("--reference-volume-sd", type=float, default=None, metavar="ML",
                   help="with --geometry infer: standard deviation of --reference-volume in mL, 0.5-50; also a data "
                        "column reference_volume_ml_sd (default 5)")
    p.add_argument("--wall-volume-sd", type=float, default=None, metavar="ML",
                   help="with --geometry infer: standard deviation of --wall-volume in mL, 0.5-50; also a data column "
                        "wall_volume_ml_sd (default 5)")
    p.add_argument("--long-axis-sd", type=float, default=None, metavar="MM",
                   help="with --geometry infer: standard deviation of --long-axis in mm, 0.2-30; also a data column "
                        "long_axis_mm_sd (default 3)")
    p.add_argument("--representation-error", choices=("floor", "off"), default="floor",
                   help="with --geometry infer or a mesh: 'floor' adds the shape model's representation error (how "
                        "far a real LV is from its 5-mode reconstruction, estimated from the SYNTHETIC cohort by "
                        "scripts/build_representation_error.py) to the variance of the strains, the LVV and the "
                        "geometric measures; 'off' leaves it out, as for a subject that is a shape-model shape "
                        "(default floor; PC scores and the mean shape never get one)")
    p.add_argument("--volunteer", default=None, metavar="NAME",
                   help="a bundled SYNTHETIC volunteer (e.g. SYNTHETIC_HV1) instead of --data and --geometry "
                        "(default: none)")
    p.add_argument("--geometry-units", choices=("mm", "cm", "m"), default="mm",
                   help="units of a volumetric --geometry mesh (default mm)")
    p.add_argument("--allow-extrapolation", action="store_true",
                   help="run even when PC scores or conditions lie outside the emulator's training box "
                        "(recorded as a warning in the output)")
    p.add_argument("--model", default="iid",
                   help="volume | iid | discrepancy, or a comma-separated list (default iid)")
    p.add_argument("--angles", choices=("fixed", "infer"), default="fixed",
                   help="fibre angles fixed at the emulator's values, or inferred (needs the 'angles' emulator)")
    p.add_argument("--emulator", default=None,
                   help=f"emulator name or directory (default: {DEFAULT_EMULATOR}, the app's default too, or angles "
                        "with --angles infer; 'angles' takes the EDP (6-14 mmHg) and fibre angles as inputs and is needed for "
                        "per-subject edp_mmhg other than 8; 'edpvr' takes the EDP over 1-30 mmHg at fibre angles "
                        "-60/60 deg, e.g. loaded states at 8 and 20 mmHg with --geometry infer); a subject-specific "
                        "emulator directory (`lvcore emulator build`) needs no --geometry")
    p.add_argument("--alpha-endo", type=float, default=None,
                   help="fixed alpha_endo (deg) for emulators that take angles (default -60); an error with "
                        "emulators trained at fixed angles (e.g. 'chapter', trained at -60/60)")
    p.add_argument("--alpha-epi", type=float, default=None,
                   help="fixed alpha_epi (deg) for emulators that take angles (default 90); an error with "
                        "emulators trained at fixed angles")
    p.add_argument("--edp", type=float, default=None,
                   help="end-diastolic pressure (mmHg, 2-40) for emulators that take it (default: the data's "
                        "edp_mmhg column, else 8); an error with emulators trained at a fixed EDP (e.g. 'chapter', "
                        "8 mmHg)")
    p.add_argument("--prior", choices=("none", "klotz"), default="none",
                   help="'klotz': the Klotz et al. (2006) normalised EDPVR as a soft constraint on the model's volumes "
                        "at 20 and 30 mmHg, predicted from the EDV at the measured EDP and the reference volume V0 "
                        "(needs an emulator whose EDP input covers 20-30 mmHg, e.g. a subject emulator built with "
                        "--inputs theta,edp --bound edp=6,30; docs/calibration.md); default none")
    p.add_argument("--sigma-v", type=float, default=SIGMA_V_ML,
                   help=f"LVV noise sd (mL), fixed, in [{SIGMA_V_RANGE_ML[0]:g}, {SIGMA_V_RANGE_ML[1]:g}] "
                        f"(default {SIGMA_V_ML:g})")
    p.add_argument("--strain-noise", type=float, default=None,
                   help=f"reference strain noise sd of the plausibility check, in [{STRAIN_NOISE_RANGE[0]:g}, "
                        f"{STRAIN_NOISE_RANGE[1]:g}] (default 0.035)")
    _add_sampler_options(p)
    p.add_argument("--derived-draws", type=int, default=None, metavar="N",
                   help="posterior draws behind the derived quantities (EDPVR by the FE simulator, stress, the "
                        "identified combination, contraction), 0 to skip them, at most 2,000 (default 100, or the "
                        "environment's LVCORE_DERIVED_DRAWS)")
    p.add_argument("--derived-pressures", default=None, metavar="P1,P2,...",
                   help="pressures (mmHg, increasing, in (0, 30]) of the derived EDPVR besides 0 mmHg (default "
                        "5,10,15,20,25,30; fewer pressures cost fewer FE solves, e.g. 20,30 in a study)")
    p.add_argument("--subject", default=None, help="row to use (subject id); default: every row")
    p.add_argument("--hierarchical", action="store_true",
                   help="one joint posterior for a cohort (--data COHORT.csv with optional group and geometry "
                        "columns): log theta ~ N(mu, Sigma) across subjects, NUTS, --model volume or iid; writes "
                        "the population, per-subject shrinkage against separate fits and group differences "
                        "(docs/calibration.md; default off: each subject alone)")
    p.add_argument("--out", type=cli_args.output_dir, default="calibration_out",
                   help="output folder, created if missing (default calibration_out)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run_calibrate)


def _add_sampler_options(p) -> None:
    """The sampler's options of ``lvcore calibrate``: the sampler, the discrepancy model's block 4 and GP kernel,
    chains, warm-up, draws and seed."""
    p.add_argument("--sampler", choices=("auto", "nuts", "hmc_gibbs"), default="auto",
                   help="auto: NUTS for volume/iid, HMC-within-Gibbs for discrepancy")
    p.add_argument("--discrepancy-block", choices=("marginal", "chapter"), default="marginal",
                   help="HMC-within-Gibbs block 4: marginal (the discrepancy integrated out of the NUTS block, then "
                        "drawn exactly; default, fewer steps and divergences) or chapter (Algorithm 4 as written: NUTS "
                        "over theta, the whitened discrepancy and v); the same posterior")
    p.add_argument("--discrepancy-kernel", choices=("additive", "product"), default="additive",
                   help="GP kernel of the discrepancy likelihood (--model discrepancy, or a list that includes it; "
                        "the other likelihoods have none): additive (default, the chapter's: a sector profile plus "
                        "a level profile, rank 9 on the 6 x 4 strain grid) or product (sector x level, full rank "
                        "24: can represent a mismatch that differs between sectors from level to level); "
                        "recorded in summary.json as discrepancy_kernel")
    p.add_argument("--chains", type=int, default=4,
                   help="MCMC chains, 1 to 64, run in parallel on up to 4 host devices (default 4)")
    p.add_argument("--warmup", type=int, default=1000,
                   help="warm-up (adaptation) iterations per chain, 1 to 1,000,000 (default 1000)")
    p.add_argument("--samples", type=int, default=1000,
                   help="draws kept per chain after convergence, 1 to 1,000,000 (default 1000)")
    p.add_argument("--seed", type=cli_args.seed, default=0,
                   help="random seed of the sampler, an integer from 0 to 2^32 - 1 (default 0)")


def check_options(args) -> None:
    """Refuse nonsensical sampler options before anything runs (DataError naming the option).

    The EDP and the fixed angles are checked against the emulator by
    :func:`lvcore.inference.guards.check_conditions`.
    """
    import math

    from lvcore.exceptions import DataError

    for name, value, lo in (("--chains", args.chains, 1), ("--warmup", args.warmup, 1), ("--samples", args.samples, 1)):
        if value < lo:
            raise DataError(f"{name} must be >= {lo}, got {value}")
    if args.chains > 64:
        raise DataError(f"--chains must be <= 64, got {args.chains}")
    if args.warmup > 1_000_000 or args.samples > 1_000_000:
        raise DataError("--warmup and --samples must be <= 1,000,000")
    raw = getattr(args, "derived_pressures", None)
    if raw is not None:
        try:
            ps = [float(x) for x in str(raw).split(",") if x.strip()]
        except ValueError:
            raise DataError(f"--derived-pressures {raw!r}: give comma-separated pressures in mmHg, e.g. 20,30") from None
        if not ps or any(not (0 < x <= 30) for x in ps) or any(b <= a for a, b in zip(ps, ps[1:])):
            raise DataError(f"--derived-pressures {raw!r}: pressures must increase within (0, 30] mmHg")
        args.derived_pressures = tuple(ps)
    kernel = getattr(args, "discrepancy_kernel", "additive")
    if kernel != "additive" and "discrepancy" not in [m.strip() for m in str(args.model).split(",")]:
        raise DataError(f"--discrepancy-kernel {kernel}: only the discrepancy likelihood has a GP kernel; "
                        "add discrepancy to --model (e.g. --model discrepancy) or leave the option out")
    n_derived = getattr(args, "derived_draws", None)
    if n_derived is not None and not 0 <= n_derived <= 2000:
        raise DataError(f"--derived-draws must be 0 (skip) to 2,000 posterior draws, got {n_derived}")
    if not (math.isfinite(args.sigma_v) and args.sigma_v > 0):
        raise DataError(f"--sigma-v must be a positive number of mL, got {args.sigma_v}")
    lo, hi = SIGMA_V_RANGE_ML
    if not lo <= args.sigma_v <= hi:
        raise DataError(f"--sigma-v {args.sigma_v:g} mL is outside [{lo:g}, {hi:g}] mL (docs/calibration.md): "
                        "larger, the volume carries no information and the posterior is the prior; smaller, "
                        "the likelihood is degenerate")
    if args.strain_noise is not None:
        lo, hi = STRAIN_NOISE_RANGE
        if not (math.isfinite(args.strain_noise) and lo <= args.strain_noise <= hi):
            raise DataError(f"--strain-noise {args.strain_noise:g} is outside [{lo:g}, {hi:g}] (a strain sd)")
    for name, value in (("--alpha-endo", args.alpha_endo), ("--alpha-epi", args.alpha_epi)):
        if value is not None and not (math.isfinite(value) and -180 <= value <= 180):
            raise DataError(f"{name} must be an angle in [-180, 180] degrees, got {value}")


def _volunteer(name: str, volunteer_files):
    """The bundled volunteer ``name``, in either spelling (``SYNTHETIC_HV1`` or the data files' ``SYNTHETIC-HV1``)."""
    from lvcore.exceptions import DataError

    try:
        return volunteer_files(name)
    except DataError as err:
        for alt in (name.replace("-", "_"), name.replace("-", "_").upper()):
            if alt != name:
                try:
                    return volunteer_files(alt)
                except DataError:
                    pass
        raise DataError(f"--volunteer {name}: {err}") from None


@dataclass(frozen=True)
class CalibrateSetup:
    """What ``lvcore calibrate`` sets up before sampling (:func:`prepare_run`).

    Attributes
    ----------
    emulator : lvcore.emulator.Emulator
    name : str
        The emulator's name or folder as given.
    models : tuple of str
        The likelihoods to run.
    rows : dict
        Subject -> its :class:`~lvcore.inference.data.MeasuredData`.
    requests : dict
        Subject -> its :class:`~lvcore.inference.request.CalibrationRequest`.
    config : lvcore.inference.samplers.SamplerConfig
    n_derived : int
        Posterior draws behind the derived quantities (0: none).
    geometry : str
        ``"infer"``, or where the given geometry came from (the netCDF attributes).
    """

    emulator: Any
    name: str
    models: tuple
    rows: dict
    requests: dict
    config: Any
    n_derived: int
    geometry: str

    @property
    def inferred(self) -> bool:
        return self.geometry == "infer"

    @property
    def bound(self) -> bool:
        """The emulator is subject-specific: its geometry is bound in."""
        return bool(getattr(self.emulator, "is_subject", False))


def _data_and_geometry(args, emulator, name: str, bound: bool) -> str:
    """Check ``--data``/``--geometry``/``--volunteer`` (a volunteer fills them in) and return how the user gave
    the geometry (the box check's error names it)."""
    from lvcore.exceptions import DataError

    if bound and args.geometry is not None:
        raise DataError(f"--geometry: the emulator '{name}' is subject-specific, built on the geometry "
                        f"{emulator.metadata['subject'].get('geometry_source')}, which is bound in; leave --geometry "
                        "out, or build an emulator for this geometry with `lvcore emulator build --geometry FILE`")
    if args.volunteer is not None:
        from lvcore.resources import volunteer_files

        if args.data is not None or args.geometry is not None:
            raise DataError("--volunteer replaces --data and --geometry: give one or the other")
        vol = _volunteer(args.volunteer, volunteer_files)
        args.data, args.geometry = str(vol.measured), None if bound else str(vol.geometry)
        label = f"--volunteer {args.volunteer} (its bundled geometry)"
    elif args.data is None or (args.geometry is None and not bound):
        raise DataError("give --data and --geometry (your measurements and the subject's geometry; "
                        "'--geometry mean' to use the mean shape knowingly), or --volunteer NAME (a bundled one)")
    else:
        label = f"--geometry {args.geometry}"
    return f"--emulator {name} (its own geometry)" if bound else label


def _measure_options(args, inferred: bool) -> tuple[dict, dict]:
    """``--reference-volume``/``--wall-volume``/``--long-axis`` and their sds, checked; only with --geometry infer."""
    from lvcore.exceptions import DataError
    from lvcore.inference import geometry_prior

    measures = geometry_prior.check_measures(
        {"reference_volume_ml": args.reference_volume, "wall_volume_ml": args.wall_volume,
         "long_axis_mm": args.long_axis}, "options")
    sds = geometry_prior.check_measure_sds(
        {"reference_volume_ml": args.reference_volume_sd, "wall_volume_ml": args.wall_volume_sd,
         "long_axis_mm": args.long_axis_sd}, "options")
    if (measures or sds) and not inferred:
        opts = [geometry_prior.MEASURE_OPTIONS[k] for k in measures] + [geometry_prior.MEASURE_SD_OPTIONS[k]
                                                                         for k in sds]
        raise DataError(f"{', '.join(opts)} inform an inferred geometry; use them with --geometry infer (a mesh or "
                        "PC scores already fix the size)")
    return measures, sds


def prepare_run(args) -> CalibrateSetup:
    """Everything ``lvcore calibrate`` does before sampling: the inputs read and checked (exit 2 on a bad one)
    and one :class:`~lvcore.inference.request.CalibrationRequest` per subject
    (:func:`lvcore.inference.request.build_request`, as the app's pages)."""
    import numpy as np

    from lvcore.emulator.forward import load_emulator_forward
    from lvcore.exceptions import DataError
    from lvcore.inference import calibrate as cal
    from lvcore.inference import derived, guards, plausibility
    from lvcore.inference.data import read_measurements
    from lvcore.inference.models import MODEL_NAMES
    from lvcore.inference.request import INFER
    from lvcore.inference.samplers import SamplerConfig
    from lvcore.domain.outputs import is_pc_name

    infer = args.angles == "infer"
    name = args.emulator or ("angles" if infer else DEFAULT_EMULATOR)
    emulator = load_emulator_forward(name, np.zeros(16), infer_angles=infer).emulator
    bound = bool(getattr(emulator, "is_subject", False))  # geometry bound in (lvcore emulator build)
    label = _data_and_geometry(args, emulator, name, bound)
    model_names = [m.strip() for m in args.model.split(",") if m.strip()]
    bad = [m for m in model_names if m not in MODEL_NAMES]
    if bad or not model_names:
        raise DataError(f"--model {','.join(bad)}: choose from {', '.join(MODEL_NAMES)}")
    sigma_ref = plausibility.DEFAULT_SIGMA_REF if args.strain_noise is None else float(args.strain_noise)
    rows = read_measurements(args.data, segments=args.segments, offset_deg=args.segment_offset)
    if args.subject is not None:
        rows = [r for r in rows if r.subject == args.subject]
        if not rows:
            raise DataError(f"--subject {args.subject}: no such subject in {args.data}")
    cal.output_stems([r.subject for r in rows], source=str(args.data))  # unique file names, before any work
    # the conditions once before the geometry (a mesh fit takes seconds); build_request checks them per subject
    guards.check_conditions(emulator, args.edp, args.alpha_endo, args.alpha_epi, infer_angles=infer)
    n_pc = sum(1 for n in emulator.input_names if is_pc_name(n))
    inferred = str(args.geometry).strip().lower() == INFER
    cli_measures, cli_sds = _measure_options(args, inferred)
    representation = None
    if args.representation_error == "floor" and not bound:   # loaded once for every subject
        from lvcore.inference.representation_error import load_representation_error

        representation = load_representation_error(n_pc)
    geometry = INFER if inferred else None if bound else guards.resolve_geometry(args.geometry, n_pc=n_pc,
                                                                                  units=args.geometry_units)
    requests = {r.subject: _request(args, emulator, name, r, geometry, label, cli_measures, cli_sds,
                                    representation=representation, sigma_ref=sigma_ref) for r in rows}
    config = SamplerConfig(num_warmup=args.warmup, num_samples=args.samples, num_chains=args.chains, seed=args.seed,
                           discrepancy_block=args.discrepancy_block,
                           discrepancy_kernel=getattr(args, "discrepancy_kernel", "additive"))
    n_derived = derived.default_draws() if args.derived_draws is None else int(args.derived_draws)
    source = INFER if inferred else next(iter(requests.values())).geometry.source if requests else str(geometry)
    return CalibrateSetup(emulator, name, tuple(model_names), {r.subject: r for r in rows}, requests, config,
                          n_derived, source)


def _request(args, emulator, name: str, row, geometry, label: str, cli_measures: dict, cli_sds: dict, *,
             representation, sigma_ref: float):
    """One subject's :class:`~lvcore.inference.request.CalibrationRequest` from the options and its row."""
    from lvcore.inference.geometry_prior import MEASURE_SD_COLUMNS, MEASURE_SD_OPTIONS
    from lvcore.inference.request import INFER, build_request

    kw = {}
    if geometry == INFER:
        measures = _subject_measures(row, cli_measures)
        sds = _subject_measure_sds(row, cli_sds, measures)
        kw = {"measures": measures, "measure_sd": sds,
              "measure_sd_source": {k: ("data column " + MEASURE_SD_COLUMNS[k] if k in row.measure_sds
                                        else MEASURE_SD_OPTIONS[k]) for k in sds}}
    return build_request(emulator, name, geometry, row=row, edp_mmhg=args.edp, alpha_endo=args.alpha_endo,
                         alpha_epi=args.alpha_epi, infer_angles=args.angles == "infer",
                         allow_extrapolation=args.allow_extrapolation, representation_error=args.representation_error,
                         prior=args.prior, geometry_label=label, representation=representation, sigma_v=args.sigma_v,
                         sigma_ref=sigma_ref, strain_layer=getattr(args, "strain_layer", None), **kw)


def run_calibrate(args) -> int:
    """``lvcore calibrate``: set up (:func:`prepare_run`), sample every subject x likelihood, give each result
    its verdict and write ``summary.json``; the exit code (0, 1 not converged, :data:`EXIT_FLAGGED`)."""
    from lvcore.inference.samplers import use_host_devices

    check_options(args)
    use_host_devices(args.chains)
    if getattr(args, "hierarchical", False):
        from lvcore.inference.hierarchical_cli import run_hierarchical_calibrate

        return run_hierarchical_calibrate(args)

    from lvcore.inference import calibrate as cal

    setup = prepare_run(args)
    for w in dict.fromkeys(w for q in setup.requests.values() for w in q.warnings):
        print(f"lvcore: warning: {w}", file=sys.stderr)
    extra, consistency = {}, {}
    attrs = {"data_file": str(args.data), "emulator": setup.name, "angles": args.angles,
             "base": str(getattr(setup.emulator, "base", "clamped")), "geometry": setup.geometry,
             "strain_layer": str(getattr(setup.emulator, "strain_layer", DEFAULT_STRAIN_LAYER))}
    if not setup.inferred:
        geo = next(iter(setup.requests.values())).geometry
        attrs.update({"pc_scores": json.dumps([float(v) for v in geo.h]), "scale": float(geo.scale)})
    results = cal.calibrate_subjects(
        [(s, q.y, q.forward) for s, q in setup.requests.items()], list(setup.models), config=setup.config,
        sampler=args.sampler, sigma_v=args.sigma_v, infer_angles=args.angles == "infer", out_dir=args.out,
        attrs=attrs, progress=None if args.json else (lambda msg, frac: print(msg)),
        on_result=lambda item: _finish(item, setup, args, extra, consistency))
    records = [{**item.record(), **extra[(item.subject, item.model)]} for item in results]
    for rec, item in zip(records, results):
        rec["edp_mmhg"] = setup.requests[item.subject].conditions["edp_mmhg"]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(records, indent=2))
    if args.json:
        print(json.dumps(records, indent=2))
    else:
        print(f"\nwrote {out}/summary.json and per-model .nc / _summary.csv / _ppc.csv")
    if not all(r["converged"] for r in records):
        return 1
    return EXIT_FLAGGED if any(r["flags"] for r in records) else 0


def _finish(item, setup: CalibrateSetup, args, extra: dict, consistency: dict) -> None:
    """Verdict, posterior-predictive CSV, derived quantities and the guard records of one (subject, model)
    result, into ``extra``; printed unless ``--json``."""
    import numpy as np

    from lvcore.inference import calibrate as cal
    from lvcore.inference import derived, geometry_prior, plausibility, verdict
    from lvcore.inference.models import lvv_sd
    from lvcore.domain.outputs import is_pc_name

    q, row, res = setup.requests[item.subject], setup.rows[item.subject], item.result
    forward, out, c = q.forward, Path(args.out), q.conditions
    if item.subject not in consistency:   # one per subject: the same for every model
        consistency[item.subject] = q.consistency(seed=args.seed)
    v = verdict.run_verdict(res, consistency[item.subject], q.bounds, forward)
    v = v.with_extra("EXTRAPOLATION", [e.split(": ", 1)[1] for e in q.extrapolation])
    check = plausibility.check_result(res, q.y, q.sigma_v, q.sigma_ref, seed=args.seed, forward=forward)
    out.mkdir(parents=True, exist_ok=True)
    derived_rec = None
    if setup.n_derived:
        given = not (setup.inferred or setup.bound)
        derived_rec, draws = derived.derive(
            res.idata, bounds={k: b for k, b in q.bounds.items() if k in derived.THETA_NAMES},
            edp_mmhg=c["edp_mmhg"], angles=(None, None) if q.infer_angles else (c["alpha_endo"], c["alpha_epi"]),
            base=q.base, resolution=q.resolution, measured_edv_ml=float(q.y[0]),
            lvv_sd_ml=lambda v_ml, fw=forward: np.asarray(lvv_sd(v_ml, q.sigma_v, fw), float),
            h=q.geometry.h if given else None, scale=q.geometry.scale if given else 1.0,
            geometry=setup.emulator.subject_geometry if setup.bound else None, n_draws=setup.n_derived,
            pressures_mmhg=getattr(args, "derived_pressures", None) or derived.EDPVR_PRESSURES_MMHG)
        draws.save(out / f"{cal.file_stem(item.subject)}_{item.model}_derived.npz")
        v = v.with_extra("CONSISTENCY", derived.check_flags(derived_rec))
    ppc_csv = out / f"{cal.file_stem(item.subject)}_{item.model}_ppc.csv"
    ppc_csv.write_text("output,p_value\n" + "".join(f"{k},{val:.6g}\n"
                                                    for k, val in check.record()["p_values"].items()))
    geometry = dict(q.geometry_record)
    if setup.inferred:
        geometry["posterior"] = geometry_prior.geometry_posterior(
            {n: np.asarray(res.idata.posterior[n]) for n in forward.latent_names}, forward)
    else:
        geometry["box"] = [b for b in q.box if is_pc_name(b["name"])]
    extra[(item.subject, item.model)] = rec = {
        "ppc_csv": str(ppc_csv),
        "geometry": geometry,
        "conditions": {"emulator": setup.name, "base": q.base, "strain_layer": q.strain_layer,
                       "edp_mmhg": c["edp_mmhg"],
                       "edp_source": q.edp_source,
                       "alpha_endo": None if q.infer_angles else c["alpha_endo"],
                       "alpha_epi": None if q.infer_angles else c["alpha_epi"],
                       "fixed_by_emulator": c["fixed"],
                       "box": [b for b in q.box if not is_pc_name(b["name"])]},
        "extrapolation_allowed": bool(args.allow_extrapolation),
        "plausible": v.plausible,
        "plausibility": v.consistency.record(),
        "posterior_predictive": check.record(),
        "verdict": v.record(),
        "flags": v.flags,
        "notes": list(v.notes) + ([] if derived_rec is None else derived_rec["weakly_identified"]),
        "derived": derived_rec,
        **_states_records(row, forward, res),
        "warnings": [x for x in q.warnings if x not in q.extrapolation] + v.flags}
    for f in v.flags:
        print(f"lvcore: warning: [{item.subject}/{item.model}] FLAGGED: {f}", file=sys.stderr)
    if not args.json:
        _print_result(item, q, v, check, rec, derived_rec)


def _print_result(item, q, v, check, rec: dict, derived_rec) -> None:
    """The printed block of one (subject, model) result: posterior table, convergence, loaded states, derived
    quantities and the fit check's worst outputs."""
    import numpy as np

    from lvcore.inference import derived, verdict

    res, c = item.result, q.conditions
    print(f"\n== {item.subject} / {item.model} ({res.sampler}, {res.wall_s:.1f} s; {q.emulator_name} emulator, "
          f"{q.base} base, EDP {c['edp_mmhg']:g} mmHg) ==")
    print(res.summary.to_string(float_format=lambda val: f"{val:.4g}"))
    print(res.convergence.message())
    for line in _states_text(rec):
        print(line)
    if derived_rec is not None:
        print(derived.text_table(derived_rec))
    names = list(check.record()["p_values"])
    worst = np.argsort(v.consistency.p_values)[:3]
    print("fit check: the best-fitting model against the data, the 3 outputs it misses most with their "
          "p-value (the chance of missing by at least this much if the model and the noise were right; "
          f"below {verdict.ALPHA:g} an output is not reached, and the LVV or {verdict.MIN_BAD_STRAINS}+ "
          "strains not reached make the data inconsistent):\n  "
          + ", ".join(f"{names[i]} p = {v.consistency.p_values[i]:.2g}" for i in worst)
          + ("" if v.plausible else "  -> IMPLAUSIBLE, see warnings")
          + (f"; {len(v.flags)} flag(s): exit code 4" if v.flagged else ""))


def _subject_measure_sds(row, cli_sds: dict, measures: dict) -> dict:
    """Measure sds of one subject: the data's ``*_sd`` columns and the CLI options (which must agree);
    an sd for a measure the subject does not have is refused."""
    from lvcore.exceptions import DataError
    from lvcore.inference.geometry_prior import MEASURE_OPTIONS, MEASURE_SD_COLUMNS, MEASURE_SD_OPTIONS

    out = dict(row.measure_sds)
    for k, v in cli_sds.items():
        if k in out and abs(out[k] - v) > 1e-9:
            raise DataError(f"subject {row.subject}: the data's {MEASURE_SD_COLUMNS[k]} {out[k]:g} and "
                            f"{MEASURE_SD_OPTIONS[k]} {v:g} disagree; drop one of them")
        out[k] = v
    for k in out:
        if k not in measures:
            where = MEASURE_SD_COLUMNS[k] if k in row.measure_sds else MEASURE_SD_OPTIONS[k]
            raise DataError(f"subject {row.subject}: {where} is given without the measure itself; give "
                            f"{MEASURE_OPTIONS[k]} (or the data column {k}) too, or drop it")
    return out


def _subject_measures(row, cli_measures: dict) -> dict:
    """Geometric measures of one subject: the data's columns, and the CLI options (which must agree)."""
    from lvcore.exceptions import DataError
    from lvcore.inference.geometry_prior import MEASURE_OPTIONS

    out = dict(row.measures)
    for k, v in cli_measures.items():
        if k in out and abs(out[k] - v) > 1e-9:
            raise DataError(f"subject {row.subject}: the data's {k} {out[k]:g} and {MEASURE_OPTIONS[k]} {v:g} disagree; "
                            "drop one of them")
        out[k] = v
    return out


def _quantile_record(x) -> dict:
    import numpy as np

    x = np.asarray(x, float).reshape(-1)
    return {"median": float(np.median(x)), "q05": float(np.quantile(x, 0.05)), "q95": float(np.quantile(x, 0.95))}


def _states_records(row, forward, res) -> dict:
    """summary.json's ``loaded_states`` (every state, measured and posterior LVV) and ``prior`` (--prior klotz)."""
    import numpy as np

    out = {}
    post = res.idata.posterior
    states = getattr(forward, "states", ())
    if states:
        eta = np.asarray(post["eta_states"])
        rows = [{"edp_mmhg": float(row.edp_mmhg), "lvv_ml": float(row.y[0]), "strains": True, "primary": True,
                 "posterior_lvv_ml": _quantile_record(np.asarray(post["eta"])[..., 0])}]
        rows += [{"edp_mmhg": float(st.edp_mmhg), "lvv_ml": float(st.y[0]), "strains": bool(st.has_strains),
                  "primary": False, "posterior_lvv_ml": _quantile_record(eta[..., k, 0])}
                 for k, st in enumerate(states)]
        out["loaded_states"] = sorted(rows, key=lambda d: d["edp_mmhg"])
    klotz = getattr(forward, "klotz", None)
    if klotz is not None:
        v0 = np.asarray(post["klotz_v0"]).reshape(-1)
        rec = klotz.record(measured_edv_ml=float(row.y[0]), v0_ml=float(np.median(v0)))
        vols = np.asarray(post["klotz_volumes"])
        rec["posterior_ml"] = {f"V{p:g}": _quantile_record(vols[..., i]) for i, p in enumerate(klotz.pressures_mmhg)}
        rec["posterior_ml"]["V0"] = _quantile_record(v0)
        out["prior"] = rec
    return out


def _states_text(rec: dict) -> list[str]:
    """The printed lines of the loaded states and the Klotz prior (from :func:`_states_records`)."""
    lines = []
    if rec.get("loaded_states"):
        lines.append("loaded states (measured LVV; posterior LVV median [90 %]): " + "; ".join(
            f"{s['edp_mmhg']:g} mmHg {s['lvv_ml']:.1f} mL{'' if s['strains'] else ' (volume only)'}"
            f"{' (primary)' if s['primary'] else ''} -> {s['posterior_lvv_ml']['median']:.1f} "
            f"[{s['posterior_lvv_ml']['q05']:.1f}, {s['posterior_lvv_ml']['q95']:.1f}] mL" for s in rec["loaded_states"]))
    prior = rec.get("prior")
    if prior:
        lines.append(f"prior: {prior['reference']} EDPVR; posterior " + ", ".join(
            f"{k} {q['median']:.1f} [{q['q05']:.1f}, {q['q95']:.1f}] mL" for k, q in prior["posterior_ml"].items()))
    return lines
