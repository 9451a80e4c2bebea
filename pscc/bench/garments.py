"""Sewn garments: the example skirt (``examples/garment``) at its shipped size and at about 20K triangles.

Each case writes the skirt with ``examples/garment/make_skirt.py`` (panels cut into more cells for the
larger case), loads ``skirt.toml`` and simulates its frames on the device path. Every frame is checked
by ipctk with the stitched pairs left out (:func:`pscc.bench.oracle.crossings`), and the seams' largest
gap is measured from frame 2 on, in thicknesses (the issue-13 bound is 2). Seconds per frame, halved
steps, fallbacks and the simulator's memory are reported.
"""

from __future__ import annotations

import importlib.util
import shutil
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pscc.bench.oracle import crossings
from pscc.scenes.scene_file import load_scene_file
from pscc.sim.simulation import Simulation, seam_gap

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "garment"
"""The example garment's folder (the bench runs from a checkout)."""

CASES: list[tuple[tuple[int, int], int]] = [((16, 12), 45), ((100, 50), 45)]
"""(cells per panel along the width and the height, frames): the shipped skirt (768 triangles) and one of
20,000 triangles, each over the example's 45 frames (1.5 s)."""

QUICK_CASES: list[tuple[tuple[int, int], int]] = [((16, 12), 6)]
"""The cases of ``--garments quick``."""


def _generator() -> Any:
    spec = importlib.util.spec_from_file_location("make_skirt", EXAMPLE / "make_skirt.py")
    if spec is None or spec.loader is None:
        raise FileNotFoundError(f"{EXAMPLE / 'make_skirt.py'} is missing (run the bench from a checkout)")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run_case(cells: tuple[int, int], frames: int, device: str,
             progress: Callable[[str], None] = lambda _: None) -> dict[str, Any]:
    """Simulate one skirt (module docstring) and return its row."""
    row: dict[str, Any] = {"cells": list(cells), "frames": frames, "error": None}
    with tempfile.TemporaryDirectory() as folder:
        _generator().main(Path(folder), cells)
        shutil.copy(EXAMPLE / "skirt.toml", Path(folder) / "skirt.toml")
        scene, contact, _ = load_scene_file(Path(folder) / "skirt.toml")
    thickness = float(scene.material[0].thickness if isinstance(scene.material, list) else scene.material.thickness)
    row["triangles"] = int(scene.faces.shape[0])
    row["stitches"] = int(scene.stitches.shape[0])
    stitches = scene.stitches
    seconds: list[float] = []
    gaps: list[float] = []
    crossing_frames = halvings = fallbacks = 0
    try:
        sim = Simulation(scene, device=device, contact=contact)
        faces = sim.solver.collision_faces
        for frame in range(1, frames + 1):
            started = time.perf_counter()
            record = sim.step_frame()
            seconds.append(time.perf_counter() - started)
            halvings += record["counts"]["halvings"]
            fallbacks += record["counts"]["device_fallbacks"]
            x = sim.state.positions.numpy().astype(np.float64)
            if not np.all(np.isfinite(x)):
                raise FloatingPointError(f"frame {frame} holds NaN or Inf")
            if frame >= 2:
                gaps.append(seam_gap(x, stitches))
            crossing_frames += int(crossings(x, faces, stitches).shape[0] > 0)
            progress(f"garment {row['triangles']}: frame {frame}/{frames} {seconds[-1]:.2f} s")
        row["bytes_per_triangle"] = sim.solver.device_bytes()["total"] / row["triangles"]
    except Exception as exc:  # SimulationError and friends: reported in the table
        row["error"] = f"{type(exc).__name__}: {exc}"
        return row
    row["seconds_per_frame"] = statistics.fmean(seconds[1:]) if len(seconds) > 1 else seconds[0]
    row["first_frame_seconds"] = seconds[0]
    row["worst_seam_gap_thicknesses"] = max(gaps) / thickness if gaps else None
    row["crossing_frames"] = crossing_frames
    row["halvings"] = halvings
    row["fallbacks"] = fallbacks
    return row


def run(cases: list[tuple[tuple[int, int], int]], device: str,
        progress: Callable[[str], None] = lambda _: None) -> dict[str, Any]:
    """Every case; returns the rows and the section's wall time."""
    started = time.perf_counter()
    rows = [run_case(cells, frames, device, progress) for cells, frames in cases]
    return {"rows": rows, "seconds": time.perf_counter() - started, "device": device}


def report(results: dict[str, Any]) -> list[str]:
    """Markdown lines of the section."""
    lines = [
        "## Sewn garments: the example skirt",
        "",
        f"Device: **{results['device']}**. The skirt of `examples/garment` (two panels cut from their UV pattern, "
        "sewn at both sides by OBJ stitch lines, hanging from its waistband around a cylinder body) at its shipped "
        "size and with its panels cut into more cells, over the example's frames on the device path. Every frame is "
        "checked by ipctk with the stitched pairs left out (`pscc.bench.oracle.crossings`); the seam gap is the "
        "largest distance of a sewn vertex from its seam point from frame 2 on, in thicknesses (issue 13: at most "
        "2). Seconds per frame leave out the first frame (kernels load, buffers grow).",
        "",
        "| triangles | stitches | frames | s/frame | first frame s | worst seam gap (h) | frames with crossings "
        "| halved steps | fallbacks | memory B/triangle |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results["rows"]:
        if r["error"]:
            lines.append(f"| {r.get('triangles', '')} | {r.get('stitches', '')} | {r['frames']} | error: {r['error']} "
                         "| | | | | | |")
            continue
        gap = "" if r["worst_seam_gap_thicknesses"] is None else f"{r['worst_seam_gap_thicknesses']:.2f}"
        lines.append(f"| {r['triangles']:,} | {r['stitches']} | {r['frames']} | {r['seconds_per_frame']:.3f} | "
                     f"{r['first_frame_seconds']:.2f} | {gap} | {r['crossing_frames']} of {r['frames']} | "
                     f"{r['halvings']} | {r['fallbacks']} | {r['bytes_per_triangle']:,.0f} |")
    lines += ["", f"Runtime of this section: {results['seconds']:.0f} s.", ""]
    return lines
