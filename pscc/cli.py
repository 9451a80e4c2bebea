"""Command-line interface: ``pscc detect``, ``demo``, ``simulate`` and ``scenes`` (also ``python -m pscc``).

The CLI only parses arguments, calls the public API and prints. Any :class:`pscc.PsccError`
becomes one line on stderr and exit status 2; nothing is written in that case.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from pscc.errors import InputError, PsccError

EXIT_INPUT_ERROR = 2
"""Exit status for bad input (any :class:`pscc.PsccError`)."""


def _write_npz_atomic(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write an NPZ file through a temporary file in the same folder and an atomic rename."""
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(str(path), "--out", f"folder {folder} does not exist", "create it or pick another path")
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(handle, "wb") as stream:
            np.savez(stream, **arrays)
        os.replace(temporary, path)
    except BaseException:
        if os.path.exists(temporary):
            os.unlink(temporary)
        raise


def _result_arrays(result: Any) -> dict[str, np.ndarray]:
    arrays = {"vertex_face": result.vertex_face, "edge_edge": result.edge_edge}
    if result.vertex_face_toi is not None:
        arrays["vertex_face_toi"] = result.vertex_face_toi
        arrays["edge_edge_toi"] = result.edge_edge_toi
    return arrays


def _print_summary(stats: dict[str, Any]) -> None:
    seconds = stats["seconds"]
    print(f"mesh: {stats['vertex_count']} vertices, {stats['face_count']} faces, {stats['edge_count']} edges")
    print(f"mode: {stats['mode']} (thickness {stats['thickness']:g}), method: {stats['method']}")
    print(f"bounding-volume tests: {stats['bv_tests']:,}; triangle pairs: {stats['triangle_pairs']:,} "
          f"({stats['self_triangle_pairs']:,} self, {stats['inter_triangle_pairs']:,} inter); "
          f"front nodes: {stats['front_size']:,}; candidate feature pairs: {stats['candidate_pairs']:,}")
    print(f"colliding pairs: {stats['vertex_face_pairs']:,} vertex-face, {stats['edge_edge_pairs']:,} edge-edge")
    stages = ", ".join(f"{k} {v * 1e3:.1f} ms" for k, v in seconds.items() if k != "total")
    print(f"time: {seconds['total']:.3f} s ({stages})")
    print(f"device memory: {stats['device_bytes']['total'] / 2**20:.2f} MiB")


def _detect(args: argparse.Namespace) -> int:
    from pscc.collision.detector import CollisionDetector
    from pscc.mesh.io import load_mesh, load_positions

    mesh = load_mesh(args.mesh)
    positions_end = mesh.vertices_end
    if args.end is not None:
        positions_end = load_positions(args.end, mesh.vertex_count)
    out = Path(args.out) if args.out else None
    if out is not None and out.suffix.lower() != ".npz":
        raise InputError(str(out), "--out", "the output must be an .npz file", "end the path in .npz")
    detector = CollisionDetector(mesh.faces, method=args.method, object_ids=mesh.object_ids, rest=mesh.rest,
                                 device=args.device)
    result = detector.detect(mesh.vertices, positions_end, thickness=args.thickness)
    if out is not None:
        _write_npz_atomic(out, _result_arrays(result))
    if args.json:
        print(json.dumps(result.stats))
    else:
        _print_summary(result.stats)
        if out is not None:
            print(f"pairs written to {out}")
    return 0


DEMO_CPU_TRIANGLES = 3000
"""Cloth triangles of the demo scene on a CPU (about a minute on 2 cores)."""

DEMO_GPU_TRIANGLES = 200_000
"""Cloth triangles of the demo scene on a GPU (the paper's resolution for its cloth scenes)."""


