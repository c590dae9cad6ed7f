"""Operator study in the geometry domain: the chapter's Table 9.4 on the SYNTHETIC cohort.

For each operator taken as the main one and each of the 6 patients: the mean
squared node distance (cm², :func:`lvcore.geometry.measures.node_mse_cm2`)
of the other two operators' geometries to the main one, and of the k-mode PCA
reconstructions (k = 5..10) of the main geometry. The bottom row is the share
of the 18 cases in which k modes beat both other operators.

The chapter (real segmentations) found operators differing by 0.003–0.03 cm²
and 10 modes beating a new operator in 94% of cases. Here the operators are
imitations (:mod:`lvcore.geometry.cohort`) and everything is SYNTHETIC.

Usage: ``lvcore study geometry-operators [--json]``.
"""
from __future__ import annotations

import json

import numpy as np

from lvcore.geometry.measures import node_mse_cm2

#: Numbers of PCA modes compared (the chapter's columns).
DEFAULT_KS = (5, 6, 7, 8, 9, 10)
#: The chapter's bottom row, for reference.
CHAPTER_SHARE = {5: 0.44, 6: 0.44, 7: 0.67, 8: 0.83, 9: 0.89, 10: 0.94}


def operator_table(operator_geometries=None, shape_model=None, ks=DEFAULT_KS) -> dict:
    """Table 9.4 as plain data.

    Parameters
    ----------
    operator_geometries : OperatorGeometries, optional
        Default: the bundled SYNTHETIC set (:func:`lvcore.geometry.cohort.load_operator_geometries`).
    shape_model : ShapeModel, optional
        Default: the bundled SYNTHETIC model (:func:`lvcore.geometry.shape_model.load_shape_model`).
    ks : sequence of int
        Numbers of modes.

    Returns
    -------
    dict with keys ``label``, ``patients``, ``operators``, ``ks``, ``blocks``
    (one per main operator: ``main``, ``others``, ``rows`` with ``patient``,
    ``operator_mse`` {other: cm²}, ``pca_mse`` {k: cm²}, ``first_k_beating_both``),
    ``share_beating_both`` {k: fraction}, ``chapter_share``, ``operator_mse_range``
    and ``n_cases``. Keys of per-k dicts are strings (JSON-ready).
    """
    if operator_geometries is None:
        from lvcore.geometry.cohort import load_operator_geometries

        operator_geometries = load_operator_geometries()
    if shape_model is None:
        from lvcore.geometry.shape_model import load_shape_model

        shape_model = load_shape_model()
    og, sm = operator_geometries, shape_model
    ks = [int(k) for k in ks]
    leaked = sorted(set(og.patients) & set(sm.train_ids))
    if leaked:
        raise ValueError(f"operator-study patients {leaked} are in the shape model's training set; hold them out")
    blocks, beats, op_mses = [], {k: [] for k in ks}, []
    for m, main in enumerate(og.operators):
        others = [o for o in og.operators if o != main]
        rows = []
        for p, pid in enumerate(og.patients):
            g = og.nodes[p, m]
            op_mse = {o: node_mse_cm2(og.nodes[p, og.operators.index(o)], g) for o in others}
            op_mses += list(op_mse.values())
            pca = {str(k): sm.reconstruction_mse_cm2(g, k) for k in ks}
            best = min(op_mse.values())
            first = None
            for k in ks:
                ok = pca[str(k)] < best
                beats[k].append(ok)
                if ok and first is None:
                    first = k
            rows.append({"patient": pid, "operator_mse": op_mse, "pca_mse": pca, "first_k_beating_both": first})
        blocks.append({"main": main, "others": others, "rows": rows})
    return {
        "label": "SYNTHETIC operator study (imitation operators on synthetic LVs)",
        "patients": list(og.patients),
        "operators": list(og.operators),
        "ks": ks,
        "blocks": blocks,
        "share_beating_both": {str(k): float(np.mean(beats[k])) for k in ks},
        "chapter_share": {str(k): v for k, v in CHAPTER_SHARE.items() if k in ks},
        "operator_mse_range": [float(min(op_mses)), float(max(op_mses))],
        "n_cases": len(og.patients) * len(og.operators),
        "shape_model": sm.label,
    }


def format_table(table: dict) -> str:
    """Plain-text rendering of :func:`operator_table` (cm²)."""
    ks = table["ks"]
    lines = [table["label"], "mean squared node distance to the main operator's geometry (cm^2)", ""]
    for b in table["blocks"]:
        lines.append(f"Main operator: {b['main']}")
        head = [f"vs {o}" for o in b["others"]] + [f"{k}PC" for k in ks] + ["first k < both"]
        lines.append(f"{'patient':16s}" + "".join(f"{h:>9s}" for h in head))
        for r in b["rows"]:
            vals = [r["operator_mse"][o] for o in b["others"]] + [r["pca_mse"][str(k)] for k in ks]
            first = r["first_k_beating_both"]
            lines.append(f"{r['patient']:16s}" + "".join(f"{v:9.4f}" for v in vals)
                         + f"{(str(first) if first else '>' + str(ks[-1])):>9s}")
        lines.append("")
    lines.append(f"{'share k beats both':34s}" + "".join(f"{table['share_beating_both'][str(k)]:9.2f}" for k in ks))
    lines.append(f"{'chapter (real data)':34s}" + "".join(f"{table['chapter_share'].get(str(k), float('nan')):9.2f}" for k in ks))
    lo, hi = table["operator_mse_range"]
    lines.append(f"operators differ by {lo:.4f}-{hi:.4f} cm^2 (chapter: 0.003-0.03 cm^2)")
    return "\n".join(lines)


def _run(args) -> int:
    from lvcore.geometry.cohort import load_operator_geometries
    from lvcore.geometry.shape_model import load_shape_model

    og = load_operator_geometries(args.cohort) if args.cohort else None
    sm = load_shape_model(args.model) if args.model else None
    table = operator_table(og, sm)
    print(json.dumps(table, indent=1) if args.json else format_table(table))
    return 0


def add_study_parser(study_subparsers) -> None:
    """Register ``lvcore study geometry-operators``."""
    p = study_subparsers.add_parser("geometry-operators",
                                    help="Table 9.4: inter-operator vs PCA reconstruction error (SYNTHETIC)")
    p.add_argument("--json", action="store_true", help="print the table as JSON")
    p.add_argument("--model", default=None, help="shape model (.json/.npz); default the bundled SYNTHETIC one")
    p.add_argument("--cohort", default=None, help="cohort directory; default the bundled lvcore/assets/cohort")
    p.set_defaults(func=_run)
