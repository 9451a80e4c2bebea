"""The device path of the simulator: host traffic per step, graph replay against eager launches, memory.

For each case the scene is simulated twice from its start, once replaying a recorded graph per frame
(``Simulation(graph=True)``, the default) and once launching eagerly (``graph=False``), the two runs
interleaved frame by frame so that both meet the same load of the machine. After a
warm-up (kernels load, buffers grow while contact builds up), the measured frames of the graph run
are counted with :func:`pscc.bench.host_traffic.count_host_traffic` and checked by ipctk
(:func:`pscc.bench.scenes.cloth_intersection_free`: crossings that involve the cloth, stitched pairs left
out, for garments on a skinned body; ``has_intersections`` on the whole mesh otherwise); seconds per
frame compare the two runs over the same frames.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from pscc.bench.host_traffic import count_host_traffic
from pscc.bench.scenes import cloth_intersection_free
from pscc.scenes import build_scene, paper
from pscc.sim.scene import Scene
from pscc.sim.simulation import Simulation

CASES: list[tuple[str, int, int, int]] = [
    ("drape", 2000, 8, 12), ("stack", 2000, 8, 12), ("twist", 2000, 8, 12),
    ("drape", 5000, 12, 8), ("stack", 5000, 12, 8), ("twist", 5000, 12, 8),
    ("twisting", 5000, 12, 8), ("kungfu", 5000, 12, 8),
]
"""(scene, cloth triangles, warm-up frames, measured frames); ``twisting`` and ``kungfu`` (a garment on
an animated body, whose triangles count in the memory but not in the denominator) are paper scenes at
their smallest scale (about 5K cloth triangles), the others are the built-in scenes. Enough measured frames that
buffers grown while contact built up are trimmed again before the memory is read; ``twisting``'s warm-up
passes its first frames of self-contact, where every frame grows a buffer and the graph is recorded again
(none of 3 frames after a warm-up of 4 was a replay)."""

QUICK_CASES: list[tuple[str, int, int, int]] = [("drape", 2000, 8, 3), ("stack", 2000, 8, 3)]
"""The cases of ``--device-path quick``."""


def _scene(name: str, triangles: int) -> Scene:
    if name in paper.PAPER_SCENES:
        return paper.PAPER_SCENES[name](max(paper.min_scale(name), triangles / paper.PAPER_TRIANGLES[name]))
    return build_scene(name, triangles)


def _intersection_free(sim: Simulation, scene: Scene) -> bool:
    """Whether nothing crosses the cloth (:func:`pscc.bench.scenes.cloth_intersection_free`: stitched pairs
    are not crossings, and a skinned body may fold into itself at a bent joint)."""
    cloth = sim.state.positions.numpy()[: sim.solver.cloth_vertex_count].astype(np.float64)
    return bool(cloth_intersection_free(scene, cloth, sim.time))


def run_case(name: str, triangles: int, warmup: int, frames: int, device: str,
             progress: Callable[[str], None] = lambda _: None) -> dict[str, Any]:
    """One scene, simulated from its start with the graph (traffic, checks, memory) and eagerly, the two
    runs interleaved frame by frame (which one goes first alternates), so that both see the same load of
    the machine: on a shared machine the speed drifts by 10-20 % over minutes, which skewed the ratio
    when one run followed the other."""
    row: dict[str, Any] = {"scene": name, "warmup_frames": warmup, "frames": frames, "error": None}
    seconds: dict[bool, list[float]] = {True: [], False: []}
    replayed: list[bool] = []
    traffic = {"reads": 0, "syncs": 0, "uploads": 0}
    fallbacks = {True: 0, False: 0}
    try:
        sims = {}
        for graph in (True, False):
            scene = _scene(name, triangles)
            sims[graph] = Simulation(scene, device=device, graph=graph)
        row["triangles"] = int(scene.faces.shape[0])
        row["steps_per_frame"] = scene.steps_per_frame
        for frame in range(1, warmup + frames + 1):
            for graph in ((True, False) if frame % 2 else (False, True)):
                sim = sims[graph]
                if frame > warmup and graph:
                    with count_host_traffic() as counts:
                        record = sim.step_frame()
                    for key in traffic:
                        traffic[key] += counts[key]
                    replayed.append(bool(record["counts"]["graph_replays"]))
                    row.setdefault("intersecting_frames", 0)
                    row["intersecting_frames"] += int(not _intersection_free(sim, scene))
                else:
                    record = sim.step_frame()
                if frame > warmup:
                    seconds[graph].append(record["seconds_total"])
                    fallbacks[graph] += record["counts"]["device_fallbacks"]
                progress(f"device path {name} {triangles} {'graph' if graph else 'eager'}: frame "
                         f"{frame}/{warmup + frames} {record['seconds_total']:.2f} s")
        row["graph_fallbacks"] = fallbacks[True]
        row["eager_fallbacks"] = fallbacks[False]
        memory = sims[True].solver.device_bytes()
        row["bytes_per_triangle"] = {k: v / row["triangles"] for k, v in memory.items()}
    except Exception as exc:  # SimulationError and friends: reported in the table
        row["error"] = f"{type(exc).__name__}: {exc}"
        return row
    steps = frames * row["steps_per_frame"]
    row["per_step"] = {k: v / steps for k, v in traffic.items()}
    row["per_frame"] = {k: v / frames for k, v in traffic.items()}
    both = [k for k, r in enumerate(replayed) if r]
    row["replayed_frames"] = len(both)
    row["graph_seconds"] = statistics.median(seconds[True][k] for k in both) if both else None
    row["eager_seconds"] = statistics.median(seconds[False][k] for k in both) if both else None
    row["graph_all_seconds"] = statistics.fmean(seconds[True])
    row["eager_all_seconds"] = statistics.fmean(seconds[False])
    return row


def run(cases: list[tuple[str, int, int, int]], device: str,
        progress: Callable[[str], None] = lambda _: None) -> dict[str, Any]:
    """Every case; returns the rows and the section's wall time."""
    started = time.perf_counter()
    rows = [run_case(*case, device=device, progress=progress) for case in cases]
    return {"rows": rows, "seconds": time.perf_counter() - started, "device": device}


