"""Peak memory of one solve against the mesh size: the data behind lvcore.safety.limits.BYTES_PER_ELEMENT.

Run one resolution per process (peak RSS is per process)::

    python benchmarks/limits_memory.py 12 8 2 3     # n_circ n_long n_trans transmural_gauss_points
    python benchmarks/limits_memory.py 24 8 2 3

and take the difference of the two peaks over the difference of the element
counts. Measured on the 2-core dev machine (docs/reliability.md): 12 x 8 x 2
(192 elements) 665 MB, 24 x 8 x 2 (384) 819 MB, i.e. 0.8 MB per element.
"""
from __future__ import annotations

import json
import resource
import sys
import time


def main(argv=None) -> None:
    from lvcore.mechanics.case import Case
    from lvcore.mechanics.simulate import simulate

    nc, nl, nt, gp = (int(v) for v in (argv or sys.argv[1:5]))
    case = Case.from_dict({
        "geometry": {"kind": "default", "resolution": {"circumferential": nc, "longitudinal": nl, "transmural": nt,
                                                       "transmural_gauss_points": gp}},
        "material": {"law": "holzapfel-ogden", "a": 0.5, "b": 5, "af": 1.5, "bf": 5},
        "load": {"pressure": 8, "units": "mmHg"}})
    t0 = time.perf_counter()
    result = simulate(case)
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps({"elements": nc * nl * nt, "dofs": result.dofs, "gauss_points_through_wall": gp,
                      "peak_rss_mb": round(peak_mb, 1), "seconds": round(time.perf_counter() - t0, 1),
                      "converged": bool(result.converged)}))


if __name__ == "__main__":
    main()
