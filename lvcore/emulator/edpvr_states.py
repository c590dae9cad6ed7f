r"""The EDPVR emulator as a calibration emulator: ``(θ, h, EDP) -> [LVV, 24 strains]`` at any EDP of 1-30 mmHg.

The calibration emulators over PC scores stop at 8 mmHg (``chapter``) or 14 mmHg (``angles``), so loaded states
at 20 or 30 mmHg could be calibrated only through a subject emulator, with a mesh. The EDPVR emulator
(:mod:`lvcore.emulator.edpvr`, FE load paths over the ``chapter`` space) predicts the whole load path's shape,
``log V(p)/V₀`` and the 24 regional strains in units of ``L₈ = log V₈/V₀``, with V₈ the ``chapter`` emulator's
LVV at 8 mmHg and V₀ the geometry's exact reference cavity. Composed, they give the 25 calibration outputs at any
pressure of the EDPVR emulator's box::

    V₀  = cavity of the shape model's LV at h (exact quadrature, linear-in-h mesh)
    L₈  = log(chapter(θ, h)[LVV] / V₀)
    LVV(p)     = V₀ · exp(L₈ · y_V(θ, h, p))
    strains(p) = L₈ · y_S(θ, h, p)

with ``y`` the EDPVR network's normalised outputs. :class:`EdpvrStateEmulator` is an
:class:`~lvcore.emulator.model.Emulator` (same inputs as ``chapter`` plus ``edp``; the same ``apply``, box
check and metadata), so ``lvcore calibrate --emulator edpvr`` takes several loaded states (one row per state, up to
30 mmHg) with a mesh's PC scores or ``--geometry infer``, and the hierarchical model takes it for a cohort.

Accuracy (BENCHMARKS.md, the EDPVR emulator against 64 held-out FE load paths): strain RMSE 0.0030 over all
pressures; ``log V/V₀`` RMSE 0.005-0.006 at 2.5-9 mmHg and 0.015-0.024 at 11-30 mmHg, i.e. 1.5-2.4 % of the
volume above 10 mmHg. That volume error is of the order of a 5 mL measurement sd at 150-250 mL, so states above
10 mmHg carry the emulator's error as well as the data's (docs/calibration.md).

It is loaded by :func:`lvcore.emulator.io.load_emulator` for a folder that holds an EDPVR emulator
(``edpvr.json``) instead of a calibration emulator's ``metadata.json``; the anchor emulator (``chapter``) is
loaded by its recorded name.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from lvcore.domain.outputs import EDP_NAME, THETA_NAMES
from lvcore.emulator.edpvr import cavity_volume_function
from lvcore.emulator.model import Emulator
from lvcore.exceptions import EmulatorError

#: Lowest EDP (mmHg) a calibration may ask of it: the lowest pressure of the training load paths (below it, the
#: held-out volume error grows to 1.6 % at 0.5 mmHg).
MIN_EDP_MMHG = 1.0


@dataclass(frozen=True, eq=False)
class EdpvrStateEmulator(Emulator):
    """The ``chapter`` emulator and the EDPVR emulator composed (module docstring).

    The fields of :class:`~lvcore.emulator.model.Emulator` describe the composed map (its inputs ``a, b, af, bf,
    h1..h5, edp``, their box, the fixed fibre angles, metadata with the training space and the held-out errors);
    ``network`` and the scalers are the EDPVR network's and are not used by :meth:`apply`.

    Attributes
    ----------
    edpvr : lvcore.emulator.edpvr.EdpvrEmulator
    anchor : lvcore.emulator.model.Emulator
        The emulator whose LVV at 8 mmHg anchors the curve (``chapter``).
    """

    edpvr: object = None
    anchor: object = None

    def __post_init__(self):
        if self.edpvr is None or self.anchor is None:
            raise EmulatorError("an EDPVR state emulator needs its EDPVR emulator and its anchor emulator")
        if tuple(self.anchor.input_names) != tuple(self.input_names[:-1]):
            raise EmulatorError(f"the anchor emulator '{self.anchor.name}' takes {list(self.anchor.input_names)}; "
                                f"the EDPVR emulator {list(self.input_names[:-1])} (plus {EDP_NAME})")
        object.__setattr__(self, "_apply", jax.jit(_composed_apply(self.edpvr, self.anchor)))
        # the compiled-sampler cache's key (lvcore.inference.compiled_samplers.emulator_fingerprint): both parts' arrays
        object.__setattr__(self, "_lvcore_fingerprint", _fingerprint(self.edpvr, self.anchor, self.lower, self.upper))

    @property
    def volume_log_sd(self):
        """The EDPVR emulator's held-out ``log V/V₀`` RMSE as a function of the pressure (mmHg)."""
        return self.edpvr.volume_log_sd


