"""Forward simulation of one case: ``simulate(case) -> SimulationResult``.

Quasi-static inflation of a (nearly) incompressible hyperelastic body from
its reference geometry by a follower pressure: the LV endocardium (pressure
as the potential ``−p V_cavity``) or one face of a box. Mixed Q2/P1
hexahedra (see :mod:`lvcore.mechanics.element`), load-stepping Newton
(:mod:`lvcore.mechanics.newton`), SciPy/CHOLMOD sparse solves.
"""
from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

import jax
import jax.numpy as jnp

from lvcore.domain import units
from lvcore.safety import limits
from lvcore.execution.bounded_cache import BoundedCache
from lvcore.execution.jax_cache import exported_kernel
from lvcore.exceptions import CaseError, GeometryError, SolverError
from lvcore.domain.outputs import N_OUTPUTS, THETA_NAMES
from lvcore.mechanics import boundary, fibres, loads, materials, newton, observables
from lvcore.mechanics.mesh import FEMesh, box_mesh, lv_mesh
from lvcore.mechanics.resolution import RESOLUTION_PRESETS, BoxResolution
from lvcore.mechanics.system import DiscreteSystem

#: Bulk penalty relative to the law's largest stiffness parameter.
KAPPA_FACTOR = 1.0e4


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """Outputs of one forward simulation (mm, mm³, kPa; see :meth:`to_dict`).

    Fields are ``None`` where they do not apply (box cases) or when the solve
    failed (``converged`` False, ``message`` says why); never NaN.
    """

    converged: bool
    message: str
    cavity_volume_mm3: tuple[float, float] | None  # (reference, loaded)
    lvv_standardised: float | None
    apex_endocardium: np.ndarray | None
    apex_epicardium: np.ndarray | None
    probes: np.ndarray
    strains: np.ndarray | None
    newton_iterations: int
    load_steps: int
    dofs: int
    seconds: float
    reference_nodes: np.ndarray
    displacement: np.ndarray | None
    elements: np.ndarray
    sensitivities: dict | None = None
    timings: dict = field(default_factory=dict)
    #: Plausibility flags (e.g. a cavity more than 3 times its reference volume at a physiological pressure, or
    #: more than 5 times at any pressure); the values are kept as computed.
    warnings: tuple[str, ...] = ()
    #: ``(free displacements, element pressures)`` of the converged solve: pass as ``simulate(..., initial=)``
    #: to warm-start a solve of the same mesh at nearby parameters.
    solver_state: tuple | None = field(default=None, repr=False)
    #: The last factorised tangent of the solve (:class:`lvcore.mechanics.newton.Tangent`, in-process only:
    #: it pickles empty); :attr:`warm_state` passes it on with the state.
    solver_tangent: newton.Tangent | None = field(default=None, repr=False)
    #: The wall layer the strains are averaged over (:data:`lvcore.domain.outputs.STRAIN_LAYERS`); None for a box.
    strain_layer: str | None = None

    @property
    def warm_state(self) -> tuple | None:
        """``(u, p, tangent)`` for ``simulate(..., initial=)``: the state and the factorised tangent to reuse."""
        if self.solver_state is None:
            return None
        return tuple(self.solver_state) + (self.solver_tangent or newton.Tangent(),)

    def outputs(self) -> np.ndarray:
        """The 25 outputs [LVV (mL), 24 circumferential strains]; raises if unavailable."""
        if not self.converged:
            raise SolverError(f"simulation did not converge: {self.message}")
        if self.cavity_volume_mm3 is None or self.strains is None:
            raise SolverError("this case has no LV outputs (box geometry)")
        return np.concatenate([[units.mm3_to_ml(self.cavity_volume_mm3[1])], self.strains])

    def to_dict(self) -> dict:
        """JSON-ready summary (see docs/simulator.md)."""
        def vec(v):
            return None if v is None else [float(c) for c in np.asarray(v)]

        vol = self.cavity_volume_mm3
        return {
            "converged": bool(self.converged),
            "message": self.message,
            "cavity_volume_ml": None if vol is None else {"reference": vol[0] / units.MM3_PER_ML,
                                                         "loaded": None if vol[1] is None else vol[1] / units.MM3_PER_ML},
            "cavity_volume_mm3": None if vol is None else {"reference": float(vol[0]),
                                                          "loaded": None if vol[1] is None else float(vol[1])},
            "lvv_standardised": None if self.lvv_standardised is None else float(self.lvv_standardised),
            "apex": None if self.apex_endocardium is None else {"endocardium": vec(self.apex_endocardium),
                                                               "epicardium": vec(self.apex_epicardium)},
            "probes": [vec(p) for p in self.probes],
            "strains": vec(self.strains),
            "strain_layer": self.strain_layer,
            "newton_iterations": int(self.newton_iterations),
            "load_steps": int(self.load_steps),
            "dofs": int(self.dofs),
            "seconds": float(self.seconds),
            "warnings": list(self.warnings),
        }


