"""The simulator benchmark sections (``pscc.bench.simulator``) on tiny runs, pscc only."""

from __future__ import annotations

from pathlib import Path

from pscc.bench.simulator import (
    STAGES,
    breakdown_scene,
    plot_breakdown,
    report_breakdown,
    report_comparison,
    run_comparison,
)


def test_comparison_rows_and_report_without_newton() -> None:
    results = run_comparison([("drape", 400, 2)], "cpu", with_newton=False)
    (row,) = results["rows"]
    assert row["method"] == "pscc" and row["frames_done"] == 2 and row["error"] is None
    assert row["intersecting"] == [] and row["median_seconds"] > 0.0 and 0.0 <= row["max_stretch"] < 0.1
    assert row["check_seconds"] > 0.0  # ipctk checked every frame
    lines = report_comparison(results)
    assert any(line.startswith("| drape |") and "| pscc |" in line for line in lines)


def test_breakdown_row_report_and_plot(tmp_path: Path) -> None:
    row = breakdown_scene("stack", 450, 1, 1, "cpu")
    assert row["error"] is None and row["measured_frames"] == 1
    assert set(STAGES) | {"other"} == set(row["stage_seconds"])
    assert row["frame_seconds"] >= sum(row["stage_seconds"][s] for s in STAGES)
    memory = row["device_bytes"]
    assert memory["collision.total"] > 0 and memory["integrator"] > 0 and memory["contact_springs"] > 0
    results = {"rows": [row], "seconds": 1.0}
    assert any(line.startswith("| stack |") for line in report_breakdown(results, None))
    assert plot_breakdown(results, tmp_path / "stages.png") and (tmp_path / "stages.png").stat().st_size > 1000
