"""The My subject flow's download: the summary record, its one-page HTML and the zip
(:mod:`lvcore.app.subject_flow`)."""
from __future__ import annotations

import html
import io
import json
import tempfile
import zipfile
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from lvcore.app.subject_results import ModelRun, geometry_posterior, geometry_posterior_rows
from lvcore.exceptions import DataError
from lvcore.inference.request import CalibrationRequest as Prepared


def _geometry_record(geometry, prepared: Prepared) -> dict:
    """``lvcore calibrate``'s geometry record: a given geometry's (with its representation-error floor, or None)
    or an inferred one's (:meth:`lvcore.app.subject_prepare.InferredGeometry.record`)."""
    rec = geometry.record()
    if not prepared.inferred:
        rec["representation_error"] = prepared.representation_error
    return rec


def summary_record(subject: str, y, geometry, prepared: Prepared, runs: Sequence[ModelRun],
                   settings: Mapping) -> dict:
    """Plain-data summary of a subject's run: inputs used, geometry, conditions, per-likelihood results and flags."""
    from lvcore.inference.diagnostics import banner_status

    models = {}
    for run in runs:
        # the convergence alone (the flags are listed once, under "flags"); the app's banner adds them (banner_status)
        level, text = banner_status(run.result.convergence)
        table = run.result.summary
        models[run.model] = {
            "convergence": text, "converged_cleanly": level == "success",
            "plausible": bool(run.check.plausible), "flags": list(run.check.flags),
            "verdict": run.check.record(),
            "wall_s": float(run.result.wall_s),
            "posterior": {str(k): {c: float(table.loc[k, c]) for c in table.columns
                                   if np.issubdtype(type(table.loc[k, c]), np.number)} for k in table.index},
        }
        if run.model == "discrepancy":  # the GP's kernel, as the run recorded it (lvcore calibrate's summary.json)
            models[run.model]["discrepancy_kernel"] = str(run.result.idata.attrs.get("discrepancy_kernel", "additive"))
        if prepared.inferred:
            models[run.model]["geometry_posterior"] = geometry_posterior(run, prepared)
    flagged = [m for m, r in models.items() if r["flags"] or not r["converged_cleanly"]]
    return {
        "subject": subject, "synthetic": str(subject).upper().startswith("SYNTHETIC"),
        "measured": {"lvv_ml": float(y[0]), "strains": [float(v) for v in np.asarray(y)[1:]]},
        "geometry": _geometry_record(geometry, prepared), "emulator": prepared.emulator_name,
        "conditions": {k: v for k, v in prepared.conditions.items() if k != "fixed"},
        "box": prepared.box, "warnings": list(prepared.warnings), "settings": dict(settings),
        "models": models, "flagged_models": flagged,
    }


