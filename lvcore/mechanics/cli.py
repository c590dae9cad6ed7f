"""``lvcore simulate CASE.json``: run one forward simulation from a case file.

Exit codes: 0 converged, 1 the solver did not converge, 2 bad input (any
:class:`~lvcore.exceptions.LVCoreError`, reported by :func:`lvcore.cli.main`).
"""
from __future__ import annotations

import json
import math

import numpy as np

from lvcore import cli_args
from lvcore.mechanics.summary import format_summary


def register(subparsers) -> None:
    """Add the ``simulate`` sub-command."""
    p = cli_args.command(
        subparsers, "simulate", run,
        help="run one forward simulation of a case file",
        description="Inflate the geometry of CASE.json (see docs/case_schema.md) and report the end-diastolic "
                    "volume, the 24 regional circumferential strains, probe positions and solver diagnostics.",
    )
    p.add_argument("case", help="case JSON file (docs/case_schema.md)")
    p.add_argument("--json", action="store_true", help="print the full result as JSON instead of a summary")
    p.add_argument("--vtu", metavar="OUT.vtu", type=cli_args.output_file,
                   help="also write the reference mesh and displacement to a VTU file (default: not written)")
    p.add_argument("--sensitivities", action="store_true",
                   help="also compute the derivatives of the outputs with respect to the material parameters")


def run(args) -> int:
    """Run the ``simulate`` sub-command; returns the exit code."""
    from lvcore.mechanics.case import load_case
    from lvcore.mechanics.simulate import simulate

    case = load_case(args.case)
    result = simulate(case, with_sensitivities=bool(args.sensitivities))
    if args.vtu:
        from lvcore.mechanics.export import export_result

        export_result(result, args.vtu, case)
    # every result names its base condition (clamped is the default; the chapter emulator is sliding)
    boundary = ({"base": case.boundary.base} if case.geometry.is_lv
                else {"clamped": list(case.boundary.clamped_faces)})
    if args.json:
        out = {**result.to_dict(), "boundary": boundary}
        if args.sensitivities and getattr(result, "sensitivities", None) is not None:
            out["sensitivities"] = _clean(json.loads(json.dumps(result.sensitivities, default=_json_default)))
        print(json.dumps(out, indent=2, default=_json_default, allow_nan=False))
    else:
        print(format_summary(result))
        print("boundary: " + (f"base {case.boundary.base}" + (" (the default; the 'chapter' emulator is sliding)"
                                                                if case.boundary.base == "clamped" else "")
                              if case.geometry.is_lv else f"clamped faces {', '.join(boundary['clamped'])}"))
        if args.vtu:
            print(f"wrote {args.vtu}")
    return 0 if bool(result.converged) else 1


def _json_default(obj):
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return _clean(obj.item())
    raise TypeError(f"cannot write {type(obj).__name__} as JSON")


def _clean(x):
    if isinstance(x, list):
        return [_clean(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x