def build_mesh(case) -> FEMesh:
    """The simulation mesh of ``case.geometry`` at its resolution (or preset)."""
    g = case.geometry
    preset = g.preset or "default"
    if g.kind == "box":
        res = g.resolution if g.resolution is not None else BoxResolution.from_preset(g.box_size, preset)
        return box_mesh(g.box_size, res)
    res = g.resolution if g.resolution is not None else RESOLUTION_PRESETS[preset]
    return lv_mesh(g.position_map(), res, g.base_z())


def build_frames(mesh: FEMesh, fib) -> np.ndarray:
    """Fibre frames (n_el, n_q, 3, 3) at the Gauss points of ``mesh.quadrature``."""
    xi, _ = mesh.quadrature
    if fib.direction is not None or mesh.kind == "box":
        d = fib.direction if fib.direction is not None else (1.0, 0.0, 0.0)
        return np.broadcast_to(fibres.constant_frame(d), (mesh.n_elements, xi.shape[0], 3, 3)).copy()
    et = mesh.template.element_grid[:, 2]
    t = (et[:, None] + 0.5 * (xi[None, :, 1] + 1.0)) / mesh.resolution[2]
    frames, _ = fibres.rule_based_frames(mesh.nodes, mesh.elements, xi, t, fib.alpha_endo_deg, fib.alpha_epi_deg)
    return frames


def constitutive_model(case, mesh: FEMesh) -> materials.ConstitutiveModel:
    """The case's law composed with the mixed bulk penalty ``KAPPA_FACTOR ×`` its stiffness scale (kPa).

    The scale is the law's :meth:`~lvcore.mechanics.materials.MaterialLaw.modulus`, or that of the stiffest
    region of a regional case (:func:`element_scale`).
    """
    _, modulus = element_scale(case, mesh)
    return materials.ConstitutiveModel(case.material, materials.MixedPenalty(KAPPA_FACTOR * modulus))


def build_system(case, mesh: FEMesh | None = None) -> DiscreteSystem:
    """The discrete system of ``case`` (mesh, fibres, material, load, boundary conditions)."""
    mesh = mesh or build_mesh(case)
    scale, _ = element_scale(case, mesh)
    model = constitutive_model(case, mesh)
    fixed = boundary.fixed_dofs(mesh, case.boundary.base, case.boundary.clamped_faces)
    surface = case.load.surface if mesh.kind == "box" else "endocardium"
    b = case.boundary
    spring = ("epicardium", b.epicardial_spring, b.spring_direction) if getattr(b, "epicardial_spring", 0) else None
    return DiscreteSystem(mesh, model, build_frames(mesh, case.fibres), surface, case.load.pressure_kpa, fixed,
                          element_scale=scale, spring=spring)


