"""Sewn garments: the example skirt (``examples/garment``) and the garment scenes on the skinned mannequin.

Each skirt case writes the skirt with ``examples/garment/make_skirt.py`` (panels cut into more cells for
the larger case), loads ``skirt.toml`` and simulates its frames on the device path. Each scene case builds
``kungfu``, ``falling`` or ``dance`` (:mod:`pscc.scenes.garments`: pattern panels sewn around the skinned
mannequin) at about 20K cloth triangles and simulates its whole animation. Every frame is checked by
ipctk with the stitched pairs left out (:func:`pscc.bench.oracle.crossings`; only crossings that involve
the cloth count: a skinned body may fold into itself at a bent knee), and the seams' largest gap is
measured from frame 2 on, in thicknesses (the issue-13 bound is 2). Seconds per frame, halved steps,
fallbacks and the simulator's memory are reported.
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

from pscc.bench.oracle import cloth_crossings
from pscc.scenes.scene_file import load_scene_file
from pscc.sim.contact_config import ContactConfig
from pscc.sim.scene import Scene
from pscc.sim.simulation import Simulation, seam_gap

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "garment"
"""The example garment's folder (the bench runs from a checkout)."""

Case = tuple[tuple[int, int], int] | tuple[str, int, int]
"""A skirt case ``((cells along the width, cells along the height), frames)`` or a scene case
``(scene name, cloth triangles, frames)``."""

CASES: list[Case] = [((16, 12), 45), ((100, 50), 45), ("kungfu", 20_000, 85), ("falling", 20_000, 48),
                     ("dance", 20_000, 72)]
"""The shipped skirt (768 triangles) and one of 20,000 triangles, each over the example's 45 frames (1.5 s);
the three garment scenes at 20K cloth triangles over their whole animations."""

QUICK_CASES: list[Case] = [((16, 12), 6), ("dance", 5_000, 4)]
"""The cases of ``--garments quick``."""


def _generator() -> Any:
    spec = importlib.util.spec_from_file_location("make_skirt", EXAMPLE / "make_skirt.py")
    if spec is None or spec.loader is None:
        raise FileNotFoundError(f"{EXAMPLE / 'make_skirt.py'} is missing (run the bench from a checkout)")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _skirt(cells: tuple[int, int]) -> tuple[Scene, ContactConfig]:
    """The example skirt cut into ``cells`` per panel."""
    with tempfile.TemporaryDirectory() as folder:
        _generator().main(Path(folder), cells)
        shutil.copy(EXAMPLE / "skirt.toml", Path(folder) / "skirt.toml")
        scene, contact, _ = load_scene_file(Path(folder) / "skirt.toml")
    return scene, contact


def _garment_scene(name: str, triangles: int) -> tuple[Scene, ContactConfig]:
    """A garment scene at about ``triangles`` cloth triangles."""
    from pscc.scenes.paper import PAPER_SCENES, PAPER_TRIANGLES

    return PAPER_SCENES[name](triangles / PAPER_TRIANGLES[name]), ContactConfig()


def run_case(case: Case, device: str, progress: Callable[[str], None] = lambda _: None) -> dict[str, Any]:
    """Simulate one skirt or garment scene (module docstring) and return its row."""
    if isinstance(case[0], str):
        name, triangles, frames = case  # type: ignore[misc]
        row: dict[str, Any] = {"garment": name, "frames": frames, "error": None}
        scene, contact = _garment_scene(str(name), int(triangles))
    else:
        cells, frames = case  # type: ignore[misc]
        row = {"garment": "skirt example", "cells": list(cells), "frames": frames, "error": None}
        scene, contact = _skirt(cells)
    thickness = float(scene.material[0].thickness if isinstance(scene.material, list) else scene.material.thickness)
    row["triangles"] = int(scene.faces.shape[0])
    row["stitches"] = int(scene.stitches.shape[0])
    stitches = scene.stitches
    cloth_vertices, cloth_faces = int(scene.vertices.shape[0]), int(scene.faces.shape[0])
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
            crossing_frames += int(cloth_crossings(x, faces, cloth_vertices, cloth_faces, stitches).shape[0] > 0)
            progress(f"{row['garment']} {row['triangles']}: frame {frame}/{frames} {seconds[-1]:.2f} s")
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


def run(cases: list[Case], device: str, progress: Callable[[str], None] = lambda _: None) -> dict[str, Any]:
    """Every case; returns the rows and the section's wall time."""
    started = time.perf_counter()
    rows = [run_case(case, device, progress) for case in cases]
    return {"rows": rows, "seconds": time.perf_counter() - started, "device": device}


def report(results: dict[str, Any]) -> list[str]:
    """Markdown lines of the section."""
    lines = [
        "## Sewn garments: the example skirt and the garment scenes",
        "",
        f"Device: **{results['device']}**. The skirt of `examples/garment` (two panels cut from their UV pattern, "
        "sewn at both sides by OBJ stitch lines, hanging from its waistband around a cylinder body) at its shipped "
        "size and with its panels cut into more cells, over the example's frames; and the garment scenes "
        "`kungfu`, `falling` and `dance` (pattern panels sewn at their seams, anchored at their top edges, on the "
        "skinned mannequin: docs/scenes.md) at about 20K cloth triangles over their whole animations; all on the "
        "device path. Every frame is checked by ipctk with the stitched pairs left out "
        "(`pscc.bench.oracle.crossings`; crossings that involve the cloth: the skinned body itself may fold at a "
        "bent knee); the seam gap is the largest distance of a sewn vertex from its seam point from frame 2 on, in "
        "thicknesses (issue 13: at most 2). Seconds per frame leave out the first frame (kernels load, buffers "
        "grow).",
        "",
        "| garment | triangles | stitches | frames | s/frame | first frame s | worst seam gap (h) "
        "| frames with crossings | halved steps | fallbacks | memory B/triangle |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results["rows"]:
        if r["error"]:
            lines.append(f"| {r.get('garment', '')} | {r.get('triangles', '')} | {r.get('stitches', '')} | "
                         f"{r['frames']} | error: {r['error']} | | | | | | |")
            continue
        gap = "" if r["worst_seam_gap_thicknesses"] is None else f"{r['worst_seam_gap_thicknesses']:.2f}"
        lines.append(f"| {r.get('garment', 'skirt example')} | {r['triangles']:,} | {r['stitches']} | {r['frames']} | "
                     f"{r['seconds_per_frame']:.3f} | "
                     f"{r['first_frame_seconds']:.2f} | {gap} | {r['crossing_frames']} of {r['frames']} | "
                     f"{r['halvings']} | {r['fallbacks']} | {r['bytes_per_triangle']:,.0f} |")
    lines += ["", f"Runtime of this section: {results['seconds']:.0f} s.", ""]
    return lines
