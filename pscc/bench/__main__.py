"""``python -m pscc.bench``: run the benchmarks and write ``BENCHMARKS.md`` (and plots beside it).

Sections:

1. CCD on the exact query benchmark: false negatives (must be 0), false-positive rate per set and
   queries per second on this machine's device.
2. CCD throughput on random trajectories (generic, mostly separated queries).
3. The brute-force detector on folded three-layer cloth at 1K, 4K and 16K triangles (CCD and DCD).
4. The broad phase: pscc against spatial hashing and Newton at 50K and 200K triangles
   (:mod:`pscc.bench.broad_phase`), then on a corpus of frames not designed for pscc (paper scenes at
   tangled moments, Newton's cloth examples, Newton's shirt) against spatial hashing, Newton's
   detector and ipctk's LBVH (:mod:`pscc.bench.corpus_bench`).
5. The cloth simulator side by side with Newton's VBD solver on ``drape`` and ``twist``: seconds per
   frame and frames with intersections (:mod:`pscc.bench.simulator`).
6. The cloth simulator's seconds per stage and device memory per structure on ``drape``, ``stack`` and
   ``twist`` (:mod:`pscc.bench.simulator`).
7. The paper's scenes: seconds per frame, stages and memory per scene on this machine's device (the
   paper's Figure 10; :mod:`pscc.bench.scenes`).
8. The device path: host reads, syncs and uploads per frame, graph replay against eager launches and
   memory per triangle (:mod:`pscc.bench.device_path`).

``--frames FILE ...`` instead benches your own frames (OBJ, PLY, NPZ or USD files exported by any system)
side by side as the corpus of section 4 (:mod:`pscc.bench.user_frames`), and writes only that section
(to ``bench-output/frames.md`` unless ``--out`` says otherwise).

Timings are the median of repeats after a warm-up run that compiles and loads the kernels.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp
from tqdm import tqdm

from pscc._atomic import write_json_atomic, write_text_atomic
from pscc.bench import broad_phase, corpus, corpus_bench, device_path, garments, simulator, user_frames
from pscc.bench import scenes as paper_scenes
from pscc.bench.ccd_queries import load_query_sets
from pscc.collision.detector import CollisionDetector
from pscc.errors import InputError, PsccError, one_line
from pscc.geometry.ccd import edge_edge_ccd, vertex_face_ccd
from pscc.mesh.generate import folded_sheet
from pscc.scenes.paper import PAPER_SCENES

DEFAULT_FRAMES_REPORT: str = "bench-output/frames.md"
"""Where ``--frames`` writes its report when ``--out`` is not given (never over ``BENCHMARKS.md``)."""


def _median_seconds(run: Any, repeats: int) -> float:
    run()  # warm-up: compile and load kernels, allocate
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        run()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def bench_query_sets(device: str, repeats: int) -> list[dict[str, Any]]:
    """CCD on every exact query set: FN, FP and throughput."""
    rows = []
    for query_set in tqdm(load_query_sets(), desc="CCD query sets", leave=False):
        ccd = vertex_face_ccd if query_set.kind == "vertex-face" else edge_edge_ccd
        hit, _ = ccd(query_set.points_t0, query_set.points_t1, device=device)
        seconds = _median_seconds(lambda: ccd(query_set.points_t0, query_set.points_t1, device=device), repeats)
        truth = query_set.truth
        negatives = int((~truth).sum())
        rows.append({
            "set": query_set.name,
            "queries": int(len(truth)),
            "positives": int(truth.sum()),
            "false_negatives": int((truth & ~hit).sum()),
            "false_positives": int((~truth & hit).sum()),
            "false_positive_rate": float((~truth & hit).sum() / negatives) if negatives else 0.0,
            "queries_per_second": len(truth) / seconds,
        })
    return rows


def bench_random_queries(device: str, count: int, repeats: int) -> list[dict[str, Any]]:
    """CCD throughput on random unit-scale trajectories."""
    rng = np.random.default_rng(0)
    x0 = rng.uniform(-1.0, 1.0, (count, 4, 3)).astype(np.float32)
    x1 = (x0 + rng.normal(0.0, 0.3, x0.shape)).astype(np.float32)
    rows = []
    for kind, ccd in (("vertex-face", vertex_face_ccd), ("edge-edge", edge_edge_ccd)):
        hit, _ = ccd(x0, x1, device=device)
        seconds = _median_seconds(lambda ccd=ccd: ccd(x0, x1, device=device), repeats)
        rows.append({"kind": kind, "queries": count, "hit_fraction": float(hit.mean()),
                     "queries_per_second": count / seconds})
    return rows


def bench_brute_force(device: str, sizes: list[int], repeats: int) -> list[dict[str, Any]]:
    """The brute-force detector on folded cloth: CCD over one step and DCD at its end."""
    rows = []
    for triangles in tqdm(sizes, desc="brute-force detector", leave=False):
        mesh = folded_sheet(triangles, layers=3, seed=0)
        detector = CollisionDetector(mesh.faces, method="brute-force", device=device)
        for mode in ("ccd", "dcd"):
            if mode == "ccd":
                def run():
                    return detector.detect(mesh.vertices, mesh.vertices_end)
            else:
                def run():
                    return detector.detect(mesh.vertices_end, thickness=0.005)
            seconds = _median_seconds(run, repeats)
            stats = run().stats
            rows.append({
                "triangles": int(mesh.face_count), "mode": mode, "seconds": seconds,
                "bv_tests": stats["bv_tests"], "candidate_pairs": stats["candidate_pairs"],
                "vertex_face_pairs": stats["vertex_face_pairs"], "edge_edge_pairs": stats["edge_edge_pairs"],
                "device_mib": stats["device_bytes"]["total"] / 2**20,
                "stage_seconds": {k: v for k, v in stats["seconds"].items() if k != "total"},
            })
    return rows


def _plot_brute_force(rows: list[dict[str, Any]], path: Path) -> bool:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    fig, ax = plt.subplots(figsize=(5, 3.5), dpi=120)
    for mode in ("ccd", "dcd"):
        pts = [(r["triangles"], r["seconds"]) for r in rows if r["mode"] == mode]
        ax.loglog([p[0] for p in pts], [p[1] for p in pts], "o-", label=mode.upper())
    ax.set_xlabel("triangles")
    ax.set_ylabel("seconds per detect() call")
    ax.set_title("Brute-force detector (all pairs), folded cloth")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return True


def _progress(bar: Any) -> Any:
    def update(message: str) -> None:
        bar.set_postfix_str(message, refresh=False)
        bar.update(1)

    return update


def write_report(results: dict[str, Any], out: Path) -> None:
    """Write the Markdown report (and its plots) from the benchmark results."""
    env = results["environment"]
    lines = [
        "# Benchmarks",
        "",
        f"Written by `make bench` on {env['date']}. Device: **{env['device']}** ({env['processor']}, "
        f"{env['cpu_count']} cores), Warp {env['warp']}, Python {env['python']}. Median of "
        f"{env['repeats']} runs after a warm-up. Raw numbers: `{out.with_suffix('.json').name}`.",
        "",
    ]
    if "query_sets" in results:
        lines += _detector_lines(results, out)
    if results.get("broad_phase"):
        lines += broad_phase.report(results["broad_phase"])
    if results.get("corpus"):
        path = out.parent / "docs" / "bench-corpus.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        drawn = corpus_bench.plot_corpus(results["corpus"], path)
        lines += corpus_bench.report(results["corpus"], path.relative_to(out.parent).as_posix() if drawn else None)
    if results.get("simulator"):
        lines += simulator.report_comparison(results["simulator"])
    sections = (("simulator_stages", "bench-sim-stages.png", simulator.plot_breakdown, simulator.report_breakdown),
                ("paper_scenes", "bench-paper-scenes.png", paper_scenes.plot_scenes, paper_scenes.report_scenes))
    for key, picture, plot, report in sections:
        if results.get(key):
            path = out.parent / "docs" / picture
            path.parent.mkdir(parents=True, exist_ok=True)
            drawn = plot(results[key], path)
            lines += report(results[key], path.relative_to(out.parent).as_posix() if drawn else None)
    if results.get("device_path"):
        lines += device_path.report(results["device_path"])
    if results.get("garments"):
        lines += garments.report(results["garments"])
    write_text_atomic(out, "\n".join(lines), field="--out")


def _detector_lines(results: dict[str, Any], out: Path) -> list[str]:
    """Sections 1 to 3: CCD query sets, random CCD throughput and the brute-force detector."""
    lines = [
        "## Conservative float32 CCD on the exact query benchmark",
        "",
        "Queries with exact rational ground truth (Wang et al. 2021, `tests/data/ccd-queries`). A false",
        "negative is a missed collision and must never happen; a false positive is a reported contact",
        "that the exact answer rejects. The Erleben sets are hand-made degenerate configurations",
        "(sliding and grazing contact at distances far below float32 resolution), where a conservative",
        "float32 method must report many near misses.",
        "",
        "| set | queries | positives | false negatives | false positives | FP rate | queries/s |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results["query_sets"]:
        lines.append(f"| {r['set']} | {r['queries']} | {r['positives']} | **{r['false_negatives']}** | "
                     f"{r['false_positives']} | {r['false_positive_rate']:.1%} | {r['queries_per_second']:,.0f} |")
    total = results["query_sets"]
    fn = sum(r["false_negatives"] for r in total)
    fp = sum(r["false_positives"] for r in total)
    neg = sum(r["queries"] - r["positives"] for r in total)
    lines += [
        f"| **all** | {sum(r['queries'] for r in total)} | {sum(r['positives'] for r in total)} | **{fn}** | "
        f"{fp} | {fp / max(1, neg):.1%} | |",
        "",
        "## CCD throughput on random trajectories",
        "",
        "Unit-scale random points with random displacements (σ = 0.3): mostly separated pairs, the common",
        "case after a broad phase.",
        "",
        "| kind | queries | hits | queries/s |",
        "|---|---:|---:|---:|",
    ]
    for r in results["random_queries"]:
        lines.append(f"| {r['kind']} | {r['queries']:,} | {r['hit_fraction']:.1%} | {r['queries_per_second']:,.0f} |")
    lines += [
        "",
        "## Brute-force detector",
        "",
        "All vertex-face and edge-edge pairs box-tested, then the narrow phase on overlapping pairs; a",
        "generated three-layer folded cloth (`pscc.mesh.generate.folded_sheet`). CCD over one step from",
        "its start to its end positions (thickness 0); DCD at the end positions with thickness 0.005.",
        "",
        "| triangles | mode | seconds | box tests | candidates | VF pairs | EE pairs | device MiB |",
        "|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results["brute_force"]:
        lines.append(f"| {r['triangles']:,} | {r['mode'].upper()} | {r['seconds']:.3f} | {r['bv_tests']:,} | "
                     f"{r['candidate_pairs']:,} | {r['vertex_face_pairs']:,} | {r['edge_edge_pairs']:,} | "
                     f"{r['device_mib']:.2f} |")
    plot = out.parent / "docs" / "bench-brute-force.png"
    plot.parent.mkdir(parents=True, exist_ok=True)
    if _plot_brute_force(results["brute_force"], plot):
        lines += ["", f"![brute-force time per call]({plot.relative_to(out.parent).as_posix()})"]
    lines.append("")
    return lines


def main(argv: list[str] | None = None) -> int:
    """Run every benchmark and write the report; return the exit status."""
    parser = argparse.ArgumentParser(description="Run the pscc benchmarks and write BENCHMARKS.md.")
    parser.add_argument("--out", default=None,
                        help=f"report path, a .md file; its folder is made, and the raw numbers go beside it as .json "
                        f"(default BENCHMARKS.md; with --frames {DEFAULT_FRAMES_REPORT})")
    parser.add_argument("--device", default=None, help="Warp device (default: Warp's default)")
    parser.add_argument("--repeats", type=int, default=5, help="timed repeats per measurement")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 4000, 16000],
                        help="triangle counts for the brute-force detector")
    parser.add_argument("--broad-phase-sizes", type=int, nargs="*", default=[50000, 200000],
                        help="triangle counts for the broad-phase comparison (none to skip it)")
    parser.add_argument("--corpus", choices=("full", "quick", "skip"), default="full",
                        help="broad phase on realistic frames (paper scenes, Newton's cloth examples, shirt, bunny, "
                        "bear, two CAD assemblies and a cube of slivers) against spatial hashing, Newton and ipctk: "
                        "full (16 frames; about 17 min to "
                        "simulate them the first time, then cached, and about 2 min to measure on 2 CPU cores), "
                        "quick (3 early frames, under a minute) or skip")
    parser.add_argument("--corpus-cache", default=str(corpus.DEFAULT_CACHE_DIR),
                        help="folder of cached corpus frames (default bench-output/corpus)")
    parser.add_argument("--no-newton", action="store_true",
                        help="skip Newton in the broad-phase and the simulator comparisons")
    parser.add_argument("--simulator", choices=("full", "quick", "skip"), default="full",
                        help="cloth simulator against Newton VBD: full (about 5 min on 2 CPU cores), quick (1 min) "
                        "or skip")
    parser.add_argument("--simulator-cases", nargs="+", default=None, metavar="SCENE:TRIANGLES:FRAMES",
                        help="override the simulator comparison's cases (e.g. drape:2000:15 twist:2000:45)")
    parser.add_argument("--stages", choices=("full", "quick", "skip"), default="full",
                        help="cloth simulator seconds per stage and memory: full (10K and 50K, about 2 min on 2 CPU "
                        "cores), quick (2K, 10 s) or skip")
    parser.add_argument("--stage-sizes", type=int, nargs="+", default=None,
                        help="override the cloth triangle counts of the per-stage breakdown")
    parser.add_argument("--stage-frames", type=int, default=None,
                        help="override the measured frames (after the warm-up) of the per-stage breakdown")
    parser.add_argument("--scenes", choices=("full", "quick", "skip"), default="full",
                        help="the paper's scenes, seconds per frame and memory: full (whole animations at about 5K "
                        "triangles and 4 frames at 20K, about 4 min on 2 CPU cores), quick (2 frames each) or skip")
    parser.add_argument("--scene-names", nargs="+", default=None, metavar="SCENE", choices=sorted(PAPER_SCENES),
                        help="only these paper scenes in the scenes section")
    parser.add_argument("--device-path", choices=("full", "quick", "skip"), default="full",
                        help="host traffic, graph against eager and memory of the device path: full (drape, stack, "
                        "twist at 2K and 5K and the paper's twisting, about 6 min on 2 CPU cores), quick (2K drape "
                        "and stack) or skip")
    parser.add_argument("--garments", choices=("full", "quick", "skip"), default="full",
                        help="the example sewn skirt at 768 and 20K triangles over 45 frames, checked by ipctk with "
                        "its seams left out: full (about 2 min on 2 CPU cores), quick (768 triangles, 6 frames) or "
                        "skip")
    parser.add_argument("--only-simulator", action="store_true",
                        help="run only the simulator sections (5 and 6); the report then holds only them")
    parser.add_argument("--frames", nargs="+", default=None, metavar="FILE",
                        help="bench only these frames (" + ", ".join(user_frames.FRAME_EXTENSIONS) + "), side by "
                        "side as the corpus: pscc with and without rest coordinates, spatial hashing, Newton and "
                        "ipctk, with issue 14's targets; the report then holds only them")
    parser.add_argument("--frame-radius", type=float, default=None,
                        help="with --frames: the DCD contact radius (default: half each frame's median edge)")
    parser.add_argument("--usd-time", type=float, default=None,
                        help="with --frames: the time code of the USD files' points to bench (default: the default "
                        "time, else the first time sample)")
    args = parser.parse_args(argv)
    if args.frames is not None:
        return _bench_frames(args)
    out = Path(args.out or "BENCHMARKS.md")
    try:  # before anything is measured: a bad report path ends the run at once, with exit 2
        _check_report_path(out, "BENCHMARKS.md")
    except PsccError as exc:
        print(f"pscc bench: error: {one_line(exc)}", file=sys.stderr)
        return 2
    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    device = wp.get_device(args.device)
    results: dict[str, Any] = {"environment": _environment(device, args.repeats)}
    if not args.only_simulator:
        results["query_sets"] = bench_query_sets(device.alias, args.repeats)
        results["random_queries"] = bench_random_queries(device.alias, 100_000, args.repeats)
        results["brute_force"] = bench_brute_force(device.alias, args.sizes, args.repeats)
        if args.broad_phase_sizes:
            results["broad_phase"] = broad_phase.run(args.broad_phase_sizes, device.alias, args.repeats,
                                                     with_newton=not args.no_newton)
        if args.corpus != "skip":
            quick = args.corpus == "quick"
            with tqdm(desc="broad-phase corpus", unit="frame", leave=False) as bar:
                results["corpus"] = corpus_bench.run(
                    corpus.QUICK_CORPUS if quick else corpus.FULL_CORPUS, device.alias,
                    corpus_bench.QUICK_REPEATS if quick else max(args.repeats, corpus_bench.CORPUS_REPEATS),
                    with_newton=not args.no_newton, cache_dir=Path(args.corpus_cache), progress=_progress(bar))
    if args.simulator != "skip":
        cases = (simulator.parse_cases(args.simulator_cases) if args.simulator_cases else
                 simulator.QUICK_COMPARISON_CASES if args.simulator == "quick" else simulator.COMPARISON_CASES)
        with tqdm(desc="simulator vs Newton", unit="frame", leave=False) as bar:
            results["simulator"] = simulator.run_comparison(cases, device.alias, _progress(bar),
                                                            with_newton=not args.no_newton)
    if args.stages != "skip":
        quick = args.stages == "quick"
        sizes = args.stage_sizes or (simulator.QUICK_BREAKDOWN_SIZES if quick else simulator.BREAKDOWN_SIZES)
        frames = args.stage_frames or (simulator.QUICK_BREAKDOWN_FRAMES if quick else simulator.BREAKDOWN_FRAMES)
        with tqdm(desc="simulator stages", unit="frame", leave=False) as bar:
            results["simulator_stages"] = simulator.run_breakdown(list(simulator.BREAKDOWN_WARMUP), sizes,
                                                                  simulator.BREAKDOWN_WARMUP, frames, device.alias,
                                                                  _progress(bar))
    if args.scenes != "skip":
        with tqdm(desc="paper scenes", unit="frame", leave=False) as bar:
            results["paper_scenes"] = paper_scenes.run_scenes(device.alias, quick=args.scenes == "quick",
                                                              names=args.scene_names, progress=_progress(bar))
    if args.device_path != "skip":
        cases = device_path.QUICK_CASES if args.device_path == "quick" else device_path.CASES
        with tqdm(desc="device path", unit="frame", leave=False) as bar:
            results["device_path"] = device_path.run(cases, device.alias, _progress(bar))
    if args.garments != "skip":
        cases = garments.QUICK_CASES if args.garments == "quick" else garments.CASES
        with tqdm(desc="garments", unit="frame", leave=False) as bar:
            results["garments"] = garments.run(cases, device.alias, _progress(bar))
    try:
        write_json_atomic(out.with_suffix(".json"), results, field="--out")
        write_report(results, out)
    except PsccError as exc:
        print(f"pscc bench: error: {one_line(exc)}", file=sys.stderr)
        return 2
    print(f"wrote {out} and {out.with_suffix('.json')}")
    return 0


def _environment(device: Any, repeats: int) -> dict[str, Any]:
    """The machine, versions and repeats a report states at its top."""
    return {"date": time.strftime("%Y-%m-%d"), "device": device.alias,
            "processor": platform.processor() or platform.machine(), "cpu_count": os.cpu_count(),
            "warp": wp.__version__, "python": platform.python_version(), "repeats": repeats}


def _check_report_path(out: Path, example: str) -> None:
    """Refuse a report path that is a folder or not a Markdown file (its folder is made when it is written).

    Raises:
        InputError: naming ``--out`` and the fix.
    """
    if out.is_dir() or out.suffix.lower() != ".md":
        raise InputError(str(out), "--out", "is a folder" if out.is_dir() else "the report must be a .md file",
                         f"name a Markdown file, e.g. --out {example}")


def _bench_frames(args: argparse.Namespace) -> int:
    """``--frames``: read every file first (a bad file or output path ends the run with exit 2 before anything
    is measured or written), bench them as the corpus, and write only that section."""
    out = Path(args.out or DEFAULT_FRAMES_REPORT)
    try:
        _check_report_path(out, "frames.md")
        frames = user_frames.load_user_frames(args.frames, args.frame_radius, args.usd_time)
    except PsccError as exc:
        print(f"pscc bench: error: {one_line(exc)}", file=sys.stderr)
        return 2
    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    device = wp.get_device(args.device)
    repeats = max(args.repeats, corpus_bench.CORPUS_REPEATS)
    results: dict[str, Any] = {"environment": _environment(device, repeats)}
    with tqdm(total=len(frames), desc="your frames", unit="frame", leave=False) as bar:
        results["corpus"] = corpus_bench.run_frames(frames, device.alias, repeats, with_newton=not args.no_newton,
                                                    progress=_progress(bar))
    env = results["environment"]
    lines = ["# Benchmarks on your frames", "",
             f"Written by `python -m pscc.bench --frames` on {env['date']}. Device: **{env['device']}** "
             f"({env['processor']}, {env['cpu_count']} cores), Warp {env['warp']}, Python {env['python']}. "
             f"Raw numbers: `{out.with_suffix('.json').name}`.", ""]
    try:
        write_json_atomic(out.with_suffix(".json"), results, field="--out")
        picture = out.with_suffix(".png")
        drawn = corpus_bench.plot_corpus(results["corpus"], picture)
        report = corpus_bench.report(results["corpus"], picture.name if drawn else None)
        write_text_atomic(out, "\n".join(lines + report), field="--out")
    except PsccError as exc:
        print(f"pscc bench: error: {one_line(exc)}", file=sys.stderr)
        return 2
    print(f"wrote {out} and {out.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