def element_scale(case, mesh: FEMesh):
    """(per-element parameter multipliers or None, stiffness scale (kPa) of the bulk penalty).

    Without ``case.regional`` the law is homogeneous (``None``, its
    :meth:`~lvcore.mechanics.materials.MaterialLaw.modulus`); with it, each
    element takes the multipliers of its region, and the bulk penalty follows
    the stiffest region, so uniform multipliers m give exactly the system of
    the homogeneous law with its stiffnesses times m.
    """
    law, regional = case.material, getattr(case, "regional", None)
    if regional is None:
        return None, law.modulus()
    per_region = regional.multipliers(law)
    modulus = max(law.scaled(row).modulus() for row in per_region)
    return per_region[mesh.template.element_regions], modulus


@dataclass(frozen=True, eq=False)
class PreparedCase:
    """Everything of a case that does not depend on its material parameters.

    Built once per geometry, resolution, fibres, load, boundary conditions,
    probes and strain layer by :func:`prepare_case` and reused by every solve
    that shares them (a campaign or a sweep solves hundreds of material points
    on one geometry: mesh, fibre frames, reference gradients and the strain
    operator cost ~20 % of a warm-started solve).
    """

    mesh: FEMesh
    system: DiscreteSystem  # with the material of the first case; see DiscreteSystem.with_model
    v_ref: float | None
    probe_elements: np.ndarray
    probe_xi: np.ndarray
    output_args: tuple | None


#: Prepared cases kept per process (least recently used dropped first).
PREPARED_CACHE_SIZE = 4
_PREPARED: "BoundedCache[PreparedCase]" = BoundedCache(PREPARED_CACHE_SIZE)


def _prepare_key(case) -> tuple:
    """Everything :class:`PreparedCase` depends on: the case less its material parameters (not its law)."""
    g = case.geometry
    nodes = None if g.template_nodes is None else hashlib.sha256(
        np.ascontiguousarray(g.template_nodes, dtype=float).tobytes()).hexdigest()
    return (g.kind, repr(g.resolution), g.preset, repr(g.ellipsoid), g.box_size, nodes, repr(case.fibres),
            repr(case.load), repr(case.boundary), tuple(case.probes), repr(case.outputs),
            repr(getattr(case, "regional", None)), type(case.material).__name__)


def prepare_case(case) -> PreparedCase:
    """The material-independent part of ``case`` (cached per process, see :class:`PreparedCase`).

    Raises
    ------
    CaseError, GeometryError
        Probes outside the mesh, a degenerate geometry (never cached).
    """
    key = _prepare_key(case)
    hit = _PREPARED.get(key)
    if hit is not None:
        return hit
    mesh = build_mesh(case)
    system = build_system(case, mesh)
    elem_p, xi_p = (np.zeros(0, int), np.zeros((0, 3)))
    if case.probes:
        try:
            elem_p, xi_p = observables.locate_points(mesh, case.probes)
        except ValueError as exc:
            raise CaseError("probes", str(exc)) from None
    v_ref = out_args = None
    if mesh.kind == "lv":
        v_ref = float(_cavity_volume(jax.device_put(mesh.nodes), *_volume_args(mesh)))
        check_reference_volumes(mesh, v_ref)
        op = observables.strain_operator(mesh, case.outputs.strain_layer)
        # jax.device_put, not jnp.asarray: the latter compiles a small program per shape (~20 ms each a process)
        out_args = (jax.device_put(mesh.nodes),) + _volume_args(mesh) + tuple(
            jax.device_put(a) for a in (op.connectivity, op.dNdX, op.e_c, op.weights))
    prep = PreparedCase(mesh, system, v_ref, elem_p, xi_p, out_args)
    _PREPARED.put(key, prep)
    return prep


def _volume_args(mesh: FEMesh):
    return jax.device_put(mesh.surfaces["endocardium"]), jax.device_put(float(mesh.base_z))


@exported_kernel
def _cavity_volume(x, faces, base_z):
    """Cavity volume (mm³), compiled once per topology (see :func:`loads.cavity_volume`)."""
    return loads.cavity_volume(x, faces, base_z)


