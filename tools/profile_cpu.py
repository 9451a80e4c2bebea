"""Where a recorded detection spends its time on the CPU: Linux `perf` samples of graph replays, per Warp kernel.

Warp runs a CPU kernel as machine code it loads itself, so `perf` sees only anonymous addresses. This tool
records the replays under `perf record`, asks Warp where each loaded kernel's entry point lies, reads each
module's object file in the kernel cache (`nm`: its functions, their offsets and sizes) and so attributes
every sample to the function of the kernel module it falls in (a kernel's entry point, or a `wp.func` the
compiler kept out of line). Samples outside every module (Python, NumPy, set-up, and functions the compiler
put in separate sections) are counted as `outside`.

Usage (Linux with `perf`; frames as for tools/profile_detection.py, read by the bench's loader):

    .venv/bin/python tools/profile_cpu.py [--replays 400] [--top 20] [--method pscc] FRAME[:RADIUS[:norest]] ...

Each frame runs in its own `perf record` (a few seconds of set-up, then the replays). Only the samples taken
during the replays count (perf records with CLOCK_MONOTONIC, and the child notes when its replays began and
ended). Reads Warp's loaded modules through its private `warp._src.context` (Warp 1.19).
"""

from __future__ import annotations

import argparse
import bisect
import collections
import ctypes
import dataclasses
import glob
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from profile_detection import parse_frame  # noqa: E402


@dataclasses.dataclass(frozen=True)
class Function:
    """A function of a loaded kernel module: its address range in the process and its names."""

    start: int
    end: int
    module: str
    name: str


def symbol_table(nm_output: str) -> dict[str, tuple[int, int]]:
    """``nm -n -S --defined-only`` lines of text symbols as {name: (offset, size)}."""
    table = {}
    for line in nm_output.splitlines():
        parts = line.split()
        if len(parts) == 4 and parts[2] in "Tt":
            table[parts[3]] = (int(parts[0], 16), int(parts[1], 16))
    return table


def module_functions(module: str, entry_symbol: str, entry_address: int,
                     table: dict[str, tuple[int, int]]) -> list[Function]:
    """The functions of one loaded module: its object file's text symbols moved by the load offset, which
    the entry point of one of its kernels gives (its address in the process minus its offset in the file)."""
    base = entry_address - table[entry_symbol][0]
    return [Function(base + offset, base + offset + size, module, name) for name, (offset, size) in table.items()
            if size > 0]


def attribute(samples: list[int], functions: list[Function]) -> collections.Counter[str]:
    """Samples per ``module:function`` (``outside`` for addresses in none of them)."""
    ordered = sorted(functions, key=lambda f: f.start)
    starts = [f.start for f in ordered]
    counts: collections.Counter[str] = collections.Counter()
    for ip in samples:
        k = bisect.bisect_right(starts, ip) - 1
        if k >= 0 and ip < ordered[k].end:
            counts[f"{ordered[k].module.rsplit('.', 1)[-1]}:{short_name(ordered[k].name)}"] += 1
        else:
            counts["outside"] += 1
    return counts


def replay_samples(script: str, first: float, last: float) -> list[int]:
    """The sampled addresses of ``perf script -F time,ip`` lines (``<seconds>: <hex ip>``) taken between
    ``first`` and ``last`` (seconds of the clock perf recorded with)."""
    samples = []
    for line in script.splitlines():
        stamp, _, ip = line.partition(":")
        try:
            at, address = float(stamp), int(ip.strip(), 16)
        except ValueError:
            continue
        if first <= at <= last:
            samples.append(address)
    return samples


def short_name(symbol: str) -> str:
    """A kernel's entry ``<key>_<hash>_cpu_forward`` as ``<key>``; a C++ function's mangled name kept short."""
    if symbol.endswith("_cpu_forward"):
        return symbol[: -len("_cpu_forward")].rsplit("_", 1)[0]
    return symbol[:60]


def _child(spec: str, method: str, replays: int, map_path: Path) -> int:
    """Under perf: record one detection, replay it, then write where every loaded kernel lies."""
    import warp as wp

    from pscc.bench.user_frames import load_user_frame
    from pscc.collision.detector import CollisionDetector
    from pscc.collision.recorded import RecordedDetection

    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    path, radius, use_rest = parse_frame(spec)
    frame = load_user_frame(str(path), radius)
    detector = CollisionDetector(frame.faces, method=method, rest=frame.rest if use_rest else None,
                                 object_ids=frame.object_ids, device="cpu")
    positions = wp.array(frame.positions, dtype=wp.vec3, device="cpu")
    recorded = RecordedDetection(detector, positions, thickness=frame.radius)
    for _ in range(5):
        recorded.replay()
    first = time.clock_gettime(time.CLOCK_MONOTONIC)  # perf records with this clock (-k CLOCK_MONOTONIC)
    for _ in range(replays):
        wp.capture_launch(recorded.graph)
    last = time.clock_gettime(time.CLOCK_MONOTONIC)
    seconds = (last - first) / replays
    cache = wp.config.kernel_cache_dir
    entries = []
    from warp._src import context

    for module in list(context.user_modules.values()):
        for execution in list(getattr(module, "execs", {}).values()):
            if execution is None or execution.device.is_cuda:
                continue
            for kernel in module.kernels.values():
                try:
                    hooks = execution.get_kernel_hooks(kernel)
                except Exception:  # a kernel of the module not built for this variant
                    continue
                entries.append({"module": module.name, "symbol": execution.get_kernel_mangled_name(kernel)
                                + "_cpu_forward", "address": ctypes.cast(hooks.forward, ctypes.c_void_p).value})
    map_path.write_text(json.dumps({"cache": cache, "seconds": seconds, "frame": frame.name, "first": first,
                                    "last": last, "kernels": entries}))
    return 0


