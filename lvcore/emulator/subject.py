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
   optionally the EDP and the fibre angles: :data:`INPUT_GROUPS`) is split at
   random into training, validation and held-out test rows.
3. Every row is simulated on the exact geometry (:func:`simulate_rows`:
   continuation chains of :mod:`lvcore.chains`, each solve starting Newton
   from a neighbour's solution, shared out to the worker processes), in
   batches of :data:`CHECKPOINT_ROWS` after each of which the runs done are
   saved (``fe_runs.npz``): a build that fails, is stopped or killed keeps
   them, and the next build of the same design resumes from them.
4. The network is trained with :func:`lvcore.emulator.training.train_emulator`
   (validation rows: early stopping and selection); the test rows, which the
   training never sees, give the held-out LVV and strain RMSE recorded in the
   metadata (``metadata["test"]``).

The emulator directory is an ordinary one (:mod:`lvcore.emulator.io`) with a
``subject`` section in ``metadata.json``: the geometry section (path relative
to the directory), where it came from, the run counts and the wall time of
each stage. :func:`lvcore.emulator.load_emulator` resolves the geometry path,
and :attr:`lvcore.emulator.model.Emulator.is_subject` tells calibration that
the geometry is bound in (no PC scores to give).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from lvcore import limits
from lvcore.conditions import CHAPTER_ANGLES, CHAPTER_EDP
from lvcore.core.space import ANGLE_BOUNDS, ANGLES_THETA_BOUNDS, EDP_BOUNDS, THETA_BOUNDS, Parameter, ParameterSpace
from lvcore.exceptions import EmulatorError, GeometryError
from lvcore.outputs import ANGLE_NAMES, EDP_NAME, N_OUTPUTS, THETA_NAMES

#: Input groups of ``--inputs``: θ (always), the EDP, the two fibre angles.
INPUT_GROUPS = {"theta": THETA_NAMES, "edp": (EDP_NAME,), "angles": ANGLE_NAMES}
#: The geometry file written into the emulator directory (template nodes, mm).
GEOMETRY_FILE = "geometry.vtu"
#: Suffixes read as volumetric meshes only (fitted with :mod:`lvcore.geometry.volume_mesh`).
VOLUME_MESH_SUFFIXES = (".inp", ".msh", ".med", ".mesh")
#: Template-mesh suffixes; a file that is not the template's 27-node hexahedra is fitted as a volume mesh.
MESH_SUFFIXES = (".vtu", ".vtk", ".xdmf")
#: Most FE runs one build may ask for.
MAX_RUNS = 20_000
#: FE runs per batch of a build: progress is reported, and the runs done are saved to :data:`RUNS_FILE`, after each.
CHECKPOINT_ROWS = 100
#: The FE runs of a build so far, in the emulator directory; kept when a build fails or is stopped (a new build of
#: the same design, geometry and mesh resumes from it), removed when the emulator is saved.
RUNS_FILE = "fe_runs.npz"


# --------------------------------------------------------------------------- geometry
@dataclass(frozen=True)
class SubjectGeometry:
    """A subject's geometry as the simulator's case section.

    Attributes
    ----------
    section : dict
        The case's ``geometry`` section (``kind`` ``mesh``, ``pca``,
        ``default`` or ``ellipsoid``), without a resolution.
    source : str
        What it came from (the file, or ``default``).
    kind : str
        ``template-mesh``, ``volume-mesh`` (fitted), ``contours`` (fitted),
        ``case``, ``scores`` or ``default``.
    nodes : ndarray or None
        Template node positions (mm) for geometries fitted or read as a mesh.
    record : dict
        Fit residuals and the like (JSON-ready).
    warnings : tuple of str
    """

    section: dict
    source: str
    kind: str
    nodes: np.ndarray | None = field(default=None, repr=False)
    record: dict = field(default_factory=dict)
    warnings: tuple[str, ...] = ()


def resolve_subject_geometry(spec, *, units: str = "mm") -> SubjectGeometry:
    """The case geometry of ``spec``: a file path or ``"default"``.

    Parameters
    ----------
    spec : str or Path
        ``default`` (the default LV); a template mesh (``.vtu``: the one
        ``lvcore geometry fit --out`` writes); a volumetric tet/hex mesh
        (``.inp``, ``.msh``, ``.med``, ``.mesh``, or a ``.vtu``/``.vtk``/
        ``.xdmf`` that is not a template mesh), fitted as ``lvcore geometry
        fit --mesh`` does; a contour stack (JSON, schema ``lvcore.contours``),
        fitted; a case file (JSON with a ``geometry`` section); or PC scores
        (JSON/CSV, reconstructed by the shape model exactly as a ``pca``
        case geometry is).
    units : {"mm", "cm", "m"}
        Units of a volumetric mesh.

    Raises
    ------
    GeometryError
        Naming the file and what to give instead.
    """
    if spec is None or str(spec).strip() == "":
        raise GeometryError("--geometry is required: a template mesh (.vtu), a volumetric mesh (.inp/.msh/.vtu), "
                            "a contour stack or case file (.json), PC scores (.json/.csv) or 'default'")
    if str(spec).strip().lower() == "default":
        return SubjectGeometry({"kind": "default"}, "default", "default")
    path = Path(spec)
    if not path.is_file():
        raise GeometryError(f"--geometry {spec}: no such file (give a mesh, contour stack, case file or PC scores, "
                            "or 'default')")
    suffix = path.suffix.lower()
    if suffix in VOLUME_MESH_SUFFIXES:
        return _volume_mesh(path, units)
    if suffix in MESH_SUFFIXES:
        from lvcore.geometry.io import read_template_mesh

        try:
            nodes = read_template_mesh(path)
        except GeometryError as err:
            if "27-node hexahedra" in str(err) or "points, the template has" in str(err):
                return _volume_mesh(path, units)
            raise
        return _nodes_geometry(nodes, str(path), "template-mesh", {})
    if suffix == ".json":
        obj = limits.read_json_file(path, limits.MAX_MESH_BYTES, "geometry file", GeometryError)
        if isinstance(obj, dict) and str(obj.get("schema", "")).startswith("lvcore.contours"):
            from lvcore.geometry.fitting import fit_contours

            res = fit_contours(path)
            return _nodes_geometry(res.nodes, str(path), "contours", {"fit_residual_mm": float(res.residual_mean_mm)},
                                   tuple(getattr(res, "warnings", ()) or ()))
        if isinstance(obj, dict) and "geometry" in obj:
            return _case_geometry(obj["geometry"], path)
    if suffix in (".json", ".csv"):
        from lvcore.geometry.scores import read_pc_scores

        read_pc_scores(path, n_pc=1)  # a clear error for a file that holds no scores
        h = _all_scores(path)
        return SubjectGeometry({"kind": "pca", "scores": [float(v) for v in h]}, str(path), "scores")
    raise GeometryError(f"--geometry {path.name}: unknown format '{suffix}'; give a template mesh (.vtu), a volumetric "
                        f"mesh ({', '.join(VOLUME_MESH_SUFFIXES)}, .vtu), a contour stack or case file (.json), "
                        "PC scores (.json/.csv) or 'default'")


def _all_scores(path: Path) -> list[float]:
    """Every PC score of a scores file, up to the shape model's number of modes (a case uses them all)."""
    from lvcore.geometry.shape_model import load_shape_model
    from lvcore.geometry.scores import read_pc_scores

    for n in range(int(load_shape_model().n_modes), 1, -1):
        try:
            return [float(v) for v in read_pc_scores(path, n_pc=n)]
        except GeometryError:
            continue
    return [float(v) for v in read_pc_scores(path, n_pc=1)]


def _volume_mesh(path: Path, units: str) -> SubjectGeometry:
    from lvcore.geometry.volume_mesh import fit_volume_mesh

    res = fit_volume_mesh(path, units=units)
    record = {"fit_residual_mm": float(res.fit.residual_mean_mm),
              "mesh_cavity_volume_ml": float(res.boundary.cavity_volume_ml)}
    return _nodes_geometry(res.fit.nodes, str(path), "volume-mesh", record,
                           tuple(res.boundary.warnings) + tuple(res.fit.warnings))


def _nodes_geometry(nodes, source: str, kind: str, record: dict, warnings: tuple = ()) -> SubjectGeometry:
    from lvcore.geometry.measures import geometry_info

    nodes = np.asarray(nodes, dtype=float)
    info = geometry_info(nodes)
    record = {**record, **{k: v for k, v in info.items() if isinstance(v, (int, float))}}
    return SubjectGeometry({"kind": "mesh", "path": None}, source, kind, nodes, record, tuple(warnings))


def _case_geometry(section, path: Path) -> SubjectGeometry:
    from lvcore.mechanics.case import Case

    if not isinstance(section, dict) or "kind" not in section:
        raise GeometryError(f"{path.name}: the case's 'geometry' section must be an object with a 'kind'")
    section = {k: v for k, v in section.items() if k != "resolution"}
    if section.get("kind") == "box":
        raise GeometryError(f"{path.name}: a box is not an LV geometry; give an LV case, mesh or contours")
    for key in ("path", "model"):  # relative to the case file, as the case reader does
        if key in section and not Path(str(section[key])).is_absolute():
            section[key] = str((path.parent / str(section[key])).resolve())
    from lvcore.core.space import build_case

    try:
        Case.from_dict(build_case({n: 1.0 for n in THETA_NAMES}, geometry=section, resolution="coarse"))
    except Exception as err:  # noqa: BLE001 - reported with the file's name
        raise GeometryError(f"{path.name}: its geometry section cannot be used: {err}") from None
    if section["kind"] == "mesh":
        from lvcore.geometry.io import read_template_mesh

        return _nodes_geometry(read_template_mesh(section["path"]), str(path), "case", {})
    return SubjectGeometry(section, str(path), "case")


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


def subject_space(groups: Sequence[str] = ("theta",), *, base: str = "sliding", edp: float = CHAPTER_EDP,
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
    edp, alpha_endo, alpha_epi : float
        Values of the inputs that are not varied (mmHg, deg).
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
    fixed = {EDP_NAME: float(edp), ANGLE_NAMES[0]: float(alpha_endo), ANGLE_NAMES[1]: float(alpha_epi)}
    fixed = tuple((k, v) for k, v in fixed.items() if k not in names)
    return ParameterSpace(name, params, fixed, base)


# --------------------------------------------------------------------------- the FE runs
@dataclass(frozen=True)
class SimulatedRows:
    """FE outputs of design rows (input order kept).

    Attributes
    ----------
    outputs : (n, 25) ndarray
        NaN rows where a solve failed.
    converged : (n,) bool ndarray
    messages : tuple of str
    seconds : (n,) ndarray
        Solver time per row (s).
    wall_s : float
        Wall time of all rows (s).
    workers : int
        Worker processes used (1: this process).
    """

    outputs: np.ndarray
    converged: np.ndarray
    messages: tuple[str, ...]
    seconds: np.ndarray
    wall_s: float
    workers: int


def simulate_rows(space: ParameterSpace, x: np.ndarray, geometry: Mapping, *, resolution: str = "default",
                  workers: int = 2, checkpoint=None, chunk: int | None = None,
                  progress: Callable[[int, int], None] | None = None,
                  stop: Callable[[], bool] | None = None) -> SimulatedRows:
    """Simulate every row of ``x`` (physical units, columns ``space.names``) on ``geometry``.

    The FE simulator with warm starts (:class:`~lvcore.mechanics.forward.SimulatorForward`
    ``(warm_start=True)``): the rows are ordered into continuation chains
    (:mod:`lvcore.chains`), each solve starting Newton from a neighbour's
    converged solution and falling back to a cold solve when that fails, so
    the results satisfy the same tolerances as cold solves; the chains are
    shared out to ``workers`` processes (``1``: this process). Failures are
    data (NaN rows, ``converged`` False).

    The rows are solved in the order of one continuation walk over the whole
    design (:func:`lvcore.chains.continuation_order`), in batches of ``chunk``
    consecutive rows of that walk; results come back in the input order.

    Parameters
    ----------
    checkpoint : path, optional
        An ``.npz`` file where the rows done so far are saved after every
        ``chunk`` rows. Rows already saved there for the same inputs, geometry,
        mesh and base are taken from it, not simulated again (a stopped or
        failed build resumes).
    chunk : int, optional
        Rows per batch (default :data:`CHECKPOINT_ROWS`); the simulator and its
        worker pool, and so the warm-start states, are kept from batch to batch.
    progress : callable, optional
        ``progress(done, total)`` after every batch (rows).
    stop : callable, optional
        Asked before every batch; when it returns True the simulation stops
        with an :class:`~lvcore.exceptions.EmulatorError` (the rows done are in
        ``checkpoint``).
    """
    import contextlib

    from lvcore.mechanics.forward import SimulatorForward

    from lvcore.chains import continuation_order, scaled_coordinates

    x_given = np.atleast_2d(np.asarray(x, dtype=float))
    n = x_given.shape[0]
    # batches are consecutive stretches of one continuation walk over the whole design, so every batch is a
    # neighbourhood (a space-filling batch of a Sobol sequence would leave its warm starts far apart)
    order = continuation_order(scaled_coordinates(space.names, x_given)) if n > 2 else np.arange(n)
    x = x_given[order]
    chunk = max(1, int(chunk or CHECKPOINT_ROWS))
    outputs = np.full((n, N_OUTPUTS), np.nan)
    converged = np.zeros(n, dtype=bool)
    messages = [""] * n
    seconds = np.zeros(n)
    signature = _runs_signature(space, geometry, resolution)
    done = _resume_rows(checkpoint, signature, x, outputs, converged, messages, seconds)
    if progress is not None and done:
        progress(done, n)
    fwd = SimulatorForward(input_names=space.names, conditions=space.fixed_dict(), geometry=dict(geometry),
                           resolution=resolution, base=space.base, workers=int(workers), warm_start=True)
    t0 = time.perf_counter()
    with contextlib.ExitStack() as stack:
        executor = None
        if int(workers) > 1 and n - done > 1:
            from lvcore.parallel import make_executor

            executor = stack.enter_context(make_executor(workers=int(workers)))
        while done < n:
            if stop is not None and stop():
                where = f"; they are kept in {checkpoint} and a new build of the same design resumes from them" \
                    if checkpoint is not None else ""
                raise EmulatorError(f"stopped after {done} of {n} FE runs{where}")
            rows = slice(done, min(n, done + chunk))
            batch = fwd.evaluate({name: x[rows, i] for i, name in enumerate(space.names)}, executor=executor)
            outputs[rows], converged[rows], seconds[rows] = batch.outputs, batch.converged, batch.seconds
            messages[rows] = list(batch.messages)
            done = rows.stop
            if checkpoint is not None:
                _save_rows(checkpoint, signature, x[:done], outputs[:done], converged[:done], messages[:done],
                           seconds[:done])
            if progress is not None:
                progress(done, n)
    back = np.empty(n, dtype=int)
    back[order] = np.arange(n)  # row i of the design was solved at position back[i]
    return SimulatedRows(outputs[back], converged[back], tuple(messages[j] for j in back), seconds[back],
                         time.perf_counter() - t0, int(workers))


def _runs_signature(space: ParameterSpace, geometry: Mapping, resolution: str) -> str:
    import json

    return json.dumps({"space": space.to_dict(), "geometry": dict(geometry), "resolution": str(resolution)},
                      sort_keys=True, default=str)


def _save_rows(path, signature: str, x, outputs, converged, messages, seconds) -> None:
    """Write the rows done so far (atomically: a killed build leaves the previous file whole)."""
    path = Path(path)
    tmp = path.with_name(path.stem + ".partial.npz")
    np.savez(tmp, signature=np.array(signature), inputs=x, outputs=outputs, converged=converged,
             messages=np.array(messages, dtype=str), seconds=seconds)
    tmp.replace(path)


def _resume_rows(path, signature: str, x, outputs, converged, messages, seconds) -> int:
    """Fill the leading rows of ``x`` already saved in ``path`` (same signature and inputs); their count."""
    if path is None or not Path(path).is_file():
        return 0
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["signature"]) != signature:
                return 0
            k = int(z["inputs"].shape[0])
            if k > x.shape[0] or not np.array_equal(z["inputs"], x[:k]):
                return 0
            outputs[:k], converged[:k], seconds[:k] = z["outputs"], z["converged"], z["seconds"]
            messages[:k] = [str(m) for m in z["messages"]]
    except (OSError, KeyError, ValueError):  # a damaged file: simulate again
        return 0
    return k


# --------------------------------------------------------------------------- the build
def default_training_config(seed: int = 0):
    """The :class:`~lvcore.emulator.training.TrainingConfig` of subject emulators.

    One 100 x 100 network (no architecture search), 600 Adam epochs (batch
    64, learning rate halved every 150 epochs), then 1,500 L-BFGS iterations
    with the LVV weighted as much as the 24 strains together. On the 800 +
    100 rows of a SYNTHETIC_HV3 build it took 21 CPU-s and gave a held-out
    LVV RMSE of 0.763 mL and strain RMSE of 0.0008 (100 test runs), where
    1,500 Adam epochs + 3,000 L-BFGS iterations gave 0.855 mL / 0.0006 in
    several times the CPU (docs/campaigns_and_emulators.md).
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
    """

    n_train: int = 800
    n_valid: int = 100
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


def build_subject_emulator(geometry, out, *, inputs: Sequence[str] | str = ("theta",),
                           design: SubjectDesign = SubjectDesign(), resolution: str = "default",
                           base: str = "sliding", edp: float = CHAPTER_EDP, alpha_endo: float = CHAPTER_ANGLES[0],
                           alpha_epi: float = CHAPTER_ANGLES[1], bounds: Mapping | None = None, units: str = "mm",
                           workers: int = 2, seed: int = 0, config=None, name: str | None = None,
                           log: Callable[[str], None] | None = None,
                           progress: Callable[[int, int], None] | None = None,
                           stop: Callable[[], bool] | None = None):
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
    base, edp, alpha_endo, alpha_epi, bounds
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
    log : callable, optional
        Progress lines.
    progress : callable, optional
        ``progress(done, total)`` FE runs, after every batch of :data:`CHECKPOINT_ROWS`.
    stop : callable, optional
        Asked between batches of FE runs; True stops the build with an
        :class:`~lvcore.exceptions.EmulatorError`.

    The FE runs done are saved in ``out/fe_runs.npz`` (:data:`RUNS_FILE`) after every batch, so a build that
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
    from lvcore.campaigns.designs import make_design
    from lvcore.emulator.io import save_emulator, save_training_data
    from lvcore.emulator.training import train_emulator

    t_start = time.perf_counter()
    say = log or (lambda msg: None)
    out = Path(out)
    groups = parse_inputs(inputs)
    space = subject_space(groups, base=base, edp=edp, alpha_endo=alpha_endo, alpha_epi=alpha_epi, bounds=bounds)
    geo = geometry if isinstance(geometry, SubjectGeometry) else resolve_subject_geometry(geometry, units=units)
    out.mkdir(parents=True, exist_ok=True)
    section = dict(geo.section)
    if geo.nodes is not None:
        from lvcore.geometry.io import write_template_mesh

        write_template_mesh(out / GEOMETRY_FILE, geo.nodes, metadata={"label": f"subject geometry from {geo.source}"})
        section = {"kind": "mesh", "path": str((out / GEOMETRY_FILE).resolve())}
    t_geometry = time.perf_counter() - t_start
    say(f"geometry: {geo.kind} from {geo.source} ({t_geometry:.1f} s)")
    for w in geo.warnings:
        say(f"  warning: {w}")

    d = make_design(space, design.method, design.total, seed)
    split = np.random.default_rng(seed).permutation(design.total)
    parts = {"train": split[:design.n_train], "valid": split[design.n_train:design.n_train + design.n_valid],
             "test": split[design.n_train + design.n_valid:]}
    say(f"design: {design.total} {design.method} points over {list(space.names)} "
        f"({design.n_train} train / {design.n_valid} validation / {design.n_test} held-out test), "
        f"{resolution} mesh, {base} base, {workers} worker(s)")
    runs = simulate_rows(space, d.points, section, resolution=resolution, workers=workers,
                         checkpoint=out / RUNS_FILE, progress=progress, stop=stop)
    n_failed = int(np.sum(~runs.converged))
    say(f"FE runs: {runs.converged.sum()} of {design.total} converged in {runs.wall_s:.1f} s "
        f"({design.total / max(runs.wall_s, 1e-9):.1f} solves/s, warm-started chains on {runs.workers} worker(s))")
    sets = {}
    for key, idx in parts.items():
        ok = idx[runs.converged[idx]]
        sets[key] = (d.points[ok], runs.outputs[ok])
        if ok.size < 2:
            reasons = sorted({runs.messages[i] for i in idx if not runs.converged[i]})[:3]
            raise EmulatorError(f"only {ok.size} of the {idx.size} {key} runs converged (e.g. {reasons}); "
                                "narrow the bounds or use another resolution (the FE runs are kept in "
                                f"{out / RUNS_FILE})")

    t_train0 = time.perf_counter()
    cfg = config or default_training_config(seed)
    from lvcore.campaigns.runner import simulator_version

    name = name or f"subject-{Path(geo.source).stem if geo.kind != 'default' else 'default'}"
    source = {"space": space.to_dict(), "resolution": [resolution], "simulator_versions": [simulator_version()],
              "forward": ["simulator"], "n_failed_excluded": n_failed}
    emu = train_emulator(*sets["train"], *sets["valid"], input_names=space.names, name=name, lower=space.lower,
                         upper=space.upper, fixed=space.fixed_dict(), config=cfg, x_test=sets["test"][0],
                         y_test=sets["test"][1], source=source, log=log)
    t_train = time.perf_counter() - t_train0
    emu.metadata["subject"] = {
        # save_emulator writes DIR/geometry.vtu's path relative to the directory
        "geometry": section, "geometry_source": geo.source, "geometry_kind": geo.kind, "geometry_record": geo.record,
        "geometry_warnings": list(geo.warnings), "inputs": list(groups), "design": design.method,
        "seed": int(seed), "workers": int(workers),
        "runs": {"total": design.total, "converged": int(runs.converged.sum()), "failed": n_failed,
                 **{f"n_{k}": int(v[0].shape[0]) for k, v in sets.items()}},
        "seconds": {"geometry": round(t_geometry, 2), "simulations": round(runs.wall_s, 2),
                    "training": round(t_train, 2)},
    }
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
    from lvcore.emulator.io import load_emulator

    return load_emulator(out)


__all__ = ["SubjectGeometry", "SubjectDesign", "SimulatedRows", "INPUT_GROUPS", "CHECKPOINT_ROWS", "RUNS_FILE",
           "build_subject_emulator",
           "resolve_subject_geometry", "subject_space", "parse_inputs", "simulate_rows",
           "default_training_config"]
