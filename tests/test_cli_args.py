"""Option bounds, exit codes, help texts and messages of the ``lvcore`` command (issue 28 findings 2, 3, 5, 6;
issue 27 item 6). Every case here exited 0 (accepted), 3 (internal error) or with a vague message before."""
from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from lvcore import cli_args
from lvcore.safety import limits
from lvcore.cli import _all_parsers, build_parser, main


def _run(capsys, *argv):
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:  # argparse refuses an option value: exit 2
        code = exc.code
    out = capsys.readouterr()
    return code, out.out + out.err


# ----------------------------------------------------------------------------- help (issue 27 item 6)
def test_every_argument_has_help_and_every_option_states_its_default():
    missing = []
    for parser in _all_parsers(build_parser()):
        fmt = parser._get_formatter()
        for a in parser._actions:
            if isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)):
                continue
            text = fmt._expand_help(a) if a.help else ""
            if not text.strip():
                missing.append(f"{parser.prog} {a.dest}: no help")
            elif (a.option_strings and not a.required and not isinstance(a, argparse._StoreTrueAction)
                  and "default" not in text.lower()):
                missing.append(f"{parser.prog} {a.dest}: no default in {text[:60]!r}")
    assert not missing, "\n".join(missing)


def test_named_help_texts(capsys):
    for argv, words in ((["calibrate", "--help"], ["--chains", "(default 4)", "--warmup", "--seed", "2^32"]),
                        (["geometry", "project", "--help"], ["--modes", "(default 5)", "template mesh"]),
                        (["geometry", "info", "--help"], ["template mesh"]),
                        (["geometry", "compare", "--help"], ["second template mesh"]),
                        (["geometry", "pca", "--help"], ["standardised PC scores"]),
                        (["report", "--help"], ["lvcore[report]", "default png,svg"])):
        with pytest.raises(SystemExit):
            main(argv)
        text = " ".join(capsys.readouterr().out.split())
        for w in words:
            assert w in text, (argv, w)


# ----------------------------------------------------------------------------- option bounds (finding 2)
@pytest.mark.parametrize("n", ["1000000000", "100000000", "400000"])
def test_design_n_is_bounded_by_what_campaign_run_reads(tmp_path, capsys, n):
    code, text = _run(capsys, "design", "sobol", "--space", "material", "--n", n, "--seed", 1,
                      "--out", tmp_path / "d.csv")
    assert code == 2 and "argument --n" in text and "100,000" in text
    assert not (tmp_path / "d.csv").exists()


def test_the_largest_design_is_below_the_design_file_limit():
    from lvcore.campaigns.designs import Design, save_design
    from lvcore.campaigns.space import get_space
    from lvcore.exceptions import CampaignError

    space = get_space("chapter", n_pcs=20)
    n = limits.MAX_DESIGN_VALUES // space.dim
    with pytest.raises(CampaignError, match="MAX_DESIGN_VALUES"):
        from lvcore.campaigns.designs import make_design
        make_design(space, "random", n + 1, 0)
    # worst case for the CSV: every value a full-length repr
    pts = space.lower + (space.upper - space.lower) * np.full((n, space.dim), 0.123456789012345678)
    import tempfile
    from pathlib import Path
    with tempfile.TemporaryDirectory() as d:
        p = save_design(Design(space, pts), Path(d) / "big.csv")
        assert p.stat().st_size < limits.MAX_DESIGN_BYTES


def test_workers_are_bounded_unless_a_scheduler_is_given(tmp_path, capsys):
    code, text = _run(capsys, "campaign", "run", tmp_path / "d.csv", "--out", tmp_path / "s.h5",
                      "--workers", 100000)
    assert code == 2 and "argument --workers" in text and "--scheduler" in text


def test_memory_estimate_is_an_admission_check_under_ulimit():
    """100 x 100 x 1 passed every limit (10 GB estimated, half the RAM) and died at 4 GB under a 4 GB limit."""
    import hostile_files as hf

    code = ("from lvcore.safety import limits\nfrom lvcore.exceptions import LimitError\n"
            "try:\n    limits.check_mesh_size((100, 100, 1))\n    print('ACCEPTED')\n"
            "except LimitError as e:\n    print('REFUSED', e)\n")
    res = hf.run_limited(code, limit_kb=4_000_000)
    assert "REFUSED" in res.stdout and "GB available" in res.stdout, res.stdout + res.stderr[-1000:]


