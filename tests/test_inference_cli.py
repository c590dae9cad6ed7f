"""``lvcore calibrate`` option handling (lvcore.inference.cli): spellings, messages, scale records."""
from __future__ import annotations

import json

import numpy as np
import pytest

from lvcore.cli import main
from lvcore.exceptions import DataError


def test_volunteer_accepts_both_spellings():
    from lvcore.inference.cli import _volunteer
    from lvcore.resources import volunteer_files

    a = _volunteer("SYNTHETIC_HV1", volunteer_files)
    b = _volunteer("SYNTHETIC-HV1", volunteer_files)   # the data files' and the Studies page's spelling
    assert a.geometry == b.geometry and a.measured == b.measured
    with pytest.raises(DataError, match="--volunteer HV99"):
        _volunteer("HV99", volunteer_files)


def test_box_refusal_names_the_option_the_user_gave(tmp_path, capsys):
    """A bundled volunteer outside the box is refused naming --volunteer, not --geometry (never passed)."""
    code = main(["calibrate", "--volunteer", "SYNTHETIC-HV5", "--out", str(tmp_path / "o"), "--chains", "1",
                 "--warmup", "5", "--samples", "5"])
    err = capsys.readouterr().err
    assert code == 2
    assert "--volunteer SYNTHETIC-HV5" in err and "--geometry" not in err.split("allow-extrapolation")[0]


def test_every_bundled_volunteer_but_hv5_is_inside_the_box_once_size_normalised():
    """The default subject (HV1, h1 = 2.40 unscaled) lands inside the emulator's box with its scale."""
    from lvcore.inference.guards import resolve_geometry
    from lvcore.resources import volunteer_files

    g = resolve_geometry(str(volunteer_files("SYNTHETIC_HV1").geometry))
    assert g.unscaled_scores[0] > 2.0
    assert np.all(np.abs(g.h) <= 2.0) and 0.9 < g.scale < 1.0
    rec = g.record()
    assert rec["scale"] == pytest.approx(g.scale) and json.dumps(rec)