def _demo(args: argparse.Namespace) -> int:
    import warp as wp

    from pscc.render.video import render_run
    from pscc.scenes import build_scene
    from pscc.sim.simulation import Simulation

    device = args.device or ("cuda:0" if wp.is_cuda_available() else "cpu")
    on_gpu = wp.get_device(device).is_cuda
    triangles = args.triangles or (DEMO_GPU_TRIANGLES if on_gpu else DEMO_CPU_TRIANGLES)
    if args.frames < 1:
        raise InputError("argument", "--frames", f"{args.frames} is below 1", "pass --frames 1 or more")
    scene = build_scene(args.scene, triangles)
    out_dir = Path(args.out_dir)
    print(f"pscc demo on {device}: scene '{scene.name}' ({scene.description}), "
          f"{scene.faces.shape[0]:,} cloth triangles, {args.frames} frames at {1.0 / scene.frame_time:g} fps")
    simulation = Simulation(scene, device=device)
    identity = {"scene": scene.name, "cloth_triangles": int(scene.faces.shape[0]), "demo": True}
    stats = simulation.run(args.frames, out_dir, progress=not args.no_progress, identity=identity, overwrite=True)
    per_frame = [f["seconds_total"] for f in stats["frames"]]
    print(f"Simulated {len(per_frame)} frames in {sum(per_frame):.1f} s "
          f"({sum(per_frame) / len(per_frame):.2f} s per frame), every frame intersection-free")
    preview, video = render_run(out_dir, fps=1.0 / scene.frame_time, device=device, progress=not args.no_progress)
    print("Outputs:")
    print(f"  frames   {out_dir}/frames/frame_00000.npz ... frame_{args.frames:05d}.npz")
    print(f"  picture  {preview}")
    print(f"  video    {video}")
    print(f"  stats    {out_dir}/stats.json")
    return 0


def _simulate(args: argparse.Namespace) -> int:
    from pscc.io.formats import parse_formats
    from pscc.io.run_folder import write_text_atomic
    from pscc.scenes.registry import open_scene
    from pscc.sim.contact_config import ContactConfig
    from pscc.sim.simulation import Simulation

    if args.frames is not None and args.frames < 1:
        raise InputError("argument", "--frames", f"{args.frames} is below 1", "pass --frames 1 or more")
    formats = parse_formats(args.format)
    source = open_scene(args.scene, triangles=args.triangles, scale=args.scale)
    scene = source.scene
    frames = args.frames if args.frames is not None else source.frames
    contact = source.contact or ContactConfig()
    if args.method is not None:
        contact = ContactConfig(**{**contact.__dict__, "method": args.method})
    contact.validate()
    out_dir = Path(args.out_dir)
    print(f"{scene.name}: {scene.description}; {scene.faces.shape[0]:,} cloth triangles, "
          f"{sum(o.faces.shape[0] for o in scene.obstacles):,} obstacle triangles, dt = {scene.time_step:.4g} s")
    simulation = Simulation(scene, device=args.device, contact=contact)
    identity = {**source.identity, "method": contact.method}
    resolved = source.resolved_toml(frames, contact)
    stats = simulation.run(frames, out_dir, progress=not args.no_progress, identity=identity,
                           resume=args.resume, overwrite=args.overwrite, checkpoint_every=args.checkpoint_every,
                           formats=formats, before_first_frame=lambda: write_text_atomic(out_dir / "scene.toml",
                                                                                          resolved))
    per_frame = [f["seconds_total"] for f in stats["frames"]]
    print(f"{len(per_frame)} frames in {sum(per_frame):.1f} s ({sum(per_frame) / max(1, len(per_frame)):.2f} s per "
          f"frame) on {stats['device']}")
    print(f"Wrote {out_dir}/frames/frame_00000.npz ... frame_{frames:05d}.npz, {out_dir}/stats.json and "
          f"{out_dir}/scene.toml")
    for name, where in (("obj", "obj/frame_*.obj"), ("ply", "ply/frame_*.ply"), ("usd", "animation.usd")):
        if name in formats:
            print(f"Wrote {out_dir}/{where}")
    if args.render:
        from pscc.render.video import render_run

        preview, video = render_run(out_dir, fps=1.0 / scene.frame_time, device=args.device,
                                    progress=not args.no_progress)
        print(f"Rendered {preview} and {video}")
    return 0


