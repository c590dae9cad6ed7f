"""Small helpers shared by the optimisation studies (bo-fibres, operators): files, progress, figures."""
from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np


def bundled_path(*parts: str) -> Path:
    """Path of a bundled data file (``lvcore/assets/...`` once installed as package data)."""
    from lvcore.resources import asset_path

    return asset_path(*parts)


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
    try:
        fig.write_image(stem.with_suffix(".png"), width=1000, height=600)
        paths.append(str(stem.with_suffix(".png")))
    except Exception:  # noqa: BLE001 - kaleido/Chrome missing or broken: HTML is the figure, PNG is optional
        pass
    return paths
