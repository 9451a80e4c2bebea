"""Run a scene frame by frame: the solver, the frame files and ``stats.json`` (``pscc simulate``)."""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable
from numbers import Integral
from pathlib import Path
from typing import Any

import numpy as np

from pscc._atomic import signals_held
from pscc.errors import InputError
from pscc.io.formats import FrameWriter, parse_formats
from pscc.io.frames import write_frame, write_json_atomic
from pscc.io.run_folder import CHECKPOINT_FILE, RunFolder
from pscc.sim.contact_config import ContactConfig
from pscc.sim.scene import Scene
from pscc.sim.solver import ClothSolver


class Simulation:
    """A scene, its solver and its current state.

    Args:
        scene: the scene to simulate.
        device: Warp device name (``None``: Warp's default).
        contact: contact settings (default :class:`ContactConfig`).
    """

    def __init__(self, scene: Scene, device: str | None = None, contact: ContactConfig | None = None, *,
                 graph: bool = True, stage_timing: bool = False) -> None:
        self.scene = scene
        self.solver = ClothSolver(scene, device=device, contact=contact)
        self.state = self.solver.initial_state()
        self._next = self.solver.initial_state()
        self.graph = bool(graph)
        """Record each frame into a graph after one eager frame and replay it (``False``: eager launches)."""
        self.stage_timing = bool(stage_timing)
        """Run every step on the host path (:meth:`ClothSolver.step`), which synchronizes after each stage
        and reports seconds per stage: a profiling mode, slower on a GPU (a host round trip per stage)."""
        self.frame = 0
        self.frame_stats: list[dict[str, Any]] = []
        self._last_checkpoint = 0
        self._last_written = -1

    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return self.solver.time

    def step_frame(self) -> dict[str, Any]:
        """Advance one frame (``scene.steps_per_frame`` steps) on the device path; return the frame's stats.

        See :meth:`ClothSolver.advance_frame`: one small read at the end of the frame, a recorded graph
        replayed when :attr:`graph` is on, and the host path as the fallback for hard steps. With
        :attr:`stage_timing`, the frame runs on the host path and its stats hold seconds per stage.
        """
        started = time.perf_counter()
        if self.stage_timing:
            record = self.solver.advance_frame_host(self.state, self._next, self.scene.time_step,
                                                    self.scene.steps_per_frame)
        else:
            record = self.solver.advance_frame(self.state, self._next, self.scene.time_step,
                                               self.scene.steps_per_frame, graph=self.graph)
        self.frame += 1
        if self.solver.intersecting_pairs or self.solver.initial_crossings and self.frame == 1:
            record["counts"]["intersecting_pairs"] = self.solver.update_tangles(self.state)
        record.update(frame=self.frame, time=self.time, seconds_total=time.perf_counter() - started)
        self.frame_stats.append(record)
        return record

    def write_frame(self, out_dir: Path) -> Path:
        """Write the current state as frame ``self.frame`` (the NPZ contract of ``pscc.io.frames``)."""
        obstacle_vertices, obstacle_faces = self.solver.obstacle_mesh(self.time)
        cloth = self.state.positions.numpy()[: self.solver.cloth_vertex_count]
        return write_frame(out_dir, self.frame, cloth, self.scene.faces, self.scene.object_ids, obstacle_vertices,
                           obstacle_faces)

    def _frame_writer(self, out_dir: Path, formats: tuple[str, ...], resume_from: int | None) -> FrameWriter:
        _, obstacle_faces = self.solver.obstacle_mesh(0.0)
        return FrameWriter(out_dir, formats, self.scene.faces, self.scene.object_ids, obstacle_faces,
                           fps=1.0 / self.scene.frame_time, resume_from=resume_from)

    def _write_current(self, writer: FrameWriter) -> None:
        obstacle_vertices, _ = self.solver.obstacle_mesh(self.time)
        cloth = self.state.positions.numpy()[: self.solver.cloth_vertex_count]
        # The file and the frame run.json will name change together: a signal held through the write
        # lands when the block ends, after both (not between them, naming one frame too few).
        with signals_held():
            writer.write(self.frame, cloth, obstacle_vertices)
            self._last_written = self.frame
        if self.scene.stitches is not None and self.frame_stats and self.frame_stats[-1].get("frame") == self.frame:
            # From the positions just written (no extra device read): how far the seams are open.
            self.frame_stats[-1]["seam_gap"] = seam_gap(cloth, self.scene.stitches)

    def checkpoint_state(self) -> dict[str, Any]:
        """Solver state plus the frame counter (see :meth:`ClothSolver.state_dict`)."""
        return self.solver.state_dict(self.state)

    def run(self, frames: int, out_dir: Path | str | RunFolder, progress: bool = True, *,
            identity: dict[str, Any] | None = None, resume: bool = False, overwrite: bool = False,
            checkpoint_every: int = 10, formats: tuple[str, ...] = ("npz",),
            before_first_frame: Callable[[], None] | None = None) -> dict[str, Any]:
        """Simulate up to frame ``frames``, writing frame files, checkpoints and ``stats.json``.

        A new run writes frame 0 (the initial state) and frames 1..``frames``. With ``resume`` the
        run continues from the folder's last checkpoint (frames after it are written again, equal
        on the CPU to those an uninterrupted run writes). See :class:`pscc.io.run_folder.RunFolder`
        for the folder rules: one process at a time, a manifest of every file written, and an
        identity that ``resume`` must match.

        When the run stops with an error (or Ctrl-C) before its first simulated frame, everything
        it wrote is removed again. Later, the folder keeps the frames written so far, ``run.json``
        and ``stats.json`` say ``failed`` (or ``interrupted``) with the error, and the exception
        carries a note saying what was kept and how to continue.

        Args:
            frames: last frame to write.
            out_dir: output folder, or a :class:`RunFolder` the caller has opened (``identity``,
                ``resume`` and ``overwrite`` are then the folder's).
            progress: show a progress bar with ETA and live counts.
            identity: what makes two runs the same run (default :func:`scene_identity`).
            resume: continue the run in ``out_dir`` from its checkpoint.
            overwrite: replace another run's output in ``out_dir``.
            checkpoint_every: frames between checkpoints (>= 1).
            formats: output formats (:data:`pscc.io.formats.FORMATS`); NPZ frames are always written
                (checkpoints and ``--resume`` rely on them).
            before_first_frame: called once the folder is claimed, before anything else is written
                (``pscc simulate`` writes ``scene.toml`` there; record what it writes with
                :meth:`RunFolder.record`).

        Returns:
            The stats written to ``out_dir/stats.json``.

        Raises:
            InputError: the folder rules refuse ``out_dir``, the checkpoint is damaged or past
                ``frames``, frame files of a resumed run are missing, or ``checkpoint_every`` < 1.
            OutputError: a file cannot be written (full disk, no permission).
        """
        if isinstance(checkpoint_every, bool) or not isinstance(checkpoint_every, Integral) or checkpoint_every < 1:
            raise InputError("argument", "--checkpoint-every", f"{checkpoint_every!r} is not an integer >= 1",
                             "pass 1 or more")
        if isinstance(frames, bool) or not isinstance(frames, Integral) or frames < 1:
            raise InputError("argument", "--frames", f"{frames!r} is not an integer >= 1", "pass --frames 1 or more")
        frames, checkpoint_every = int(frames), int(checkpoint_every)
        formats = tuple(dict.fromkeys(("npz", *parse_formats(formats))))
        if isinstance(out_dir, RunFolder):
            return self._run(out_dir, frames, progress, checkpoint_every, formats, before_first_frame)
        folder = RunFolder(Path(out_dir), identity if identity is not None else scene_identity(self.scene,
                                                                                             self.solver.contact))
        with folder.open(resume=resume, overwrite=overwrite):
            return self._run(folder, frames, progress, checkpoint_every, formats, before_first_frame)

    def _run(self, folder: RunFolder, frames: int, progress: bool, checkpoint_every: int, formats: tuple[str, ...],
             before_first_frame: Callable[[], None] | None) -> dict[str, Any]:
        out_dir = folder.out_dir
        resume = folder.resuming
        start = 0
        if resume:
            state, start, frame_stats = folder.load_checkpoint()
            if start > frames:
                raise InputError("argument", "--frames", f"{frames} is below the run's checkpoint at frame {start}",
                                 f"pass --frames {start} or more to continue the run")
            missing = folder.missing_frames(start)
            if missing:
                raise InputError(str(out_dir / missing[0]), "frames", f"{len(missing)} frame file(s) of the run up "
                                 f"to its checkpoint at frame {start} are missing",
                                 "restore them, or start the run over with --overwrite")
            try:
                self.solver.load_state_dict(state, self.state)
            except InputError as error:
                raise InputError(str(folder.checkpoint_path), error.field, error.problem, error.fix) from None
            self.frame, self.frame_stats = start, frame_stats
        self._last_checkpoint = start
        self._last_written = start if resume else -1
        try:
            # Inside the try: an interrupt that lands just after run.json says "running" (a cancelled
            # batch task) must still record the stop.
            folder.claim()
            for pattern in _series_patterns(formats):
                folder.record_series(pattern, frames)
            folder.record(*(["animation.usd"] if "usd" in formats else []), CHECKPOINT_FILE, "stats.json")
            if before_first_frame is not None:
                before_first_frame()
            writer = self._frame_writer(out_dir, formats, start + 1 if resume else None)
            try:
                if not resume:
                    self._write_current(writer)
                    folder.save_checkpoint(self.checkpoint_state(), self.frame, self.frame_stats)
                self._simulate(folder, writer, frames, progress, checkpoint_every)
            finally:
                writer.close()
        except BaseException as error:
            self._stopped(folder, error)
            raise
        stats = self.summary()
        write_json_atomic(out_dir / "stats.json", {**stats, "status": "done"})
        folder.set_status("done", frame=self.frame)
        return stats

    def _simulate(self, folder: RunFolder, writer: FrameWriter, frames: int, progress: bool,
                  checkpoint_every: int) -> None:
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=frames, initial=min(self.frame, frames), unit="frame", desc=self.scene.name,
                       dynamic_ncols=True)
        try:
            while self.frame < frames:
                record = self.step_frame()
                self._write_current(writer)
                if self.frame % checkpoint_every == 0 or self.frame == frames:
                    with signals_held():  # as in _write_current: the checkpoint and the frame run.json names
                        folder.save_checkpoint(self.checkpoint_state(), self.frame, self.frame_stats)
                        self._last_checkpoint = self.frame
                if bar is not None:
                    seams = {} if "seam_gap" not in record else {"seam_gap_mm": f"{1e3 * record['seam_gap']:.2f}"}
                    bar.set_postfix(contacts=record["counts"]["contacts"], ccd_hits=record["counts"]["ccd_hits"],
                                    halvings=record["counts"]["halvings"], **seams, refresh=False)
                    bar.update(1)
        finally:
            if bar is not None:
                bar.close()

    def _stopped(self, folder: RunFolder, error: BaseException) -> None:
        """Leave the folder in a clear state after ``error`` stopped the run (see :meth:`run`)."""
        out_dir = folder.out_dir
        if not folder.resuming and self._last_written < 1:
            try:
                folder.discard()
            except Exception:  # the original error matters more than a failed clean-up
                pass
            else:
                error.add_note(f"nothing was kept in {out_dir}")
            return
        status = "interrupted" if isinstance(error, KeyboardInterrupt) else "failed"
        message = str(error) or type(error).__name__
        checkpoint, kept = self._last_checkpoint, self._last_written
        recorded = "run.json says why"
        try:
            write_json_atomic(out_dir / "stats.json", {**self.summary(), "status": status, "error": message})
            folder.set_status(status, error=message, frame=kept, checkpoint=checkpoint)
        except Exception as failure:  # e.g. the disk is full: say so, keep the original error
            recorded = f"run.json could not be updated: {failure}"
        if status == "interrupted":
            error.add_note(f"{out_dir} keeps frames 0-{kept}; pass --resume to continue from its checkpoint "
                           f"at frame {checkpoint}")
        else:
            error.add_note(f"{out_dir} keeps frames 0-{kept} of the failed run ({recorded}); "
                           "pass --overwrite to start it again")

    def summary(self) -> dict[str, Any]:
        """Scene, device, graph use (``off``, ``replayed`` or why it is unavailable), sizes and the
        per-frame stats."""
        solver = self.solver
        return {
            "scene": self.scene.name,
            "description": self.scene.description,
            "device": str(solver.device),
            "graph": "off" if not self.graph else ("replayed" if solver.graph_unavailable is None
                                                   else f"unavailable: {solver.graph_unavailable}"),
            "cloth_vertices": int(self.scene.vertices.shape[0]),
            "cloth_triangles": int(self.scene.faces.shape[0]),
            "obstacle_triangles": int(sum(o.faces.shape[0] for o in self.scene.obstacles)),
            "time_step": self.scene.time_step,
            "frame_time": self.scene.frame_time,
            "frames": self.frame_stats,
            "device_bytes": solver.device_bytes(),
        }