def _scenes(args: argparse.Namespace) -> int:
    from pscc.scenes.registry import scene_rows

    rows = scene_rows()
    if args.json:
        print(json.dumps(rows))
        return 0
    for row in rows:
        counts = ", ".join(f"{k}: {v:,}" for k, v in row["triangles"].items())
        label = "scale" if row["kind"] == "paper" else "triangles"
        print(f"{row['name']:<12} {row['kind']:<6} {row['description']}")
        print(f"{'':<19} cloth triangles by {label}: {counts}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``pscc`` command."""
    from pscc.collision.detector import METHODS

    parser = argparse.ArgumentParser(prog="pscc", description="PSCC collision detection on NVIDIA Warp.")
    sub = parser.add_subparsers(dest="command", required=True)

    detect = sub.add_parser("detect", help="find colliding vertex-face and edge-edge pairs of a mesh")
    detect.add_argument("mesh", help="mesh file (.obj, .ply or .npz); an NPZ may carry vertices_end")
    detect.add_argument("--end", help="mesh file with the end-of-step positions (runs CCD)")
    detect.add_argument("--thickness", type=float, default=0.0, help="proximity distance (default 0)")
    detect.add_argument("--method", default=METHODS[0], choices=METHODS, help="detection method")
    detect.add_argument("--device", default=None, help="Warp device, e.g. cpu or cuda:0")
    detect.add_argument("--out", help="write the pairs to this .npz file")
    detect.add_argument("--json", action="store_true", help="print the stats as one JSON line")
    detect.set_defaults(run=_detect)

    from pscc.scenes.builtin import SCENES

    demo = sub.add_parser("demo", help="simulate a default scene sized for this machine; write frames, a picture, "
                                       "a video and stats")
    demo.add_argument("--scene", default="drape", choices=sorted(SCENES), help="scene (default drape)")
    demo.add_argument("--frames", type=int, default=45, help="frames to simulate (default 45)")
    demo.add_argument("--triangles", type=int, default=None,
                      help=f"cloth triangles (default {DEMO_CPU_TRIANGLES} on a CPU, {DEMO_GPU_TRIANGLES} on a GPU)")
    demo.add_argument("--device", default=None, help="Warp device (default: cuda:0 when present, else cpu)")
    demo.add_argument("--out-dir", default="demo-output", help="folder for the outputs (replaced)")
    demo.add_argument("--no-progress", action="store_true", help="no progress bars")
    demo.set_defaults(run=_demo)

    simulate = sub.add_parser("simulate", help="simulate a scene (a name of `pscc scenes` or a .toml file)")
    simulate.add_argument("scene", help="built-in scene name (see `pscc scenes`) or a scene file ending in .toml")
    simulate.add_argument("--frames", type=int, default=None, help="frames to simulate (default: the scene's)")
    simulate.add_argument("--triangles", type=int, default=None, help="cloth triangles (built-in scenes)")
    simulate.add_argument("--scale", type=float, default=None,
                          help="size as a fraction of the paper's resolution (paper scenes) or of the default")
    simulate.add_argument("--device", default=None, help="Warp device, e.g. cpu or cuda:0")
    simulate.add_argument("--method", default=None, choices=METHODS, help="collision detection method")
    simulate.add_argument("--out-dir", default="simulation-output", help="folder for the outputs")
    simulate.add_argument("--no-progress", action="store_true", help="no progress bar")
    simulate.add_argument("--resume", action="store_true", help="continue the run in --out-dir from its checkpoint")
    simulate.add_argument("--overwrite", action="store_true", help="replace another run's output in --out-dir")
    simulate.add_argument("--checkpoint-every", type=int, default=10, help="frames between checkpoints")
    simulate.add_argument("--format", default="npz",
                          help="comma-separated output formats: npz (always written), obj, ply, usd")
    simulate.add_argument("--render", action="store_true", help="render preview.png and animation.mp4")
    simulate.set_defaults(run=_simulate)

    scenes = sub.add_parser("scenes", help="list the built-in scenes with their cloth triangles per scale")
    scenes.add_argument("--json", action="store_true", help="print the list as JSON")
    scenes.set_defaults(run=_scenes)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the ``pscc`` command; return its exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING
    try:
        return int(args.run(args))
    except PsccError as error:
        print(f"pscc: error: {error}", file=sys.stderr)
        return EXIT_INPUT_ERROR
