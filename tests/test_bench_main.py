"""`python -m pscc.bench` (the whole bench's entry point): its report path is checked before anything is
measured, and the report lands in a folder made for it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pscc.bench.__main__ import main

ALL_SECTIONS_SKIPPED = ["--broad-phase-sizes", "--corpus", "skip", "--simulator", "skip", "--stages", "skip",
                        "--scenes", "skip", "--device-path", "skip", "--garments", "skip"]


@pytest.mark.parametrize("name", ["folder", "report.txt"])
def test_a_bad_report_path_ends_the_run_before_it_measures(tmp_path: Path, capsys, name: str) -> None:
    out = tmp_path if name == "folder" else tmp_path / name
    assert main(["--out", str(out), "--sizes", "100", "--repeats", "1", *ALL_SECTIONS_SKIPPED]) == 2
    message = capsys.readouterr().err
    assert "--out" in message and "Fix:" in message and "Markdown" in message
    assert list(tmp_path.iterdir()) == []


def test_the_report_and_its_numbers_land_in_a_new_folder(tmp_path: Path) -> None:
    out = tmp_path / "new" / "deeper" / "B.md"
    assert main(["--out", str(out), "--sizes", "100", "--repeats", "1", *ALL_SECTIONS_SKIPPED]) == 0
    text = out.read_text()
    assert text.startswith("# Benchmarks") and "## Brute-force detector" in text
    results = json.loads(out.with_suffix(".json").read_text())
    assert results["brute_force"] and results["query_sets"]
    assert sorted(p.name for p in out.parent.iterdir()) == ["B.json", "B.md", "docs"]
