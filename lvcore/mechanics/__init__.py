"""The finite-element simulator: cases, meshes, material laws, the solve and its outputs.

One forward simulation of a :class:`Case` (or a case dictionary, see
docs/case_schema.md) is ``lvcore.simulate(case)``, i.e.
:func:`lvcore.mechanics.simulate.simulate`. (``lvcore.mechanics.simulate``
is that module; the package does not re-export the function under the
module's name, which Python's import system would shadow.) Names are
imported from their submodules on first use.
"""
from __future__ import annotations

from lvcore._exports import lazy_exports

_EXPORTS = {
    # one forward simulation
    "SimulationResult": "simulate", "build_mesh": "simulate", "build_system": "simulate",
    "N_OUTPUTS": "simulate",
    # cases
    "Case": "case", "load_case": "case", "GeometrySpec": "case", "FibreSpec": "case", "LoadSpec": "case",
    "BoundarySpec": "case", "OutputSpec": "case",
    "build_case": "case_inputs", "space_case": "case_inputs",
    # resolutions
    "LVResolution": "resolution", "BoxResolution": "resolution", "ResolutionError": "resolution",
    "RESOLUTION_PRESETS": "resolution", "RESOLUTION_PRESET_NAMES": "resolution",
    "BOX_RESOLUTION_PRESETS": "resolution", "BOX_RESOLUTION_PRESET_NAMES": "resolution",
    # constitutive models
    "MaterialLaw": "materials", "HolzapfelOgden": "materials", "Guccione": "materials", "NeoHookean": "materials",
    "LAWS": "materials", "MixedPenalty": "materials", "ConstitutiveModel": "materials",
    # the simulator as a forward model (lvcore.core.forward)
    "SimulatorForward": "forward", "AdjointSimulatorForward": "forward",
    # solver, meshes, export, reports
    "NewtonOptions": "newton", "FEMesh": "mesh", "lv_mesh": "mesh", "box_mesh": "mesh",
    "DiscreteSystem": "system", "export_result": "export", "result_vtu_bytes": "export",
    "format_summary": "summary",
    # verification problems (Land et al. 2015)
    "problem1_case": "verification", "problem2_case": "verification",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
