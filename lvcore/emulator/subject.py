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
   continuation chains of :mod:`lvcore.chains`, each solve starting Newton
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
#: FE runs per batch of a build on one worker (in this process): progress is reported, and the runs done are saved
#: to :data:`RUNS_FILE`, after each. With a pool every chain chunk (:data:`lvcore.chains.DEFAULT_CHUNK` runs) is.
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
                  stop: Callable[[], bool] | None = None, executor=None) -> SimulatedRows:
    """Simulate every row of ``x`` (physical units, columns ``space.names``) on ``geometry``.

    The FE simulator with warm starts (:meth:`~lvcore.mechanics.forward.SimulatorForward.evaluate_warm`):
    the rows are ordered along one continuation walk over the whole design
    (:func:`lvcore.chains.continuation_order`), each solve starting Newton from
    a neighbour's converged solution and falling back to a cold solve when that
    fails, so the results satisfy the same tolerances as cold solves. Failures
    are data (NaN rows, ``converged`` False); results come back in the input order.

    With ``workers > 1`` the walk is split into continuation chains fed to a
    process pool chunk by chunk (:func:`lvcore.chains.run_chains`: the next
    chunk of a chain is submitted as soon as the previous one returns, and a
    chain that runs dry splits the longest remaining one), with no barrier
    anywhere: both cores are busy until the last chunk. With ``workers=1`` the
    walk is solved in this process, ``chunk`` rows at a time.

    Parameters
    ----------
    checkpoint : path, optional
        An ``.npz`` file where the rows done so far are saved as every chunk
        returns. Rows already saved there for the same inputs, geometry, mesh
        and base are taken from it, not simulated again (a stopped or failed
        build resumes; the rest is walked again from cold starts).
    chunk : int, optional
        Rows per task (default :data:`lvcore.chains.DEFAULT_CHUNK` with a pool,
        :data:`CHECKPOINT_ROWS` in this process).
    progress : callable, optional
        ``progress(done, total)`` (rows) as every chunk returns.
    stop : callable, optional
        Asked as every chunk returns (and before the first); when it returns
        True the simulation stops with an :class:`~lvcore.exceptions.EmulatorError`
        (the rows done are in ``checkpoint``; chunks in flight are finished
        and kept too).
    executor : optional
        A running pool of :mod:`lvcore.parallel` to use (not closed), e.g.
        shared by the stages of a build; default one of ``workers`` processes
        is started for the call.
    """
    import contextlib

    from lvcore.chains import DEFAULT_CHUNK, ChainTaskError, continuation_order, run_chains, scaled_coordinates
    from lvcore.mechanics.forward import SimulatorForward

    x_given = np.atleast_2d(np.asarray(x, dtype=float))
    n = x_given.shape[0]
    order = continuation_order(scaled_coordinates(space.names, x_given)) if n > 2 else np.arange(n)
    x = x_given[order]  # walk order: a chain is a stretch of it
    units = scaled_coordinates(space.names, x)
    pooled = int(workers) > 1
    chunk = max(1, int(chunk or (DEFAULT_CHUNK if pooled else CHECKPOINT_ROWS)))
    outputs = np.full((n, N_OUTPUTS), np.nan)
    converged = np.zeros(n, dtype=bool)
    messages = [""] * n
    seconds = np.zeros(n)
    signature = _runs_signature(space, geometry, resolution)
    done = _resume_rows(checkpoint, signature, x, outputs, converged, messages, seconds)
    if progress is not None and done.any():
        progress(int(done.sum()), n)
    fwd = SimulatorForward(input_names=space.names, conditions=space.fixed_dict(), geometry=dict(geometry),
                           resolution=resolution, base=space.base, workers=1, warm_start=True)

    def record(rows) -> None:
        for r in rows:
            outputs[r.key], converged[r.key], messages[r.key], seconds[r.key] = r.result
            done[r.key] = True
        if checkpoint is not None:
            _save_rows(checkpoint, signature, x, done, outputs, converged, messages, seconds)
        if progress is not None:
            progress(int(done.sum()), n)
        check_stop()

    def check_stop() -> None:
        if stop is not None and not done.all() and stop():
            where = f"; they are kept in {checkpoint} and a new build of the same design resumes from them" \
                if checkpoint is not None else ""
            raise EmulatorError(f"stopped after {int(done.sum())} of {n} FE runs{where}")

    t0 = time.perf_counter()
    check_stop()
    todo = np.flatnonzero(~done)
    if todo.size and pooled and todo.size > 1:
        from lvcore.parallel import make_executor

        with contextlib.ExitStack() as stack:
            if executor is None:
                executor = stack.enter_context(make_executor(workers=int(workers)))

            def submit(positions, seeds):  # rows keyed by position in todo (run_chains' bookkeeping)
                walk = todo[positions]
                return executor.submit(_fe_chunk, fwd, x[walk], positions, units[walk], seeds)

            def on_rows(rows):
                record([r.__class__(int(todo[r.key]), r.unit, r.result) for r in rows])

            try:
                run_chains(executor, submit, units[todo], workers=int(workers), on_rows=on_rows, chunk=chunk)
            except ChainTaskError as err:
                raise err.__cause__ or err from None
    else:
        state = None
        for start in range(0, todo.size, chunk):
            keys = [int(k) for k in todo[start:start + chunk]]
            seeds = [] if state is None else [state]
            rows = _fe_chunk(fwd, x[keys], keys, units[keys], seeds)
            last = [r for r in rows if r.state is not None]
            if last:
                from lvcore.chains import Seed

                state = Seed(last[-1].unit, last[-1].state)
            record(rows)
    back = np.empty(n, dtype=int)
    back[order] = np.arange(n)  # row i of the design was solved at position back[i]
    return SimulatedRows(outputs[back], converged[back], tuple(messages[j] for j in back), seconds[back],
                         time.perf_counter() - t0, int(workers))


