"""Build a SYNTHETIC subject for the real-data worked example (docs/real_data.md).

What a user brings, generated from a known truth:

1. ``subject_lv.inp``: a volumetric tetrahedral LV mesh (ABAQUS format, mm, in
   "scanner" coordinates: tilted and shifted), meshed by gmsh from a truncated
   ellipsoid that is *not* the population-mean shape;
2. ``subject_aha.mat``: MATLAB file with the end-diastolic volume ``lvv_ml`` and
   16 AHA-segment circumferential strains ``strains`` (``segments = 'aha'``),
   simulated with lvcore's finite-element model on the subject's fitted
   geometry at a known theta (chapter conditions: fibre angles -60/60 deg,
   EDP 8 mmHg; the base condition of the bundled ``chapter`` emulator unless
   ``--base`` says otherwise) plus Gaussian noise;
3. ``truth.json``: the true theta, the noise and how everything was made.

Usage::

    python scripts/synthetic_subject.py --out subject/ [--size 4] [--seed 1] [--base clamped|sliding]

Everything written is labelled SYNTHETIC.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported

import numpy as np  # noqa: E402

#: The subject's true material parameters (kPa, -, kPa, -).
TRUE_THETA = {"a": 0.8, "b": 4.0, "af": 2.0, "bf": 6.0}
#: Noise of the synthetic measurements: LVV (mL) and strains.
NOISE = {"lvv_ml": 3.0, "strain": 0.015}


def subject_geometry():
    """A truncated ellipsoid larger and rounder than the mean shape (mm)."""
    from lvcore.geometry.analytic import EllipsoidSurface, TruncatedEllipsoidLV

    return TruncatedEllipsoidLV(EllipsoidSurface(26.0, 70.0, ry=23.0), EllipsoidSurface(35.0, 80.0, ry=32.0), 10.0)


def scanner_pose():
    """Rotation and shift placing the LV as in a scanner (long axis tilted ~50 deg)."""
    ax, az = np.radians(50.0), np.radians(-30.0)
    rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
    return rz @ rx, np.array([-35.0, 120.0, 260.0])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="synthetic_subject", help="output folder")
    ap.add_argument("--size", type=float, default=4.0, help="tetrahedron size (mm)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--base", choices=("clamped", "sliding"), default=None,
                    help="base boundary condition of the simulated data (default: that of the bundled `chapter` "
                         "emulator, so the worked example has no base-condition discrepancy)")
    args = ap.parse_args(argv)

    import scipy.io

    from lvcore.domain.conditions import CHAPTER_ANGLES, CHAPTER_EDP
    from lvcore.geometry.io import write_template_mesh
    from lvcore.geometry.meshing import ellipsoid_tet_mesh
    from lvcore.geometry.volume_mesh import fit_volume_mesh
    from lvcore.inference.segments import lvcore_to_aha
    from lvcore.mechanics.case import Case
    from lvcore.mechanics.simulate import simulate

    base = args.base
    if base is None:
        from lvcore.emulator import load_emulator

        base = load_emulator("chapter").base
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rot, shift = scanner_pose()
    geo = subject_geometry()
    mesh = ellipsoid_tet_mesh(geo, args.size, out / "subject_lv.inp", rotation=rot, shift=shift)
    print(f"SYNTHETIC subject mesh: {len(mesh.cells[0].data)} tetrahedra -> {out / 'subject_lv.inp'} "
          f"(exact cavity {geo.cavity_volume_mm3() / 1000:.2f} mL)")
    # the septum: +x of the ellipsoid frame, carried to scanner coordinates, so sector 0 is septal
    septum = rot @ np.array([geo.epi.rs, 0.0, 0.0]) + shift
    fit = fit_volume_mesh(out / "subject_lv.inp", septum=septum)
    fitted = write_template_mesh(out / "subject_fitted.vtu", fit.fit.nodes,
                                 metadata={"label": "SYNTHETIC subject (scripts/synthetic_subject.py)"})
    print(f"fitted template: cavity {fit.fit.cavity_volume_ml:.2f} mL, residual {fit.fit.residual_mean_mm:.3f} mm "
          f"-> {fitted}")
    case = Case.from_dict({
        "geometry": {"kind": "mesh", "path": str(fitted.resolve())},
        "material": {"law": "holzapfel-ogden", **TRUE_THETA},
        "fibres": {"alpha_endo": CHAPTER_ANGLES[0], "alpha_epi": CHAPTER_ANGLES[1]},
        "load": {"pressure": CHAPTER_EDP, "units": "mmHg"},
        "boundary": {"base": base},
    })
    res = simulate(case, raise_on_failure=True)
    y = res.outputs()
    rng = np.random.default_rng(args.seed)
    lvv = float(y[0] + rng.normal(0.0, NOISE["lvv_ml"]))
    strains = y[1:] + rng.normal(0.0, NOISE["strain"], 24)
    aha = lvcore_to_aha(strains, 0.0)
    scipy.io.savemat(out / "subject_aha.mat", {
        "lvv_ml": lvv, "strains": aha, "subject": "SYNTHETIC-S1", "segments": "aha", "segment_offset_deg": 0.0,
        "note": "SYNTHETIC data from scripts/synthetic_subject.py"})
    truth = {"label": "SYNTHETIC subject (scripts/synthetic_subject.py)", "theta": TRUE_THETA, "noise": NOISE,
             "seed": args.seed, "edp_mmhg": CHAPTER_EDP, "base": base, "angles_deg": list(CHAPTER_ANGLES),
             "ellipsoid": {"endo": [geo.endo.rs, geo.endo.ry, geo.endo.rl], "epi": [geo.epi.rs, geo.epi.ry, geo.epi.rl],
                           "base_z": geo.base_z},
             "noise_free_outputs": [float(v) for v in y], "lvv_ml": lvv, "aha_strains": [float(v) for v in aha],
             "simulator": {"dofs": res.dofs, "seconds": res.seconds}}
    (out / "truth.json").write_text(json.dumps(truth, indent=1))
    print(f"simulated ({base} base) at theta {TRUE_THETA}: LVV {y[0]:.1f} mL (measured {lvv:.1f}), mean strain {y[1:].mean():.4f}; "
          f"wrote {out / 'subject_aha.mat'} (16 AHA strains) and truth.json ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
