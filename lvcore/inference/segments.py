"""Strain segment conventions: lvcore's 6 sectors x 4 levels and the AHA 17-segment model.

lvcore's grid
    Region ``r = 6 * level + sector`` (:mod:`lvcore.domain.outputs`): level 0 (basal)
    to 3 (apical) are the quarters of the base-to-apex parameter ``s``; sector
    ``k`` spans ``φ ∈ [60k, 60k + 60)`` degrees, ``φ`` measured counter-clockwise
    *seen from the base* from the template's +x axis, which a fit with a
    septum landmark points at the septum (:mod:`lvcore.geometry.fitting`).
    With the apex-to-base axis as +z and +x at the septum, +y points to the
    anterior wall, so sector 0 is antero-septal.

AHA (Cerqueira et al. 2002, Circulation 105:539)
    Basal 1-6 and mid 7-12: six 60° segments in the order anterior,
    anteroseptal, inferoseptal, inferior, inferolateral, anterolateral;
    apical 13-16: four 90° segments anterior, septal, inferior, lateral;
    17 the apical cap. The septum's centre is the boundary between segments
    2 and 3 (8 and 9), and the centre of apical segment 14.

Mapping (``offset`` = the lvcore angle ``φ``, in degrees, of the septum's centre
in the data; 0 when the geometry's +x points at the septal centre)
    * levels: lvcore level 0 takes AHA basal, levels 1 and 2 take AHA mid,
      level 3 takes AHA apical (the level holding each level's centre when
      the AHA thirds and lvcore's quarters share the base-to-apex length);
    * sectors: each lvcore region takes the AHA segment of its level that
      contains the region's angular centre ``φ_c = 60k + 30``. Every basal and
      mid segment holds exactly one sector centre (60° each), every apical
      segment one or two (90° each), for any offset;
    * segment 17 (apical cap) has no circumferential direction and is unused.

Hence AHA -> lvcore (:func:`aha_to_lvcore`) copies values, and lvcore -> AHA
(:func:`lvcore_to_aha`) averages the lvcore regions assigned to each segment;
the round trip AHA -> lvcore -> AHA is the identity for every offset, while
lvcore -> AHA -> lvcore is a projection (it averages level 1 with level 2 and
pairs of apical sectors).
"""
from __future__ import annotations

import numpy as np

from lvcore.exceptions import DataError
from lvcore.geometry.template import N_LEVELS, N_REGIONS, N_SECTORS

#: Segment conventions understood by ``--segments``.
CONVENTIONS = ("lvcore", "aha")
#: Number of AHA segments with a circumferential strain (17, the apical cap, has none).
N_AHA = 16
#: AHA segment names 1..16.
AHA_NAMES = (
    "basal anterior", "basal anteroseptal", "basal inferoseptal", "basal inferior", "basal inferolateral",
    "basal anterolateral",
    "mid anterior", "mid anteroseptal", "mid inferoseptal", "mid inferior", "mid inferolateral",
    "mid anterolateral",
    "apical anterior", "apical septal", "apical inferior", "apical lateral",
)
#: Column names of AHA strains in data files.
AHA_COLUMNS = tuple(f"aha_{i + 1:02d}" for i in range(N_AHA))
#: lvcore level -> AHA level (0 basal, 1 mid, 2 apical).
LEVEL_TO_AHA = (0, 1, 1, 2)


def _aha_segment_ranges() -> list[tuple[int, float, float]]:
    """(AHA level, start angle, end angle) of segments 1..16 in lvcore's φ with the septal centre at 0 (deg).

    φ grows counter-clockwise seen from the base, i.e. from the septum towards
    the anterior wall (AHA order 2 -> 1 -> 6 -> 5 -> 4 -> 3 for basal/mid).
    """
    out = []
    # basal/mid: segment 2 (anteroseptal) spans [0, 60), 1 anterior [60, 120), 6 [120, 180), 5 [180, 240),
    # 4 inferior [240, 300), 3 inferoseptal [300, 360)
    start = {1: 60.0, 2: 0.0, 3: 300.0, 4: 240.0, 5: 180.0, 6: 120.0}
    for lvl in (0, 1):
        for k in range(1, 7):
            out.append((lvl, start[k], start[k] + 60.0))
    # apical: 13 anterior [45, 135), 14 septal [-45, 45), 15 inferior [225, 315), 16 lateral [135, 225)
    for a in (45.0, -45.0, 225.0, 135.0):
        out.append((2, a, a + 90.0))
    return out


def _in_range(angle: float, start: float, end: float) -> bool:
    return (angle - start) % 360.0 < (end - start)


