"""The device-path benchmark section (``pscc.bench.device_path``) on one short case."""

from __future__ import annotations

from pscc.bench.device_path import report, run_case
from pscc.scenes import build_scene
from pscc.sim.simulation import Simulation


def test_one_device_path_row_and_its_report() -> None:
    row = run_case("stack", 300, 7, 2, "cpu")
    assert row["error"] is None and row["triangles"] > 0
    assert row["graph_fallbacks"] == 0 and row["replayed_frames"] == 2
    assert row["per_frame"]["reads"] == 1.0 and row["per_frame"]["syncs"] == 0.0  # the report, nothing else
    assert row["per_frame"]["uploads"] == 1.0  # the obstacle's targets
    assert row["intersecting_frames"] == 0
    assert row["graph_seconds"] > 0.0 and row["eager_seconds"] > 0.0
    assert row["bytes_per_triangle"]["total"] > row["bytes_per_triangle"]["collision"] > 0.0
    lines = report({"rows": [row], "seconds": 1.0, "device": "cpu"})
    table_row = next(line for line in lines if line.startswith("| stack |"))
    assert "| 2 (2) | 1.0 | 0.0 | 1.0 |" in table_row and "0 of 2" in table_row


def test_stage_timing_runs_the_host_path_and_times_its_stages() -> None:
    sim = Simulation(build_scene("drape", 200), device="cpu", stage_timing=True)
    record = sim.step_frame()
    assert record["counts"]["graph_replays"] == 0
    assert {"integration", "broad_phase", "narrow_phase", "total"} <= set(record["seconds"])
    assert abs(sim.time - sim.scene.frame_time) < 1e-9
