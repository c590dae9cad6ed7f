"""``lvcore geometry ...``: fit segmentations, inspect meshes, use the shape model.

* ``lvcore geometry fit CONTOURS.json --out MESH.vtu [--json]``
* ``lvcore geometry fit --endo ENDO.stl --epi EPI.stl [--units mm] --out MESH.vtu [--json]``
* ``lvcore geometry fit --mesh LV.inp|LV.msh|LV.vtu [--units mm] --out MESH.vtu [--json]``: a volumetric
  tet/hex mesh, split into endo/epi/base automatically (:mod:`lvcore.geometry.volume_mesh`)
* ``--base-cut MM`` (any input): cut the LV MM below the base ring's centre (contours: drop the slices
  above); default: :mod:`lvcore.geometry.base_plane`'s rule. Every fit prints the base plane, the cut and
  the cavity volume removed (``"base"`` in ``--json``)
* ``lvcore geometry info MESH.vtu [--json]``: cavity volume, wall volume, length
* ``lvcore geometry compare A.vtu B.vtu [--json]``: node MSE (cm²), max node distance
* ``lvcore geometry pca SCORES... --out MESH.vtu [--model M.json]``: reconstruct from PC scores
* ``lvcore geometry project MESH.vtu [--modes K] [--json]``: PC scores of a mesh
"""
from __future__ import annotations

import json

import numpy as np

from lvcore import cli_args
from lvcore.exceptions import GeometryError
from lvcore.geometry.measures import geometry_info


def _fit(args) -> int:
    from lvcore.geometry.fitting import fit_contours, fit_surfaces, units_warnings
    from lvcore.geometry.io import write_template_mesh

    given = [n for n, v in (("CONTOURS.json", args.contours), ("--endo/--epi", args.endo or args.epi),
                            ("--mesh", getattr(args, "mesh", None))) if v]
    if len(given) > 1:
        raise GeometryError(f"give one input to fit, not {' and '.join(given)}")
    if args.base_cut is not None and not (np.isfinite(args.base_cut) and args.base_cut >= 0):
        raise GeometryError(f"--base-cut {args.base_cut}: give a distance >= 0 mm below the base ring")
    mesh_fit = None
    if getattr(args, "mesh", None):
        from lvcore.geometry.volume_mesh import fit_volume_mesh

        mesh_fit = fit_volume_mesh(args.mesh, units=args.units, base_z=args.base_z, septum=args.septum,
                                   base_cut_mm=args.base_cut)
        res = mesh_fit.fit
    elif args.contours:
        res = fit_contours(args.contours, base_z=args.base_z, base_cut_mm=args.base_cut)
    elif args.endo and args.epi:
        septum = None if args.septum is None else [v * {"mm": 1.0, "cm": 10.0, "m": 1000.0}[args.units]
                                                    for v in args.septum]
        res = fit_surfaces(args.endo, args.epi, units=args.units, base_z=args.base_z, septum=septum,
                           base_cut_mm=args.base_cut)
    else:
        raise GeometryError("nothing to fit: give CONTOURS.json, both --endo and --epi surface files, "
                            "or a volumetric mesh with --mesh")
    out = None
    if args.out:
        meta = {"label": res.label, "residual_mean_mm": f"{res.residual_mean_mm:.4f}"}
        out = write_template_mesh(args.out, res.nodes, metadata=meta)
    summary = {**(mesh_fit.summary() if mesh_fit else res.summary()), "out": str(out) if out else None}
    summary["warnings"] = list(summary.get("warnings", [])) + units_warnings(res, args.units, "--units")
    if args.json:
        print(json.dumps(summary, indent=1))
    else:
        print(f"fitted {res.label}")
        print(f"  residual: mean {res.residual_mean_mm:.3f} mm, max {res.residual_max_mm:.3f} mm "
              f"(endo {res.residual_endo_mean_mm:.3f}, epi {res.residual_epi_mean_mm:.3f}; {res.n_points} points, "
              f"{res.n_above_base} above the base plane ignored)")
        print(f"  cavity volume {res.cavity_volume_ml:.1f} mL, base-apex length {res.length_mm:.1f} mm")
        if res.base is not None:
            print(f"  base: {res.base.describe()}")
        if mesh_fit:
            b = mesh_fit.boundary
            print(f"  volume mesh: {b.n_tets} tetrahedra, {b.n_hexes} hexahedra; boundary triangles endo "
                  f"{b.n_faces['endo']}, epi {b.n_faces['epi']}, base {b.n_faces['base']}; the mesh's own cavity "
                  f"{b.cavity_volume_ml:.2f} mL, {mesh_fit.mesh_cavity_ml:.2f} mL below the cut "
                  f"({summary['cavity_volume_change_pct']:+.2f} % after fitting)")
        for w in summary["warnings"]:
            print(f"  warning: {w}")
        if out:
            print(f"  wrote {out}  (use it as {{\"geometry\": {{\"kind\": \"mesh\", \"path\": \"{out}\"}}}})")
    return 0