def _fe_chunk(forward, points: np.ndarray, keys: Sequence[int], units: np.ndarray, seeds) -> list:
    """Worker task: FE runs of one chain chunk, in order, each warm-started from the nearest converged state.

    Returns :class:`lvcore.chains.ChainRow` objects keyed by ``keys`` whose results are
    ``(outputs (25,), converged, message, seconds)``.
    """
    from lvcore.chains import solve_in_order

    by_key = {int(k): p for k, p in zip(keys, np.atleast_2d(points))}

    def solve(key, initial):
        batch, state = forward.evaluate_warm(dict(zip(forward.input_names, by_key[key])), initial)
        result = (np.asarray(batch.outputs[0], dtype=float), bool(batch.converged[0]), str(batch.messages[0] or ""),
                  float(batch.seconds[0]))
        return result, state

    return solve_in_order(keys, units, seeds, solve)


def _runs_signature(space: ParameterSpace, geometry: Mapping, resolution: str) -> str:
    import json

    return json.dumps({"space": space.to_dict(), "geometry": dict(geometry), "resolution": str(resolution)},
                      sort_keys=True, default=str)


def _save_rows(path, signature: str, x, done, outputs, converged, messages, seconds) -> None:
    """Write the rows done so far (atomically: a killed build leaves the previous file whole)."""
    path = Path(path)
    tmp = path.with_name(path.stem + ".partial.npz")
    np.savez(tmp, signature=np.array(signature), inputs=x[done], outputs=outputs[done], converged=converged[done],
             messages=np.array([m for m, d in zip(messages, done) if d], dtype=str), seconds=seconds[done])
    tmp.replace(path)


def _resume_rows(path, signature: str, x, outputs, converged, messages, seconds) -> np.ndarray:
    """Fill the rows of ``x`` already saved in ``path`` (same signature, identical inputs); the mask of rows done.

    The saved rows may be any subset of ``x`` (chains return out of order); a saved row that is not a row of
    ``x`` means another design, and nothing is taken.
    """
    done = np.zeros(x.shape[0], dtype=bool)
    if path is None or not Path(path).is_file():
        return done
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["signature"]) != signature:
                return done
            saved = np.asarray(z["inputs"], dtype=float)
            where = {row.tobytes(): i for i, row in enumerate(x)}
            idx = [where.get(row.tobytes(), -1) for row in saved]
            if saved.ndim != 2 or saved.shape[1] != x.shape[1] or min(idx, default=0) < 0 \
                    or len(set(idx)) != len(idx):
                return done
            idx = np.asarray(idx, dtype=int)
            outputs[idx], converged[idx], seconds[idx] = z["outputs"], z["converged"], z["seconds"]
            for i, m in zip(idx, z["messages"]):
                messages[i] = str(m)
            done[idx] = True
    except (OSError, KeyError, ValueError):  # a damaged file: simulate again
        done[:] = False
    return done


