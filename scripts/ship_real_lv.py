#!/usr/bin/env python
"""Ship the real (patient-derived, not synthetic) LV of Dalton et al. 2022 in ``assets/real_lv/``.

The source is the project's shared data folder ``../shared/data/real-lv-dalton2022/`` (a hexahedral mesh in mm,
rebuilt from the repository dodaltuin/passive-lv-gnn-emul, MIT licence). The app and the package must run without
that folder, so this script fits lvcore's template to the mesh exactly as
``lvcore geometry fit --mesh lv_reference_hex8_mm.vtu --out ...`` does and writes, under ``--out``:

* ``real_lv_dalton2022_template.vtu``: the fitted template mesh (27-node hexahedra, mm) lvcore simulates on;
* ``fit_summary.json``: the fit's summary (cavity volume, residual, base, the mesh's own cavity) and the source;
* ``LICENSE-upstream.md``: the upstream licence text, copied unchanged;
* ``README.md``: what the geometry is, where it comes from and how it was made.

Run from the repository root::

    python scripts/ship_real_lv.py                      # ../shared/data/real-lv-dalton2022 -> assets/real_lv

The subject emulators of this geometry used by the fibre-discrepancy study (``lvcore study fibre-discrepancy
--geometry real-lv``) are built from the shipped template with ``lvcore emulator build`` (docs/studies.md).
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: The upstream mesh in the shared data folder.
SOURCE = ROOT.parent / "shared" / "data" / "real-lv-dalton2022"
MESH = "lv_reference_hex8_mm.vtu"

README = """# A real left ventricle (patient-derived, NOT synthetic)

**This is the geometry of one real human left ventricle**, the only non-synthetic geometry lvcore ships. It comes
from Dalton et al. 2022, "Emulation of cardiac mechanics using Graph Neural Networks", Computer Methods in Applied
Mechanics and Engineering, published with the repository dodaltuin/passive-lv-gnn-emul (folder
data/lvDataFixedGeom), under the MIT licence; the upstream licence text is `LICENSE-upstream.md` beside this file,
and it must travel with any copy. Copyright (c) 2022 David Dalton. It is a patient-derived shape, not a smooth
model: the wall thickness varies around the circumference and the cross-sections are not ellipses. No image data
and no personal data are included: node positions only.

| file | what |
|---|---|
| `{template}` | lvcore's template (27-node hexahedra, mm) fitted to the upstream mesh's endocardium and epicardium; base plane z = 0, apex on the negative z axis. Use it as `{{"geometry": {{"kind": "mesh", "path": ...}}}}` or `--geometry` |
| `fit_summary.json` | the fit: cavity volume {cavity:.1f} mL, residual mean {resid:.3f} mm (max {resid_max:.2f} mm), base-apex length {length:.1f} mm; the upstream mesh's own cavity {mesh_cavity:.2f} mL |
| `LICENSE-upstream.md` | the upstream MIT licence |

Made by `python scripts/ship_real_lv.py` from the upstream hexahedral mesh ({source_mesh}: {n_hexes} linear
hexahedra), exactly as `lvcore geometry fit --mesh {source_mesh} --out {template}` fits it. In Python:
`lvcore.resources.real_lv_files()`.

Upstream the base slid in its plane (u_z = 0) and the fibres ran from about +60 deg at the endocardium to -60 deg
at the epicardium; lvcore's simulations on it use lvcore's own rule-based fibres and basal condition.
"""


def ship(source: Path, out: Path) -> dict:
    """Fit the template to ``source/lv_reference_hex8_mm.vtu`` and write the shipped files into ``out``."""
    from lvcore.geometry.io import write_template_mesh
    from lvcore.geometry.volume_mesh import fit_volume_mesh
    from lvcore.resources import REAL_LV_LABEL, REAL_LV_TEMPLATE

    mesh_fit = fit_volume_mesh(source / MESH, units="mm")
    res = mesh_fit.fit
    out.mkdir(parents=True, exist_ok=True)
    write_template_mesh(out / REAL_LV_TEMPLATE, res.nodes,
                        metadata={"label": REAL_LV_LABEL, "residual_mean_mm": f"{res.residual_mean_mm:.4f}"})
    summary = mesh_fit.summary()
    summary["source"] = MESH  # the file name only: no build-machine paths in shipped files
    summary["mesh"]["source"] = MESH
    summary = {"label": REAL_LV_LABEL, "synthetic": False,
               "upstream": "dodaltuin/passive-lv-gnn-emul, data/lvDataFixedGeom (MIT licence)",
               "command": f"lvcore geometry fit --mesh {MESH} --out {REAL_LV_TEMPLATE}", "fit": summary}
    text = json.dumps(summary, indent=1).replace(f"{source / MESH}", MESH)  # no build-machine paths
    (out / "fit_summary.json").write_text(text + "\n")
    shutil.copyfile(source / "LICENSE-upstream.md", out / "LICENSE-upstream.md")
    (out / "README.md").write_text(README.format(
        template=REAL_LV_TEMPLATE, cavity=res.cavity_volume_ml, resid=res.residual_mean_mm,
        resid_max=res.residual_max_mm, length=res.length_mm, mesh_cavity=mesh_fit.mesh_cavity_ml, source_mesh=MESH,
        n_hexes=mesh_fit.boundary.n_hexes))
    return summary


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--source", type=Path, default=SOURCE, help=f"upstream folder (default {SOURCE})")
    p.add_argument("--out", type=Path, default=ROOT / "assets" / "real_lv", help="output folder (default assets/real_lv)")
    args = p.parse_args(argv)
    if not (args.source / MESH).is_file():
        print(f"no {MESH} in {args.source}", file=sys.stderr)
        return 2
    s = ship(args.source, args.out)["fit"]
    print(f"wrote {args.out}: cavity {s['cavity_volume_ml']:.2f} mL, residual {s['residual_mean_mm']:.3f} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