def _fingerprint(edpvr, anchor, lower, upper) -> str:
    import hashlib

    h = hashlib.sha1(b"EdpvrStateEmulator")
    arrays = [*edpvr.weights, *edpvr.biases, edpvr.x_mean, edpvr.x_sd, edpvr.y_mean, edpvr.y_sd, lower, upper,
              *(edpvr.geometry[k] for k in sorted(edpvr.geometry)), *jax.tree.leaves(anchor.network),
              anchor.x_mean, anchor.x_sd, anchor.y_mean, anchor.y_sd, anchor.lower, anchor.upper]
    for a in arrays:
        if hasattr(a, "shape") and hasattr(a, "dtype"):
            a = np.ascontiguousarray(np.asarray(a))
            h.update(f"{a.shape}{a.dtype}".encode() + a.tobytes())
    return h.hexdigest()


def _mlp(weights, biases):
    ws = [jnp.asarray(w) for w in weights]
    bs = [jnp.asarray(b) for b in biases]

    def net(z):
        for w, b in zip(ws[:-1], bs[:-1]):
            z = jnp.tanh(z @ w.T + b)
        return z @ ws[-1].T + bs[-1]

    return net


def _composed_apply(edpvr, anchor):
    net = _mlp(edpvr.weights, edpvr.biases)
    x_mean, x_sd = jnp.asarray(edpvr.x_mean), jnp.asarray(edpvr.x_sd)
    y_mean, y_sd = jnp.asarray(edpvr.y_mean), jnp.asarray(edpvr.y_sd)
    v0_of = cavity_volume_function(edpvr.geometry, jnp)
    n_theta = len(THETA_NAMES)
    anchor_apply = anchor.apply

    def apply(x):
        theta_h, p = x[..., :-1], x[..., -1:]
        v0 = v0_of(theta_h[..., n_theta:])
        l8 = jnp.log(anchor_apply(theta_h)[..., 0] / v0)
        safe = jnp.where(theta_h[..., :n_theta] > 0, theta_h[..., :n_theta], 1.0)
        z = jnp.concatenate([jnp.log(safe), theta_h[..., n_theta:], p], axis=-1)
        y = (net((z - x_mean) / x_sd) * y_sd + y_mean) * l8[..., None]
        y = jnp.where(p <= 0.0, 0.0, y)
        lvv = v0 * jnp.exp(y[..., 0])
        return jnp.concatenate([lvv[..., None], y[..., 2:]], axis=-1)

    return apply


def is_edpvr_folder(folder) -> bool:
    """True for a folder that holds an EDPVR emulator (``edpvr.json``) and no calibration emulator."""
    from lvcore.emulator.edpvr import METADATA_FILE

    folder = Path(folder)
    return (folder / METADATA_FILE).is_file() and not (folder / "metadata.json").is_file()


