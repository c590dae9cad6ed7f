"""Draw lvcore's 6 x 4 strain grid next to the AHA 16-segment bull's-eye (docs/figures/segments.png).

Both panels are drawn as seen from the base (lvcore's convention: phi counter-clockwise
from +x, the septal centre), rings from base (outside) to apex (inside). Each lvcore
region is labelled with its index r = 6 * level + sector (1-based, as strain_01 ..
strain_24) and the AHA segment it takes (lvcore.inference.segments) at the given offset.

Usage::

    python scripts/plot_segments.py [--offset DEG] [--out docs/figures/segments.png]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Wedge

    from lvcore.inference.segments import AHA_NAMES, _aha_segment_ranges, aha_assignment

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--offset", type=float, default=0.0, help="lvcore angle of the septal centre (deg)")
    ap.add_argument("--out", default="docs/figures/segments.png")
    args = ap.parse_args(argv)

    assign = aha_assignment(args.offset)
    cmap = plt.get_cmap("tab20")
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.6))
    # lvcore: 4 rings (level 0 outermost), 6 sectors
    ax = axes[0]
    radii = [4.4, 3.6, 2.8, 2.0]  # outer radius of each level's ring (width 0.8)
    for r in range(24):
        level, sector = divmod(r, 6)
        a0 = 60.0 * sector
        ax.add_patch(Wedge((0, 0), radii[level], a0, a0 + 60, width=0.8, facecolor=cmap(assign[r] % 20),
                           edgecolor="k", alpha=0.55))
        ang = np.radians(a0 + 30)
        rad = radii[level] - 0.4
        ax.text(rad * np.cos(ang), rad * np.sin(ang), f"r{r + 1}\nAHA {assign[r] + 1}", ha="center",
                va="center", fontsize=6.5)
    ax.set_title(f"lvcore: 6 sectors x 4 levels (strain_01..24)\nlevel 0 basal (outer) .. 3 apical; "
                 f"AHA offset {args.offset:g}°", fontsize=9)
    # AHA: 3 rings + cap, drawn in the same frame (septal centre at offset)
    ax = axes[1]
    ring = {0: 4.4, 1: 3.4, 2: 2.4}
    for j, (lvl, a, b) in enumerate(_aha_segment_ranges()):
        r_out = ring[lvl]
        ax.add_patch(Wedge((0, 0), r_out, a + args.offset, b + args.offset, width=1, facecolor=cmap(j % 20),
                           edgecolor="k", alpha=0.55))
        ang = np.radians(0.5 * (a + b) + args.offset)
        rad = r_out - 0.5
        name = AHA_NAMES[j].split(" ", 1)[1]
        ax.text(rad * np.cos(ang), rad * np.sin(ang), f"{j + 1}\n{name}", ha="center", va="center", fontsize=6.5)
    ax.add_patch(plt.Circle((0, 0), 1.4, facecolor="0.85", edgecolor="k"))
    ax.text(0, 0, "17\napex\n(unused)", ha="center", va="center", fontsize=7)
    ax.set_title("AHA 17 segments (Cerqueira et al. 2002)\nbasal 1-6, mid 7-12, apical 13-16", fontsize=9)
    for ax in axes:
        ax.set_xlim(-5.0, 5.0)
        ax.set_ylim(-5.0, 5.0)
        ax.set_aspect("equal")
        ax.axis("off")
        ax.annotate("", xy=(5.0, 0), xytext=(4.4, 0), arrowprops={"arrowstyle": "->"})
        ax.text(4.9, -0.3, "+x\n(septal\ncentre)", fontsize=7, ha="center", va="top")
        ax.text(0, 4.6, "+y (anterior)", fontsize=7, ha="center")
    fig.suptitle("Strain segments seen from the base (phi counter-clockwise); colours = AHA segment", fontsize=10)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=85, bbox_inches="tight")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
