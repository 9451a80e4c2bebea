"""The bench's sewn-garment section: the example skirt and a garment scene simulate, every frame checked by
ipctk with its seams left out, and the report holds one row per case."""

from __future__ import annotations

from pscc.bench import garments


def test_quick_garment_cases_run_and_report() -> None:
    results = garments.run(garments.QUICK_CASES, "cpu")
    skirt, dance = results["rows"]
    for row in (skirt, dance):
        assert row["error"] is None, row["error"]
        assert row["crossing_frames"] == 0 and row["halvings"] == 0
        assert row["worst_seam_gap_thicknesses"] < 2.0
        assert 0 < row["bytes_per_triangle"] < 4000
    assert skirt["triangles"] == 768 and skirt["stitches"] == 26
    assert dance["garment"] == "dance" and abs(dance["triangles"] - 5000) < 500 and dance["stitches"] > 50
    lines = garments.report(results)
    assert lines[0] == "## Sewn garments: the example skirt and the garment scenes"
    assert any(line.startswith("| skirt example | 768 | 26 | 6 |") for line in lines), lines
    assert any(line.startswith(f"| dance | {dance['triangles']:,} |") for line in lines), lines