def summary_html(summary: Mapping) -> str:
    """A one-page HTML summary of :func:`summary_record` (inputs, conditions, posterior table, flags)."""
    esc = html.escape
    rows = []
    for model, rec in summary["models"].items():
        for name, stats in rec["posterior"].items():
            cells = "".join(f"<td>{v:.4g}</td>" for v in stats.values())
            rows.append(f"<tr><td>{esc(model)}</td><td>{esc(name)}</td>{cells}</tr>")
    first = next(iter(summary["models"].values()), {"posterior": {}})
    columns = next(iter(first["posterior"].values()), {})
    from lvcore.app.tables import SUMMARY_COLUMNS  # q05/q95: "q05 (90 % equal-tailed interval)", as in the app

    head = "".join(f"<th>{esc(SUMMARY_COLUMNS.get(c, (c,))[0])}</th>" for c in columns)
    flags = [f"<li><b>{esc(m)}</b>: {esc(f)}</li>" for m, r in summary["models"].items() for f in r["flags"]]
    flags += [f"<li>{esc(w)}</li>" for w in summary["warnings"]]
    conv = "".join(f"<li><b>{esc(m)}</b>: {esc(r['convergence'])}</li>" for m, r in summary["models"].items())
    geo = summary["geometry"]
    cond = summary["conditions"]
    if geo["kind"] == "inferred":
        given = ", ".join(f"{k} {v:g}" for k, v in geo["measures"].items()) or "none (size and stiffness trade off)"
        geo_rows = []
        for model, rec in summary["models"].items():
            for row in geometry_posterior_rows(rec.get("geometry_posterior", {})):
                geo_rows.append(f"<tr><td>{esc(model)}</td><td>{esc(row['quantity'])} ({esc(row['unit'])})</td>"
                                f"<td>{row['median']:.4g}</td><td>{row['5 %']:.4g}</td><td>{row['95 %']:.4g}</td>"
                                f"<td>{'' if row['measured'] is None else format(row['measured'], '.4g')}</td></tr>")
        geometry_text = (f"<p>Geometry: inferred (no mesh): PC scores h and scale s sampled with &theta; "
                         f"(lvcore calibrate --geometry infer); geometric measures given: {esc(given)}.</p>"
                         "<table><tr><th>likelihood</th><th>quantity</th><th>median</th><th>q05 (90 % equal-tailed "
                         "interval)</th><th>q95 (90 % equal-tailed interval)</th>"
                         f"<th>measured</th></tr>{''.join(geo_rows)}</table>")
    elif geo["kind"] == "subject-emulator":
        geometry_text = (f"<p>Geometry: bound into the subject-specific emulator, built on "
                         f"{esc(Path(str(geo['source'])).name)} as it is (no PC projection).</p>")
    else:
        geometry_text = (f"<p>Geometry: {esc(geo['kind'])} from {esc(Path(str(geo['source'])).name)}; PC scores "
                         f"{esc(', '.join(f'{v:.2f}' for v in geo['scores']))}; scale s = {geo['scale']:.3f} "
                         "(emulated LVV &times; s&sup3;).</p>")
    label = " (SYNTHETIC data: generated, not a real subject)" if summary["synthetic"] else ""
    from lvcore.app.freshness import readable  # yes/no, – and none: never null/None/{} (settings.json keeps JSON)

    settings_rows = "".join(f"<tr><td>{esc(str(k))}</td><td>{esc(readable(v))}</td></tr>"
                            for k, v in summary["settings"].items())
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>{esc(summary['subject'])}: calibration</title>
<style>body{{font-family:sans-serif;max-width:60em;margin:2em auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #bbb;padding:2px 6px;text-align:right}}td:first-child,td:nth-child(2){{text-align:left}}</style>
</head><body><h1>Calibration of {esc(summary['subject'])}{esc(label)}</h1>
<p>Measured LVV {summary['measured']['lvv_ml']:.1f} mL; strains {min(summary['measured']['strains']):.3f} to
{max(summary['measured']['strains']):.3f}.</p>
{geometry_text}
<p>Emulator {esc(summary['emulator'])}; EDP {cond['edp_mmhg']:.2f} mmHg; fibre angles
{cond['alpha_endo']:.0f}&deg; / {cond['alpha_epi']:.0f}&deg;.</p>
<h2>Verdict</h2><p>{'Flagged: ' + esc(', '.join(summary['flagged_models'])) if summary['flagged_models']
                      else 'No flags: every likelihood converged and the data look plausible for it.'}</p>
<ul>{''.join(flags) or '<li>no warnings</li>'}</ul>
<h2>Convergence</h2><ul>{conv}</ul>
<h2>Posterior</h2><table><tr><th>likelihood</th><th>parameter</th>{head}</tr>{''.join(rows)}</table>
<h2>Settings</h2><table>{settings_rows}</table>
</body></html>"""


def bundle(summary: Mapping, runs: Sequence[ModelRun], figures: Mapping[str, Any]) -> bytes:
    """The subject's download: a zip with ``<stem>_<model>.nc``, ``figures/<name>.html``,
    ``settings.json``, ``summary.json`` and ``summary.html``."""
    from lvcore.inference.calibrate import file_stem

    stem = file_stem(str(summary["subject"]))
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z, tempfile.TemporaryDirectory() as tmp:
        for run in runs:
            nc = Path(tmp) / f"{stem}_{run.model}.nc"
            run.result.idata.to_netcdf(str(nc))
            z.write(nc, nc.name)
        for name, fig in figures.items():
            z.writestr(f"figures/{name}.html", fig.to_html(include_plotlyjs=True, full_html=True))
        z.writestr("settings.json", json.dumps(summary["settings"], indent=1))
        z.writestr("summary.json", json.dumps(summary, indent=1, default=_plain))
        z.writestr("summary.html", summary_html(summary))
    return buf.getvalue()


def _plain(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise DataError(f"cannot write {type(value).__name__} to summary.json")
