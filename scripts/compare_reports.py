"""Compare two ``lvcore report`` folders item by item from their manifest.json (a refactor's before/after check).

For every item: present in both, same status, and the same data (CSV: the
same values column by column, compared by position when the headers were
renamed, floats to ``--rtol``; JSON: equal after the same float tolerance).
Prints one line per item and exits 1 when an item is missing from one side or
its status differs.

Usage: python scripts/compare_reports.py BEFORE_DIR AFTER_DIR [--rtol 1e-9]
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path


def _close(a, b, rtol: float) -> bool:
    if isinstance(a, bool) or isinstance(b, bool):
        return a == b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        if math.isnan(a) and math.isnan(b):
            return True
        return math.isclose(a, b, rel_tol=rtol, abs_tol=1e-300)
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_close(a[k], b[k], rtol) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_close(x, y, rtol) for x, y in zip(a, b))
    return a == b


def compare_data(before: Path, after: Path, rtol: float) -> str:
    """'same', 'same values, columns renamed: ...' or what differs."""
    import numpy as np
    import pandas as pd

    if before.suffix != after.suffix:
        return f"format changed ({before.suffix} -> {after.suffix})"
    if before.suffix == ".json":
        a, b = json.loads(before.read_text()), json.loads(after.read_text())
        return "same" if _close(a, b, rtol) else "JSON differs"
    a, b = pd.read_csv(before), pd.read_csv(after)
    if a.shape != b.shape:
        return f"shape {a.shape} -> {b.shape}"
    diffs = []
    for (ca, sa), (cb, sb) in zip(a.items(), b.items()):
        if pd.api.types.is_numeric_dtype(sa) and pd.api.types.is_numeric_dtype(sb):
            ok = np.allclose(sa.to_numpy(float), sb.to_numpy(float), rtol=rtol, atol=0, equal_nan=True)
        else:
            ok = sa.astype(str).tolist() == sb.astype(str).tolist()
        if not ok:
            diffs.append(f"values of '{ca}'" + ("" if ca == cb else f"/'{cb}'"))
    renamed = [f"{ca}->{cb}" for ca, cb in zip(a.columns, b.columns) if ca != cb]
    if diffs:
        return "differs: " + ", ".join(diffs) + (f" (renamed {', '.join(renamed)})" if renamed else "")
    return "same" + (f" values, columns renamed: {', '.join(renamed)}" if renamed else "")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--rtol", type=float, default=1e-9, help="relative tolerance of float data (default 1e-9)")
    args = ap.parse_args(argv)
    mb = {f["name"]: f for f in json.loads((args.before / "manifest.json").read_text())["figures"]}
    ma = {f["name"]: f for f in json.loads((args.after / "manifest.json").read_text())["figures"]}
    bad = 0
    print(f"{'item':34s} {'status':9s} {'title':6s} data")
    for name in list(mb) + [n for n in ma if n not in mb]:
        fb, fa = mb.get(name), ma.get(name)
        if fb is None or fa is None:
            print(f"{name:34s} only in {'after' if fb is None else 'before'}")
            bad += 1
            continue
        status = fb["status"] if fb["status"] == fa["status"] else f"{fb['status']}->{fa['status']}"
        bad += fb["status"] != fa["status"]
        title = "same" if fb["title"] == fa["title"] else "new"
        if fb.get("data") and fa.get("data"):
            data = compare_data(args.before / fb["data"], args.after / fa["data"], args.rtol)
        else:
            data = "none" if not (fb.get("data") or fa.get("data")) else "data only on one side"
        print(f"{name:34s} {status:9s} {title:6s} {data}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