def report(results: dict[str, Any]) -> list[str]:
    """Markdown lines of the section."""
    lines = [
        "## The device path: host traffic, graph replay and memory",
        "",
        f"Device: **{results['device']}**. `Simulation(scene)` runs every step on the device "
        "(`pscc/sim/device_step.py`) and reads one small report back per frame; after an eager frame it "
        "records the frame into a graph and replays it. Each scene is run from its start twice, with the graph "
        "and with eager launches (`graph=False`), the two runs interleaved frame by frame (alternating which goes "
        "first) so that both meet the same load of the machine; after the warm-up frames (kernels load, buffers "
        "grow while contact builds up), the measured frames of the graph run are counted from outside with the same "
        "patches as `../shared/tools/host_traffic.py` (reads: `.numpy()`/`.list()`; syncs; uploads: "
        "`assign`, `from_numpy`, arrays built from host data) and checked with ipctk (`has_intersections` on "
        "the whole mesh; for garments on the skinned body, crossings that involve the cloth with stitched pairs "
        "left out, as in the paper-scenes section). "
        "Seconds per frame are medians over the measured frames that the graph run replayed, the eager run's "
        "over the same frames; *fallbacks* are measured frames that a flag sent back to the host path. "
        "Targets (issue 12): reads + syncs <= 2 per frame and 0 per step, uploads only of kinematic targets, "
        "graph >= 1.3x faster than eager on the 2K scenes on the CPU.",
        "",
        "| scene | cloth triangles | measured frames (replayed) | reads / frame | syncs / frame | uploads / frame "
        "| reads + syncs / step | graph s/frame | eager s/frame | eager / graph | fallbacks | intersecting frames "
        "| memory B/triangle |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results["rows"]:
        if r["error"]:
            lines.append(f"| {r['scene']} | {r.get('triangles', '')} | failed: {r['error'][:100]} |"
                         " | | | | | | | | | |")
            continue
        per_frame, per_step = r["per_frame"], r["per_step"]
        ratio = (f"{r['eager_seconds'] / r['graph_seconds']:.2f}x" if r["graph_seconds"] else "")
        graph = f"{r['graph_seconds']:.3f}" if r["graph_seconds"] else ""
        eager = f"{r['eager_seconds']:.3f}" if r["eager_seconds"] else ""
        lines.append(
            f"| {r['scene']} | {r['triangles']:,} | {r['frames']} ({r['replayed_frames']}) | "
            f"{per_frame['reads']:.1f} | "
            f"{per_frame['syncs']:.1f} | {per_frame['uploads']:.1f} | {per_step['reads'] + per_step['syncs']:.2f} | "
            f"{graph} | {eager} | {ratio} | {r['graph_fallbacks']} | {r['intersecting_frames']} of {r['frames']} | "
            f"{r['bytes_per_triangle']['total']:,.0f} |")
    lines += [
        "",
        "Memory per structure, bytes per cloth triangle (the graph run after its last frame; `collision` is the "
        "detector's own accounting over the whole collision mesh, `integrator` includes the model, `device step` "
        "is the report, the targets table and the frame-start copies a fallback restores):",
        "",
        "| scene | cloth triangles | collision | contact springs | projection | intersection check | integrator "
        "| device step | total |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results["rows"]:
        if r["error"]:
            continue
        b = r["bytes_per_triangle"]
        lines.append(f"| {r['scene']} | {r['triangles']:,} | {b['collision']:,.0f} | {b['contact_springs']:,.0f} | "
                     f"{b['projection']:,.0f} | {b['intersection_check']:,.0f} | {b['integrator']:,.0f} | "
                     f"{b.get('device_step', 0):,.0f} | **{b['total']:,.0f}** |")
    lines += ["", f"Runtime of this section: {results['seconds']:.0f} s.", ""]
    return lines
