"""Small helpers shared by the optimisation studies (bo-fibres, operators): files, progress, figures, and the
command line (simulator options, comma lists, printing a result)."""
from __future__ import annotations

import contextlib
import json
import math
import os
import sys
import threading
import warnings
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from lvcore import cli_args

#: Seconds a study waits for one PNG export (kaleido starts Chromium) before it goes on with the HTML only.
PNG_TIMEOUT_S = 120.0
#: Tries of one PNG export before it is given up (the HTML is written either way).
PNG_ATTEMPTS = 2


def write_json_atomic(path, data: Any) -> Path:
    """Write ``data`` as JSON to ``path`` atomically (temporary file, then rename).

    A run killed mid-write leaves the previous file intact. NaN is written as
    ``NaN`` (Python's JSON dialect), so state files round-trip exactly.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    tmp.write_text(json.dumps(data, indent=1, allow_nan=True))
    os.replace(tmp, path)
    return path


def round_floats(obj, digits: int = 6):
    """Every float rounded to ``digits`` significant digits (the shipped file stays small)."""
    if isinstance(obj, float):
        return float(f"{obj:.{digits}g}")
    if isinstance(obj, dict):
        return {k: round_floats(v, digits) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [round_floats(v, digits) for v in obj]
    return obj


def clean(obj):
    """``obj`` with numpy scalars/arrays as Python values and non-finite floats as None (strict JSON)."""
    if isinstance(obj, dict):
        return {str(k): clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return clean(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    return obj


def progress_bar(total: int, desc: str, enabled: bool):
    """A tqdm bar on stderr (disabled: a bar that prints nothing)."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, disable=not enabled, file=sys.stderr, unit="eval", leave=False)


def save_figure(fig, stem: Path) -> list[str]:
    """Write a plotly figure as ``stem.html`` and, when kaleido works, ``stem.png``; returns the paths."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    html = stem.with_suffix(".html")
    fig.write_html(html, include_plotlyjs="cdn")
    paths = [str(html)]
    if os.environ.get("LVCORE_NO_PNG"):
        return paths
    png = stem.with_suffix(".png")
    done = threading.Event()

    def export():
        for _ in range(PNG_ATTEMPTS):   # a Chromium that fails to start once (a busy machine) gets a second try
            try:
                fig.write_image(png, width=1000, height=600)
                done.set()
                return
            except Exception:  # noqa: BLE001 - kaleido/Chrome missing or broken: HTML is the figure, PNG is optional
                continue

    # a hung Chrome (seen on a starved machine: kaleido blocked for 30+ min) must not hang the study:
    # the export runs in a daemon thread and is abandoned after PNG_TIMEOUT_S
    worker = threading.Thread(target=export, daemon=True, name=f"png-export-{stem.name}")
    worker.start()
    worker.join(PNG_TIMEOUT_S)
    if done.is_set():
        paths.append(str(png))
    elif worker.is_alive():
        warnings.warn(f"PNG export of {stem.name} gave no answer in {PNG_TIMEOUT_S:.0f} s (kaleido/Chromium); "
                      f"the HTML figure {html} is written, the PNG is not", RuntimeWarning, stacklevel=2)
    return paths


def percentile_bootstrap(values, stat=np.median, n_boot: int = 2000, seed: int = 0, level: float = 0.9) -> dict:
    """``{"value", "ci", "n"}``: ``stat(values, axis=...)`` and its percentile bootstrap CI, resampling the values
    themselves (vectorised; :func:`bootstrap_ci` resamples units through any Python statistic)."""
    v = np.asarray(values, dtype=float)
    rng = np.random.default_rng(seed)
    boots = stat(v[rng.integers(0, v.size, size=(n_boot, v.size))], axis=1)
    lo, hi = np.quantile(boots, [(1 - level) / 2, (1 + level) / 2])
    return {"value": float(stat(v)), "ci": [float(lo), float(hi)], "n": int(v.size)}


def bootstrap_ci(units, statistic, n_boot: int = 2000, seed: int = 0, level: float = 0.9) -> dict:
    """Percentile bootstrap over independent units (patients, volunteers) of any statistic.

    Parameters
    ----------
    units : sequence
        The independent units (e.g. patient ids); resampled with replacement.
    statistic : callable
        ``statistic(list_of_units) -> float`` (a resample may repeat a unit);
        NaN resamples (a statistic undefined on that resample) are dropped.
    n_boot, seed, level : int, int, float
        Resamples, their seed, and the CI's level (0.9: 5th to 95th percentile).

    Returns
    -------
    dict
        ``value`` (the statistic on ``units``), ``ci`` [low, high] (None when
        fewer than 2 units or no finite resample), ``n_units``, ``n_boot``, ``level``.
    """
    units = list(units)
    value = float(statistic(units)) if units else float("nan")
    ci = None
    if len(units) >= 2:
        rng = np.random.default_rng(seed)
        draws = rng.integers(0, len(units), size=(int(n_boot), len(units)))
        boots = np.array([statistic([units[i] for i in row]) for row in draws], dtype=float)
        boots = boots[np.isfinite(boots)]
        if boots.size:
            ci = [float(v) for v in np.quantile(boots, [(1 - level) / 2, (1 + level) / 2])]
    return {"value": value, "ci": ci, "n_units": len(units), "n_boot": int(n_boot), "level": float(level)}


def add_simulator_options(parser) -> None:
    """``--workers``, ``--scheduler`` and ``--resolution`` of a study command that runs the FE simulator."""
    parser.add_argument("--workers", type=cli_args.workers, default=1,
                        help="local worker processes for simulator batches, up to 4 per core (default 1)")
    parser.add_argument("--scheduler", default=None,
                        help="tcp://HOST:PORT of a Dask scheduler instead of local workers (default: none)")
    parser.add_argument("--resolution", default="default", help="simulator mesh preset (default 'default')")


def add_sampler_options(parser, *, chains: int, warmup: int, samples: int) -> None:
    """``--chains``, ``--warmup`` and ``--samples`` of a study command that runs ``lvcore calibrate``, with the
    study's defaults."""
    parser.add_argument("--chains", type=cli_args.int_in(1, 64), default=chains, help=f"MCMC chains (default {chains})")
    parser.add_argument("--warmup", type=cli_args.int_in(1, 1_000_000), default=warmup,
                        help=f"warm-up iterations per chain (default {warmup})")
    parser.add_argument("--samples", type=cli_args.int_in(1, 1_000_000), default=samples,
                        help=f"draws kept per chain (default {samples})")


def comma_list(text: str | None) -> list[str]:
    """The items of a comma-separated option, stripped, empty ones dropped (``" a,,b "`` -> ``["a", "b"]``)."""
    return [s.strip() for s in (text or "").split(",") if s.strip()]


def print_result(as_json: bool, payload: Mapping, text: Callable[[], str]) -> int:
    """Print a study command's result: ``payload`` as indented JSON with ``--json``, else ``text()``; exit code 0."""
    print(json.dumps(payload, indent=1) if as_json else text())
    return 0


def study_executor(workers: int, scheduler: str | None, *, local: bool = False):
    """A context manager giving the executor of a study's simulator batches (:func:`lvcore.execution.parallel.make_executor`,
    closed on leaving; pending tasks cancelled after an error), or None where the batches run in this process: one
    worker and no scheduler, or ``local`` (e.g. a test's own forward model)."""
    if local or not (scheduler or workers > 1):
        return contextlib.nullcontext()
    from lvcore.execution.parallel import make_executor

    return make_executor(workers=workers, scheduler=scheduler)