def _info(args) -> int:
    from lvcore.geometry.io import read_template_mesh

    info = geometry_info(read_template_mesh(args.mesh))
    if args.json:
        print(json.dumps(info, indent=1))
    else:
        for k, v in info.items():
            print(f"{k:18s} {v:.2f}" if isinstance(v, float) else f"{k:18s} {v}")
    return 0


def _compare(args) -> int:
    from lvcore.geometry.io import read_template_mesh
    from lvcore.geometry.measures import node_mse_cm2

    a, b = read_template_mesh(args.a), read_template_mesh(args.b)
    d = np.linalg.norm(a - b, axis=1)
    out = {"node_mse_cm2": node_mse_cm2(a, b), "max_node_distance_mm": float(d.max()),
           "mean_node_distance_mm": float(d.mean())}
    print(json.dumps(out, indent=1) if args.json else
          f"node MSE {out['node_mse_cm2']:.4f} cm², mean {out['mean_node_distance_mm']:.2f} mm, "
          f"max {out['max_node_distance_mm']:.2f} mm")
    return 0


def _pca(args) -> int:
    from lvcore.geometry.io import write_template_mesh
    from lvcore.geometry.shape_model import load_shape_model

    sm = load_shape_model(args.model)
    nodes = sm.reconstruct(np.asarray(args.scores, float))
    out = write_template_mesh(args.out, nodes, metadata={"label": f"PCA scores {args.scores} of {sm.label}"})
    print(f"wrote {out} ({len(args.scores)} of {sm.n_modes} standardised scores; model {sm.label})")
    return 0


def _project(args) -> int:
    from lvcore.geometry.io import read_template_mesh
    from lvcore.geometry.shape_model import load_shape_model

    sm = load_shape_model(args.model)
    if args.modes > sm.n_modes:
        raise GeometryError(f"--modes {args.modes}: the shape model {sm.label} has {sm.n_modes} modes")
    nodes = read_template_mesh(args.mesh)
    h = sm.project(nodes, args.modes)
    out = {"scores": [float(v) for v in h], "reconstruction_mse_cm2": sm.reconstruction_mse_cm2(nodes, args.modes),
           "model": sm.label}
    print(json.dumps(out, indent=1) if args.json else
          "scores " + " ".join(f"{v:.3f}" for v in h) + f"\nreconstruction MSE {out['reconstruction_mse_cm2']:.4f} cm²")
    return 0


