"""SYNTHETIC cohort: LV shapes, their MRI-like contour stacks and imitation operators.

Nothing here is patient data. Every stack and geometry generated here is
labelled SYNTHETIC (``synthetic: true`` in the JSON, "SYNTHETIC" in ids and
file names).

Shape family (early diastole, mm; ranges in ``docs/geometry.md``)
-----------------------------------------------------------------
In the LV frame (base plane z = 0, apex towards −z, septum at phi = 0) each
surface is a truncated ellipsoid of revolution deformed by

* an elliptical cross-section (ratio ``ell`` of the y to the x radius),
* septal flattening (radius reduced by ``flat`` · max(0, cos phi)^4),
* a regionally varying wall: septal/lateral thickness ratio, apical thinning,
* a bent long axis (apex displaced by ``bend`` mm in direction ``bend_dir``),
  which tilts the basal sections relative to the base–apex line,
* smooth random radial perturbations (Fourier modes in phi times Chebyshev
  polynomials along the axis) with decaying amplitudes, independently for endo-
  and epicardium, giving the shape population a long spectral tail.

Samples whose cavity volume falls outside :data:`VOLUME_RANGE_ML` are redrawn.

Contour stacks mimic cine short-axis stacks (slice spacing ``spacing`` mm,
default 10: 8 mm slices + 2 mm gap, Kramer et al. 2020 SCMR protocols) plus
2- and 4-chamber long-axis contours, placed in a random scanner pose.

Operators (:class:`OperatorStyle`) err the way segmentations err: a systematic
endocardial offset (tracing through or around trabeculae), a systematic
epicardial offset, the level of the basal contour (partial-volume choice of
the base, ``base_offset_mm``), smooth per-contour noise (low Fourier modes)
with small in-plane slice shifts, and optionally a motion-correction error:
a block of slices shifted in plane by a few mm.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from lvcore.exceptions import GeometryError
from lvcore.geometry.contours import ContourSlice, ContourStack, LongAxisContour, validate_contours
from lvcore.resources import asset_path

#: Early-diastolic cavity volumes accepted for synthetic LVs (mL).
VOLUME_RANGE_ML = (60.0, 110.0)
#: Default short-axis slice spacing (mm).
DEFAULT_SPACING = 10.0
_N_M, _N_K = 4, 3  # perturbation: Fourier orders 1..4 (+ m = 0), Chebyshev 0..2


@dataclass(frozen=True)
class SyntheticLV:
    """Parameters of one synthetic LV shape (mm, rad)."""

    a: float  # endocardial equatorial radius along x (septal-lateral)
    ell: float  # y/x radius ratio of the cross-section
    c: float  # endocardial semi-long axis
    hb: float  # base plane height above the ellipsoid centre
    wall: float  # mean equatorial wall thickness
    wall_sep: float  # relative septal (phi = 0) minus lateral thickness variation
    wall_apex: float  # apical wall thickness / equatorial wall thickness
    flat: float  # septal flattening fraction
    bend: float  # apex displacement off the base-apex line (mm)
    bend_dir: float  # direction of that displacement (rad)
    pert_endo: np.ndarray = field(default_factory=lambda: np.zeros((2, _N_M + 1, _N_K)))
    pert_epi: np.ndarray = field(default_factory=lambda: np.zeros((2, _N_M + 1, _N_K)))

    # ------------------------------------------------------------------ surfaces
    @property
    def zc(self) -> float:
        return -self.hb

    def c_of(self, surface: str) -> float:
        return self.c if surface == "endo" else self.c + self.wall * self.wall_apex

    def _pert(self, surface, phi, u):
        P = self.pert_endo if surface == "endo" else self.pert_epi
        m = np.arange(_N_M + 1)
        cheb = np.polynomial.chebyshev.chebvander(np.clip(u, -1, 1), _N_K - 1)  # (..., K)
        cm = np.cos(m * phi[..., None])
        sm = np.sin(m * phi[..., None])
        return np.einsum("...m,mk,...k->...", cm, P[0], cheb) + np.einsum("...m,mk,...k->...", sm, P[1], cheb)

    def _a_of(self, surface, phi):
        b = self.a * self.ell
        r = self.a * b / np.sqrt((b * np.cos(phi)) ** 2 + (self.a * np.sin(phi)) ** 2)
        r = r * (1.0 - self.flat * np.maximum(0.0, np.cos(phi)) ** 4)
        if surface == "epi":
            r = r + self.wall * (1.0 + self.wall_sep * np.cos(phi))
        return r

    def centre_offset(self, z):
        """In-plane position of the (bent) axis at height z (mm)."""
        L = self.c_of("epi") + self.hb
        w = (np.minimum(np.asarray(z, float), 0.0) / L) ** 2
        return self.bend * w[..., None] * np.array([np.cos(self.bend_dir), np.sin(self.bend_dir)])

    def point(self, surface: str, phi, psi) -> np.ndarray:
        """Surface point at azimuth phi and ellipsoidal polar angle psi from the apex (mm)."""
        phi, psi = np.broadcast_arrays(np.asarray(phi, float), np.asarray(psi, float))
        cs = self.c_of(surface)
        z = self.zc - cs * np.cos(psi)
        u = (z - self.zc) / cs
        r = self._a_of(surface, phi) * np.sin(psi) * (1.0 + self._pert(surface, phi, u))
        off = self.centre_offset(z)
        return np.stack([off[..., 0] + r * np.cos(phi), off[..., 1] + r * np.sin(phi), z], axis=-1)

    def ring(self, surface: str, z: float, n: int = 48, radial_offset=0.0) -> np.ndarray:
        """Closed short-axis contour of a surface at height z (n, 3)."""
        cs = self.c_of(surface)
        psi = np.arccos(np.clip(-(z - self.zc) / cs, -1.0, 1.0))
        phi = np.linspace(0, 2 * np.pi, n, endpoint=False)
        x = self.point(surface, phi, psi)
        if np.any(radial_offset):
            off = self.centre_offset(z)
            d = x[:, :2] - off
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            x[:, :2] += np.asarray(radial_offset)[..., None] * d
        return x

    def apex_z(self, surface: str) -> float:
        return self.zc - self.c_of(surface)

    def cavity_volume_ml(self, n: int = 200) -> float:
        """Cavity volume below z = 0 by slice integration (mL)."""
        z = np.linspace(self.apex_z("endo"), 0.0, n)
        areas = []
        for zz in z:
            r = self.ring("endo", zz, 96)
            xy = r[:, :2]
            areas.append(0.5 * abs(np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1])))
        return float(np.trapezoid(areas, z) / 1000.0)


#: Relative amplitudes of the random radial perturbations (endo, epi) and their spectral decay exponent.
PERTURBATION = (0.04, 0.035)
PERTURBATION_DECAY = 1.0


def sample_lv(rng, perturbation=PERTURBATION, decay: float = PERTURBATION_DECAY) -> SyntheticLV:
    """Draw one SYNTHETIC LV with cavity volume in :data:`VOLUME_RANGE_ML`."""
    rng = np.random.default_rng(rng)
    m_fac = (1.0 + np.arange(_N_M + 1)) ** decay
    k_fac = (1.0 + np.arange(_N_K)) ** decay
    while True:
        amp = lambda scale: (rng.standard_normal((2, _N_M + 1, _N_K))  # noqa: E731
                             * scale / m_fac[None, :, None] / k_fac[None, None, :])
        pe, pp = amp(perturbation[0]), amp(perturbation[1])
        pe[1, 0] = pp[1, 0] = 0.0  # sin(0 phi) is void
        lv = SyntheticLV(
            a=rng.uniform(20.0, 27.0),
            ell=rng.uniform(0.85, 1.0),
            c=rng.uniform(58.0, 76.0),
            hb=rng.uniform(2.0, 16.0),
            wall=rng.uniform(7.5, 11.0),
            wall_sep=rng.uniform(-0.15, 0.15),
            wall_apex=rng.uniform(0.55, 0.9),
            flat=rng.uniform(0.0, 0.08),
            bend=rng.uniform(0.0, 6.0),
            bend_dir=rng.uniform(0, 2 * np.pi),
            pert_endo=pe,
            pert_epi=pp,
        )
        if VOLUME_RANGE_ML[0] <= lv.cavity_volume_ml(60) <= VOLUME_RANGE_ML[1]:
            return lv


@dataclass(frozen=True)
class OperatorStyle:
    """How one (imitation) operator segments (mm).

    endo_bias_mm : outward offset of the endocardial border (> 0: through the
        trabeculae, larger cavity; < 0: around them, smaller cavity).
    epi_bias_mm : outward offset of the epicardial border.
    base_offset_mm : level of the traced basal contour above the true base.
    noise_mm : SD of the smooth per-contour radial noise (Fourier modes 0..4).
    shift_mm : SD of the per-slice in-plane shift (breath-hold variation).
    motion_error_mm : in-plane shift of the apical half of the stack (a
        motion-correction error); 0 for none.
    basal_slices : whole-slice choice of the base: +1 includes one more slice
        above the true base, -1 drops the basal slice (not used by
        :data:`OPERATORS`: a whole 10 mm slice moves nodes by up to 10 mm, an
        order of magnitude beyond the chapter's operator differences; the
        realistic operators of :mod:`lvcore.geometry.operator_model` draw it
        per patient).
    apical_slices : whole-slice choice of the apex: +1 includes one more
        (partial-volume) slice below the usual last one when it still cuts
        the epicardium, -1 drops the most apical slice.
    trabecular_mm : depth (mm) by which the endocardial contour is pulled
        inwards over a local arc (trabeculae and papillary muscles counted as
        myocardium) on the slices it affects; 0 for none.
    trabecular_arc_deg : width of that arc (deg; raised-cosine profile), centred
        on the lateral wall (phi = 180 deg) ± 60 deg, drawn per slice.
    trabecular_share : probability that a slice with an endocardial contour is
        affected.
    registration : fraction of the scan's per-slice breath-hold shifts
        (``contour_stack(..., breath_hold=...)``) the operator removes by
        realigning the slices (0: traced as acquired, 1: fully corrected).
    """

    name: str
    endo_bias_mm: float = 0.0
    epi_bias_mm: float = 0.0
    base_offset_mm: float = 0.0
    noise_mm: float = 0.3
    shift_mm: float = 0.2
    motion_error_mm: float = 0.0
    basal_slices: int = 0
    apical_slices: int = 0
    trabecular_mm: float = 0.0
    trabecular_arc_deg: float = 90.0
    trabecular_share: float = 0.0
    registration: float = 0.0


#: The three imitation operators of the operator study (see docs/geometry.md).
OPERATORS = (
    OperatorStyle("op1", endo_bias_mm=0.0, epi_bias_mm=0.0, base_offset_mm=0.0, noise_mm=0.35, shift_mm=0.25),
    OperatorStyle("op2", endo_bias_mm=0.9, epi_bias_mm=0.5, base_offset_mm=-1.5, noise_mm=0.5, shift_mm=0.35),
    OperatorStyle("op3", endo_bias_mm=-0.2, epi_bias_mm=0.1, base_offset_mm=0.3, noise_mm=0.35, shift_mm=0.25),
)
#: A careful reference segmentation used for the training cohort and the volunteers.
REFERENCE_OPERATOR = OperatorStyle("ref", noise_mm=0.25, shift_mm=0.15)


def random_pose(rng) -> tuple[np.ndarray, np.ndarray]:
    """A random scanner rotation (3, 3) and translation (3,) (mm)."""
    rng = np.random.default_rng(rng)
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q, rng.normal(0.0, 30.0, 3)


def contour_stack(lv: SyntheticLV, operator: OperatorStyle = REFERENCE_OPERATOR, rng=None, patient: str = "",
                  spacing: float = DEFAULT_SPACING, n_points: int = 48, pose=None, jitter: float = 0.3,
                  breath_hold=None) -> ContourStack:
    """The SYNTHETIC contour stack an operator would draw of ``lv``.

    Parameters
    ----------
    lv : SyntheticLV
    operator : OperatorStyle
    rng : seed or Generator
    patient : str
        Patient id (prefixed "SYNTHETIC-" in the label if it is not already).
    spacing : float
        Short-axis slice spacing (mm).
    pose : (rotation, translation), optional
        Scanner pose; default random from ``rng``.
    jitter : float
        SD (mm) of the per-patient variation of the operator's biases.
    breath_hold : (n, 2) array, optional
        The scan's in-plane shift (mm) of each short-axis slice, shared by every
        operator who segments the same scan (:func:`breath_hold_shifts`). Row 0
        is the slice one spacing above the base level, row ``k + 1`` the slice
        ``k`` spacings below it (slices beyond the rows: the last row). Each
        operator keeps ``1 - registration`` of it. Default: none.
    """
    rng = np.random.default_rng(rng)
    R, t = pose if pose is not None else random_pose(rng)
    tf = lambda p: p @ R.T + t  # noqa: E731
    eb = operator.endo_bias_mm + jitter * rng.standard_normal()
    pb = operator.epi_bias_mm + jitter * rng.standard_normal()
    base = operator.base_offset_mm + jitter * rng.standard_normal()
    phi = np.linspace(0, 2 * np.pi, n_points, endpoint=False)

    def noise():
        m = np.arange(5)
        amp = operator.noise_mm * rng.standard_normal(5) / (1.0 + m)
        ph = rng.uniform(0, 2 * np.pi, 5)
        return np.sum(amp[:, None] * np.cos(m[:, None] * phi[None, :] + ph[:, None]), axis=0)

    levels = [0] + list(range(1, 40))  # slice level: k spacings below the base level
    zs = [base] + list(-spacing * np.arange(1, 40))
    if operator.basal_slices > 0:
        levels = list(range(-operator.basal_slices, 0)) + levels
        zs = [base + spacing * k for k in range(operator.basal_slices, 0, -1)] + zs
    elif operator.basal_slices < 0:
        levels, zs = levels[-operator.basal_slices:], zs[-operator.basal_slices:]
    z_epi_apex, z_endo_apex = lv.apex_z("epi"), lv.apex_z("endo")
    keep = [i for i, z in enumerate(zs) if z > z_epi_apex + 4.0]
    endo_floor = np.full(len(zs), z_endo_apex + 4.0)
    if operator.apical_slices > 0:  # partial-volume apical slices that still cut the epicardium (endo: the cavity)
        extra = [i for i in range(keep[-1] + 1, len(zs)) if zs[i] > z_epi_apex + 0.5][:operator.apical_slices]
        endo_floor[extra] = z_endo_apex + 1.0
        keep += extra
    elif operator.apical_slices < 0:
        keep = keep[:max(3, len(keep) + operator.apical_slices)]
    levels, zs, endo_floor = [levels[i] for i in keep], [zs[i] for i in keep], endo_floor[keep]
    n_slices = len(zs)
    motion_dir = rng.uniform(0, 2 * np.pi)
    bh = None if breath_hold is None else np.asarray(breath_hold, float).reshape(-1, 2)
    trabeculae = operator.trabecular_mm > 0 and operator.trabecular_share > 0
    slices = []
    for k, z in enumerate(zs):
        shift = operator.shift_mm * rng.standard_normal(2)
        if operator.motion_error_mm and k >= n_slices // 2:
            shift = shift + operator.motion_error_mm * np.array([np.cos(motion_dir), np.sin(motion_dir)])
        if bh is not None:
            shift = shift + (1.0 - operator.registration) * bh[min(max(levels[k] + 1, 0), len(bh) - 1)]
        epi = lv.ring("epi", z, n_points, radial_offset=pb + noise())
        epi[:, :2] += shift
        endo = None
        if z > endo_floor[k]:
            inward = 0.0
            if trabeculae and rng.random() < operator.trabecular_share:
                inward = operator.trabecular_mm * trabecular_profile(phi, np.pi + rng.uniform(-np.pi / 3, np.pi / 3),
                                                                     np.deg2rad(operator.trabecular_arc_deg))
            endo = lv.ring("endo", z, n_points, radial_offset=eb + noise() - inward)
            endo[:, :2] += shift
        slices.append(ContourSlice(epi=tf(epi), endo=None if endo is None else tf(endo), position=float(z)))
    # long axis: 4CH through septum (phi = 0) and lateral wall, 2CH at 90 degrees
    la = []
    for name, p0 in (("4CH", 0.0), ("2CH", np.pi / 2)):
        curves = {}
        for surf, bias in (("endo", eb), ("epi", pb)):
            cs = lv.c_of(surf)
            psi_top = np.arccos(np.clip(-(base - lv.zc) / cs, -1, 1))
            psi = np.linspace(0.0, psi_top, 40)
            side_a = lv.point(surf, np.full_like(psi, p0), psi)
            side_b = lv.point(surf, np.full_like(psi, p0 + np.pi), psi)
            pts = np.vstack([side_a[::-1], side_b[1:]])
            cen = lv.centre_offset(pts[:, 2])
            d = pts[:, :2] - cen
            nrm = np.linalg.norm(d, axis=1, keepdims=True)
            d = np.where(nrm > 1e-9, d / np.maximum(nrm, 1e-9), 0.0)
            pts[:, :2] += bias * d
            pts += operator.noise_mm * 0.5 * rng.standard_normal(3) * np.array([1, 1, 0.3])
            curves[surf] = tf(pts)
        la.append(LongAxisContour(name=name, endo=curves["endo"], epi=curves["epi"]))
    z_mid = 0.5 * zs[min(2, n_slices - 1)]
    sep = lv.ring("epi", z_mid, 4)[0]
    label = patient if patient.upper().startswith("SYNTHETIC") else f"SYNTHETIC-{patient}" if patient else "SYNTHETIC"
    stack = ContourStack(slices=tuple(slices), long_axis=tuple(la), patient=label, operator=operator.name,
                         synthetic=True, septum=tf(sep), source=f"{label} {operator.name}",
                         extra={"generator": "lvcore.geometry.cohort.contour_stack", "spacing_mm": spacing})
    return validate_contours(stack)


def trabecular_profile(phi, centre: float, arc: float) -> np.ndarray:
    """Raised-cosine bump over azimuth: 1 at ``centre``, 0 beyond ±arc/2 (rad); the trabecular pull's shape."""
    d = np.angle(np.exp(1j * (np.asarray(phi, float) - centre)))  # wrapped to (-pi, pi]
    return np.where(np.abs(d) < arc / 2, 0.5 * (1.0 + np.cos(2.0 * np.pi * d / arc)), 0.0)


