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