# --------------------------------------------------------------------------- the prior mean
def subject_template_nodes(section: Mapping) -> np.ndarray:
    """Template node positions (mm) of a case ``geometry`` section (mesh, PC scores, ellipsoid or default)."""
    from lvcore.core.space import build_case
    from lvcore.geometry.template import DEFAULT_TEMPLATE
    from lvcore.mechanics.case import Case

    spec = Case.from_dict(build_case({n: 1.0 for n in THETA_NAMES}, geometry=dict(section),
                                     resolution="coarse")).geometry
    if spec.template_nodes is not None:
        return np.asarray(spec.template_nodes, dtype=float)
    if spec.ellipsoid is not None:
        return np.asarray(spec.ellipsoid.nodes(DEFAULT_TEMPLATE), dtype=float)
    raise GeometryError(f"geometry kind '{spec.kind}' has no LV template nodes")


def _prior_mismatch(emu, space: ParameterSpace) -> str | None:
    """Why ``emu`` cannot be the prior mean of a subject emulator over ``space`` (None: it can)."""
    if emu.is_subject or emu.prior is not None:
        return "it is itself a subject emulator"
    if emu.base != space.base:
        return f"its base is {emu.base}, the FE runs' is {space.base}"
    def inside(name, lo, hi) -> bool:  # [lo, hi] within the emulator's box of input `name` (Emulator.in_box's tolerance)
        rows = np.tile(np.asarray(emu.lower, dtype=float), (2, 1))
        rows[:, emu.input_names.index(name)] = (lo, hi)
        return bool(emu.in_box(rows).all())

    def box(name) -> str:
        i = emu.input_names.index(name)
        return f"[{emu.lower[i]:g}, {emu.upper[i]:g}]"

    for n, lo, hi in zip(space.names, space.lower, space.upper):
        if n not in emu.input_names:
            return f"it does not take {n}" + (f" (fixed at {emu.fixed[n]:g})" if n in emu.fixed else "")
        if not inside(n, lo, hi):
            return f"{n}'s range [{lo:g}, {hi:g}] leaves its box {box(n)}"
    for k, v in space.fixed_dict().items():
        if k in emu.fixed and abs(float(emu.fixed[k]) - float(v)) > 1e-9 * max(1.0, abs(float(v))):
            return f"it was trained at {k} = {emu.fixed[k]:g}, the FE runs use {v:g}"
        if k in emu.input_names and not inside(k, v, v):
            return f"{k} = {v:g} is outside its box {box(k)}"
    if any(_score_index(n) is None for n in _score_inputs(emu, space)):
        return f"it takes inputs the subject emulator neither varies nor fixes: {_score_inputs(emu, space)}"
    return None


def _score_inputs(emu, space: ParameterSpace) -> list[str]:
    """The emulator's inputs that the subject's space neither varies nor fixes (PC scores ``h1``, ``h2``, ...)."""
    return [n for n in emu.input_names if n not in space.names and n not in space.fixed_dict()]


def _score_index(name: str) -> int | None:
    """0-based mode of a PC-score input name (``h3`` -> 2), or None for another name."""
    return int(name[1:]) - 1 if name.startswith("h") and name[1:].isdigit() and int(name[1:]) > 0 else None


def choose_prior(space: ParameterSpace, section: Mapping, choice: str = "auto"):
    """The prior mean of a subject emulator over ``space`` on geometry ``section``.

    The subject's template mesh is split into a size ``s`` and PC scores
    ``h`` of its size-normalised shape
    (:func:`lvcore.geometry.scaling.size_normalised_scores`); the prior is an
    emulator over PC scores (``chapter``, ``angles``, or one on
    ``$LVCORE_EMULATORS``) evaluated there, with LVV times ``s^3``. It must
    match the FE runs: the same base condition, every varied input within its
    box, the same fixed conditions. ``auto`` takes the matching emulator with
    the fewest inputs; scores outside its box are clipped to it (recorded;
    the network corrects the rest).

    Parameters
    ----------
    choice : str
        ``auto``, ``none``, or an emulator name or directory.

    Returns
    -------
    (PriorMean or None, dict)
        The prior (None for ``none`` or when no emulator matches under
        ``auto``) and a JSON-ready record of the choice.

    Raises
    ------
    EmulatorError
        When a named emulator does not match (saying why).
    """
    from lvcore.emulator.io import available_emulators, load_emulator
    from lvcore.emulator.model import PriorMean
    from lvcore.geometry.scaling import size_normalised_scores

    choice = str(choice or "auto").strip()
    if choice == "none":
        return None, {"used": False, "reason": "not asked for (--prior none)"}
    names = available_emulators() if choice == "auto" else [choice]
    rejected, candidates = {}, []
    for name in names:
        try:
            emu = load_emulator(name)
        except EmulatorError as err:
            if choice != "auto":
                raise
            rejected[name] = str(err)
            continue
        why = _prior_mismatch(emu, space)
        if why is None:
            candidates.append(emu)
        elif choice != "auto":
            raise EmulatorError(f"--prior {choice}: cannot be the prior mean of this build: {why}; give another "
                                f"emulator, 'auto' or 'none'")
        else:
            rejected[name] = why
    if not candidates:
        return None, {"used": False, "reason": "no emulator matches the FE runs", "rejected": rejected}
    emu = min(candidates, key=lambda e: (len(e.input_names), e.name))
    fixed = space.fixed_dict()
    scores = _score_inputs(emu, space)
    split = size_normalised_scores(subject_template_nodes(section), max([_score_index(n) + 1 for n in scores] or [1]))
    inputs, clipped = {}, []
    for i, n in enumerate(emu.input_names):
        if n in space.names:
            continue
        if n in fixed:
            inputs[n] = float(fixed[n])
            continue
        h = float(split.h[_score_index(n)])
        inputs[n] = float(np.clip(h, emu.lower[i], emu.upper[i]))
        if inputs[n] != h:
            clipped.append(f"{n} {h:.3g} -> {inputs[n]:g}")
    prior = PriorMean(emu, inputs, split.scale)
    record = {"used": True, "name": emu.name, "inputs": inputs, "scale": float(split.scale),
              "projection_mse_cm2": float(split.projection_mse_cm2), "clipped": clipped, "rejected": rejected}
    return prior, record