@exported_kernel
def _outputs(u_full, X, faces, base_z, connectivity, dNdX, e_c, weights):
    """The 25 outputs ``[LVV (mL), 24 strains]`` of a full displacement vector.

    Jitted at module level with the mesh data as traced arguments, so it is
    compiled once per topology rather than once per call.
    """
    x = X + u_full.reshape(-1, 3)
    v = loads.cavity_volume(x, faces, base_z) / units.MM3_PER_ML
    op = observables.StrainOperator(elements=None, connectivity=connectivity, dNdX=dNdX, e_c=e_c, weights=weights)
    s = observables.regional_strains(x, op)
    return jnp.concatenate([v[None], s])


def _as_case(case):
    if isinstance(case, Mapping):
        from lvcore.mechanics.case import Case

        return Case.from_dict(case)
    return case


def simulate(case, with_sensitivities: bool = False, options: newton.NewtonOptions | None = None,
             raise_on_failure: bool = False, initial: tuple | None = None) -> SimulationResult:
    """Run one forward simulation.

    Parameters
    ----------
    case : lvcore.mechanics.case.Case or dict (the case JSON schema).
    with_sensitivities : also return d(25 outputs)/d(a, b, af, bf) by the
        adjoint method (Holzapfel–Ogden LV cases; other laws: all parameters).
    options : Newton settings.
    raise_on_failure : raise :class:`SolverError` instead of returning
        ``converged=False``.
    initial : optional ``solver_state`` (or ``warm_state``, which adds the
        factorised tangent, reused in this process) of an earlier converged
        result on the same mesh and boundary conditions (a Newton warm start
        at full load, see :func:`lvcore.mechanics.newton.solve`; ignored if
        its shapes do not match, and a cold solve follows if it does not
        converge).

    Returns
    -------
    SimulationResult

    Examples
    --------
    The default LV (coarse ``fast`` mesh) at the typical-heart material, inflated to 8 mmHg:

    >>> from lvcore.domain import conditions
    >>> from lvcore.mechanics.simulate import simulate
    >>> case = {"geometry": {"kind": "default", "resolution": "fast"},
    ...         "material": {"law": "holzapfel-ogden", **conditions.SIMULATOR_DEFAULT_THETA},
    ...         "load": {"pressure": 8, "units": "mmHg"}}
    >>> result = simulate(case)
    >>> result.converged, result.strains.shape    # 24 regional circumferential strains
    (True, (24,))
    >>> v0_ml, edv_ml = (v / 1000 for v in result.cavity_volume_mm3)
    >>> 1.5 < edv_ml / v0_ml < 2.1                # EDV/V₀ inside the typical band at 8 mmHg
    True
    """
    t0 = time.perf_counter()
    case = _as_case(case)
    prep = prepare_case(case)
    mesh, v_ref, elem_p, xi_p = prep.mesh, prep.v_ref, prep.probe_elements, prep.probe_xi
    if getattr(case, "regional", None) is None:
        system = prep.system.with_model(constitutive_model(case, mesh))
    else:  # per-element multipliers depend on the law: a system of its own
        system = build_system(case, mesh)
    is_lv = mesh.kind == "lv"
    layer = case.outputs.strain_layer if is_lv else None
    if case.load.pressure_kpa == 0:
        res = newton.NewtonResult(True, "converged (zero load)", np.zeros(system.n_free), system.zero_pressure(),
                                  1.0, 0, 0, 0, {})
    else:
        res = newton.solve(system, options, initial=initial)
    dofs = system.n_free
    if not res.converged:
        if raise_on_failure:
            raise SolverError(res.message)
        return SimulationResult(False, res.message, None if v_ref is None else (v_ref, None), None, None, None,
                                np.zeros((0, 3)), None, res.iterations, res.load_steps, dofs,
                                time.perf_counter() - t0, mesh.nodes, None, mesh.elements, None, res.timings,
                                strain_layer=layer)
    u = system.full(res.u)
    x = mesh.nodes + u.reshape(-1, 3)
    probes = observables.point_positions(x, mesh, elem_p, xi_p)
    vol = strains = apex_endo = apex_epi = standardised = None
    sens = None
    if is_lv:
        out_args = prep.output_args

        def output_fn(u_full):
            return _outputs(u_full, *out_args)

        y = np.asarray(output_fn(jax.device_put(u)))
        vol = (v_ref, float(y[0]) * units.MM3_PER_ML)
        strains = y[1:]
        standardised = vol[1] / v_ref
        apex_endo = x[mesh.template.apex_endo_node].copy()
        apex_epi = x[mesh.template.apex_epi_node].copy()
        if with_sensitivities:
            from lvcore.mechanics.sensitivities import output_sensitivities

            names = case.material.keys
            which = THETA_NAMES if isinstance(case.material, materials.HolzapfelOgden) else names
            sens = output_sensitivities(system, res.u, res.p, output_fn, names, which)
    if not (np.all(np.isfinite(x)) and (strains is None or np.all(np.isfinite(strains)))):
        msg = "solver produced non-finite outputs"
        if raise_on_failure:
            raise SolverError(msg)
        return SimulationResult(False, msg, None, None, None, None, np.zeros((0, 3)), None, res.iterations,
                                res.load_steps, dofs, time.perf_counter() - t0, mesh.nodes, None, mesh.elements,
                                strain_layer=layer)
    return SimulationResult(
        converged=True, message=res.message, cavity_volume_mm3=vol, lvv_standardised=standardised,
        apex_endocardium=apex_endo, apex_epicardium=apex_epi, probes=probes, strains=strains,
        newton_iterations=res.iterations, load_steps=res.load_steps, dofs=dofs,
        seconds=time.perf_counter() - t0, reference_nodes=mesh.nodes, displacement=u.reshape(-1, 3),
        elements=mesh.elements, sensitivities=sens, timings=res.timings,
        warnings=plausibility_warnings(vol, standardised, units.kpa_to_mmhg(case.load.pressure_kpa) if is_lv else None),
        solver_state=(res.u, res.p),
        solver_tangent=res.tangent, strain_layer=layer,
    )