def load_state_emulator(folder) -> EdpvrStateEmulator:
    """The EDPVR emulator in ``folder`` composed with its anchor emulator, as a calibration emulator.

    Raises
    ------
    EmulatorError
        The folder's EDPVR emulator or its anchor cannot be read, or their inputs differ.
    """
    from lvcore.core.space import ParameterSpace
    from lvcore.emulator import edpvr as ev
    from lvcore.emulator.io import load_emulator, resolve_emulator_dir
    from lvcore.emulator.network import from_arrays

    emu = ev.load_edpvr_emulator(Path(folder))
    anchor_name = (emu.metadata.get("anchor") or {}).get("emulator", ev.ANCHOR_EMULATOR)
    if not isinstance(anchor_name, str) or not anchor_name or is_edpvr_folder(resolve_emulator_dir(anchor_name)):
        raise EmulatorError(f"EDPVR emulator '{folder}': its anchor {anchor_name!r} must name a calibration emulator "
                            f"such as '{ev.ANCHOR_EMULATOR}'")
    anchor = load_emulator(anchor_name)
    if anchor.prior is not None:
        raise EmulatorError(f"the anchor emulator '{anchor_name}' has a prior mean; an EDPVR emulator needs a plain one")
    lower, upper = np.array(emu.lower, float), np.array(emu.upper, float)
    lower[-1] = max(lower[-1], MIN_EDP_MMHG)
    try:
        space = _space_with_pressure(emu, lower[-1], upper[-1])
        ParameterSpace.from_dict(space)   # checked now: the emulator's base and resolution are read from it
        arrays = {}
        for i, (w, b) in enumerate(zip(emu.weights, emu.biases)):
            arrays[f"layer{i}_weight"], arrays[f"layer{i}_bias"] = w, b
        network = from_arrays(arrays)
    except EmulatorError:
        raise
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as err:
        raise EmulatorError(f"EDPVR emulator '{folder}': its recorded training space or network is malformed "
                            f"({type(err).__name__}: {str(err)[:200]})") from None
    n_out = 1 + (len(ev.OUTPUT_NAMES) - 2)
    meta = {"source": {**dict(emu.metadata.get("source") or {}), "space": space, "resolution": [emu.resolution]},
            "strain_layer": anchor.strain_layer, "test": emu.metadata.get("test"),
            "composed_of": {"edpvr": emu.name, "anchor": anchor_name},
            "description": "the EDPVR emulator composed with its anchor: LVV and strains at any EDP of "
                           f"{lower[-1]:g}-{upper[-1]:g} mmHg (lvcore.emulator.edpvr_states)"}
    return EdpvrStateEmulator(
        name=emu.name, input_names=ev.INPUT_NAMES, lower=lower, upper=upper,
        log_inputs=tuple(n in THETA_NAMES for n in ev.INPUT_NAMES), x_mean=np.asarray(emu.x_mean, float),
        x_sd=np.asarray(emu.x_sd, float), y_mean=np.ones(n_out), y_sd=np.ones(n_out), network=network,
        fixed=dict(emu.fixed), metadata=meta, edpvr=emu, anchor=anchor)


def _space_with_pressure(emu, lo: float, hi: float) -> dict:
    """The EDPVR emulator's training space (the anchor's, recorded in its source) with the EDP varied."""
    space = json.loads(json.dumps((emu.metadata.get("source") or {}).get("space") or {}))
    if not isinstance(space, dict) or not space:
        raise EmulatorError(f"EDPVR emulator '{emu.name}': its metadata does not record its training space")
    params = [p for p in space.get("parameters", []) if p.get("name") != EDP_NAME]
    space["parameters"] = params + [{"name": EDP_NAME, "lower": float(lo), "upper": float(hi), "scale": "linear"}]
    space["fixed"] = {n: v for n, v in dict(space.get("fixed") or {}).items() if n != EDP_NAME}
    space["name"] = f"{space.get('name', 'chapter')}+{EDP_NAME}"
    return space


__all__ = ["EdpvrStateEmulator", "MIN_EDP_MMHG", "is_edpvr_folder", "load_state_emulator"]