def aha_assignment(offset_deg: float = 0.0) -> np.ndarray:
    """AHA segment (0-based, 0..15) taken by each of lvcore's 24 regions.

    Parameters
    ----------
    offset_deg : float
        lvcore angle φ (deg, counter-clockwise seen from the base) of the
        septum's centre in the data.
    """
    if not np.isfinite(offset_deg):
        raise DataError(f"segment offset must be a finite angle in degrees, got {offset_deg}")
    ranges = _aha_segment_ranges()
    out = np.empty(N_REGIONS, dtype=np.int64)
    for r in range(N_REGIONS):
        level, sector = divmod(r, N_SECTORS)
        phi = (sector + 0.5) * 360.0 / N_SECTORS - offset_deg
        hits = [j for j, (lv, a, b) in enumerate(ranges) if lv == LEVEL_TO_AHA[level] and _in_range(phi, a, b)]
        if len(hits) != 1:  # pragma: no cover - impossible by construction
            raise AssertionError(f"region {r}: {len(hits)} AHA segments")
        out[r] = hits[0]
    return out


def aha_to_lvcore_matrix(offset_deg: float = 0.0) -> np.ndarray:
    """(24, 16) 0/1 matrix: ``lvcore_strains = M @ aha_strains``."""
    m = np.zeros((N_REGIONS, N_AHA))
    m[np.arange(N_REGIONS), aha_assignment(offset_deg)] = 1.0
    return m


def lvcore_to_aha_matrix(offset_deg: float = 0.0) -> np.ndarray:
    """(16, 24) averaging matrix: ``aha_strains = W @ lvcore_strains`` (rows sum to 1)."""
    m = aha_to_lvcore_matrix(offset_deg).T
    return m / m.sum(axis=1, keepdims=True)


def aha_to_lvcore(aha, offset_deg: float = 0.0) -> np.ndarray:
    """24 lvcore strains from 16 (or 17: the apical cap is dropped) AHA segment strains."""
    a = np.asarray(aha, dtype=float).reshape(-1)
    if a.size == N_AHA + 1:
        a = a[:N_AHA]
    if a.size != N_AHA:
        raise DataError(f"AHA strains: expected {N_AHA} segments (1-16; 17 optional and unused), got {a.size}")
    return aha_to_lvcore_matrix(offset_deg) @ a


def lvcore_to_aha(strains, offset_deg: float = 0.0) -> np.ndarray:
    """16 AHA segment strains (averages) from lvcore's 24 regional strains."""
    s = np.asarray(strains, dtype=float).reshape(-1)
    if s.size != N_REGIONS:
        raise DataError(f"lvcore strains: expected {N_REGIONS} regions, got {s.size}")
    return lvcore_to_aha_matrix(offset_deg) @ s


def rotate_lvcore(strains, offset_deg: float = 0.0) -> np.ndarray:
    """lvcore-layout strains whose sector 0 starts at ``offset_deg`` re-binned onto lvcore's sectors.

    Each lvcore region takes the data sector containing its angular centre
    (a 1:1 relabelling for every offset).
    """
    s = np.asarray(strains, dtype=float).reshape(-1)
    if s.size != N_REGIONS:
        raise DataError(f"lvcore strains: expected {N_REGIONS} regions, got {s.size}")
    if not np.isfinite(offset_deg):
        raise DataError(f"segment offset must be a finite angle in degrees, got {offset_deg}")
    width = 360.0 / N_SECTORS
    out = np.empty(N_REGIONS)
    for r in range(N_REGIONS):
        level, sector = divmod(r, N_SECTORS)
        k = int(np.floor((((sector + 0.5) * width - offset_deg) % 360.0) / width)) % N_SECTORS
        out[r] = s[N_SECTORS * level + k]
    return out


def to_lvcore(strains, convention: str = "lvcore", offset_deg: float = 0.0) -> np.ndarray:
    """Strains in ``convention`` (``lvcore``: 24 values; ``aha``: 16 or 17) as lvcore's 24 regions."""
    if convention == "lvcore":
        return rotate_lvcore(strains, offset_deg)
    if convention == "aha":
        return aha_to_lvcore(strains, offset_deg)
    raise DataError(f"segment convention '{convention}' not understood; use one of {', '.join(CONVENTIONS)}")


assert N_LEVELS == len(LEVEL_TO_AHA)

__all__ = ["CONVENTIONS", "N_AHA", "AHA_NAMES", "AHA_COLUMNS", "LEVEL_TO_AHA", "aha_assignment",
           "aha_to_lvcore_matrix", "lvcore_to_aha_matrix", "aha_to_lvcore", "lvcore_to_aha", "rotate_lvcore",
           "to_lvcore"]
