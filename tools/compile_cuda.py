"""Compile every Warp kernel module of pscc for CUDA ahead of time (no GPU needed: NVRTC).

Imports every module of the package, finds those that define ``@wp.kernel`` functions and runs
``wp.compile_aot_module`` for each requested architecture. A kernel that does not compile for CUDA
makes this script exit with status 1, so ``make test`` fails.

Usage: python tools/compile_cuda.py --arch 80 90 [--out DIR]
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
import tempfile
import time

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


def main(argv: list[str] | None = None) -> int:
    """Compile each kernel module for each architecture; return the process exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arch", type=int, nargs="+", default=[80, 90], help="SM architectures, e.g. 80 90")
    parser.add_argument("--out", default=None, help="directory for the cubins (default: a temporary one)")
    args = parser.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    names = kernel_modules()
    failures = 0
    with tempfile.TemporaryDirectory() as scratch:
        out = args.out or scratch
        for name in names:
            started = time.perf_counter()
            try:
                paths = wp.compile_aot_module(name, arch=args.arch, module_dir=out)
            except Exception as exc:  # report every failing module, then fail
                failures += 1
                print(f"FAILED  {name}: {type(exc).__name__}: {exc}", file=sys.stderr)
                continue
            arches = ", ".join(p.suffixes[-2].lstrip(".") for p in paths)
            print(f"ok      {name} -> {arches} ({time.perf_counter() - started:.1f} s)")
    print(f"CUDA ahead-of-time compile: {len(names) - failures} of {len(names)} kernel modules compiled "
          f"for sm_{', sm_'.join(str(a) for a in args.arch)}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