def test_typed_angle_pairs_are_bounded():
    from lvcore.exceptions import LVCoreError
    from lvcore.studies.fibre_angles import MAX_TYPED_ANGLE_PAIRS, parse_angle_pairs

    assert parse_angle_pairs("-45 75; -90 0") == [(-45.0, 75.0), (-90.0, 0.0)]
    with pytest.raises(LVCoreError, match="at most 20"):
        parse_angle_pairs("; ".join(["-60 60"] * 10_000))
    assert MAX_TYPED_ANGLE_PAIRS == 20
    with pytest.raises(LVCoreError, match=r"\[-180, 180\]"):
        parse_angle_pairs("1e300 0")
    with pytest.raises(LVCoreError, match="could not read"):
        parse_angle_pairs("-60 60 7")


# ----------------------------------------------------------------------------- exit codes (finding 3)
def test_out_paths_exit_2_naming_the_option(tmp_path, capsys):
    afile = tmp_path / "existing.csv"
    afile.write_text("x")
    for out, words in ((afile / "x.csv", "is a file, not a folder"), (".", "is a folder"),
                       (tmp_path, "is a folder")):
        code, text = _run(capsys, "design", "sobol", "--space", "material", "--n", 8, "--seed", 1, "--out", out)
        assert code == 2 and "argument --out" in text and words in text, text
    code, text = _run(capsys, "calibrate", "--volunteer", "SYNTHETIC_HV3", "--out", afile)
    assert code == 2 and "argument --out" in text and "is a file" in text


def test_os_errors_on_user_paths_exit_2_naming_the_path(monkeypatch, capsys):
    """E.g. a read-only folder (as root the up-front check cannot see it; the write fails): exit 2, not 3."""
    import lvcore.campaigns.cli as ccli

    def refuse(args):
        raise PermissionError(13, "Permission denied", "/read-only/store.h5.lock")
    monkeypatch.setattr(ccli, "_resume", refuse)
    code, text = _run(capsys, "campaign", "resume", "/read-only/store.h5")
    assert code == 2 and "/read-only/store.h5.lock" in text and "Permission denied" in text


@pytest.mark.parametrize("seed", ["-1", str(2 ** 70)])
def test_seeds_out_of_range_exit_2(tmp_path, capsys, seed):
    code, text = _run(capsys, "design", "sobol", "--space", "material", "--n", 8, "--seed", seed,
                      "--out", tmp_path / "d.csv")
    assert code == 2 and "argument --seed" in text and "4,294,967,295" in text


def test_negative_pcs_exit_2(tmp_path, capsys):
    code, text = _run(capsys, "design", "sobol", "--space", "material", "--n", 8, "--seed", 1, "--pcs", -1,
                      "--out", tmp_path / "d.csv")
    assert code == 2 and "argument --pcs" in text


