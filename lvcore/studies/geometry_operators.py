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


# ----------------------------------------------------------------------------- tables and figures
#: Figures and tables :func:`figures` draws, with their titles.
TITLES = {"table9_4_operators_pca": "Table 9.4: inter-operator vs k-mode PCA reconstruction error (cm²)",
          "fig_pca_vs_operators": "PCA reconstruction error vs k, main operator op1",
          "fig9_10_geometry_effect": "Fig 9.10: effect of the LV geometry on strains and LVV"}
#: Why a figure can be absent.
MISSING = {"fig9_10_geometry_effect": "the `chapter` emulator is not installed; build it with python "
                                      "scripts/build_emulators.py --emulators chapter"}


def geometry_effect(table: dict | None = None, theta=None, emulator: str = "chapter",
                    operator_geometries=None, shape_model=None) -> dict | None:
    """Fig 9.10's data: the emulator at one θ on each patient's geometry (first operator, 5-PC projection).

    Each geometry is size-normalised as ``lvcore calibrate`` does
    (:func:`lvcore.geometry.scaling.size_normalised_scores`): ``h`` is the
    projection of the geometry scaled to the shape model's mean reference
    cavity, ``scale`` the factor back to the patient's size, and the emulated
    LVV is multiplied by ``scale**3`` (:class:`lvcore.geometry.scaling.ScaledForward`;
    strains do not change with size). The emulator is then evaluated inside
    the box its scores were trained on, whatever the patient's size.

    Returns ``{"operator", "theta", "emulator", "rows": [{patient, operator, h1..h5, scale, lvv_ml,
    strain_01..strain_24}]}``, or None when the emulator is not installed.
    """
    from lvcore.domain import conditions, units
    from lvcore.emulator.io import available_emulators

    if emulator not in available_emulators():
        return None
    from lvcore.emulator.forward import load_emulator_forward
    from lvcore.geometry.cohort import load_operator_geometries
    from lvcore.geometry.scaling import ScaledForward, size_normalised_scores
    from lvcore.geometry.shape_model import load_shape_model

    og = operator_geometries or load_operator_geometries()
    sm = shape_model or load_shape_model()
    theta = dict(conditions.THETA_TILDE) if theta is None else dict(theta)
    op = og.operators[0]
    rows = []
    for p, pid in enumerate(og.patients):
        sc = size_normalised_scores(og.nodes[p, 0], 5, sm)
        y = np.asarray(ScaledForward(load_emulator_forward(emulator, sc.h), sc.scale)(theta), dtype=float)
        rows.append({"patient": pid, "operator": op, **{f"h{i + 1}": float(v) for i, v in enumerate(sc.h)},
                     "scale": float(sc.scale), "lvv_ml": float(y[0]),
                     **{f"strain_{k + 1:02d}": float(y[1 + k]) for k in range(24)}})
    return {"operator": op, "theta": theta, "emulator": emulator, "rows": rows}


def compute(emulator: str = "chapter") -> dict:
    """Everything :func:`figures` draws, computed from the bundled SYNTHETIC cohort (seconds).

    ``{"table": operator_table(...), "geometry_effect": geometry_effect(...) or None}``.
    """
    from lvcore.geometry.cohort import load_operator_geometries
    from lvcore.geometry.shape_model import load_shape_model

    og, sm = load_operator_geometries(), load_shape_model()
    table = operator_table(og, sm)
    return {"table": table, "geometry_effect": geometry_effect(table, emulator=emulator, operator_geometries=og,
                                                               shape_model=sm)}


def table94_frame(table: dict):
    """Table 9.4 as the chapter prints it (one row per main operator and patient, then the share rows) and its bold cells."""
    import pandas as pd

    ks = table["ks"]
    rows, bold = [], []
    for b in table["blocks"]:
        for r in b["rows"]:
            row = {"main": b["main"], "patient": r["patient"].replace("SYNTHETIC-", "")}
            for j, o in enumerate(b["others"]):
                row[f"test op {j + 1}"] = f"{o}: {r['operator_mse'][o]:.4f}"
            row.update({f"{k}PC": r["pca_mse"][str(k)] for k in ks})
            if r["first_k_beating_both"]:
                bold.append((len(rows), f"{r['first_k_beating_both']}PC"))
            rows.append(row)
    rows.append({"main": "share", "patient": "k beats both",
                 **{f"{k}PC": table["share_beating_both"][str(k)] for k in ks}})
    rows.append({"main": "chapter", "patient": "(real data)",
                 **{f"{k}PC": table["chapter_share"].get(str(k), float("nan")) for k in ks}})
    return pd.DataFrame(rows), bold


def tables(result: dict) -> dict:
    """The data of each figure by name: Table 9.4 (plain data), the first main operator's block, Fig 9.10's rows."""
    import pandas as pd

    table = result["table"]
    main = table["operators"][0]
    out = {"table9_4_operators_pca": table,
           "fig_pca_vs_operators": next(b for b in table["blocks"] if b["main"] == main)}
    if result.get("geometry_effect"):
        out["fig9_10_geometry_effect"] = pd.DataFrame(result["geometry_effect"]["rows"])
    return out


def captions(result: dict) -> dict:
    lo, hi = result["table"]["operator_mse_range"]
    return {"table9_4_operators_pca": f"operators differ by {lo:.4f}–{hi:.4f} cm² (chapter: 0.003–0.03 cm²)",
            "fig9_10_geometry_effect": "the emulator sees the geometry through 5 PC scores only; the FE simulator on "
                                       "the full geometries would show more spread"}


def figures(result: dict) -> dict:
    """Table 9.4 drawn as a table, the first main operator's error-vs-k plot, and Fig 9.10 (when computed)."""
    from lvcore.viz.geometry_views import operator_mse_figure
    from lvcore.viz.report_figures import strain_lines, table_figure

    table = result["table"]
    df, bold = table94_frame(table)
    out = {"table9_4_operators_pca": table_figure(
        df, title="Table 9.4 — SYNTHETIC cohort: mean squared node distance to the main operator's geometry (cm²); "
                  "bold: first k beating both operators", bold=bold)}
    main = table["operators"][0]
    fig = operator_mse_figure(table, main)
    fig.update_layout(title=f"Reconstruction error vs k, main operator {main} (SYNTHETIC cohort)")
    out["fig_pca_vs_operators"] = fig
    ge = result.get("geometry_effect")
    if ge:
        series = {f"{r['patient'].replace('SYNTHETIC-', '')} (EDV {r['lvv_ml']:.1f} mL)":
                  [r[f"strain_{k + 1:02d}"] for k in range(24)] for r in ge["rows"]}
        th = ", ".join(f"{k} {v:g}" for k, v in ge["theta"].items())
        out["fig9_10_geometry_effect"] = strain_lines(
            series, title=f"Fig 9.10 — SYNTHETIC patients ({ge['operator']}'s geometries, 5-PC projections): strains "
                          f"and EDV at the same θ ({th}), `{ge['emulator']}` emulator")
    return out


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


def source_line(result: dict) -> str:
    ge = result.get("geometry_effect")
    return ("bundled SYNTHETIC cohort and shape model"
            + (f"; Fig 9.10: `{ge['emulator']}` emulator on the 5-PC projections of the SYNTHETIC patients" if ge else ""))