def check_reference_volumes(mesh: FEMesh, cavity_mm3: float) -> None:
    """Refuse a degenerate LV: cavity or wall volume below the floors of :mod:`lvcore.safety.limits` (mm³ in).

    Raises
    ------
    GeometryError
        E.g. a base plane just above the apex, which leaves a near-empty cavity.
    """
    from lvcore.mechanics.quadrature import reference_gradients

    wall_ml = float(np.sum(reference_gradients(mesh.nodes, mesh.elements)[1])) / units.MM3_PER_ML
    cavity_ml = float(cavity_mm3) / units.MM3_PER_ML
    if not cavity_ml >= limits.MIN_CAVITY_ML:
        raise GeometryError(f"degenerate geometry: the reference cavity volume is {cavity_ml:.3g} mL, below the floor "
                            f"of {limits.MIN_CAVITY_ML} mL (lvcore.safety.limits.MIN_CAVITY_ML); check the base plane "
                            "(geometry.base_z must leave a cavity between the base and the apex) and the radii")
    if not wall_ml >= limits.MIN_WALL_ML:
        raise GeometryError(f"degenerate geometry: the wall volume is {wall_ml:.3g} mL, below the floor of "
                            f"{limits.MIN_WALL_ML} mL (lvcore.safety.limits.MIN_WALL_ML); check the geometry")