def seam_gap(positions: np.ndarray, stitches: np.ndarray) -> float:
    """The largest distance [m] of a sewn vertex from its seam point: ``max |x_i - ((1 - r) x_j + r x_k)|`` over
    the stitch rows ``(i, j, k, r)``; 0 without stitches."""
    rows = np.asarray(stitches, dtype=np.float64).reshape(-1, 4)
    if rows.shape[0] == 0:
        return 0.0
    x = np.asarray(positions, dtype=np.float64)
    i, j, k = (rows[:, c].astype(np.int64) for c in range(3))
    r = rows[:, 3:4]
    return float(np.linalg.norm(x[i] - ((1.0 - r) * x[j] + r * x[k]), axis=1).max())


def _series_patterns(formats: tuple[str, ...]) -> list[str]:
    """Manifest patterns of the per-frame files of ``formats`` (USD is one file)."""
    folders = {"npz": "frames", "obj": "obj", "ply": "ply"}
    return [f"{folders[name]}/frame_{{index:05d}}.{name}" for name in formats if name in folders]


def scene_identity(scene: Scene, contact: ContactConfig) -> dict[str, Any]:
    """The default identity of a run of ``scene``: its name, size and a SHA-256 of everything it is made of.

    The hash covers the cloth arrays (positions, faces, rest shape, object ids, flat-bending faces,
    stitches), the materials, the solver and contact settings, the handles' vertices and positions and the
    obstacles' faces and positions at t = 0 and t = 1 s.
    """
    digest = hashlib.sha256()

    def add(*values: Any) -> None:
        for value in values:
            if isinstance(value, np.ndarray):
                value = np.ascontiguousarray(value)
                digest.update(f"{value.dtype.str}{value.shape}".encode())
                digest.update(value.tobytes())
            else:
                digest.update(repr(value).encode())

    add(np.asarray(scene.vertices, np.float32), np.asarray(scene.faces, np.int32), np.asarray(scene.rest, np.float32),
        np.asarray(scene.object_ids, np.int32), scene.material, scene.solver, contact, scene.frame_time,
        scene.steps_per_frame)
    if scene.flat_bending is not None:
        add(np.asarray(scene.flat_bending, bool))
    if scene.stitches is not None:
        add(np.asarray(scene.stitches, np.float64))
    for handle in scene.handles:
        add(np.asarray(handle.vertices), *(np.asarray(handle.transform(t)[k]) for t in (0.0, 1.0) for k in (0, 1)))
    for obstacle in scene.obstacles:
        add(np.asarray(obstacle.faces), *(np.asarray(obstacle.positions(t), np.float32) for t in (0.0, 1.0)))
    return {"scene": scene.name, "cloth_triangles": int(scene.faces.shape[0]), "method": contact.method,
            "scene_sha256": digest.hexdigest()}
