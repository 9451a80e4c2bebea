"""The broad-phase benchmark section on a small scene, with a stand-in for Newton's detector."""

from __future__ import annotations

import time

from pscc.bench import broad_phase


class _FakeNewton:
    """Takes a fixed time per call, so the paired ratios are known to within the timer's noise."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self.calls = 0

    def run(self) -> None:
        self.calls += 1
        time.sleep(self.seconds)

    def row(self, seconds: float) -> dict:
        return {"method": "newton", "mode": "dcd", "seconds": seconds, "radius": 0.0,
                "vertex_face_pairs": 0, "edge_edge_pairs": 0, "overflow": False}


class _Result:
    stats = {"seconds": {"setup": 0.0, "spatial_hash": 0.001, "output": 0.001, "total": 0.002}}


class _Clock:
    """A stand-in for ``time``: ``perf_counter`` reads a time that only the calls below advance."""

    def __init__(self) -> None:
        self.now = 0.0

    def perf_counter(self) -> float:
        return self.now


def test_paired_medians_alternate_and_ratio_each_pair(monkeypatch) -> None:
    clock = _Clock()
    monkeypatch.setattr(broad_phase, "time", clock)
    order = []
    # Per call (warm-up first): run takes 10, 30, 20, 10 ms, other 40, 40, 80, 40 ms.
    run_ms = iter([10, 30, 20, 10])
    other_ms = iter([40, 40, 80, 40])

    def run():
        order.append("a")
        clock.now += next(run_ms) / 1000
        return _Result()

    def other():
        order.append("b")
        clock.now += next(other_ms) / 1000

    seconds, result, other_seconds, ratio, device_ratio = broad_phase._paired_medians(run, other, 3)
    assert order == ["a", "b"] * 4
    assert isinstance(result, _Result)
    assert abs(seconds - 0.020) < 1e-12 and abs(other_seconds - 0.040) < 1e-12
    # Per-repeat ratios 0.75, 0.25, 0.25: the median of the ratios, not the ratio of the medians (0.5).
    assert abs(ratio - 0.25) < 1e-12
    # Device seconds of run (_Result: its 1 ms spatial hash) over other's: 0.025, 0.0125, 0.025.
    assert abs(device_ratio - 0.025) < 1e-12


def test_bench_methods_and_report_on_a_small_scene() -> None:
    mesh = broad_phase.SCENES["twisted"](600)
    newton = _FakeNewton(0.02)
    rows = broad_phase.bench_methods(mesh, "cpu", repeats=2, newton=newton)
    # One warm-up call and one per pair, alternating with pscc's DCD (at least PAIRED_REPEATS pairs).
    assert newton.calls == 1 + broad_phase.PAIRED_REPEATS
    methods = [(r["method"], r["mode"]) for r in rows]
    assert methods == [("spatial-hash", "ccd"), ("spatial-hash", "dcd"), ("pscc", "ccd"), ("pscc", "dcd"),
                       ("newton", "dcd")]
    pscc_dcd = rows[3]
    # pscc's 600-triangle DCD takes far less than the stand-in's 20 ms.
    assert 0.0 < pscc_dcd["newton_ratio"] < 1.0
    assert 0.0 < pscc_dcd["newton_device_ratio"] <= pscc_dcd["newton_ratio"]
    for r in rows[:4]:
        assert r["bv_tests"] > 0 and r["triangle_pairs"] >= r["kept_triangle_pairs"] >= 0
    assert rows[2]["slab_tests"] >= 0 and rows[0]["slab_tests"] == 0
    lines = broad_phase.report([{"scene": "twisted", "triangles": mesh.face_count, **r} for r in rows])
    text = "\n".join(lines)
    assert "| twisted | 600 | DCD | pscc |" in text.replace(",", "")
    ratio_row = next(line for line in lines if line.startswith("| twisted | 600 | DCD |") and "pscc" not in line
                     and "newton" not in line and "spatial" not in line)
    assert ratio_row.split("|")[8].strip() == f"{pscc_dcd['newton_ratio']:.2f}"
