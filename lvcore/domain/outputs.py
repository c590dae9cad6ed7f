"""The 25 simulator outputs, their order and names (shared by every layer).

``y[0]`` is the end-diastolic LV cavity volume (LVV, mL). ``y[1 + r]`` is the
circumferential Green strain (end diastole as reference, negative in filling)
of region ``r = 6 * level + sector`` (see :mod:`lvcore.geometry.template`):
level 0 is the most basal of four short-axis levels, sector 0 spans 0°–60°
counter-clockwise from +x seen from the base.
"""
from __future__ import annotations

import numpy as np

#: Circumferential sectors per short-axis level, short-axis levels, and regions (the template's region map,
#: :mod:`lvcore.geometry.template`, is built to these numbers).
N_SECTORS = 6
N_LEVELS = 4
N_REGIONS = N_SECTORS * N_LEVELS
N_OUTPUTS = 1 + N_REGIONS
LEVEL_NAMES = ("basal", "mid-basal", "mid-apical", "apical")
STRAIN_NAMES = tuple(f"E_cc L{level + 1} S{sector + 1}" for level in range(N_LEVELS) for sector in range(N_SECTORS))
OUTPUT_NAMES = ("LVV",) + STRAIN_NAMES
#: Column names used in CSV files (measured data, campaign stores, designs).
OUTPUT_COLUMNS = ("lvv_ml",) + tuple(f"strain_{r + 1:02d}" for r in range(N_REGIONS))

# One spelling per concept. The *input names* below name a model input wherever inputs are listed by name: emulator
# inputs and their metadata ("fixed"), campaign spaces, design and store columns, the inputs of
# lvcore.mechanics.case_inputs.build_case and a case file's material keys (af, bf). A *value with its unit* passed
# around in Python or written to a data file is named with the unit: ``edp_mmhg`` (a parameter, an attribute, the
# measured-data column, summary.json), like ``lvv_ml``. Users read ``a_f``/``b_f`` (DISPLAY_NAMES below); the CLI
# option is ``--edp`` (mmHg). The subscripted forms a_f, b_f, a_s, a_fs are the attributes of the Holzapfel–Ogden law
# only (lvcore.mechanics.materials: its math symbols; ``as`` cannot be a Python name).
#: Names of material parameters (kPa for a, af; dimensionless b, bf).
THETA_NAMES = ("a", "b", "af", "bf")
#: Names of physiological inputs: fibre angles (deg) and EDP (mmHg).
ANGLE_NAMES = ("alpha_endo", "alpha_epi")
#: The EDP's input name (mmHg); a pressure value passed as a parameter or written as a column is ``edp_mmhg``.
EDP_NAME = "edp"
#: How inputs are written wherever a user reads them (the θ sliders' labels too): a_f, b_f, α_endo, α_epi; other
#: names as they are (:func:`lvcore.viz.inference_figures.display_name`).
DISPLAY_NAMES = {"af": "a_f", "bf": "b_f", "alpha_endo": "α_endo", "alpha_epi": "α_epi"}
#: LV base boundary conditions (the case schema's ``boundary.base``; a campaign space's ``base``).
BASE_CONDITIONS = ("clamped", "sliding")

# The strain layer: which part of the wall the 24 regional strains are averaged over. The chapter does not say which
# layer its strains come from, so the layer is a condition of every simulation, store, emulator and data set; every
# layer's strain is the circumferential Green strain with end diastole as its reference (the early-diastolic,
# stress-free geometry is the simulator's reference configuration).
#: Strain layers by name -> transmural band ``(lo, hi)`` as fractions of the wall from the endocardium (t = 0) to
#: the epicardium (t = 1). ``mid_wall`` is the band of the same width as the halves centred on the mid-wall surface
#: t = 1/2, where tagging and feature-tracking analyses report "mid-wall" strain.
STRAIN_LAYERS = {"inner_half": (0.0, 0.5), "mid_wall": (0.25, 0.75), "whole_wall": (0.0, 1.0),
                 "outer_half": (0.5, 1.0)}
#: The layer of every simulation, campaign and emulator that does not name one (and of everything written before
#: the layer was recorded): the inner half of the wall.
DEFAULT_STRAIN_LAYER = "inner_half"
#: Old names still read (deprecated): ``endocardial`` is the inner half, ``wall`` the whole wall.
STRAIN_LAYER_ALIASES = {"endocardial": "inner_half", "wall": "whole_wall"}
#: How the layers are written for a reader.
STRAIN_LAYER_LABELS = {"inner_half": "inner half of the wall (t in [0, 1/2])",
                       "mid_wall": "mid-wall band (t in [1/4, 3/4])",
                       "whole_wall": "whole wall (t in [0, 1])", "outer_half": "outer half of the wall (t in [1/2, 1])"}


def strain_layer(name, where: str = "strain_layer") -> str:
    """The canonical name of a strain layer (:data:`STRAIN_LAYERS`); the deprecated aliases are accepted.

    Raises
    ------
    ValueError
        Naming ``where`` for anything else.

    Examples
    --------
    >>> strain_layer("endocardial"), strain_layer("whole_wall")
    ('inner_half', 'whole_wall')
    """
    key = name.strip().lower().replace("-", "_") if isinstance(name, str) else None
    key = STRAIN_LAYER_ALIASES.get(key, key)
    if key not in STRAIN_LAYERS:
        raise ValueError(f"{where}: strain layer must be one of {', '.join(STRAIN_LAYERS)} (or the deprecated "
                         f"{', '.join(STRAIN_LAYER_ALIASES)}), got {name!r}")
    return key


def strain_vector(values, where: str = "strains") -> np.ndarray:
    """The 24 regional strains (-) of ``values``: 24 strains, or 25 outputs whose first entry (LVV) is dropped.

    Raises
    ------
    ValueError
        Naming ``where`` when ``values`` holds neither 24 nor 25 numbers.
    """
    y = np.asarray(values, dtype=float).ravel()
    if y.size == N_REGIONS + 1:  # a full 25-output vector: drop LVV
        y = y[1:]
    if y.size != N_REGIONS:
        raise ValueError(f"{where}: expected {N_REGIONS} regional strains (or 25 outputs), got {y.size} values")
    return y


def strains_by_level(values) -> np.ndarray:
    """The 24 regional strains as a (4 levels, 6 sectors) array: row = level (basal first), column = sector."""
    return strain_vector(values).reshape(N_LEVELS, N_SECTORS)


def pc_names(k: int) -> tuple[str, ...]:
    """Names of the first ``k`` PCA shape scores: h1..hk."""
    return tuple(f"h{i + 1}" for i in range(k))


def is_pc_name(name) -> bool:
    """True for a PCA shape-score name ``h<k>`` (h1, h2, ...)."""
    name = str(name)
    return name.startswith("h") and name[1:].isdigit()