def register(subparsers) -> None:
    """Add ``lvcore geometry`` and its sub-commands."""
    sub = cli_args.command_group(
        subparsers, "geometry", help="fit segmentations to the LV template, inspect meshes, PCA",
        description="Fit a segmentation (contour stack, endo/epi surfaces or a volumetric mesh) to the LV template, "
                    "inspect and compare template meshes, and go between meshes and the shape model's PC scores.")

    f = cli_args.command(
        sub, "fit", _fit, help="fit the template to a contour stack (JSON), endo/epi surfaces or a volume mesh",
        description="Fit the LV template to a contour stack, a pair of endocardial and epicardial surfaces "
                    "(--endo/--epi) or a volumetric mesh (--mesh), after finding and cutting the base; prints the "
                    "residual, the cavity volume and any warnings, and --out writes the fitted template mesh.")
    f.add_argument("contours", nargs="?", help="contour stack JSON (schema lvcore.contours/1)")
    f.add_argument("--endo", help="endocardial surface (VTK/VTP/STL/PLY/OBJ), open at the base (default: none; "
                                  "give --endo and --epi, or --mesh, or a contour stack)")
    f.add_argument("--epi", help="epicardial surface, open at the base (default: none; needed with --endo)")
    f.add_argument("--mesh", help="volumetric LV mesh (tetrahedra/hexahedra; .inp, .msh, .vtu, .vtk, .xdmf, ... - "
                                  "anything meshio reads), open at the base: a flat cap, an uneven or notched base, "
                                  "or walls that meet at the base (default: none)")
    f.add_argument("--units", default="mm", choices=("mm", "cm", "m"),
                   help="units of surface or volume-mesh files (default mm)")
    f.add_argument("--septum", type=float, nargs=3, metavar=("X", "Y", "Z"), default=None,
                   help="a point on the septum (file coordinates and --units) fixing phi = 0 for --mesh or --endo/--epi "
                        "(default: the file's x axis projected onto the base plane)")
    f.add_argument("--base-cut", type=float, default=None, metavar="MM",
                   help="cut the LV this far (mm) below the centre of the base ring, orthogonal to the long axis "
                        "(contours: below the basal slice). Default: a flat base is kept as it is; an oblique, "
                        "uneven or notched base is cut below its lowest point; where the endocardium and epicardium "
                        "meet at the base, where the wall first reaches 80%% of its typical thickness. The fit "
                        "reports the base plane, the cut and the cavity volume removed")
    f.add_argument("--base-z", type=float, default=0.0, help="height of the base plane in the output (mm, default 0)")
    f.add_argument("--out", type=cli_args.output_file,
                   help="write the fitted mesh here (.vtu; default: not written, the summary is printed)")
    f.add_argument("--json", action="store_true", help="print the fit summary as JSON")

    i = cli_args.command(sub, "info", _info, help="cavity and wall volume of a template mesh",
                         description="Print the cavity and wall volumes (mL) of a template mesh.")
    i.add_argument("mesh", help="template mesh (.vtu written by `lvcore geometry fit --out` or `geometry pca`)")
    i.add_argument("--json", action="store_true", help="print the volumes as JSON (default: a text line)")

    c = cli_args.command(sub, "compare", _compare, help="node MSE (cm²) between two template meshes",
                         description="Print the mean squared distance (cm²) between the nodes of two template meshes "
                                     "on the same template, the chapter's measure of how far two geometries differ.")
    c.add_argument("a", help="first template mesh (.vtu)")
    c.add_argument("b", help="second template mesh (.vtu) on the same template")
    c.add_argument("--json", action="store_true", help="print the comparison as JSON (default: a text line)")

    r = cli_args.command(sub, "pca", _pca, help="reconstruct a mesh from standardised PCA scores",
                         description="Build a template mesh from standardised PC scores of the shape model (modes not "
                                     "given are 0) and write it as .vtu.")
    r.add_argument("scores", nargs="+", type=cli_args.float_in(-10.0, 10.0),
                   help="standardised PC scores h1 h2 ... (units of each mode's sd, each in [-10, 10]; modes "
                        "not given are 0)")
    r.add_argument("--out", type=cli_args.output_file, required=True, help="output template mesh (.vtu)")
    r.add_argument("--model", default=None, help="shape model .json (default: bundled SYNTHETIC model)")

    q = cli_args.command(sub, "project", _project, help="standardised PCA scores of a template mesh",
                         description="Project a template mesh onto the shape model: its standardised PC scores and "
                                     "the mean squared node error (cm²) of their reconstruction.")
    q.add_argument("mesh", help="template mesh (.vtu) to project onto the shape model")
    q.add_argument("--modes", type=cli_args.int_in(1, 100), default=5,
                   help="number of PC modes to project onto, 1 to the model's number of modes (default 5)")
    q.add_argument("--model", default=None, help="shape model .json (default: the bundled SYNTHETIC model)")
    q.add_argument("--json", action="store_true", help="print the scores as JSON (default: a text line)")
