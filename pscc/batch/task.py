"""One run of a sweep, in its own run folder: what each Ray task of ``pscc batch`` executes.

:func:`run_task` runs a :class:`~pscc.batch.sweep.Run` exactly as ``pscc simulate`` runs a scene: a
:class:`~pscc.sim.simulation.Simulation` writing a :class:`~pscc.io.run_folder.RunFolder` (frames,
checkpoints, ``stats.json``, the resolved ``scene.toml``). It decides from the folder how to start:

==================================================  ============================================
the folder                                          the task
==================================================  ============================================
holds this run, done with at least its frames        returns its record without running
holds a checkpoint                                   resumes from it (a retry after a dead
                                                     worker, or ``--resume``)
holds a start that never reached a checkpoint        starts the run over
is missing or empty                                  starts the run
==================================================  ============================================

It returns a small record (:func:`run_record`) and never raises for a failed run: the error is in the
record (``"status": "failed"``), so Ray does not retry a run that fails on its own. A ``KeyboardInterrupt``
(the batch was cancelled) does propagate, after the run folder recorded it as ``interrupted``.
"""

from __future__ import annotations

import copy
import json
import socket
from pathlib import Path
from typing import Any

import numpy as np

from pscc.batch.sweep import Run
from pscc.errors import InputError, PsccError, one_line
from pscc.io.run_folder import CHECKPOINT_FILE, MANIFEST_FILE, RUN_FILE, RunFolder, identity_differences

__all__ = ["finished", "run_record", "run_task"]


def _read_json(path: Path) -> dict[str, Any] | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def finished(out_dir: Path, frames: int, identity: dict[str, Any]) -> bool:
    """Whether ``out_dir`` holds this run (``identity``), done with at least ``frames`` frames.

    Done means ``run.json`` and ``stats.json`` both say ``done`` (written after the last frame and
    checkpoint) with at least ``frames`` frames.
    """
    run = _read_json(out_dir / RUN_FILE)
    stats = _read_json(out_dir / "stats.json")
    if run is None or stats is None or run.get("status") != "done" or stats.get("status") != "done":
        return False
    frame = run.get("frame")
    if not isinstance(frame, int) or frame < frames or len(stats.get("frames") or []) < frames:
        return False
    return not identity_differences(run.get("identity"), json.loads(json.dumps(identity)))


def run_record(out_dir: Path, *, status: str, error: str | None = None, resumed_from: int | None = None,
               ran: bool = True) -> dict[str, Any]:
    """The result of a run for the batch summary, from its ``stats.json`` (what exists of it).

    Returns:
        ``status``, ``error``, ``frames`` (simulated frames kept: ``stats.json``'s, or the last
        checkpoint's when it holds more, as after a worker died), ``seconds_per_frame`` (mean wall time
        of a frame, ``None`` before the first), ``intersecting_frames`` (frames that ended with
        crossings left, counted by the solver's ``intersecting_pairs``), ``halvings`` (halved time
        steps, summed), ``resumed_from`` (the checkpoint frame this attempt continued from), ``ran``
        (``False``: found done, not run again), ``device`` and ``host`` (this machine's name when ``ran``).
    """
    stats = _read_json(out_dir / "stats.json") or {}
    frames = [f for f in stats.get("frames") or [] if isinstance(f, dict)]
    if status != "done":  # a worker that died wrote no stats.json: its checkpoint holds the frames it kept
        saved = _checkpoint_stats(out_dir / CHECKPOINT_FILE)
        frames = saved if len(saved) > len(frames) else frames
    seconds = [float(f.get("seconds_total", 0.0)) for f in frames]
    counts = [f.get("counts") or {} for f in frames]
    return {
        "status": status,
        "error": error,
        "frames": len(frames),
        "seconds_per_frame": sum(seconds) / len(seconds) if seconds else None,
        "intersecting_frames": sum(1 for c in counts if int(c.get("intersecting_pairs", 0)) > 0),
        "halvings": sum(int(c.get("halvings", 0)) for c in counts),
        "resumed_from": resumed_from,
        "ran": ran,
        "device": stats.get("device"),
        "host": socket.gethostname() if ran else None,
    }


def _checkpoint_stats(path: Path) -> list[dict[str, Any]]:
    """The per-frame stats a checkpoint holds (empty when there is none or it cannot be read)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            stats = json.loads(bytes(np.asarray(data["frame_stats"], dtype=np.uint8)).decode())
    except Exception:  # missing or damaged: RunFolder.load_checkpoint reports it when the run resumes
        return []
    return [f for f in stats if isinstance(f, dict)] if isinstance(stats, list) else []


def _checkpoint_frame(path: Path) -> int | None:
    """The frame of a checkpoint file, or ``None`` when it cannot be read (the run folder then says why)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            return int(np.asarray(data["frame"]).reshape(-1)[0])
    except Exception:  # a damaged file: RunFolder.load_checkpoint reports it
        return None


def _init_warp(device: str) -> str:
    """Initialise Warp quietly in this worker and check that ``device`` is there; return its alias."""
    import warp as wp

    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    try:
        return str(wp.get_device(device).alias)
    except (RuntimeError, ValueError):
        names = ", ".join(d.alias for d in wp.get_devices())
        raise InputError(f"worker on {socket.gethostname()}", "--devices", f"{device!r} is not available there "
                         f"(Warp sees {names})", "pass --devices cpu, or give the Ray workers GPUs") from None


def run_task(run: Run, out_dir: str, device: str) -> dict[str, Any]:
    """Simulate ``run`` in the run folder ``out_dir`` on ``device``; return its record (:func:`run_record`).

    Raises:
        KeyboardInterrupt: the task was cancelled; the folder says ``interrupted`` and keeps its checkpoint.
    """
    from pscc.io.run_folder import write_text_atomic
    from pscc.scenes.registry import source_from_toml
    from pscc.sim.contact_config import ContactConfig
    from pscc.sim.simulation import Simulation

    folder_path = Path(out_dir)
    resumed_from = None
    try:
        if finished(folder_path, run.frames, run.identity):
            return run_record(folder_path, status="done", ran=False)
        device = _init_warp(device)
        source = source_from_toml(copy.deepcopy(run.document), Path(run.origin))
        contact = source.contact or ContactConfig()
        resume = (folder_path / CHECKPOINT_FILE).is_file() and (folder_path / RUN_FILE).is_file()
        overwrite = not resume and any((folder_path / name).exists() for name in (RUN_FILE, MANIFEST_FILE, "frames"))
        if resume:
            resumed_from = _checkpoint_frame(folder_path / CHECKPOINT_FILE)
        resolved = source.resolved_toml(run.frames, contact)
        with RunFolder(folder_path, source.run_identity(contact)).open(resume=resume, overwrite=overwrite) as folder:
            simulation = Simulation(source.scene, device=device, contact=contact)

            def write_scene_file() -> None:
                folder.record("scene.toml")
                write_text_atomic(folder_path / "scene.toml", resolved, field="--out-dir")

            simulation.run(run.frames, folder, progress=False, checkpoint_every=run.checkpoint_every,
                           formats=run.formats, before_first_frame=write_scene_file)
    except PsccError as error:
        return run_record(folder_path, status="failed", error=one_line(error), resumed_from=resumed_from)
    except Exception as error:  # a bug, or a library's error: the run failed, the batch goes on
        return run_record(folder_path, status="failed", error=f"{type(error).__name__}: {one_line(error)}",
                          resumed_from=resumed_from)
    return run_record(folder_path, status="done", resumed_from=resumed_from)