def plausibility_warnings(volume_mm3, standardised, pressure_mmhg: float | None = None) -> tuple[str, ...]:
    """Flags for physiologically implausible or unusual LV results (values are kept, not hidden).

    The loaded cavity above :data:`lvcore.safety.limits.PLAUSIBLE_MAX_LVV_ML` is always flagged (a units slip). EDV/V₀
    (``standardised``) is judged only for an LV at a physiological pressure (``pressure_mmhg`` in
    :data:`lvcore.domain.physiology.PHYSIOLOGICAL_EDP_RANGE_MMHG`): above
    :data:`lvcore.safety.limits.PLAUSIBLE_MAX_STANDARDISED_LVV` it is "implausible", outside the typical range of
    :func:`lvcore.domain.physiology.typical_edv_ratio` by more than its own uncertainty
    (:data:`lvcore.domain.physiology.EDV_RATIO_NOTE_TOLERANCE`, 2 %) "unusual". At any other pressure (or ``pressure_mmhg=None``,
    unknown) only EDV/V₀ above :data:`lvcore.safety.limits.PLAUSIBLE_MAX_STANDARDISED_LVV_ANY_PRESSURE` (5) is
    flagged, so benchmarks such as Land et al. (2015) problem 2 (10 kPa, EDV/V₀ 4.3) are not.

    Parameters
    ----------
    volume_mm3 : (float, float) or None
        Reference and loaded cavity volume (mm³); ``None`` when not an LV.
    standardised : float or None
        Loaded over reference cavity volume (EDV/V₀, dimensionless); ``None`` when not an LV.
    pressure_mmhg : float, optional
        The cavity pressure (mmHg); ``None`` when unknown.

    Returns
    -------
    tuple of str
        One sentence per flag (empty when nothing is flagged).
    """
    from lvcore.domain import physiology

    out = []
    if volume_mm3 is not None and volume_mm3[1] is not None:
        lvv = float(volume_mm3[1]) / units.MM3_PER_ML
        if lvv > limits.PLAUSIBLE_MAX_LVV_ML:
            out.append(f"implausible result: loaded cavity volume {lvv:.0f} mL exceeds "
                       f"{limits.PLAUSIBLE_MAX_LVV_ML:.0f} mL (check the stiffness parameters and the pressure units)")
    if standardised is None:
        return tuple(out)
    if not physiology.is_physiological_pressure(pressure_mmhg):
        if float(standardised) > limits.PLAUSIBLE_MAX_STANDARDISED_LVV_ANY_PRESSURE:
            at = ("" if pressure_mmhg is None else
                  f" at {float(pressure_mmhg):.3g} mmHg ({units.mmhg_to_kpa(float(pressure_mmhg)):.3g} kPa)")
            vols = ("" if volume_mm3 is None or volume_mm3[1] is None else
                    f" ({float(volume_mm3[0]) / units.MM3_PER_ML:.3g} -> {float(volume_mm3[1]) / units.MM3_PER_ML:.3g}"
                    " mL)")
            out.append(f"implausible result: the cavity inflated to {float(standardised):.3g} times its reference "
                       f"volume{vols}{at}, more than {limits.PLAUSIBLE_MAX_STANDARDISED_LVV_ANY_PRESSURE:g} times "
                       "at any pressure (lvcore.safety.limits.PLAUSIBLE_MAX_STANDARDISED_LVV_ANY_PRESSURE), so check the "
                       "geometry, the stiffness parameters and the pressure units")
        return tuple(out)
    if float(standardised) > limits.PLAUSIBLE_MAX_STANDARDISED_LVV:
        out.append(f"implausible result: the cavity inflated to {float(standardised):.2f} times its reference "
                   f"volume at {float(pressure_mmhg):g} mmHg (more than {limits.PLAUSIBLE_MAX_STANDARDISED_LVV:g}; "
                   f"{physiology.typical_edv_ratio(pressure_mmhg).text()}), so check the stiffness parameters and "
                   "the pressure units")
    else:
        note = physiology.edv_ratio_note(float(standardised), float(pressure_mmhg))
        if note:
            out.append(note)
    return tuple(out)


__all__ = ["SimulationResult", "simulate", "build_mesh", "build_system", "RESOLUTION_PRESETS", "N_OUTPUTS"]
