"""Verification problems of Land et al. (2015): the cases and their reference values.

Land S. et al., "Verification of cardiac mechanics software: benchmark problems and solutions
for testing active and passive material behaviour", Proc. R. Soc. A 471 (2015) 20150641.
Problems 1 (a bending beam) and 2 (inflation of an idealised LV) use the transversely isotropic
Guccione law with a follower pressure. The cases here are plain case dicts (see
``docs/case_schema.md``) for :func:`lvcore.mechanics.simulate.simulate`; the tests
(``tests/test_mechanics_verification.py``) and the convergence tables
(``benchmarks/land2015.py``) both build them from this module.
"""
from __future__ import annotations

from lvcore.mechanics.resolution import LVResolution

#: Problem 1: z of the tip point ``P1_TIP_POINT`` after loading must lie in the spread of the
#: converged submissions, ``[min, max]`` in mm.
P1_TIP_Z_RANGE_MM = (4.151, 4.185)

#: Problem 1: the probed tip point (mm) in the reference configuration.
P1_TIP_POINT = (10.0, 0.5, 1.0)

#: Problem 2 (Simula/FEniCS converged solution): endocardial and epicardial apex z (mm) and the
#: loaded cavity volume (mm³).
P2_REF = {"endo": -26.612, "epi": -28.279, "volume": 10734.0}


def problem1_case(res) -> dict:
    """Problem 1, the 10 × 1 × 1 mm beam clamped at x = 0 with 0.004 kPa on its bottom face.

    Parameters
    ----------
    res : tuple of int
        Elements along ``(x, y, z)``.

    Returns
    -------
    dict
        The case; its single probe is the tip point :data:`P1_TIP_POINT`.
    """
    return {
        "geometry": {"kind": "box", "size": [10, 1, 1], "resolution": {"x": res[0], "y": res[1], "z": res[2]}},
        "material": {"law": "guccione", "C": 2.0, "bf": 8.0, "bt": 2.0, "bfs": 4.0},
        "fibres": {"direction": [1, 0, 0]},
        "load": {"pressure": 0.004, "units": "kPa", "surface": "z0"},
        "boundary": {"clamped": ["x0"]},
        "probes": [list(P1_TIP_POINT)],
    }


def problem2_case(res) -> dict:
    """Problem 2, the truncated-ellipsoid LV (mm) inflated to 10 kPa with a clamped base.

    Parameters
    ----------
    res : str or LVResolution
        A preset name, an :class:`~lvcore.mechanics.resolution.LVResolution` or ``"NC,NL,NT[,GP]"``
        (NL may be graded, e.g. ``2+1+1+2``).

    Returns
    -------
    dict
        The case.
    """
    resolution = (res if isinstance(res, LVResolution) else LVResolution.from_spec(res)).case_dict()
    return {
        "geometry": {"kind": "ellipsoid", "endo": {"rs": 7.0, "rl": 17.0}, "epi": {"rs": 10.0, "rl": 20.0},
                     "base_z": 5.0, "resolution": resolution},
        "material": {"law": "guccione", "C": 10.0, "bf": 1.0, "bt": 1.0, "bfs": 1.0},
        "load": {"pressure": 10.0, "units": "kPa"},
        "boundary": {"base": "clamped"},
    }