def _functions(kernel_map: dict[str, Any]) -> list[Function]:
    """Every function of every module in the map, from the newest object file of that module holding its entry."""
    functions: list[Function] = []
    done: set[str] = set()
    for entry in kernel_map["kernels"]:
        if entry["module"] in done:
            continue
        objects = sorted(glob.glob(os.path.join(kernel_map["cache"], f"wp_{entry['module']}_*", "*.o")),
                         key=os.path.getmtime, reverse=True)
        for obj in objects:
            table = symbol_table(subprocess.run(["nm", "-n", "-S", "--defined-only", obj], capture_output=True,
                                                text=True, check=True).stdout)
            if entry["symbol"] in table:
                functions += module_functions(entry["module"], entry["symbol"], entry["address"], table)
                done.add(entry["module"])
                break
    return functions


def profile(spec: str, method: str, replays: int, top: int, perf: str) -> None:
    """Record one frame's replays under perf and print the largest shares."""
    with tempfile.TemporaryDirectory() as folder:
        data, map_path = Path(folder) / "perf.data", Path(folder) / "kernels.json"
        subprocess.run([perf, "record", "-q", "-k", "CLOCK_MONOTONIC", "-F", "4000", "-o", str(data), sys.executable,
                        __file__, "--child",
                        str(map_path), "--method", method, "--replays", str(replays), spec], check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        kernel_map = json.loads(map_path.read_text())
        script = subprocess.run([perf, "script", "-i", str(data), "-F", "time,ip"], capture_output=True, text=True,
                                check=True).stdout
    samples = replay_samples(script, kernel_map["first"], kernel_map["last"])
    counts = attribute(samples, _functions(kernel_map))
    total = sum(counts.values())
    print(f"{kernel_map['frame']} {method}: replay {kernel_map['seconds'] * 1e3:.3f} ms, {total} samples", flush=True)
    for name, count in counts.most_common(top):
        print(f"    {100.0 * count / total:5.1f} %  {name}")


def main(argv: list[str] | None = None) -> int:
    """Profile every frame given; return the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("frames", nargs="+", help="FILE[:RADIUS[:norest]]")
    parser.add_argument("--method", default="pscc", choices=("pscc", "spatial-hash"))
    parser.add_argument("--replays", type=int, default=400, help="graph replays recorded per frame")
    parser.add_argument("--top", type=int, default=20, help="functions listed per frame")
    parser.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child is not None:
        return _child(args.frames[0], args.method, max(1, args.replays), Path(args.child))
    perf = shutil.which("perf")
    if perf is None:
        print("profile_cpu: error: `perf` (Linux perf_events) was not found on PATH. Fix: install it (the "
              "linux-tools package of your distribution), or use tools/profile_detection.py for replay times",
              file=sys.stderr)
        return 2
    if shutil.which("nm") is None:
        print("profile_cpu: error: `nm` (GNU binutils), which reads the kernels' object files, was not found on "
              "PATH. Fix: install binutils", file=sys.stderr)
        return 2
    from pscc.bench.user_frames import load_user_frame
    from pscc.errors import PsccError, one_line

    try:  # every frame read (and checked) before anything is recorded
        for spec in args.frames:
            path, radius, _ = parse_frame(spec)
            load_user_frame(str(path), radius)
    except (PsccError, ValueError) as exc:
        message = one_line(exc) if isinstance(exc, PsccError) else f"{exc}. Fix: write FILE[:RADIUS[:norest]]"
        print(f"profile_cpu: error: {message}", file=sys.stderr)
        return 2
    for spec in args.frames:
        try:
            profile(spec, args.method, max(1, args.replays), args.top, perf)
        except subprocess.CalledProcessError as exc:
            detail = (exc.stderr or "").strip().splitlines()[-1:] if isinstance(exc.stderr, str) else []
            print(f"profile_cpu: error: {spec}: `{' '.join(map(str, exc.cmd[:2]))}` failed with exit status "
                  f"{exc.returncode}{': ' + detail[0] if detail else ''}. Fix: if perf refused to record, let this "
                  "user record perf events (sysctl kernel.perf_event_paranoid=1, or run as root); otherwise fix "
                  "what the quoted line names", file=sys.stderr)
            return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
