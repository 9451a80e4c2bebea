"""Where a recorded detection spends its time: graph replays timed, and one eager call's GPU activities.

For each frame (any file ``python -m pscc.bench --frames`` reads: OBJ, PLY, NPZ, USD, or a cached corpus
frame; read by :func:`pscc.bench.user_frames.load_user_frame`, with its errors) and each method (``pscc``,
``spatial-hash``): a DCD detection at the frame's radius is recorded once
(:class:`pscc.collision.recorded.RecordedDetection`), replayed ``--replays`` times back to back (the
seconds per replay, with and without the counter read a caller needs), and on a CUDA device one more
eager call is timed activity by activity with ``wp.timing_begin`` (kernels, copies, memsets), which adds
a few microseconds to each activity. BENCHMARKS-cuda.md's per-kernel figures come from this script.

Usage: python tools/profile_detection.py --device cuda:0 [--top 14] [--replays 40] [FRAME[:RADIUS[:norest]] ...]
(default: four cached corpus frames in bench-output/corpus: twisting f48, cloth_rollers f3, crazyflie,
unisex_shirt).
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import sys
import time
from pathlib import Path
from typing import Any

import warp as wp

DEFAULT_FRAMES = ("bench-output/corpus/paper-twisting-f48-v1.npz:0.002",
                  "bench-output/corpus/newton-rollers-f3-v1.npz:0.3",
                  "bench-output/corpus/usd-crazyflie_usd-f0-v1.npz:0.0007684:norest",
                  "bench-output/corpus/usd-unisex_shirt_usd-f0-v1.npz:0.5052:norest")


def parse_frame(spec: str) -> tuple[Path, float | None, bool]:
    """``FILE[:RADIUS[:norest]]`` as (path, radius or None for half the median edge, use rest)."""
    parts = spec.split(":")
    radius = float(parts[1]) if len(parts) > 1 and parts[1] else None
    return Path(parts[0]), radius, not (len(parts) > 2 and parts[2] == "norest")


def profile(frame: Any, device: str, replays: int, top: int) -> None:
    """Print one frame's replay times per method and, on CUDA, the eager call's largest activities.

    Args:
        frame: a :class:`pscc.bench.corpus.CorpusFrame` (its rest coordinates are used when it has them).
    """
    from pscc.collision.detector import CollisionDetector
    from pscc.collision.recorded import RecordedDetection

    for method in ("pscc", "spatial-hash"):
        detector = CollisionDetector(frame.faces, method=method, rest=frame.rest, object_ids=frame.object_ids,
                                     device=device)
        positions = wp.array(frame.positions, dtype=wp.vec3, device=device)
        recorded = RecordedDetection(detector, positions, thickness=frame.radius)
        for _ in range(5):
            recorded.replay()
        wp.synchronize_device(device)
        started = time.perf_counter()
        for _ in range(replays):
            wp.capture_launch(recorded.graph)
        wp.synchronize_device(device)
        bare = (time.perf_counter() - started) / replays * 1e3
        started = time.perf_counter()
        for _ in range(replays):
            recorded.replay()
        checked = (time.perf_counter() - started) / replays * 1e3
        line = f"{frame.name} {method}: replay {bare:.3f} ms, replay + counter read {checked:.3f} ms"
        if not wp.get_device(device).is_cuda:
            print(line, flush=True)
            continue
        detector.detect(positions, thickness=frame.radius)
        wp.synchronize_device(device)
        wp.timing_begin(cuda_filter=wp.TIMING_ALL)
        detector.detect(positions, thickness=frame.radius)
        activities = wp.timing_end()
        totals: dict[str, list[float]] = collections.defaultdict(lambda: [0, 0.0])
        for activity in activities:
            totals[activity.name][0] += 1
            totals[activity.name][1] += activity.elapsed
        busy = sum(total for _, total in totals.values())
        print(f"{line}; eager call: {len(activities)} activities, {busy:.3f} ms timed", flush=True)
        for name, (count, total) in sorted(totals.items(), key=lambda item: -item[1][1])[:top]:
            print(f"    {total:7.3f} ms {count:3d}x {name}")


def main(argv: list[str] | None = None) -> int:
    """Profile every frame given (or the default four); return the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("frames", nargs="*", default=list(DEFAULT_FRAMES), help="FILE[:RADIUS[:norest]]")
    parser.add_argument("--device", default=None, help="Warp device (default: Warp's default)")
    parser.add_argument("--replays", type=int, default=40, help="timed graph replays per method")
    parser.add_argument("--top", type=int, default=14, help="activities listed per pscc call (CUDA only)")
    args = parser.parse_args(argv)
    from pscc.bench.user_frames import load_user_frame
    from pscc.errors import PsccError, one_line

    frames = []
    try:  # every file read (and checked) before anything is measured
        for spec in args.frames:
            path, radius, use_rest = parse_frame(spec)
            frame = load_user_frame(str(path), radius)
            frames.append(frame if use_rest else dataclasses.replace(frame, rest=None))
    except (PsccError, ValueError) as exc:
        message = one_line(exc) if isinstance(exc, PsccError) else f"{exc}. Fix: write FILE[:RADIUS[:norest]]"
        print(f"profile_detection: error: {message}", file=sys.stderr)
        return 2
    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    device = wp.get_device(args.device).alias
    for frame in frames:
        profile(frame, device, max(1, args.replays), args.top)
    return 0


if __name__ == "__main__":
    sys.exit(main())
