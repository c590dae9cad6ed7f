"""Measured-data validation: every malformed input gets a DataError that says what to fix."""
import numpy as np
import pytest

from lvcore.exceptions import DataError
from lvcore.inference import data
from lvcore.domain.outputs import OUTPUT_COLUMNS


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


# --------------------------------------------------------------------------- readers: JSON, MATLAB, AHA segments
def test_mat_reader_one_and_many_subjects(tmp_path):
    import scipy.io

    from lvcore.inference.segments import aha_to_lvcore

    y = _good()
    p = tmp_path / "one.mat"
    scipy.io.savemat(p, {"lvv_ml": y[0], "strains": y[1:], "subject": "HV7"})
    (got,) = data.read_measurements(p)
    np.testing.assert_allclose(got.y, y)
    assert got.subject == "HV7" and got.source == str(p)
    # several subjects, one row each, AHA segments declared in the file, with an offset
    aha = np.linspace(-0.2, -0.08, 16)
    p2 = tmp_path / "many.mat"
    scipy.io.savemat(p2, {"lvv_ml": np.array([120.0, 150.0]), "strains": np.vstack([aha, aha + 0.01]),
                          "subject": np.array(["A", "B"], dtype=object), "segments": "aha",
                          "segment_offset_deg": 30.0})
    a, b = data.read_measurements(p2)
    assert (a.subject, b.subject) == ("A", "B")
    np.testing.assert_allclose(a.y, np.r_[120.0, aha_to_lvcore(aha, 30.0)])
    np.testing.assert_allclose(b.y[1:], aha_to_lvcore(aha + 0.01, 30.0))
    # the file's convention and --segments must agree
    with pytest.raises(DataError, match="--segments"):
        data.read_measurements(p2, segments="lvcore")


def test_mat_reader_errors(tmp_path):
    import scipy.io

    p = tmp_path / "bad.mat"
    scipy.io.savemat(p, {"volume": 130.0, "strains": np.full(24, -0.1)})
    with pytest.raises(DataError, match="'lvv_ml' not found.*volume"):
        data.read_measurements(p)
    scipy.io.savemat(p, {"lvv_ml": 130.0, "strains": np.full(20, -0.1)})
    with pytest.raises(DataError, match="20 strains"):
        data.read_measurements(p)
    scipy.io.savemat(p, {"lvv_ml": 130.0, "strains": np.full(16, -0.1)})
    with pytest.raises(DataError, match="--segments aha"):
        data.read_measurements(p)
    assert data.read_measurements(p, segments="aha")[0].y.shape == (25,)
    (tmp_path / "junk.mat").write_bytes(b"not a mat file at all" * 10)
    with pytest.raises(DataError, match="MATLAB"):
        data.read_measurements(tmp_path / "junk.mat")


def test_json_and_aha_csv_readers(tmp_path):
    import json

    from lvcore.inference.segments import AHA_COLUMNS, aha_to_lvcore

    y = _good()
    p = tmp_path / "m.json"
    p.write_text(json.dumps([{"subject": "S1", "lvv_ml": y[0], "strains": list(y[1:])},
                             {"lvv_ml": 140.0, "segments": "aha", "strains": [-0.1] * 16}]))
    a, b = data.read_measurements(p)
    np.testing.assert_allclose(a.y, y)
    assert b.subject == "row2" and np.allclose(b.y[1:], -0.1)
    aha = np.linspace(-0.2, -0.05, 16)
    c = tmp_path / "aha.csv"
    c.write_text("subject,lvv_ml," + ",".join(AHA_COLUMNS) + "\nV1,130," + ",".join(str(v) for v in aha) + "\n")
    (r,) = data.read_measurements(c, offset_deg=-20.0)
    assert r.subject == "V1"
    np.testing.assert_allclose(r.y, np.r_[130.0, aha_to_lvcore(aha, -20.0)])
    # the lvcore CSV path is unchanged
    np.testing.assert_allclose(data.read_measurements(_write(tmp_path, [y]))[0].y, y)
    with pytest.raises(DataError, match="unknown measured-data format"):
        data.read_measurements(tmp_path / "m.xlsx") if (tmp_path / "m.xlsx").write_text("x") else None


# ----------------------------------------------------------------------------- optional per-subject columns
def test_optional_columns_edp_and_geometric_measures(tmp_path):
    """edp_mmhg, reference_volume_ml, wall_volume_ml, long_axis_mm: CSV columns, JSON keys, .mat variables."""
    import json

    import scipy.io

    y = _good()
    header = "subject," + ",".join(OUTPUT_COLUMNS) + ",edp_mmhg,reference_volume_ml"
    p = tmp_path / "x.csv"
    p.write_text(header + "\nA," + ",".join(map(str, y)) + ",10.5,48\nB," + ",".join(map(str, y)) + ",,\n")
    a, b = data.read_measurements(p)
    assert a.edp_mmhg == 10.5 and a.measures == {"reference_volume_ml": 48.0}
    assert b.edp_mmhg is None and b.measures == {}
    np.testing.assert_allclose(a.y, y)
    j = tmp_path / "x.json"
    j.write_text(json.dumps({"subject": "J", "lvv_ml": y[0], "strains": list(y[1:]), "edp_mmhg": 12,
                             "long_axis_mm": 70}))
    (r,) = data.read_measurements(j)
    assert r.edp_mmhg == 12.0 and r.measures == {"long_axis_mm": 70.0}
    m = tmp_path / "x.mat"
    scipy.io.savemat(m, {"lvv_ml": [y[0], y[0]], "strains": np.stack([y[1:], y[1:]]), "edp_mmhg": [9.0, 11.0],
                         "wall_volume_ml": [100.0, 120.0]})
    r1, r2 = data.read_measurements(m)
    assert (r1.edp_mmhg, r2.edp_mmhg) == (9.0, 11.0) and r2.measures == {"wall_volume_ml": 120.0}


@pytest.mark.parametrize("col,value,match", [("edp_mmhg", "1.2", "edp_mmhg = 1.2 is outside"),
                                             ("edp_mmhg", "abc", "not a number"),
                                             ("reference_volume_ml", "0.05", "outside the plausible range"),
                                             ("long_axis_mm", "7", "long_axis_mm")])
def test_optional_columns_are_validated(tmp_path, col, value, match):
    p = tmp_path / "x.csv"
    p.write_text("subject," + ",".join(OUTPUT_COLUMNS) + f",{col}\nA," + ",".join(map(str, _good())) + f",{value}\n")
    with pytest.raises(DataError, match=match):
        data.read_measurements(p)
