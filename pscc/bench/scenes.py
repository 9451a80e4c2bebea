"""The paper's scenes on this machine: seconds per frame and memory per scene (the paper's Figure 10).

:func:`run_scenes` simulates every paper scene (:mod:`pscc.scenes.paper`) at the sizes this machine
can afford and records, per run: the device, cloth and collision triangles, seconds per frame (mean,
worst and per stage), the largest contact counts, halved steps, and the device memory of the solver's
structures after the run. Every written-out frame is checked with ipctk's ``has_intersections`` when
ipctk is installed (the check's time is not in the frame time); garment scenes (seams, a skinned body) with
:func:`pscc.bench.oracle.cloth_crossings`.

Two kinds of run per scene:

* ``animation``: the smallest scale (about 5K cloth triangles) for the scene's default frame count
  (``pscc.scenes.registry.DEFAULT_FRAMES``): the whole animation, like the paper's averages;
* ``start``: a larger scale (about 20K cloth triangles by default) for its first few frames: how the
  cost grows with resolution (these frames have less contact than the whole animation's average).
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pscc.bench.oracle import cloth_crossings
from pscc.bench.simulator import STAGES, _check_mesh, intersection_free, pyplot, solver_memory, stage_bars
from pscc.scenes import paper
from pscc.scenes.registry import DEFAULT_FRAMES
from pscc.sim.scene import Scene
from pscc.sim.simulation import Simulation

ANIMATION_TRIANGLES: int = paper.MIN_TRIANGLES
"""Cloth triangles of the whole-animation runs (the smallest scale of every scene)."""

START_TRIANGLES: int = 20_000
"""Cloth triangles of the ``start`` runs."""

START_FRAMES: int = 4
"""Frames of the ``start`` runs."""

QUICK_FRAMES: int = 2
"""Frames of every run with ``--scenes quick``."""


def cloth_intersection_free(scene: Scene, cloth: np.ndarray, t: float) -> bool | None:
    """Whether nothing crosses the cloth (None without ipctk). Scenes with seams or a skinned body are checked
    with :func:`pscc.bench.oracle.cloth_crossings` (stitched pairs are not crossings, and the body may fold into
    itself); the others with ipctk's ``has_intersections`` on the whole mesh."""
    vertices, faces = _check_mesh(scene, cloth, t)
    if scene.stitches is None and all(getattr(o, "rigid", True) for o in scene.obstacles):
        return intersection_free(vertices, faces)
    try:
        found = cloth_crossings(vertices, faces, int(scene.vertices.shape[0]), int(scene.faces.shape[0]),
                                scene.stitches)
    except ImportError:
        return None
    return found.shape[0] == 0


def run_scene(name: str, triangles: int, frames: int, kind: str, device: str,
              progress: Callable[[str], None] = lambda _: None) -> dict[str, Any]:
    """Simulate paper scene ``name`` at about ``triangles`` cloth triangles for ``frames`` frames."""
    scale = max(paper.min_scale(name), triangles / paper.PAPER_TRIANGLES[name])
    scene = paper.PAPER_SCENES[name](scale)
    started = time.perf_counter()
    sim = Simulation(scene, device=device, stage_timing=True)  # the host path: it times every stage
    setup = time.perf_counter() - started
    row: dict[str, Any] = {
        "scene": name, "kind": kind, "scale": scale, "device": device, "triangles": int(scene.faces.shape[0]),
        "collision_triangles": int(sim.solver.collision_faces.shape[0]), "frames": frames,
        "simulated_seconds": frames * scene.frame_time, "setup_seconds": setup, "error": None,
        "intersecting_frames": 0, "checked_frames": 0,
    }
    records = []
    try:
        for frame in range(1, frames + 1):
            record = sim.step_frame()
            records.append(record)
            cloth = sim.state.positions.numpy()[: sim.solver.cloth_vertex_count].astype(np.float64)
            free = cloth_intersection_free(scene, cloth, sim.time)
            if free is not None:
                row["checked_frames"] += 1
                row["intersecting_frames"] += int(not free)
            progress(f"{name} {row['triangles']:,}: frame {frame}/{frames} {record['seconds_total']:.2f} s")
    except Exception as exc:  # SimulationError and friends: reported in the table
        row["error"] = f"{type(exc).__name__}: {exc}"
    row["measured_frames"] = len(records)
    totals = [r["seconds_total"] for r in records]
    row["frame_seconds"] = statistics.fmean(totals) if totals else 0.0
    row["worst_frame_seconds"] = max(totals, default=0.0)
    row["stage_seconds"] = {k: statistics.fmean(r["seconds"].get(k, 0.0) for r in records) if records else 0.0
                            for k in STAGES}
    row["max_counts"] = {k: max((r["counts"].get(k, 0) for r in records), default=0)
                         for k in ("contacts", "ccd_hits", "zone_rounds")}
    row["halvings"] = sum(r["counts"].get("halvings", 0) for r in records)
    row["device_bytes"] = solver_memory(sim)
    return row


