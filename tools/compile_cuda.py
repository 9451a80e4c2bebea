"""Compile every Warp kernel module of pscc for CUDA ahead of time (no GPU needed: NVRTC).

Imports every module of the package, finds those that define ``@wp.kernel`` functions and runs
``wp.compile_aot_module`` for each requested architecture. A kernel that does not compile for CUDA
makes this script exit with status 1, so ``make test`` fails.

The modules are compiled in ``--jobs`` worker processes (default: one per CPU), each importing pscc and
Warp afresh; NVRTC compiles on the CPU, so two cores halve the wait.

With ``--cache DIR`` the binaries go into a Warp kernel cache at DIR instead (Warp's own layout, under
DIR/<Warp version>), which a machine with a GPU of that architecture loads with ``WARP_CACHE_PATH=DIR``
instead of compiling: on an H200 with 16 cores every pscc module then loaded from a cache made here, and
``pytest -n 16 -k cuda`` took 49 s (BENCHMARKS-cuda.md).

Usage: python tools/compile_cuda.py --arch 80 90 [--out DIR | --cache DIR] [--jobs N]
"""

from __future__ import annotations

import argparse
import importlib
import multiprocessing
import os
import pkgutil
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor

import warp as wp

import pscc


def kernel_modules() -> list[str]:
    """Names of the pscc modules that define at least one Warp kernel."""
    names = []
    for info in pkgutil.walk_packages(pscc.__path__, prefix="pscc."):
        if info.name.endswith("__main__"):
            continue  # entry points run on import
        module = importlib.import_module(info.name)
        warp_module = wp.get_module(module.__name__)
        if warp_module.kernels:
            names.append(info.name)
    return sorted(names)


def _start_worker(cache: str | None = None) -> None:
    """Worker set-up: Warp's log quiet, its kernel cache at ``cache`` when given, Warp initialised once
    per process."""
    wp.config.log_level = wp.LOG_WARNING
    if cache is not None:
        wp.config.kernel_cache_dir = cache
    wp.init()


def compile_module(name: str, arch: list[int], out: str | None) -> tuple[str, str | None, float]:
    """Compile one kernel module for ``arch`` into ``out``, or into the process's kernel cache when ``out``
    is ``None`` (importing it first, so that its kernels are registered in this process).

    Returns:
        ``(arches, error, seconds)``: the compiled architectures ("sm80, sm90") and ``None``, or ``""``
        and the error when the module does not compile.
    """
    started = time.perf_counter()
    importlib.import_module(name)
    try:
        paths = wp.compile_aot_module(name, arch=arch, module_dir=out)
    except Exception as exc:  # report every failing module, then fail
        return "", f"{type(exc).__name__}: {exc}", time.perf_counter() - started
    return ", ".join(p.suffixes[-2].lstrip(".") for p in paths), None, time.perf_counter() - started


def _cpu_count() -> int:
    """The CPUs this process may run on (the affinity mask where the platform has one)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


def main(argv: list[str] | None = None) -> int:
    """Compile each kernel module for each architecture; return the process exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arch", type=int, nargs="+", default=[80, 90], help="SM architectures, e.g. 80 90")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--out", default=None, help="directory for the cubins (default: a temporary one)")
    where.add_argument("--cache", default=None,
                       help="a Warp kernel cache to fill instead (load it elsewhere with WARP_CACHE_PATH=DIR)")
    parser.add_argument("--jobs", type=int, default=_cpu_count(),
                        help="worker processes (default: one per CPU)")
    args = parser.parse_args(argv)
    if args.jobs < 1:
        parser.error(f"--jobs must be at least 1, got {args.jobs}")
    cache = None if args.cache is None else os.path.abspath(args.cache)
    _start_worker(cache)
    names = kernel_modules()
    failures = 0
    with tempfile.TemporaryDirectory() as scratch:
        out = None if cache is not None else args.out or scratch
        # Spawned workers: a fork would copy this process's initialised Warp runtime.
        with ProcessPoolExecutor(max_workers=max(1, min(args.jobs, len(names))), initializer=_start_worker,
                                 initargs=(cache,), mp_context=multiprocessing.get_context("spawn")) as pool:
            jobs = {name: pool.submit(compile_module, name, args.arch, out) for name in names}
            for name, job in jobs.items():  # in module order
                arches, error, seconds = job.result()
                if error is not None:
                    failures += 1
                    print(f"FAILED  {name}: {error}", file=sys.stderr)
                else:
                    print(f"ok      {name} -> {arches} ({seconds:.1f} s)", flush=True)
    print(f"CUDA ahead-of-time compile: {len(names) - failures} of {len(names)} kernel modules compiled "
          f"for sm_{', sm_'.join(str(a) for a in args.arch)}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