def breath_hold_shifts(rng, sd_mm: float, n_levels: int = 42) -> np.ndarray:
    """A scan's per-slice in-plane breath-hold shifts (mm), ``(n_levels, 2)``, i.i.d. N(0, sd²) per axis.

    Rows as ``contour_stack``'s ``breath_hold``: row 0 one spacing above the base level, row k + 1 k spacings below.
    """
    return float(sd_mm) * np.random.default_rng(rng).standard_normal((int(n_levels), 2))


def with_motion_error(operator: OperatorStyle, shift_mm: float = 3.5) -> OperatorStyle:
    """The same operator with a motion-correction error of ``shift_mm``."""
    return replace(operator, motion_error_mm=shift_mm)


# ----------------------------------------------------------------------------- bundled assets
#: The bundled SYNTHETIC cohort (package data, ``assets/cohort``; written by ``scripts/build_cohort.py``).
COHORT_DIR = asset_path("cohort")
ROLE_TRAIN, ROLE_OPERATOR, ROLE_VOLUNTEER = "train", "operator-study", "volunteer"


@dataclass(frozen=True)
class Cohort:
    """The SYNTHETIC cohort's fitted geometries (mm) and metadata."""

    ids: tuple
    roles: tuple
    nodes: np.ndarray  # (n, n_nodes, 3)
    meta: dict

    def select(self, role: str) -> tuple[tuple, np.ndarray]:
        idx = [i for i, r in enumerate(self.roles) if r == role]
        return tuple(self.ids[i] for i in idx), self.nodes[idx]

    def geometry(self, pid: str) -> np.ndarray:
        if pid not in self.ids:
            raise GeometryError(f"unknown cohort id '{pid}'; known: {', '.join(self.ids[:5])}, ...")
        return self.nodes[self.ids.index(pid)]


