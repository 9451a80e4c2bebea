"""The paper-scenes benchmark section (``pscc.bench.scenes``) on one short run."""

from __future__ import annotations

from pathlib import Path

from pscc.bench.scenes import plot_scenes, report_scenes, run_scene


def test_one_paper_scene_row_and_its_report(tmp_path: Path) -> None:
    row = run_scene("dance", 5000, 1, "animation", "cpu")
    assert row["error"] is None and row["measured_frames"] == 1
    assert abs(row["triangles"] - 5000) <= 125 and row["collision_triangles"] > row["triangles"]
    assert row["checked_frames"] == 1 and row["intersecting_frames"] == 0
    assert row["frame_seconds"] > 0.0 and row["worst_frame_seconds"] >= row["frame_seconds"]
    assert 0.0 < row["stage_seconds"]["integration"] <= row["frame_seconds"]
    memory = row["device_bytes"]
    assert memory["collision.total"] > 0 and memory["integrator"] > 0 and memory["states"] > 0
    results = {"rows": [row], "seconds": 1.0}
    lines = report_scenes(results, "plot.png")
    table_row = next(line for line in lines if line.startswith("| dance | animation |"))
    assert "0 of 1" in table_row and f"{row['triangles']:,}" in table_row
    assert plot_scenes(results, tmp_path / "plot.png") and (tmp_path / "plot.png").stat().st_size > 1000
