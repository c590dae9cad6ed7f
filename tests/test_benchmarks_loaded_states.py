"""benchmarks/bench_loaded_states.py in its CI version (``--quick``): the angles emulator's own outputs at 8 and
14 mmHg (SYNTHETIC, mean geometry) calibrated through ``lvcore calibrate`` with 2 chains and a small budget. It
checks that the script and the several-states route run end to end and print the table; the numbers of the
full measurement (FE truth at 8 and 20 mmHg) are in BENCHMARKS.md."""
from __future__ import annotations

import json

import pytest
from repo_scripts import load_script

pytestmark = pytest.mark.slow


def test_quick_version_runs_and_prints_the_table(tmp_path, capsys):
    bench = load_script("benchmarks/bench_loaded_states.py")
    rows_file = tmp_path / "rows.json"
    # 2 chains x (15 + 15) (--quick's own budget is 40 + 40): the test checks the route and the table, not the numbers
    assert bench.main(["--quick", "--warmup", "15", "--samples", "15", "--out", str(tmp_path / "w"),
                       "--json", str(rows_file)]) == 0
    out = capsys.readouterr().out
    assert "| row | a 90 % | a q95/q05 |" in out and "SYNTHETIC subject" in out
    rows = {r["row"]: r for r in json.loads(rows_file.read_text())}
    assert rows["quick: 8 mmHg"]["states"] == [8.0] and rows["quick: 8 + 14 mmHg"]["states"] == [8.0, 14.0]
    for r in rows.values():
        assert r["exit"] in (0, 1, 4) and 0 < r["a_q05"] < r["a_q95"]
    assert "x narrower (ratio q95/q05)" in out