def test_huge_fibre_direction_is_normalised_not_zero():
    from lvcore.mechanics.case import Case

    case = Case.from_dict({"geometry": {"kind": "default", "resolution": "fast"},
                           "material": {"law": "holzapfel-ogden", "a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6},
                           "fibres": {"direction": [1e308, 1e308, 1e308]},
                           "load": {"pressure": 8, "units": "mmHg"}})
    np.testing.assert_allclose(case.fibres.direction, np.full(3, 1 / np.sqrt(3)))


def test_resume_of_a_store_with_a_text_design_seed_exits_2(tmp_path, capsys):
    import h5py

    from lvcore.campaigns.designs import make_design
    from lvcore.campaigns.space import get_space
    from lvcore.campaigns.store import CampaignStore

    path = tmp_path / "s.h5"
    CampaignStore.create(path, make_design(get_space("material"), "lhs", 4, 0), forward="simulator",
                         resolution="fast").close()
    with h5py.File(path, "r+") as f:
        f.attrs["design_seed"] = "abc"
    code, text = _run(capsys, "campaign", "resume", path, "--no-progress")
    assert code == 2 and "design_seed" in text and "'abc'" in text


def test_report_from_a_folder_holding_binary_json_is_a_clear_error(tmp_path):
    from lvcore.exceptions import LVCoreError
    from lvcore.report.build import SECTIONS, section_items

    (tmp_path / "fibre_discrepancy.json").write_bytes(bytes(range(256)))
    section = next(s for s in SECTIONS if s.study == "fibre_discrepancy" and s.saved)
    with pytest.raises(LVCoreError, match="fibre_discrepancy.json' is not UTF-8 text"):
        section_items(section, tmp_path)
    (tmp_path / "fibre_discrepancy.json").write_text("[1, 2]")
    with pytest.raises(LVCoreError, match="fibre_discrepancy.json"):
        section_items(section, tmp_path)


def test_report_formats_are_checked(tmp_path, capsys):
    code, text = _run(capsys, "report", "--out", tmp_path / "r", "--formats", "exe,../../../x")
    assert code == 2 and "argument --formats" in text and "'exe'" in text
    assert not (tmp_path / "r").exists()


# ----------------------------------------------------------------------------- plausibility (finding 5)
def test_sigma_v_outside_its_documented_range_is_refused(capsys):
    for value in ("1e300", "0.001"):
        code, text = _run(capsys, "calibrate", "--volunteer", "SYNTHETIC_HV3", "--sigma-v", value)
        assert code == 2 and "--sigma-v" in text and "[0.1, 50] mL" in text


def test_modes_0_is_refused(capsys):
    code, text = _run(capsys, "geometry", "project", "x.vtu", "--modes", 0)
    assert code == 2 and "argument --modes" in text


@pytest.mark.parametrize("septum, words", [((float("nan"),) * 3, "3 finite coordinates"),
                                           ("axis", "from the LV's long axis")])
def test_degenerate_septum_landmarks_are_refused(septum, words):
    from lvcore.exceptions import GeometryError
    from lvcore.geometry.fitting import _x_axis

    ez, origin = np.array([0.0, 0.0, 1.0]), np.array([1.0, 2.0, 3.0])
    if septum == "axis":
        septum = origin + 40.0 * ez
    with pytest.raises(GeometryError, match=words):
        _x_axis(ez, origin, septum)
    ex = _x_axis(ez, origin, origin + np.array([0.0, 30.0, 5.0]))
    np.testing.assert_allclose(ex, [0.0, 1.0, 0.0])


def test_a_mm_mesh_read_as_cm_gets_a_units_warning():
    from types import SimpleNamespace

    from lvcore.geometry.fitting import units_warnings

    assert units_warnings(SimpleNamespace(cavity_volume_ml=120.0, length_mm=85.0), "mm") == []
    (w,) = units_warnings(SimpleNamespace(cavity_volume_ml=2470.0, length_mm=250.0), "cm")
    assert "check --units (read as cm" in w and "2,470 mL" in w
    assert units_warnings(SimpleNamespace(cavity_volume_ml=120.0, length_mm=170.0), "mm") != []


# ----------------------------------------------------------------------------- messages (finding 6)
@pytest.mark.parametrize("content", ["[]", '"x"', "42", "null"])
def test_case_files_that_are_not_objects_name_the_file(tmp_path, capsys, content):
    p = tmp_path / "my_case.json"
    p.write_text(content)
    code, text = _run(capsys, "simulate", p)
    assert code == 2 and "my_case.json" in text and "JSON object" in text


def test_huge_pc_scores_are_refused_as_scores_not_as_a_quadrature_failure(tmp_path, capsys):
    p = tmp_path / "pca.json"
    p.write_text(json.dumps({"geometry": {"kind": "pca", "scores": [1e300, 0, 0], "resolution": "fast"},
                             "material": {"law": "holzapfel-ogden", "a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6},
                             "load": {"pressure": 8, "units": "mmHg"}}))
    code, text = _run(capsys, "simulate", p)
    assert code == 2 and "geometry.scores[0]" in text and "quadrature" not in text


def test_huge_keys_and_paths_are_echoed_at_most_200_characters(tmp_path, capsys):
    p = tmp_path / "case.json"
    p.write_text(json.dumps({"k" * 900_000: 1}))
    code, text = _run(capsys, "simulate", p)
    assert code == 2 and "unknown key" in text and len(text) < 2000
    long_path = "/nonexistent/" + "d" * 100_000 + ".json"
    code, text = _run(capsys, "simulate", long_path)
    assert code == 2 and "(100,0" in text and len(text) < 2000


def test_echo_cuts_long_values():
    assert cli_args.echo("abc") == "abc"
    assert cli_args.echo("x" * 1000).endswith("(1,000 characters)") and len(cli_args.echo("x" * 1000)) < 240
