"""Command-line interface: ``pscc detect``, ``demo``, ``simulate``, ``batch`` and ``scenes`` (also ``python -m pscc``).

The CLI only parses arguments, calls the public API and prints. Exit statuses:

====  =====================================================================================
0     success
1     an internal error (a bug in pscc): one line; set ``PSCC_TRACEBACK=1`` for the traceback
2     bad input or an output that cannot be written (any :class:`pscc.PsccError`, an OS error,
      not enough memory): one line on stderr naming the file, the field and the fix; nothing
      is left half-written
130   interrupted (Ctrl-C): one line; a simulation keeps its last checkpoint for ``--resume``
143   terminated (SIGTERM): as for Ctrl-C
====  =====================================================================================

``pscc batch`` (docs/batch.md) exits with 0 when every run of the sweep is done; 2 for a bad sweep
file (nothing is written and no task starts), a folder that holds a batch without ``--resume``, Ray
missing or unreachable, ``--devices cuda`` on a cluster without GPUs, and when some runs failed
(the others ran to the end; ``summary.json`` holds each error); 130 / 143 after Ctrl-C / SIGTERM,
once the tasks are cancelled (they keep their checkpoints), ``summary.json`` lists what finished and
a local Ray instance is shut down (a cluster named by ``--address`` never is).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import warnings
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from pscc._atomic import write_atomic
from pscc.errors import InputError, OutputError, PsccError
from pscc.errors import one_line as _one_line
from pscc.io.run_folder import RunFolder, write_text_atomic

EXIT_INTERNAL_ERROR = 1
"""Exit status for an internal error (a bug in pscc)."""

EXIT_INPUT_ERROR = 2
"""Exit status for bad input or an unwritable output (any :class:`pscc.PsccError`)."""

EXIT_INTERRUPTED = 130
"""Exit status after Ctrl-C (128 + SIGINT)."""

EXIT_TERMINATED = 143
"""Exit status after SIGTERM (128 + SIGTERM)."""

RENDER_FILES: tuple[str, ...] = ("preview.png", "animation.mp4")
"""Files ``--render`` adds to a run folder."""


def _out_dir(text: str) -> Path:
    """``--out-dir`` as a path; an empty name (which would mean the current folder) is refused."""
    if not text.strip():
        raise InputError(repr(text), "--out-dir", "is empty", "name a folder for the run, e.g. --out-dir runs/drape")
    return Path(text)


def _check_output_file(out: Path, inputs: list[str]) -> None:
    """Refuse an ``--out`` path before any work: wrong suffix, an input file, a folder, an unwritable folder."""
    if out.suffix.lower() != ".npz":
        raise InputError(str(out), "--out", "the output must be an .npz file", "end the path in .npz")
    for name in inputs:
        if out.resolve() == Path(name).resolve() or (out.exists() and os.path.samefile(out, name)):
            raise InputError(str(out), "--out", f"is the input file {name}; writing would destroy it",
                             "name a new file for the pairs")
    if out.is_dir():
        raise InputError(str(out), "--out", "is a folder", "name a file, e.g. pairs.npz")
    folder = out.parent if str(out.parent) else Path(".")
    if not folder.is_dir():
        problem = f"{folder} is not a folder" if folder.exists() else f"folder {folder} does not exist"
        raise InputError(str(out), "--out", problem, "create the folder or pick another path")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(str(out), "--out", f"folder {folder} is not writable", "pick a writable folder")


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
    if out is not None:
        _check_output_file(out, [args.mesh, *([args.end] if args.end else [])])
    device = _device(args.device)
    detector = CollisionDetector(mesh.faces, method=args.method, object_ids=mesh.object_ids, rest=mesh.rest,
                                 device=device)
    result = detector.detect(mesh.vertices, positions_end, thickness=args.thickness)
    if out is not None:
        arrays = _result_arrays(result)
        write_atomic(out, lambda stream: np.savez(stream, **arrays), field="--out")
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
    from pscc.render.video import render_run
    from pscc.scenes import build_scene
    from pscc.sim.simulation import Simulation, scene_identity

    device = _device(args.device) if args.device else ("cuda:0" if _cuda_available() else "cpu")
    on_gpu = device.startswith("cuda")
    triangles = args.triangles or (DEMO_GPU_TRIANGLES if on_gpu else DEMO_CPU_TRIANGLES)
    if args.frames < 1:
        raise InputError("argument", "--frames", f"{args.frames} is below 1", "pass --frames 1 or more")
    scene = build_scene(args.scene, triangles)
    out_dir = _out_dir(args.out_dir)
    print(f"pscc demo on {device}: scene '{scene.name}' ({scene.description}), "
          f"{scene.faces.shape[0]:,} cloth triangles, {args.frames} frames at {1.0 / scene.frame_time:g} fps")
    simulation = Simulation(scene, device=device)
    identity = {**scene_identity(scene, simulation.solver.contact), "demo": True}
    with RunFolder(out_dir, identity).open(resume=False, overwrite=True) as folder:
        stats = simulation.run(args.frames, folder, progress=not args.no_progress)
        per_frame = [f["seconds_total"] for f in stats["frames"]]
        print(f"Simulated {len(per_frame)} frames in {sum(per_frame):.1f} s "
              f"({sum(per_frame) / len(per_frame):.2f} s per frame), every frame intersection-free")
        folder.record(*RENDER_FILES)
        preview, video = render_run(out_dir, fps=1.0 / scene.frame_time, device=device,
                                    progress=not args.no_progress)
    print("Outputs:")
    print(f"  frames   {out_dir}/frames/frame_00000.npz ... frame_{args.frames:05d}.npz")
    print(f"  picture  {preview}")
    print(f"  video    {video}")
    print(f"  stats    {out_dir}/stats.json")
    return 0


def _simulate(args: argparse.Namespace) -> int:
    from pscc.io.formats import parse_formats
    from pscc.scenes.registry import open_scene
    from pscc.sim.contact_config import ContactConfig
    from pscc.sim.simulation import Simulation

    if args.frames is not None and args.frames < 1:
        raise InputError("argument", "--frames", f"{args.frames} is below 1", "pass --frames 1 or more")
    if args.checkpoint_every < 1:
        raise InputError("argument", "--checkpoint-every", f"{args.checkpoint_every} is below 1", "pass 1 or more")
    if args.resume and args.overwrite:
        raise InputError("argument", "--resume", "--resume and --overwrite contradict each other",
                         "pass --resume to continue the run, or --overwrite to start it over")
    formats = parse_formats(args.format)
    device = _device(args.device)
    source = open_scene(args.scene, triangles=args.triangles, scale=args.scale)
    scene = source.scene
    frames = args.frames if args.frames is not None else source.frames
    contact = source.contact or ContactConfig()
    if args.method is not None:
        contact = ContactConfig(**{**contact.__dict__, "method": args.method})
    contact.validate()
    out_dir = _out_dir(args.out_dir)
    resolved = source.resolved_toml(frames, contact)
    with RunFolder(out_dir, source.run_identity(contact)).open(resume=args.resume, overwrite=args.overwrite) as folder:
        described = f"{scene.name}: {scene.description}" if scene.description else scene.name
        print(f"{described}; {scene.faces.shape[0]:,} cloth triangles, "
              f"{sum(o.faces.shape[0] for o in scene.obstacles):,} obstacle triangles, dt = {scene.time_step:.4g} s")
        simulation = Simulation(scene, device=device, contact=contact, graph=not args.no_graph)

        def write_scene_file() -> None:
            folder.record("scene.toml")
            write_text_atomic(out_dir / "scene.toml", resolved, field="--out-dir")

        stats = simulation.run(frames, folder, progress=not args.no_progress, checkpoint_every=args.checkpoint_every,
                               formats=formats, before_first_frame=write_scene_file)
        per_frame = [f["seconds_total"] for f in stats["frames"]]
        print(f"{len(per_frame)} frames in {sum(per_frame):.1f} s ({sum(per_frame) / max(1, len(per_frame)):.2f} s "
              f"per frame) on {stats['device']}")
        print(f"Wrote {out_dir}/frames/frame_00000.npz ... frame_{frames:05d}.npz, {out_dir}/stats.json and "
              f"{out_dir}/scene.toml")
        for name, where in (("obj", "obj/frame_*.obj"), ("ply", "ply/frame_*.ply"), ("usd", "animation.usd")):
            if name in formats:
                print(f"Wrote {out_dir}/{where}")
        if args.render:
            from pscc.render.video import render_run

            folder.record(*RENDER_FILES)
            preview, video = render_run(out_dir, fps=1.0 / scene.frame_time, device=device,
                                        progress=not args.no_progress)
            print(f"Rendered {preview} and {video}")
    return 0


def _batch(args: argparse.Namespace) -> int:
    from pscc.batch.runner import run_batch

    if args.workers is not None and args.workers < 1:
        raise InputError("argument", "--workers", f"{args.workers} is below 1", "pass --workers 1 or more")
    if args.workers is not None and args.address is not None:
        raise InputError("argument", "--workers", "--workers sizes a local Ray instance, but --address names a "
                         "cluster", "leave out --workers: the cluster's resources decide how many runs go at once")
    out_dir = _out_dir(args.out_dir)
    data = run_batch(args.sweep, out_dir, workers=args.workers, address=args.address, devices=args.devices,
                     resume=args.resume, progress=not args.no_progress, echo=print)
    total, ran = len(data["runs"]), sum(1 for r in data["runs"] if r["ran"])
    print(f"{total} run{'s' if total != 1 else ''} done ({ran} run now). Wrote {out_dir}/runs/<run id>/, "
          f"{out_dir}/summary.json and {out_dir}/summary.csv")
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


class _Parser(argparse.ArgumentParser):
    """argparse with pscc's error form: one line on stderr, exit 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_INPUT_ERROR, f"pscc: error: {self.prog}: {' '.join(message.split())}. "
                                    f"Fix: see `{self.prog} --help`\n")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``pscc`` command."""
    from pscc.collision.detector import METHODS

    parser = _Parser(prog="pscc", description="PSCC collision detection on NVIDIA Warp.")
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
    simulate.add_argument("--no-graph", action="store_true",
                          help="launch every step eagerly instead of replaying a recorded graph per frame")
    simulate.add_argument("--resume", action="store_true", help="continue the run in --out-dir from its checkpoint")
    simulate.add_argument("--overwrite", action="store_true", help="replace another run's output in --out-dir")
    simulate.add_argument("--checkpoint-every", type=int, default=10, help="frames between checkpoints")
    simulate.add_argument("--format", default="npz",
                          help="comma-separated output formats: npz (always written), obj, ply, usd")
    simulate.add_argument("--render", action="store_true", help="render preview.png and animation.mp4")
    simulate.set_defaults(run=_simulate)

    batch = sub.add_parser("batch", help="run every combination of a sweep file as a Ray task (docs/batch.md)")
    batch.add_argument("sweep", help="sweep file (.toml): [batch] scenes, frames, size and [batch.vary] key paths")
    batch.add_argument("--out-dir", required=True,
                       help="batch folder: runs/<run id>/, summary.json, summary.csv (a cluster: shared by all nodes)")
    batch.add_argument("--workers", type=int, default=None,
                       help="CPUs of the local Ray instance, i.e. runs at once (default: this machine's cores)")
    batch.add_argument("--address", default=None,
                       help="an existing Ray cluster: auto, HOST:PORT or ray://HOST:PORT (default: start a local one)")
    batch.add_argument("--devices", default=None, choices=("cpu", "cuda"),
                       help="each task takes one CPU, or one GPU (simulating on it); default: cuda when the "
                            "cluster has GPUs, else cpu")
    batch.add_argument("--resume", action="store_true", help="continue the batch in --out-dir: run only the runs "
                                                             "not done, from their checkpoints")
    batch.add_argument("--no-progress", action="store_true", help="no progress bar")
    batch.set_defaults(run=_batch)

    scenes = sub.add_parser("scenes", help="list the built-in scenes with their cloth triangles per scale")
    scenes.add_argument("--json", action="store_true", help="print the list as JSON")
    scenes.set_defaults(run=_scenes)
    return parser


_warp_messages = ""
"""What Warp printed on stderr while it initialised (shown only when a CUDA device is asked for)."""


def _init_warp() -> None:
    """Initialise Warp quietly: its native start-up warnings (no CUDA driver) are kept, not printed."""
    global _warp_messages
    import tempfile

    import warp as wp

    wp.config.log_level = wp.LOG_WARNING
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as capture:
        os.dup2(capture.fileno(), 2)
        try:
            wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        capture.seek(0)
        _warp_messages = capture.read().decode(errors="replace").strip()


def _cuda_available() -> bool:
    import warp as wp

    return bool(wp.is_cuda_available())


def _device(name: str | None) -> str:
    """The Warp device ``--device`` names (``None``: Warp's default), as its alias.

    Raises:
        InputError: no such device here (the message lists the devices there are).
    """
    import warp as wp

    try:
        device = wp.get_device(name)
    except (RuntimeError, ValueError):
        names = ", ".join(d.alias for d in wp.get_devices())
        why = f" ({' '.join(_warp_messages.split())})" if _warp_messages and str(name).startswith("cuda") else ""
        raise InputError("argument", "--device", f"{name!r} is not available on this machine{why}",
                         f"use one of: {names}") from None
    if device.is_cuda and _warp_messages:
        print(_warp_messages, file=sys.stderr)
    return str(device.alias)


def main(argv: list[str] | None = None) -> int:
    """Run the ``pscc`` command; return its exit status (see the module docstring)."""
    previous_handler = _handle_sigterm()
    try:
        with warnings.catch_warnings():
            # NumPy's overflow warnings would print lines before ours; the checks report the problem.
            warnings.simplefilter("ignore", RuntimeWarning)
            parser = build_parser()
            args = parser.parse_args(argv)
            _init_warp()
            return int(args.run(args))
    except KeyboardInterrupt as error:
        notes = " ".join(" ".join(note.split()) for note in getattr(error, "__notes__", []))
        word = "terminated" if isinstance(error, Terminated) else "interrupted"
        print(f"pscc: {word}{'. ' + notes if notes else ''}", file=sys.stderr)
        return EXIT_TERMINATED if isinstance(error, Terminated) else EXIT_INTERRUPTED
    except PsccError as error:
        print(f"pscc: error: {_one_line(error)}", file=sys.stderr)
        return EXIT_INPUT_ERROR
    except MemoryError as error:
        print(f"pscc: error: not enough memory ({_one_line(error)}). Fix: use a smaller scene or a machine with "
              "more memory", file=sys.stderr)
        return EXIT_INPUT_ERROR
    except OSError as error:
        where = f"{error.filename}: file" if error.filename else "argument: path"
        notes = " ".join(" ".join(note.split()) for note in getattr(error, "__notes__", []))
        print(f"pscc: error: {where}: {error.strerror or str(error)}. Fix: check the path, its permissions "
              f"and the free disk space{'. ' + notes if notes else ''}", file=sys.stderr)
        return EXIT_INPUT_ERROR
    except Exception as error:
        if os.environ.get("PSCC_TRACEBACK"):
            raise
        print(f"pscc: internal error: {type(error).__name__}: {_one_line(error)} (a bug in pscc; run again with "
              "PSCC_TRACEBACK=1 for the traceback and report it)", file=sys.stderr)
        return EXIT_INTERNAL_ERROR
    finally:
        if previous_handler is not None:
            signal.signal(signal.SIGTERM, previous_handler)


class Terminated(KeyboardInterrupt):
    """SIGTERM, handled like Ctrl-C: the run stops cleanly and keeps its last checkpoint."""


def _handle_sigterm() -> Any:
    """Turn SIGTERM into :class:`Terminated` (main thread only); return the previous handler or ``None``."""
    def terminate(signum: int, frame: Any) -> None:
        raise Terminated

    try:
        return signal.signal(signal.SIGTERM, terminate)
    except ValueError:  # not the main thread
        return None
