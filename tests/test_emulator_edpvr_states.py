"""lvcore.emulator.edpvr_states: the EDPVR emulator composed with ``chapter`` as a calibration emulator at any EDP.

The composed ``apply`` (JAX) must equal the EDPVR path the derived quantities use (NumPy, checked against FE in
test_emulator_edpvr.py), agree with ``chapter`` at its 8 mmHg, rise with the pressure, be differentiable, and
load through :func:`lvcore.emulator.io.load_emulator` by name; a broken folder is refused with a clear error; a
loaded state at 20 mmHg is accepted through it where the ``angles`` emulator refuses it.
"""
import json
import shutil

import jax
import numpy as np
import pytest

from lvcore.domain.outputs import EDP_NAME, THETA_NAMES
from lvcore.emulator import edpvr
from lvcore.emulator.edpvr_states import EdpvrStateEmulator, MIN_EDP_MMHG
from lvcore.emulator.io import load_emulator
from lvcore.exceptions import EmulatorError

THETA = np.array([[0.6, 1.3, 1.0, 3.6], [2.0, 8.0, 0.4, 12.0], [0.15, 20.0, 3.0, 1.5]])
H = np.array([[0.5, -0.3, 0.2, 0.0, 0.1], [-1.2, 0.8, -0.5, 1.1, 0.3], [0.0, 0.0, 0.0, 0.0, 0.0]])


@pytest.fixture(scope="module")
def emu():
    return load_emulator("edpvr")


def _x(p):
    return np.c_[THETA, H, np.full(len(THETA), float(p))]


def test_it_loads_by_name_with_the_calibration_emulators_interface(emu):
    assert isinstance(emu, EdpvrStateEmulator)
    assert emu.input_names == THETA_NAMES + tuple(f"h{k}" for k in range(1, 6)) + (EDP_NAME,)
    assert emu.lower[-1] == MIN_EDP_MMHG and emu.upper[-1] == 30.0
    assert emu.fixed == {"alpha_endo": -60.0, "alpha_epi": 60.0}
    assert (emu.base, emu.resolution, emu.strain_layer, emu.is_subject) == ("sliding", "default", "inner_half", False)
    assert emu.training_space.names == emu.input_names
    assert np.asarray(emu.apply(_x(20.0))).shape == (3, 25)


@pytest.mark.parametrize("p", [5.0, 8.0, 20.0, 30.0])
def test_the_composed_volume_is_the_derived_edpvrs(emu, p):
    """The same numbers as :func:`lvcore.emulator.edpvr.emulated_load_path` (the derived EDPVR's, NumPy)."""
    draws = [{**dict(zip(THETA_NAMES, t)), "h": list(h), "scale": 1.0} for t, h in zip(THETA, H)]
    path = edpvr.emulated_load_path(edpvr.load_edpvr_emulator(), draws, edp_mmhg=p, pressures_mmhg=[5.0])
    lvv = np.asarray(emu.apply(_x(p)))[:, 0]
    np.testing.assert_allclose(lvv, path.volume_at_edp_ml, rtol=1e-9)


def test_at_8_mmhg_it_agrees_with_its_anchor(emu):
    """At the anchor's pressure the curve passes through ``chapter``'s LVV (the EDPVR network gives 1 there up to
    its training error) and the strains agree to well below σ_S = 0.03."""
    y, c = np.asarray(emu.apply(_x(8.0))), np.asarray(load_emulator("chapter").apply(np.c_[THETA, H]))
    np.testing.assert_allclose(y[:, 0], c[:, 0], rtol=0.01)
    assert np.max(np.abs(y[:, 1:] - c[:, 1:])) < 0.01


def test_the_volume_rises_with_the_pressure_and_strains_are_negative(emu):
    v = np.stack([np.asarray(emu.apply(_x(p)))[:, 0] for p in (2.0, 5.0, 10.0, 20.0, 30.0)])
    assert np.all(np.diff(v, axis=0) > 0)
    assert np.all(np.asarray(emu.apply(_x(20.0)))[:, 1:] < 0)   # the sign of the bundled emulators' strains