@dataclass(frozen=True)
class OperatorGeometries:
    """The operator study's fitted geometries: ``nodes[p, o]`` is patient p by operator o (mm)."""

    patients: tuple
    operators: tuple
    nodes: np.ndarray  # (n_patients, n_operators, n_nodes, 3)
    fits: dict  # "<patient>/<operator>" -> FitResult.summary()
    meta: dict

    def contour_path(self, patient: str, operator: str) -> Path:
        """Path of the stored contour stack of a patient id (e.g. "SYNTHETIC-P01") and operator."""
        short = patient.replace("SYNTHETIC-", "").replace("SYNTHETIC_", "")
        return COHORT_DIR / "contours" / f"SYNTHETIC_{short}_{operator}.json"


def _load_npz_json(stem: Path):
    jpath, npath = stem.with_suffix(".json"), stem.with_suffix(".npz")
    if not jpath.exists() or not npath.exists():
        raise GeometryError(f"'{npath}' / '{jpath.name}' not found; build them with `python scripts/build_cohort.py`")
    meta = json.loads(jpath.read_text())
    from lvcore.safety import limits
    from lvcore.safety.headers import load_npz

    arrays = load_npz(npath, limits.MAX_SHAPE_MODEL_BYTES, "cohort arrays", GeometryError)
    return meta, arrays


def load_cohort(directory=None) -> Cohort:
    """Load the SYNTHETIC cohort built by ``scripts/build_cohort.py``."""
    d = Path(directory) if directory is not None else COHORT_DIR
    meta, arr = _load_npz_json(d / "SYNTHETIC_cohort")
    return Cohort(ids=tuple(meta["ids"]), roles=tuple(meta["roles"]), nodes=arr["nodes"].astype(float), meta=meta)


def load_operator_geometries(directory=None) -> OperatorGeometries:
    """Load the fitted operator-study geometries (6 SYNTHETIC patients × 3 imitation operators)."""
    d = Path(directory) if directory is not None else COHORT_DIR
    meta, arr = _load_npz_json(d / "SYNTHETIC_operators")
    return OperatorGeometries(patients=tuple(meta["patients"]), operators=tuple(meta["operators"]),
                              nodes=arr["nodes"].astype(float), fits=meta["fits"], meta=meta)
