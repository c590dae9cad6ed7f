"""The documentation's map and hygiene: docs/index.md lists every page, the README links it, no machine paths."""
from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def test_index_links_every_page_and_the_readme_links_the_index():
    index = (DOCS / "index.md").read_text()
    linked = set(re.findall(r"\]\(([\w.-]+\.md)\)", index))
    pages = {p.name for p in DOCS.glob("*.md")} - {"index.md"}
    assert pages <= linked, f"docs/index.md does not link {sorted(pages - linked)}"
    assert all((DOCS / name).is_file() for name in linked), "docs/index.md links a page that does not exist"
    assert "](docs/index.md)" in (ROOT / "README.md").read_text()


def test_docs_name_no_folder_of_a_build_machine():
    machine = re.compile(r"(?<![\w$])/(work|root|home|Users)/")
    offenders = [f"{p.relative_to(ROOT)}:{i}" for p in [ROOT / "README.md", ROOT / "BENCHMARKS.md", *DOCS.glob("*.md")]
                 for i, line in enumerate(p.read_text().splitlines(), 1) if machine.search(line)]
    assert not offenders, offenders


def test_benchmarks_summary_is_one_short_line_per_row_with_details():
    text = (ROOT / "BENCHMARKS.md").read_text()
    summary = text[text.index("## Summary against the targets"):]
    summary = summary[: summary.index("\n## ")]
    rows = [line for line in summary.splitlines() if re.match(r"\| \d+ \|", line)]
    assert rows, "no summary rows"
    long_cells = [(r.split(" | ")[0], c.strip()) for r in rows for c in r.strip("|").split(" | ") if len(c.strip()) > 120]
    assert not long_cells, f"summary cells over 120 characters (details go below): {long_cells}"
    details = text[text.index("## Details of the summary rows"):]
    numbers = [int(r.split("|")[1]) for r in rows]
    assert numbers == list(range(1, len(rows) + 1))
    missing = [n for n in numbers if f"\n### {n}. " not in details]
    assert not missing, f"summary rows without a details subsection: {missing}"


#: Reference docs whose dated run logs live in one "## Appendix: measured runs" section at the end (issue 23).
APPENDIX_DOCS = ("calibration.md", "simulator.md", "campaigns_and_emulators.md", "studies.md", "report.md",
                 "real_data.md")


def test_dated_run_logs_sit_in_one_appendix_at_the_end():
    date = re.compile(r"\b20\d\d-\d\d-\d\d\b")
    for name in APPENDIX_DOCS:
        headings = [h for h in (DOCS / name).read_text().splitlines() if h.startswith("## ")]
        assert headings.count("## Appendix: measured runs") == 1 and headings[-1] == "## Appendix: measured runs", name
        text = (DOCS / name).read_text()
        above = [h for h in text[: text.index("## Appendix: measured runs")].splitlines()
                 if h.startswith("#") and (date.search(h) or h.lstrip("#").strip().lower().startswith("measured ("))]
        assert not above, f"docs/{name}: dated run-log sections above the appendix: {above}"


def test_every_doc_states_the_strain_reference_as_the_code_computes_it():
    """lvcore's strains are circumferential Green strain with end diastole as the reference, (1/λ² − 1)/2
    (lvcore.mechanics.kinematics.circumferential_green_strain): no doc may call the strain's reference early
    diastole (the *geometry*'s reference is early-diastolic, which is another thing)."""
    import numpy as np

    from lvcore.mechanics.kinematics import circumferential_green_strain

    lam = 1.1  # a filling stretch: with end diastole as the reference the strain is negative, (1/λ² − 1)/2
    F = np.diag([lam, 1.0, 1.0])
    assert float(circumferential_green_strain(F, np.array([1.0, 0.0, 0.0]))) == \
        __import__("pytest").approx(0.5 * (1 / lam**2 - 1))
    bad = re.compile(r"strain[^.|]{0,80}?early[- ]diastol\w*\s+reference|early[- ]diastol\w*\s+reference[^.|]{0,30}?"
                     r"negative in filling", re.IGNORECASE | re.DOTALL)
    for path in [*DOCS.glob("*.md"), ROOT / "README.md"]:
        text = path.read_text()
        hits = [m.group(0) for m in bad.finditer(text) if "convert" not in text[max(0, m.start() - 60):m.end()]]
        assert not hits, f"{path.name} calls the strain's reference early diastole: {hits}"
    for name in ("real_data.md", "simulator.md"):
        assert "end diastole as the reference" in (DOCS / name).read_text(), name
