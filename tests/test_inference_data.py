"""Measured-data validation: every malformed input gets a DataError that says what to fix."""
import numpy as np
import pytest

from lvcore.exceptions import DataError
from lvcore.inference import data
from lvcore.outputs import OUTPUT_COLUMNS


def _good():
    rng = np.random.default_rng(0)
    return np.r_[135.0, -0.15 + 0.03 * rng.standard_normal(24)]


def _write(tmp_path, rows, header=True, subject=False, name="m.csv"):
    lines = []
    if header:
        lines.append(",".join((["subject"] if subject else []) + list(OUTPUT_COLUMNS)))
    for i, r in enumerate(rows):
        vals = [str(v) for v in r]
        lines.append(",".join(([f"HV{i + 1}"] if subject else []) + vals))
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def test_roundtrip_and_headerless(tmp_path):
    y = _good()
    p = data.write_measured_csv(tmp_path / "a.csv", [data.MeasuredData(y, "HV1")])
    got = data.read_measured_csv(p)
    assert len(got) == 1 and got[0].subject == "HV1"
    np.testing.assert_allclose(got[0].y, y, rtol=1e-7)
    got2 = data.read_measured_csv(_write(tmp_path, [y, y], header=False))
    assert len(got2) == 2 and got2[1].subject == "row2"


def test_wrong_column_count(tmp_path):
    y = _good()
    p = tmp_path / "short.csv"
    p.write_text(",".join(OUTPUT_COLUMNS[:24]) + "\n" + ",".join(map(str, y[:24])) + "\n")
    with pytest.raises(DataError, match="expected 25 data columns"):
        data.read_measured_csv(p)
    with pytest.raises(DataError, match="expected 25 columns"):
        data.read_measured_csv(_write(tmp_path, [y[:20]], header=False))


def test_wrong_column_names(tmp_path):
    p = tmp_path / "names.csv"
    names = list(OUTPUT_COLUMNS)
    names[0] = "EDV"
    p.write_text(",".join(names) + "\n" + ",".join(map(str, _good())) + "\n")
    with pytest.raises(DataError, match="'EDV' \\(expected 'lvv_ml'\\)"):
        data.read_measured_csv(p)


def test_nan(tmp_path):
    y = _good()
    y[5] = np.nan
    with pytest.raises(DataError, match="strain_05"):
        data.read_measured_csv(_write(tmp_path, [y]))
    p = tmp_path / "empty_cell.csv"
    p.write_text(",".join(OUTPUT_COLUMNS) + "\n" + ",".join(["135"] + [""] + ["-0.1"] * 23) + "\n")
    with pytest.raises(DataError, match="strain_01"):
        data.read_measured_csv(p)


def test_positive_strains_sign_convention(tmp_path):
    y = _good()
    y[1:] = -y[1:]
    with pytest.raises(DataError, match="Flip the sign"):
        data.read_measured_csv(_write(tmp_path, [y]))
    # a few positive values from noise are allowed
    y2 = _good()
    y2[1:3] = 0.01
    assert data.validate_measurements(y2)[1] == pytest.approx(0.01)


def test_percent_strains():
    y = _good()
    y[1:] *= 100
    with pytest.raises(DataError, match="percent"):
        data.validate_measurements(y)


@pytest.mark.parametrize("lvv, fix", [(1.35e-4, "multiply by 1e6"), (135000.0, "divide by 1000"),
                                      (0.135, "multiply by 1000"), (-5.0, "positive"), (900.0, "plausible range")])
def test_volume_units(lvv, fix):
    y = _good()
    y[0] = lvv
    with pytest.raises(DataError, match=fix):
        data.validate_measurements(y)


def test_non_numeric_and_missing_file(tmp_path):
    p = tmp_path / "text.csv"
    p.write_text(",".join(OUTPUT_COLUMNS) + "\n" + ",".join(["135"] + ["abc"] + ["-0.1"] * 23) + "\n")
    with pytest.raises(DataError, match="non-numeric.*strain_01"):
        data.read_measured_csv(p)
    with pytest.raises(DataError, match="does not exist"):
        data.read_measured_csv(tmp_path / "nope.csv")
