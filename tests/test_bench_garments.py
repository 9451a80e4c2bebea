"""The bench's sewn-garment section: the example skirt simulates, every frame checked by ipctk with its seams
left out, and the report holds one row per case."""

from __future__ import annotations

from pscc.bench import garments


def test_quick_garment_case_runs_and_reports() -> None:
    results = garments.run(garments.QUICK_CASES, "cpu")
    (row,) = results["rows"]
    assert row["error"] is None, row["error"]
    assert row["triangles"] == 768 and row["stitches"] == 26
    assert row["crossing_frames"] == 0 and row["halvings"] == 0
    assert row["worst_seam_gap_thicknesses"] < 2.0
    assert 0 < row["bytes_per_triangle"] < 4000
    lines = garments.report(results)
    assert lines[0] == "## Sewn garments: the example skirt"
    assert any(line.startswith("| 768 | 26 | 6 |") for line in lines), lines