def test_gradients_are_finite(emu):
    g = jax.grad(lambda x: emu.apply(x)[0])(_x(20.0)[0])
    assert np.all(np.isfinite(np.asarray(g))) and np.asarray(g)[-1] > 0   # dV/dp > 0


def test_a_broken_edpvr_folder_is_refused(tmp_path):
    folder = tmp_path / "edpvr"
    shutil.copytree(edpvr.find_edpvr_emulator(), folder)
    meta = json.loads((folder / edpvr.METADATA_FILE).read_text())
    (folder / edpvr.METADATA_FILE).write_text(json.dumps({**meta, "format": "something-else"}))
    with pytest.raises(EmulatorError, match="not an lvcore-edpvr-emulator"):
        load_emulator(folder)
    (folder / edpvr.METADATA_FILE).write_text("{not json")
    with pytest.raises(EmulatorError, match="cannot read an EDPVR emulator"):
        load_emulator(folder)
    (folder / edpvr.METADATA_FILE).write_text(json.dumps({**meta, "anchor": {"emulator": "no-such-emulator"}}))
    with pytest.raises(EmulatorError, match="no-such-emulator"):
        load_emulator(folder)
    for anchor in ("edpvr", str(folder), 3):   # an EDPVR emulator cannot anchor itself (no endless loading)
        (folder / edpvr.METADATA_FILE).write_text(json.dumps({**meta, "anchor": {"emulator": anchor}}))
        with pytest.raises(EmulatorError, match="must name a calibration emulator"):
            load_emulator(folder)


def test_a_20_mmhg_state_is_accepted_through_it_and_refused_by_angles(tmp_path):
    """Two loaded states (8, 20 mmHg) with an inferred geometry: one forward model over both states through
    ``edpvr``; the ``angles`` emulator (EDP box 6-14 mmHg) refuses the 20 mmHg state."""
    from lvcore.inference.data import read_measurements
    from lvcore.inference.loaded_states import edp_box
    from lvcore.inference.request import INFER, build_request

    assert edp_box(load_emulator("edpvr")) == (MIN_EDP_MMHG, 30.0)
    strains = ",".join(["-0.2"] * 24)
    p = tmp_path / "states.csv"
    p.write_text("subject,edp_mmhg,lvv_ml," + ",".join(f"strain_{k:02d}" for k in range(1, 25))
                 + ",reference_volume_ml\n" + f"S1,8,150,{strains},80\nS1,20,180,{strains},80\n")
    (row,) = read_measurements(p)
    req = build_request(load_emulator("edpvr"), "edpvr", INFER, row=row)
    assert [s.edp_mmhg for s in req.forward.states] == [20.0]
    assert req.record()["conditions"]["edp_mmhg"] == 8.0 and "2 loaded states" in req.record()["forward"]
    with pytest.raises(EmulatorError, match="edp = 20"):
        build_request(load_emulator("angles"), "angles", INFER, row=row)


def test_its_fingerprint_covers_both_parts(emu):
    """Compiled samplers are cached by the emulator's fingerprint: another anchor or EDPVR network is another key."""
    import dataclasses

    from lvcore.inference.compiled_samplers import emulator_fingerprint

    fp = emulator_fingerprint(emu)
    again = load_emulator("edpvr")
    assert emulator_fingerprint(again) == fp
    e2 = dataclasses.replace(emu.edpvr, y_sd=emu.edpvr.y_sd * 1.01)
    assert emulator_fingerprint(dataclasses.replace(emu, edpvr=e2)) != fp
    a2 = dataclasses.replace(emu.anchor, y_mean=emu.anchor.y_mean + 1.0)
    assert emulator_fingerprint(dataclasses.replace(emu, anchor=a2)) != fp
