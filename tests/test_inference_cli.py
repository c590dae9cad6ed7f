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


def _csv(tmp_path, extra_header="", extra_values=""):
    from lvcore.domain.outputs import OUTPUT_COLUMNS
    from lvcore.resources import volunteer_files
    from lvcore.inference.data import read_measured_csv

    y = read_measured_csv(volunteer_files("SYNTHETIC_HV2").measured)[0].y
    p = tmp_path / "m.csv"
    p.write_text("subject," + ",".join(OUTPUT_COLUMNS) + extra_header + "\nS1," + ",".join(map(str, y))
                 + extra_values + "\n")
    return p


def test_data_edp_is_refused_by_a_fixed_edp_emulator(tmp_path, capsys):
    """edp_mmhg = 10 in the data with the 'chapter' emulator (trained at 8 mmHg): exit 2, naming the column."""
    p = _csv(tmp_path, ",edp_mmhg", ",10")
    code = main(["calibrate", "--data", str(p), "--geometry", "mean", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and "edp_mmhg = 10" in err and "'chapter'" in err and "angles" in err
    # the same EDP as the emulator's is fine up to the sampling (checked by the guard itself)
    from lvcore.emulator import load_emulator
    from lvcore.inference.guards import subject_edp as _subject_edp
    from lvcore.inference.data import read_measurements
    from lvcore.inference.guards import check_conditions

    emu = load_emulator("chapter")
    (row,) = read_measurements(_csv(tmp_path, ",edp_mmhg", ",8"))
    assert _subject_edp(row, check_conditions(emu), emu, "chapter", None) == 8.0
    angles = load_emulator("angles")
    (row,) = read_measurements(_csv(tmp_path, ",edp_mmhg", ",11.5"))
    assert _subject_edp(row, check_conditions(angles), angles, "angles", None) == 11.5
    with pytest.raises(DataError, match="disagree"):
        _subject_edp(row, check_conditions(angles), angles, "angles", 9.0)


def test_geometric_measures_need_geometry_infer(tmp_path, capsys):
    p = _csv(tmp_path)
    code = main(["calibrate", "--data", str(p), "--geometry", "mean", "--reference-volume", "50",
                 "--out", str(tmp_path / "o")])
    assert code == 2 and "--reference-volume" in capsys.readouterr().err
    code = main(["calibrate", "--data", str(p), "--geometry", "infer", "--reference-volume", "5000",
                 "--out", str(tmp_path / "o")])
    assert code == 2 and "reference_volume_ml = 5000" in capsys.readouterr().err


def test_default_emulator_is_one_for_cli_and_app():
    """The CLI's default emulator is the app sidebar's default (issue 27: 'chapter' vs 'angles' before)."""
    from lvcore.app import controls
    from lvcore.inference.cli import DEFAULT_EMULATOR

    assert controls.DEFAULT_EMULATOR == DEFAULT_EMULATOR == "chapter"


def test_default_subject_is_inside_the_default_emulators_box():
    from lvcore.app.controls import DEFAULT_SUBJECT
    from lvcore.emulator import load_emulator
    from lvcore.inference import guards
    from lvcore.inference.calibrate import read_pc_scores
    from lvcore.resources import volunteer_files

    emu = load_emulator("chapter")
    geo = volunteer_files(DEFAULT_SUBJECT).geometry
    cond = guards.check_conditions(emu)
    for h in (guards.resolve_geometry(str(geo)).h, read_pc_scores(geo)):   # size-normalised and as projected
        guards.check_inputs_in_box(guards.fixed_inputs(h, cond, emu), emu)   # raises outside


def test_geometry_infer_without_a_measure_warns_that_size_and_stiffness_trade_off(tmp_path, capsys, monkeypatch):
    """The warning comes before any sampling (sampling replaced by nothing here); a measure silences it."""
    from lvcore.inference import calibrate as cal

    monkeypatch.setattr(cal, "calibrate_subjects", lambda *a, **k: [])
    p = _csv(tmp_path)
    assert main(["calibrate", "--data", str(p), "--geometry", "infer", "--out", str(tmp_path / "o")]) == 0
    assert "size and stiffness trade off" in capsys.readouterr().err
    p = _csv(tmp_path, ",reference_volume_ml", ",70")
    assert main(["calibrate", "--data", str(p), "--geometry", "infer", "--out", str(tmp_path / "o2")]) == 0
    assert "trade off" not in capsys.readouterr().err


@pytest.mark.parametrize("extra_args,header,values,match", [
    (["--reference-volume", "70", "--reference-volume-sd", "0.01"], "", "", "--reference-volume-sd = 0.01 is outside"),
    (["--long-axis", "80", "--long-axis-sd", "100"], "", "", "--long-axis-sd = 100 is outside 0.2-30 mm"),
    (["--wall-volume-sd", "4"], "", "", "--wall-volume-sd is given without the measure"),
    ([], ",reference_volume_ml,reference_volume_ml_sd", ",70,80", "reference_volume_ml_sd = 80 is outside 0.5-50 mL"),
    ([], ",reference_volume_ml,reference_volume_ml_sd", ",70,x", "reference_volume_ml_sd = 'x' is not a number"),
    (["--reference-volume-sd", "5"], ",reference_volume_ml,reference_volume_ml_sd", ",70,4", "disagree"),
    ([], ",long_axis_mm_sd", ",2", "long_axis_mm_sd is given without the measure"),
])
def test_measure_sds_are_checked_and_named(tmp_path, capsys, extra_args, header, values, match):
    """--reference-volume-sd / --wall-volume-sd / --long-axis-sd and the *_sd columns: exit 2 naming them."""
    p = _csv(tmp_path, header, values)
    code = main(["calibrate", "--data", str(p), "--geometry", "infer", *extra_args, "--out", str(tmp_path / "o")])
    assert code == 2
    assert match in capsys.readouterr().err


def test_measure_sds_need_geometry_infer(tmp_path, capsys):
    code = main(["calibrate", "--data", str(_csv(tmp_path)), "--geometry", "mean", "--long-axis-sd", "2",
                 "--out", str(tmp_path / "o")])
    assert code == 2 and "--long-axis-sd inform an inferred geometry" in capsys.readouterr().err


def test_measure_sd_columns_are_read_from_csv_json_and_mat(tmp_path):
    from scipy.io import savemat

    from lvcore.inference.data import read_measurements

    (row,) = read_measurements(_csv(tmp_path, ",reference_volume_ml,reference_volume_ml_sd,long_axis_mm",
                                    ",70,3.5,82"))
    assert row.measures == {"reference_volume_ml": 70.0, "long_axis_mm": 82.0}
    assert row.measure_sds == {"reference_volume_ml": 3.5}
    j = tmp_path / "m.json"
    j.write_text(json.dumps({"subject": "S", "lvv_ml": 120.0, "strains": [-0.15] * 24, "wall_volume_ml": 90.0,
                             "wall_volume_ml_sd": 6.0}))
    (row,) = read_measurements(j)
    assert row.measure_sds == {"wall_volume_ml": 6.0} and row.measures == {"wall_volume_ml": 90.0}
    m = tmp_path / "m.mat"
    savemat(m, {"lvv_ml": 120.0, "strains": np.full(24, -0.15), "long_axis_mm": 80.0, "long_axis_mm_sd": 2.0})
    (row,) = read_measurements(m)
    assert row.measure_sds == {"long_axis_mm": 2.0}


@pytest.mark.slow
def test_geometry_infer_records_the_measure_sds_and_the_representation_floor(tmp_path, monkeypatch):
    """A short infer run (not converged: the sampler is cut short): summary.json names each measure's sd,
    where it came from, the likelihood sd with the floor and the representation error; 'off' drops the floor.

    The 'off' run stops before sampling (its sampler, without the floor, would be a second trace and compile,
    about 24 CPU-s): it checks the geometry record the CLI's request carries, which the floor run shows reaching
    summary.json unchanged."""
    from lvcore.inference import calibrate as cal
    from lvcore.inference import cli as inference_cli

    setups, prepare_run = [], inference_cli.prepare_run
    monkeypatch.setattr(inference_cli, "prepare_run", lambda args: setups.append(prepare_run(args)) or setups[-1])
    p = _csv(tmp_path, ",reference_volume_ml,long_axis_mm", ",70,82")
    short = ["--chains", "1", "--warmup", "15", "--samples", "15", "--model", "iid"]
    code = main(["calibrate", "--data", str(p), "--geometry", "infer", "--reference-volume-sd", "4", *short,
                 "--out", str(tmp_path / "o")])
    assert code in (0, 1, 4)
    (rec,) = json.loads((tmp_path / "o" / "summary.json").read_text())
    geo = rec["geometry"]
    assert geo["measure_sd"] == {"reference_volume_ml": 4.0, "long_axis_mm": 3.0}
    assert geo["measure_sd_source"] == {"reference_volume_ml": "--reference-volume-sd", "long_axis_mm": "default"}
    assert geo["likelihood_sd"]["reference_volume_ml"] > 4.0 and geo["likelihood_sd"]["long_axis_mm"] > 3.0
    rep = geo["representation_error"]
    assert rep["mode"] == "floor" and rep["n_cases"] >= 30 and 0 < rep["strain_sd_rms"] < 0.1
    assert geo["posterior"]["measure_sd"] == geo["measure_sd"]
    # the request's geometry record is what summary.json says (the posterior added)
    (request,) = setups[-1].requests.values()
    assert request.geometry_record and {k: geo[k] for k in request.geometry_record} == json.loads(
        json.dumps(request.geometry_record))
    monkeypatch.setattr(cal, "calibrate_subjects", lambda *a, **k: [])
    code = main(["calibrate", "--data", str(p), "--geometry", "infer", "--representation-error", "off", *short,
                 "--out", str(tmp_path / "o2")])
    assert code == 0
    (request,) = setups[-1].requests.values()
    assert request.geometry_record["representation_error"] is None
    assert request.geometry_record["likelihood_sd"] == {"reference_volume_ml": 5.0, "long_axis_mm": 3.0}