def run_scenes(device: str, quick: bool = False, names: list[str] | None = None,
               progress: Callable[[str], None] = lambda _: None) -> dict[str, Any]:
    """Every paper scene (or ``names``): the whole animation at the smallest scale, then the start at 20K."""
    started = time.perf_counter()
    names = names or list(paper.PAPER_SCENES)
    rows = []
    for name in names:
        frames = QUICK_FRAMES if quick else DEFAULT_FRAMES.get(name, 30)
        rows.append(run_scene(name, ANIMATION_TRIANGLES, frames, "animation", device, progress))
    if not quick:
        for name in names:
            rows.append(run_scene(name, START_TRIANGLES, START_FRAMES, "start", device, progress))
    return {"rows": rows, "seconds": time.perf_counter() - started}


def plot_scenes(results: dict[str, Any], path: Path) -> bool:
    """Bar chart of seconds per frame per scene and run kind, stacked by stage; False without matplotlib."""
    plt = pyplot()
    if plt is None:
        return False
    rows = [r for r in results["rows"] if r["measured_frames"]]
    if not rows:
        return False
    labels = [f"{r['scene']}\n{r['triangles'] / 1000:.0f}K" for r in rows]
    fig, ax = plt.subplots(figsize=(max(6.0, 0.8 * len(rows)), 4.0))
    stage_bars(ax, labels, rows)
    ax.set_ylabel("seconds per frame")
    ax.set_title(f"pscc, paper scenes on {rows[0]['device']}")
    ax.legend(fontsize=7, ncol=2)
    ax.tick_params(axis="x", labelsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def report_scenes(results: dict[str, Any], plot: str | None) -> list[str]:
    """Markdown lines for the paper-scenes section."""
    rows = results["rows"]
    device = rows[0]["device"] if rows else "?"
    lines = [
        "## The paper's scenes: seconds per frame and memory (like the paper's Figure 10)",
        "",
        f"Device: **{device}**. Each paper scene (`pscc simulate SCENE`, `docs/scenes.md`) at the sizes this "
        "machine can run: `animation` rows simulate the scene's whole default animation at its smallest scale "
        "(about 5K cloth triangles); `start` rows simulate its first frames at about 20K triangles (less "
        "contact than the whole animation). Seconds per frame are the mean over the frames, solver set-up "
        "excluded; every frame is checked by ipctk's `has_intersections` (check time not included; the garment "
        "scenes by ipctk's edge-face test for crossings that involve the cloth, stitched pairs left out). The paper "
        "reports 0.6-11 s per frame at 80K-1M triangles on a Titan Xp; "
        + ("this machine is a CPU. " if str(device).startswith("cpu") else f"this run is on {device}. ")
        + "The runs use the "
        "host path (`Simulation(stage_timing=True)`), which times every stage; the default device path with "
        "graph replay is measured in the device-path section.",
        "",
        "| scene | run | cloth triangles | scale | frames | s/frame | worst frame | integration share "
        "| max contacts | halved steps | intersecting frames | memory MiB | B/triangle |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        memory = r["device_bytes"]
        total = sum(v for k, v in memory.items() if k != "collision.total")
        share = r["stage_seconds"]["integration"] / r["frame_seconds"] if r["frame_seconds"] else 0.0
        checked = (f"{r['intersecting_frames']} of {r['checked_frames']}" if r["checked_frames"]
                   else "not checked")
        note = f" ({r['error'][:80]})" if r["error"] else ""
        lines.append(f"| {r['scene']} | {r['kind']} | {r['triangles']:,} | {r['scale']:.3f} | "
                     f"{r['measured_frames']}/{r['frames']}{note} | {r['frame_seconds']:.2f} | "
                     f"{r['worst_frame_seconds']:.2f} | {share:.0%} | {r['max_counts']['contacts']:,} | "
                     f"{r['halvings']} | {checked} | {total / 2**20:.1f} | {total / r['triangles']:,.0f} |")
    if plot:
        lines += ["", f"![pscc seconds per frame on the paper's scenes]({plot})"]
    lines += ["", "Memory: every Warp array of the solver after the run (collision structures, contact springs, "
              "intersection check, integrator with its block-sparse system, states), per cloth triangle. The "
              "host path grows every buffer to each frame's exact need and never shrinks it; the default device "
              "path trims buffers to 1.25x their recent peak (the device-path section: its `kungfu` row is this "
              "garment scene on the default path).",
              "", f"Runtime of this section: {results['seconds']:.0f} s.", ""]
    return lines
