"""Subject-specific emulators: the FE simulator on one subject's exact geometry, emulated.

The bundled emulators take the geometry as PC scores of the shape model, so a
subject's own mesh is approximated by its projection (and refused outside the
±2 score box). A *subject emulator* is trained on FE runs on the subject's
geometry as it is, with no projection:

1. :func:`resolve_subject_geometry` turns what the user has (a template mesh,
   a volumetric tet/hex mesh, a contour stack, a case file, PC scores, or
   ``default``) into the case's ``geometry`` section; template-node
   geometries are written to ``DIR/geometry.vtu`` so the emulator directory
   is self-contained.
2. A scrambled Sobol design (:func:`lvcore.campaigns.designs.make_design`,
   ``scipy.stats.qmc``) over the prior box of the chosen inputs (θ, and
   optionally the EDP and the fibre angles: :data:`INPUT_GROUPS`) gives the
   training rows, and an independent one the validation and held-out test
   rows, split at random (:func:`design_rows`).
3. Every row is simulated on the exact geometry (:func:`simulate_rows`:
   continuation chains of :mod:`lvcore.execution.chains`, each solve starting Newton
   from a neighbour's solution, fed chunk by chunk to the worker processes
   with no barrier between them); the runs done are saved (``fe_runs.npz``)
   as every chunk returns: a build that fails, is stopped or killed keeps
   them, and the next build of the same design resumes from them.
4. The network is trained with :func:`lvcore.emulator.training.train_emulator`
   (validation rows: early stopping and selection) on the correction to a
   prior mean where one matches (:func:`choose_prior`: a bundled emulator over
   PC scores at the subject's size-normalised shape, LVV times ``s^3``; the
   network learns the LVV ratio and the strain differences, so fewer runs
   suffice); the test rows, which the training never sees, give the held-out
   LVV and strain RMSE of the full outputs recorded in the metadata
   (``metadata["test"]``).
5. For a mesh geometry (unless ``edpvr=False``, ``lvcore emulator build
   --no-edpvr``), its own EDPVR emulator is built into ``DIR/edpvr``
   (:mod:`lvcore.emulator.subject_edpvr`: FE load paths of 0-30 mmHg on the
   same mesh), which the derived quantities of a calibration through this
   emulator evaluate instead of FE load paths.

The emulator directory is an ordinary one (:mod:`lvcore.emulator.io`) with a
``subject`` section in ``metadata.json``: the geometry section (path relative
to the directory), where it came from, the run counts and the wall time of
each stage. :func:`lvcore.emulator.load_emulator` resolves the geometry path,
and :attr:`lvcore.emulator.model.Emulator.is_subject` tells calibration that
the geometry is bound in (no PC scores to give).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from lvcore._exports import renamed_keywords
from lvcore.domain.conditions import CHAPTER_ANGLES, CHAPTER_EDP
from lvcore.core.space import ANGLE_BOUNDS, ANGLES_THETA_BOUNDS, EDP_BOUNDS, THETA_BOUNDS, Parameter, ParameterSpace
from lvcore.emulator.subject_geometry import (GEOMETRY_FILE, MESH_SUFFIXES, VOLUME_MESH_SUFFIXES, SubjectGeometry,
                                              resolve_subject_geometry, subject_template_nodes)
from lvcore.emulator.subject_prior import choose_prior, describe_prior
from lvcore.emulator.subject_runs import CHECKPOINT_ROWS, RUNS_FILE, SimulatedRows, simulate_rows
from lvcore.exceptions import EmulatorError
from lvcore.domain.outputs import ANGLE_NAMES, DEFAULT_STRAIN_LAYER, EDP_NAME, THETA_NAMES
from lvcore.domain.outputs import strain_layer as canonical_strain_layer

#: Input groups of ``--inputs``: θ (always), the EDP, the two fibre angles.
INPUT_GROUPS = {"theta": THETA_NAMES, EDP_NAME: (EDP_NAME,), "angles": ANGLE_NAMES}
#: Most FE runs one build may ask for.
MAX_RUNS = 20_000
#: Whether a build of a mesh geometry also trains the subject EDPVR emulator unless told (``--edpvr``/``--no-edpvr``;
#: see :func:`build_subject_emulator`); a geometry that is no mesh (``default``, PC scores) never gets one unasked.
DEFAULT_EDPVR = True


# --------------------------------------------------------------------------- the design space
def parse_inputs(text: str | Sequence[str]) -> tuple[str, ...]:
    """``"theta,edp,angles"`` -> the input groups (θ always first).

    Raises
    ------
    EmulatorError
        For an unknown group or one without ``theta``.
    """
    groups = [g.strip() for g in (text.split(",") if isinstance(text, str) else text) if g.strip()]
    bad = [g for g in groups if g not in INPUT_GROUPS]
    if bad or "theta" not in groups:
        raise EmulatorError(f"--inputs {','.join(groups)}: give 'theta' plus optionally 'edp' and 'angles', "
                            f"comma-separated (e.g. theta,edp,angles); unknown: {bad}")
    return tuple(g for g in INPUT_GROUPS if g in groups)


@renamed_keywords(edp="edp_mmhg")
def subject_space(groups: Sequence[str] = ("theta",), *, base: str = "sliding", edp_mmhg: float = CHAPTER_EDP,
                  alpha_endo: float = CHAPTER_ANGLES[0], alpha_epi: float = CHAPTER_ANGLES[1],
                  bounds: Mapping[str, tuple[float, float]] | None = None, name: str = "subject") -> ParameterSpace:
    """The design space of a subject emulator.

    Parameters
    ----------
    groups : sequence of str
        Input groups (:data:`INPUT_GROUPS`). θ is log-uniform over the prior
        box :data:`~lvcore.core.space.THETA_BOUNDS` (with the fibre angles
        varied, :data:`~lvcore.core.space.ANGLES_THETA_BOUNDS`, as for the
        ``angles`` emulator); the EDP over :data:`EDP_BOUNDS` (mmHg) and the
        angles over :data:`ANGLE_BOUNDS` (deg), uniform.
    base : {"clamped", "sliding"}
        Basal boundary condition (``chapter`` is trained sliding).
    edp_mmhg, alpha_endo, alpha_epi : float
        Values of the inputs that are not varied (mmHg, deg); ``edp`` is the old name of ``edp_mmhg``.
    bounds : mapping, optional
        Narrower (or other) bounds by input name, e.g. ``{"a": (0.5, 2)}``.
    """
    groups = parse_inputs(list(groups))
    theta = ANGLES_THETA_BOUNDS if "angles" in groups else THETA_BOUNDS
    box = {**theta, EDP_NAME: EDP_BOUNDS, **ANGLE_BOUNDS}
    unknown = [k for k in (bounds or {}) if k not in box]
    if unknown:
        raise EmulatorError(f"bounds for unknown input(s) {unknown}; inputs: {list(box)}")
    box.update({k: (float(v[0]), float(v[1])) for k, v in (bounds or {}).items()})
    names = [n for g in groups for n in INPUT_GROUPS[g]]
    outside = [k for k in (bounds or {}) if k not in names]
    if outside:
        raise EmulatorError(f"bounds given for {outside}, which are not varied (inputs {','.join(groups)})")
    params = tuple(Parameter(n, *box[n], "log" if n in THETA_NAMES else "linear") for n in names)
    fixed = {EDP_NAME: float(edp_mmhg), ANGLE_NAMES[0]: float(alpha_endo), ANGLE_NAMES[1]: float(alpha_epi)}
    fixed = tuple((k, v) for k, v in fixed.items() if k not in names)
    return ParameterSpace(name, params, fixed, base)


# --------------------------------------------------------------------------- the build
def default_training_config(seed: int = 0):
    """The :class:`~lvcore.emulator.training.TrainingConfig` of subject emulators.

    One 100 x 100 network (no architecture search), 600 Adam epochs (batch
    64, learning rate halved every 150 epochs), then 1,500 L-BFGS iterations
    with the LVV weighted as much as the 24 strains together. On the 800 +
    100 rows of a SYNTHETIC_HV3 build it took 21 CPU-s and gave a held-out
    LVV RMSE of 0.763 mL and strain RMSE of 0.0008 (100 test runs), where
    1,500 Adam epochs + 3,000 L-BFGS iterations gave 0.855 mL / 0.0006 in
    several times the CPU (docs/campaigns_and_emulators.md; those builds
    had no prior mean). With a prior mean, 512 + 50 rows of SYNTHETIC_HV3 train
    in about 15 s to a held-out LVV RMSE of 0.3 mL (BENCHMARKS.md row 44).
    """
    from lvcore.emulator.training import TrainingConfig

    return TrainingConfig(architectures=((100, 100),), max_epochs=600, patience=300, decay_epochs=150,
                          batch_size=64, lbfgs_iterations=1500, lvv_weight=1.0, lbfgs_lvv_weight=24.0, seed=seed)


@dataclass(frozen=True)
class SubjectDesign:
    """Run counts of a subject emulator's design.

    Attributes
    ----------
    n_train, n_valid, n_test : int
        Training rows, validation rows (early stopping, iterate selection)
        and held-out test rows (never seen by the training).
    method : str
        Design method of :func:`lvcore.campaigns.designs.unit_design`
        (``sobol``: scrambled Sobol; ``lhs``).

    The defaults (512 + 50 + 100 runs) are sized for a build with a prior
    mean (:func:`choose_prior`), whose network learns a small correction;
    without one, the whole map needs more training runs for the same
    accuracy (docs/campaigns_and_emulators.md).
    """

    n_train: int = 512
    n_valid: int = 50
    n_test: int = 100
    method: str = "sobol"

    def __post_init__(self):
        for k in ("n_train", "n_valid", "n_test"):
            if int(getattr(self, k)) < 2:
                raise EmulatorError(f"{k.replace('_', '-')} must be >= 2, got {getattr(self, k)}")
        if self.total > MAX_RUNS:
            raise EmulatorError(f"a subject emulator's design is capped at {MAX_RUNS:,} FE runs, got {self.total}")

    @property
    def total(self) -> int:
        return int(self.n_train) + int(self.n_valid) + int(self.n_test)


def design_rows(space: ParameterSpace, design: SubjectDesign, seed: int) -> tuple[np.ndarray, dict]:
    """The design's points (physical units) and the row indices of its ``train``, ``valid`` and ``test`` parts.

    The training rows are one space-filling design of ``n_train`` points
    (:func:`lvcore.campaigns.designs.make_design`, seed ``seed``), so they fill
    the box as evenly as that many points can (a random subset of a larger
    design leaves holes). The validation and held-out test rows are an
    independent design of their own (seed ``seed + 1``), split at random: they
    cover the same box, and none of them is a training point.
    """
    from lvcore.campaigns.designs import make_design

    train = make_design(space, design.method, design.n_train, seed).points
    held = make_design(space, design.method, design.n_valid + design.n_test, (int(seed) + 1) % 2 ** 32).points
    split = design.n_train + np.random.default_rng(seed).permutation(design.n_valid + design.n_test)
    parts = {"train": np.arange(design.n_train), "valid": split[:design.n_valid],
             "test": split[design.n_valid:]}
    return np.concatenate([train, held]), parts


@renamed_keywords(edp="edp_mmhg")
def build_subject_emulator(geometry, out, *, inputs: Sequence[str] | str = ("theta",),
                           design: SubjectDesign = SubjectDesign(), resolution: str = "default",
                           base: str = "sliding", edp_mmhg: float = CHAPTER_EDP, alpha_endo: float = CHAPTER_ANGLES[0],
                           alpha_epi: float = CHAPTER_ANGLES[1], bounds: Mapping | None = None, units: str = "mm",
                           workers: int = 2, seed: int = 0, config=None, name: str | None = None,
                           prior: str = "auto", log: Callable[[str], None] | None = None,
                           progress: Callable[[int, int], None] | None = None,
                           stop: Callable[[], bool] | None = None, strain_layer: str = DEFAULT_STRAIN_LAYER,
                           edpvr: bool | None = None, edpvr_design=None):
    """Build, validate and save a subject-specific emulator (see the module docstring).

    Parameters
    ----------
    geometry : str, Path or SubjectGeometry
        As :func:`resolve_subject_geometry` takes it.
    out : str or Path
        Emulator directory (created; ``geometry.vtu``, ``network.npz``,
        ``metadata.json``, ``validation.npz`` with the test rows,
        ``training_data.npz`` with every converged row).
    inputs : sequence or str
        Input groups, e.g. ``"theta,edp,angles"`` (:func:`parse_inputs`).
    design : SubjectDesign
        Run counts (at most 1,000 in all by default).
    resolution : str
        Mesh preset of the FE runs.
    base, edp_mmhg, alpha_endo, alpha_epi, bounds
        See :func:`subject_space`.
    units : str
        Units of a volumetric mesh.
    workers : int
        FE worker processes (one continuation chain each).
    seed : int
        Seed of the design, the split and the training.
    config : TrainingConfig, optional
        Default :func:`default_training_config`.
    name : str, optional
        Emulator name (default ``subject-<file stem>``).
    prior : str
        The prior mean the network corrects (:func:`choose_prior`): ``auto``
        (a matching emulator over PC scores at the subject's projected shape
        and size, or none), ``none`` (the network learns the whole map), or
        an emulator name or directory. A copy of it is saved in ``out/prior``.
    log : callable, optional
        Progress lines.
    progress : callable, optional
        ``progress(done, total)`` FE runs, as every chunk of runs returns (:func:`simulate_rows`).
    stop : callable, optional
        Asked as every chunk of FE runs returns; True stops the build with an
        :class:`~lvcore.exceptions.EmulatorError`.
    strain_layer : str
        The wall layer of the FE runs' strains (:data:`lvcore.domain.outputs.STRAIN_LAYERS`; default the inner
        half), recorded in the emulator's metadata; a prior mean must have the same layer.
    edpvr, edpvr_design : bool or None, EdpvrDesign
        Also build the subject EDPVR emulator (:mod:`lvcore.emulator.subject_edpvr`; ``out/edpvr``, design default
        256 + 16 + 32 paths, 82 s for SYNTHETIC_HV3, BENCHMARKS.md row 51); None: :func:`resolve_edpvr`.

    The FE runs done are saved in ``out/fe_runs.npz`` (:data:`RUNS_FILE`) as every chunk returns, so a build that
    fails, is stopped or killed keeps them, and a new build of the same design into ``out`` resumes from them.

    Returns
    -------
    lvcore.emulator.model.Emulator
        As saved; ``metadata["test"]`` holds the held-out accuracy and
        ``metadata["subject"]`` the geometry, counts and stage times.

    Raises
    ------
    GeometryError, EmulatorError
        Bad geometry or options; too few converged rows to train.
    """
    t_start = time.perf_counter()
    say = log or (lambda msg: None)
    out = Path(out)
    groups = parse_inputs(inputs)
    space = subject_space(groups, base=base, edp_mmhg=edp_mmhg, alpha_endo=alpha_endo, alpha_epi=alpha_epi,
                          bounds=bounds)
    geo = geometry if isinstance(geometry, SubjectGeometry) else resolve_subject_geometry(geometry, units=units)
    out.mkdir(parents=True, exist_ok=True)
    section = _write_geometry(geo, out, edpvr=bool(edpvr))
    t_geometry = time.perf_counter() - t_start
    say(f"geometry: {geo.kind} from {geo.source} ({t_geometry:.1f} s)")
    edpvr = resolve_edpvr(edpvr, section, say)
    for w in geo.warnings:
        say(f"  warning: {w}")

    strain_layer = _checked_strain_layer(strain_layer)
    prior_mean, prior_record = choose_prior(space, section, prior, strain_layer=strain_layer)
    say(_prior_line(prior_mean, prior_record))
    points, parts = design_rows(space, design, seed)
    say(f"design: {design.total} {design.method} points over {list(space.names)} "
        f"({design.n_train} train / {design.n_valid} validation / {design.n_test} held-out test), "
        f"{resolution} mesh, {base} base, {strain_layer} strains, {workers} worker(s)")
    runs = simulate_rows(space, points, section, resolution=resolution, workers=workers, strain_layer=strain_layer,
                         checkpoint=out / RUNS_FILE, progress=progress, stop=stop)
    n_failed = int(np.sum(~runs.converged))
    say(f"FE runs: {runs.converged.sum()} of {design.total} converged in {runs.wall_s:.1f} s "
        f"({design.total / max(runs.wall_s, 1e-9):.1f} solves/s, warm-started chains on {runs.workers} worker(s))")
    sets = _converged_sets(points, runs, parts, out)

    t_train0 = time.perf_counter()
    name = name or f"subject-{Path(geo.source).stem if geo.kind != 'default' else 'default'}"
    emu = _train(space, sets, name=name, resolution=resolution, n_failed=n_failed, strain_layer=strain_layer,
                 config=config or default_training_config(seed), log=log, prior_mean=prior_mean)
    t_train = time.perf_counter() - t_train0
    emu.metadata["subject"] = {
        # save_emulator writes DIR/geometry.vtu's path relative to the directory
        "geometry": section, "geometry_source": geo.source, "geometry_kind": geo.kind, "geometry_record": geo.record,
        "geometry_warnings": list(geo.warnings), "inputs": list(groups), "design": design.method,
        "seed": int(seed), "workers": int(workers), "prior": prior_record,
        "runs": {"total": design.total, "converged": int(runs.converged.sum()), "failed": n_failed,
                 **{f"n_{k}": int(v[0].shape[0]) for k, v in sets.items()}},
        "seconds": {"geometry": round(t_geometry, 2), "simulations": round(runs.wall_s, 2),
                    "training": round(t_train, 2)},
    }
    if edpvr:
        _build_edpvr(emu.metadata["subject"], space, section, out, design=edpvr_design, say=say, workers=workers,
                     resolution=resolution, strain_layer=strain_layer, alpha_endo=alpha_endo, alpha_epi=alpha_epi,
                     seed=seed, name=f"{name}-edpvr")
    return _save_build(emu, out, sets, geo, t_start, t_train, say)


def resolve_edpvr(edpvr: bool | None, section: Mapping, say: Callable[[str], None] | None = None) -> bool:
    """Whether a build makes its subject EDPVR emulator: ``edpvr`` as given, or None: :data:`DEFAULT_EDPVR` for a
    mesh geometry (``section["kind"] == "mesh"``) and False for any other (it cannot have one; ``edpvr=True`` for
    it is refused by the build). ``say`` gets a line when none is built."""
    mesh = section.get("kind") == "mesh"
    built = bool(edpvr) if edpvr is not None else bool(DEFAULT_EDPVR) and mesh
    if not built and say is not None:
        say(f"EDPVR emulator: not built ({'--no-edpvr' if mesh else 'the geometry is no mesh'}): the derived EDPVR "
            "and stress of a calibration through this emulator take FE load paths")
    return built


def _build_edpvr(record: dict, space: ParameterSpace, section: Mapping, out: Path, *, design, say, **kw) -> None:
    """Build the subject EDPVR emulator into ``out/edpvr``; its summary and seconds go into ``record`` (the
    subject emulator's ``metadata["subject"]``)."""
    from lvcore.emulator import subject_edpvr

    say(f"EDPVR emulator: FE load paths of 0-30 mmHg on the same mesh ({out / subject_edpvr.FOLDER})")
    e = subject_edpvr.build_subject_edpvr(section, space, out / subject_edpvr.FOLDER,
                                          design=design or subject_edpvr.EdpvrDesign(), log=say, **kw)
    t = e.metadata["test"]
    record["edpvr"] = {"folder": subject_edpvr.FOLDER, "name": e.name, "n_test_paths": t["n_paths"],
                       "log_volume_ratio_rmse_max": max(t["log_volume_ratio_rmse"]),
                       "fibre_stretch_rmse_max": max(t["fibre_stretch_rmse"]),
                       "seconds": e.metadata["subject"]["seconds"]["total"]}
    record["seconds"]["edpvr"] = record["edpvr"]["seconds"]


def _checked_strain_layer(layer: str) -> str:
    """The canonical name of the strain layer ``layer`` (EmulatorError naming ``--strain-layer``)."""
    try:
        return canonical_strain_layer(layer, "--strain-layer")
    except ValueError as err:
        raise EmulatorError(str(err)) from None


def _write_geometry(geo: SubjectGeometry, out: Path, edpvr: bool = False) -> dict:
    """The case geometry section of the build; template nodes are written to ``out/geometry.vtu`` first. With
    ``edpvr`` a geometry that is no mesh file (``default``, PC scores, an analytic case) is refused: the derived
    quantities find a subject EDPVR emulator next to the mesh file."""
    section = dict(geo.section)
    if geo.nodes is not None:
        from lvcore.geometry.io import write_template_mesh

        write_template_mesh(out / GEOMETRY_FILE, geo.nodes, metadata={"label": f"subject geometry from {geo.source}"})
        section = {"kind": "mesh", "path": str((out / GEOMETRY_FILE).resolve())}
    if edpvr and section.get("kind") != "mesh":
        raise EmulatorError(f"--edpvr needs a mesh geometry (a template or volume mesh, contours or a case with a "
                            f"mesh), got {geo.kind} ({section.get('kind')}): the derived quantities of such a subject "
                            "emulator use FE load paths; build without --edpvr")
    return section


def _prior_line(prior_mean, prior_record: Mapping) -> str:
    """The build log's line on the prior mean chosen (:func:`choose_prior`)."""
    if prior_mean is None:
        return (f"prior mean: none ({prior_record['reason']}); the network learns the whole map, which needs more "
                f"training runs for the same accuracy (e.g. --n-train 800 or more; docs/campaigns_and_emulators.md)")
    return (f"prior mean: '{prior_record['name']}' at the subject's size-normalised shape "
            f"(scale {prior_record['scale']:.3f}; {', '.join(f'{k} {v:.3g}' for k, v in prior_record['inputs'].items())}"
            + (f"; clipped {', '.join(prior_record['clipped'])}" if prior_record["clipped"] else "") + ")")


def _converged_sets(points: np.ndarray, runs: SimulatedRows, parts: Mapping, out: Path) -> dict:
    """``{part: (inputs, outputs)}`` of the converged rows of each part; refused when a part keeps fewer than 2."""
    sets = {}
    for key, idx in parts.items():
        ok = idx[runs.converged[idx]]
        sets[key] = (points[ok], runs.outputs[ok])
        if ok.size < 2:
            reasons = sorted({runs.messages[i] for i in idx if not runs.converged[i]})[:3]
            raise EmulatorError(f"only {ok.size} of the {idx.size} {key} runs converged (e.g. {reasons}); "
                                "narrow the bounds or use another resolution (the FE runs are kept in "
                                f"{out / RUNS_FILE})")
    return sets


def _train(space: ParameterSpace, sets: Mapping, *, name: str, resolution: str, n_failed: int, config, log,
           prior_mean, strain_layer: str = DEFAULT_STRAIN_LAYER):
    """Train the network on the training rows (validation rows: early stopping; test rows: held-out accuracy)."""
    from lvcore.campaigns.runner import simulator_version
    from lvcore.emulator.training import train_emulator

    source = {"space": space.to_dict(), "resolution": [resolution], "simulator_versions": [simulator_version()],
              "forward": ["simulator"], "n_failed_excluded": n_failed, "strain_layer": strain_layer}
    return train_emulator(*sets["train"], *sets["valid"], input_names=space.names, name=name, lower=space.lower,
                          upper=space.upper, fixed=space.fixed_dict(), config=config, x_test=sets["test"][0],
                          y_test=sets["test"][1], source=source, log=log, prior=prior_mean)


def _save_build(emu, out: Path, sets: Mapping, geo: SubjectGeometry, t_start: float, t_train: float, say):
    """Save the emulator, its training data and the held-out rows into ``out``; drop the FE-run checkpoint."""
    from lvcore.emulator.io import load_emulator, save_emulator, save_training_data

    test = emu.metadata["test"]
    emu.metadata["spec_note"] = (f"subject-specific emulator (geometry fixed: {geo.source}); held-out test "
                                 f"({test['n']} FE runs never used in training): LVV RMSE {test['lvv_rmse_ml']:.3f} mL, "
                                 f"strain RMSE {test['strain_rmse']:.4f}")
    xt, yt = sets["test"]
    save_training_data(out, sets)
    emu.metadata["subject"]["seconds"]["total"] = round(time.perf_counter() - t_start, 2)
    save_emulator(emu, out, validation={"inputs": xt, "outputs": yt, "predictions": np.asarray(emu.apply(xt))})
    (out / RUNS_FILE).unlink(missing_ok=True)  # the converged rows are in training_data.npz
    say(f"held-out test ({test['n']} runs): LVV RMSE {test['lvv_rmse_ml']:.3f} mL, strain RMSE "
        f"{test['strain_rmse']:.4f}; training {t_train:.1f} s; total {emu.metadata['subject']['seconds']['total']:.1f} s")
    return load_emulator(out)


__all__ = ["SubjectGeometry", "SubjectDesign", "SimulatedRows", "INPUT_GROUPS", "CHECKPOINT_ROWS", "RUNS_FILE",
           "GEOMETRY_FILE", "MESH_SUFFIXES", "VOLUME_MESH_SUFFIXES", "MAX_RUNS",
           "build_subject_emulator", "design_rows", "choose_prior", "describe_prior", "subject_template_nodes",
           "resolve_subject_geometry", "subject_space", "parse_inputs", "simulate_rows",
           "default_training_config", "DEFAULT_EDPVR", "resolve_edpvr"]