def describe_prior(record) -> str:
    """One sentence on a subject emulator's prior mean (``metadata["subject"]["prior"]``), for the app and the CLI."""
    rec = dict(record or {})
    if rec.get("used"):
        return (f"The network corrects the bundled `{rec.get('name')}` emulator at this geometry's size-normalised "
                f"shape (scale {float(rec.get('scale', 1.0)):.3f}"
                + (f"; scores clipped to its box: {', '.join(rec['clipped'])}" if rec.get("clipped") else "") + ").")
    if rec:
        return f"No prior mean: {rec.get('reason')}; the network learns the whole map."
    return "Built before prior means were recorded: the network learns the whole map."


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


def build_subject_emulator(geometry, out, *, inputs: Sequence[str] | str = ("theta",),
                           design: SubjectDesign = SubjectDesign(), resolution: str = "default",
                           base: str = "sliding", edp: float = CHAPTER_EDP, alpha_endo: float = CHAPTER_ANGLES[0],
                           alpha_epi: float = CHAPTER_ANGLES[1], bounds: Mapping | None = None, units: str = "mm",
                           workers: int = 2, seed: int = 0, config=None, name: str | None = None,
                           prior: str = "auto", log: Callable[[str], None] | None = None,
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

    prior_mean, prior_record = choose_prior(space, section, prior)
    if prior_mean is None:
        say(f"prior mean: none ({prior_record['reason']}); the network learns the whole map, which needs more "
            f"training runs for the same accuracy (e.g. --n-train 800 or more; docs/campaigns_and_emulators.md)")
    else:
        say(f"prior mean: '{prior_record['name']}' at the subject's size-normalised shape "
            f"(scale {prior_record['scale']:.3f}; {', '.join(f'{k} {v:.3g}' for k, v in prior_record['inputs'].items())}"
            + (f"; clipped {', '.join(prior_record['clipped'])}" if prior_record["clipped"] else "") + ")")
    points, parts = design_rows(space, design, seed)
    say(f"design: {design.total} {design.method} points over {list(space.names)} "
        f"({design.n_train} train / {design.n_valid} validation / {design.n_test} held-out test), "
        f"{resolution} mesh, {base} base, {workers} worker(s)")
    runs = simulate_rows(space, points, section, resolution=resolution, workers=workers,
                         checkpoint=out / RUNS_FILE, progress=progress, stop=stop)
    n_failed = int(np.sum(~runs.converged))
    say(f"FE runs: {runs.converged.sum()} of {design.total} converged in {runs.wall_s:.1f} s "
        f"({design.total / max(runs.wall_s, 1e-9):.1f} solves/s, warm-started chains on {runs.workers} worker(s))")
    sets = {}
    for key, idx in parts.items():
        ok = idx[runs.converged[idx]]
        sets[key] = (points[ok], runs.outputs[ok])
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
                         y_test=sets["test"][1], source=source, log=log, prior=prior_mean)
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
           "build_subject_emulator", "design_rows", "choose_prior", "describe_prior", "subject_template_nodes",
           "resolve_subject_geometry", "subject_space", "parse_inputs", "simulate_rows",
           "default_training_config"]
