"""scripts/build_emulators.py end to end on a tiny real campaign (FE simulator, fast mesh)."""
import json

import pytest

from lvcore.campaigns.store import read_store
from repo_scripts import load_script


def _script():
    return load_script("scripts/build_emulators.py")


@pytest.mark.slow
def test_below_spec_build_goes_to_workdir_and_says_so(tmp_path):
    mod = _script()
    out = tmp_path / "assets"
    args = ["--emulators", "material", "--n-train", "8", "--n-valid", "8", "--n-test", "0", "--resolution", "fast",
            "--workdir", str(tmp_path / "work"), "--out", str(out), "--architectures", "20x20",
            "--max-epochs", "20", "--batch-size", "4", "--lbfgs-iterations", "50", "--no-progress"]
    assert mod.main(args) == 0
    store = read_store(tmp_path / "work" / "material" / "train_fast.h5")
    assert store.pending.sum() == 0 and store.converged.sum() >= 4
    assert not out.exists()                                       # never into assets below spec
    meta = json.loads((tmp_path / "work" / "below-spec" / "material" / "metadata.json").read_text())
    assert meta["spec_note"].startswith("BELOW SPEC")
    assert meta["training"]["n_train"] == int(store.converged.sum())
    assert meta["training"]["lbfgs"]["iterations"] == 50
    import numpy as np
    with np.load(tmp_path / "work" / "below-spec" / "material" / "training_data.npz", allow_pickle=False) as z:
        assert z["train_inputs"].shape == (meta["training"]["n_train"], 4)
        assert z["train_outputs"].shape == (meta["training"]["n_train"], 25) and "test_inputs" not in z
    assert meta["source"]["design_seeds"] == {"train": 2026, "valid": 2027}
    # rerunning resumes: nothing is simulated again, designs are reused
    assert mod.main(args[:-1] + ["--steps", "design", "run", "--no-progress"]) == 0
    again = read_store(tmp_path / "work" / "material" / "train_fast.h5")
    assert (again.record_count == store.record_count).all()


def test_spec_defaults():
    mod = _script()
    args = mod.parse_args([])
    assert (args.n_train, args.n_valid, args.resolution) == (10_000, 1_000, "default")
    assert args.emulators == ["chapter", "angles"] and mod.below_spec(args) == ""


def test_each_bundled_emulator_gets_its_shipped_schedule_unless_told_otherwise():
    import json

    mod = _script()
    args = mod.parse_args([])
    for name in ("chapter", "angles"):
        meta = json.loads((args.out / name / "metadata.json").read_text())  # the default --out is the shipped folder
        shipped = meta["training"]["config"]
        filled = mod.schedule_args(name, args)
        assert {k: getattr(filled, k) for k in mod.SCHEDULE_OPTIONS} == {k: shipped[k] for k in mod.SCHEDULE_OPTIONS}
    told = mod.schedule_args("angles", mod.parse_args(["--lbfgs-iterations", "5"]))
    assert told.lbfgs_iterations == 5 and told.max_epochs == 1000


def test_recorded_paths_are_relative_to_the_build_folder(tmp_path):
    """The metadata never records a path of the build machine: stores and the command are relative to --workdir."""
    mod = _script()
    work = tmp_path / "build"
    cmd = mod.portable_command(["build_emulators.py", "--emulators", "chapter", "--workdir", str(work),
                                f"--out={work / 'x' / 'y'}", "--below-spec-out", str(tmp_path / "other" / "bs")], work)
    assert cmd == "build_emulators.py --emulators chapter --workdir WORKDIR --out=WORKDIR/x/y --below-spec-out bs"
    from lvcore.emulator.io import provenance_path

    assert provenance_path(work / "chapter" / "train_default.h5", work) == "chapter/train_default.h5"
    assert provenance_path(tmp_path / "elsewhere.h5", work) == "elsewhere.h5"


def test_shipped_files_record_no_machine_paths():
    """Nothing under assets/ (metadata, READMEs, study results) names a folder of the machine that built it."""
    from lvcore.resources import assets_dir

    machine = ("/work/", "/tmp/", "/root/", "/home/", "/Users/")
    offenders = [f"{p.relative_to(assets_dir())}: {m}" for p in sorted(assets_dir().rglob("*"))
                 if p.suffix in (".json", ".md", ".csv") and p.is_file()
                 for m in machine if m in p.read_text(errors="replace")]
    assert not offenders, offenders


def test_base_option_sets_the_designs_base_condition(tmp_path):
    """--base clamped records the clamped base in the angles designs (whose space is sliding, as shipped), so the
    campaigns run with it; the default keeps the space's own."""
    from lvcore.campaigns.designs import load_design

    mod = _script()
    common = ["--emulators", "angles", "--n-train", "4", "--n-valid", "0", "--n-test", "0", "--steps", "design",
              "--no-progress"]
    assert mod.main(common + ["--workdir", str(tmp_path / "c"), "--base", "clamped"]) == 0
    d = load_design(tmp_path / "c" / "angles" / "train_design.csv")
    assert d.space.base == "clamped" and d.space.name == "angles" and d.n == 4
    assert all(c["boundary"]["base"] == "clamped" for c in d.cases("fast"))
    assert mod.main(common + ["--workdir", str(tmp_path / "s")]) == 0
    assert load_design(tmp_path / "s" / "angles" / "train_design.csv").space.base == "sliding"
