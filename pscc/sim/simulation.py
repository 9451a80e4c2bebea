"""Run a scene frame by frame: the solver, the frame files and ``stats.json`` (``pscc simulate``)."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pscc.errors import InputError
from pscc.io.formats import FrameWriter, parse_formats
from pscc.io.frames import write_frame, write_json_atomic
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

    def __init__(self, scene: Scene, device: str | None = None, contact: ContactConfig | None = None) -> None:
        self.scene = scene
        self.solver = ClothSolver(scene, device=device, contact=contact)
        self.state = self.solver.initial_state()
        self._next = self.solver.initial_state()
        self.frame = 0
        self.frame_stats: list[dict[str, Any]] = []

    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return self.solver.time

    def step_frame(self) -> dict[str, Any]:
        """Advance one frame (``scene.steps_per_frame`` steps); return the frame's stats."""
        started = time.perf_counter()
        steps = []
        for _ in range(self.scene.steps_per_frame):
            stats = self.solver.step(self.state, self._next, self.scene.time_step)
            self.state, self._next = self._next, self.state
            steps.append(stats)
        self.frame += 1
        record = _sum_steps(steps)
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
        writer.write(self.frame, cloth, obstacle_vertices)

    def checkpoint_state(self) -> dict[str, Any]:
        """Solver state plus the frame counter (see :meth:`ClothSolver.state_dict`)."""
        return self.solver.state_dict(self.state)

    def run(self, frames: int, out_dir: Path, progress: bool = True, *, identity: dict[str, Any] | None = None,
            resume: bool = False, overwrite: bool = False, checkpoint_every: int = 10,
            formats: tuple[str, ...] = ("npz",),
            before_first_frame: Callable[[], None] | None = None) -> dict[str, Any]:
        """Simulate up to frame ``frames``, writing frame files, checkpoints and ``stats.json``.

        A new run writes frame 0 (the initial state) and frames 1..``frames``. With ``resume`` the
        run continues from the folder's last checkpoint (frames after it are written again, equal
        on the CPU to those an uninterrupted run writes). See :class:`pscc.io.run_folder.RunFolder`
        for the folder rules.

        Args:
            frames: last frame to write.
            out_dir: output folder.
            progress: show a progress bar with ETA and live counts.
            identity: what makes two runs the same run (default: scene name and sizes).
            resume: continue the run in ``out_dir`` from its checkpoint.
            overwrite: replace another run's output in ``out_dir``.
            checkpoint_every: frames between checkpoints (>= 1).
            formats: output formats (:data:`pscc.io.formats.FORMATS`); NPZ frames are always written
                (checkpoints and ``--resume`` rely on them).
            before_first_frame: called once the folder is claimed, before anything else is written
                (``pscc simulate`` writes ``scene.toml`` there).

        Returns:
            The stats written to ``out_dir/stats.json``.

        Raises:
            InputError: the folder rules refuse ``out_dir``, or ``checkpoint_every`` < 1.
        """
        from pscc.io.run_folder import RunFolder

        if checkpoint_every < 1:
            raise InputError("argument", "--checkpoint-every", f"{checkpoint_every} is below 1", "pass 1 or more")
        if identity is None:
            identity = {"scene": self.scene.name, "cloth_triangles": int(self.scene.faces.shape[0])}
        folder = RunFolder(Path(out_dir), identity)
        folder.prepare(resume=resume, overwrite=overwrite)
        out_dir = Path(out_dir)
        formats = tuple(dict.fromkeys(("npz", *parse_formats(formats))))
        if before_first_frame is not None:
            before_first_frame()
        if resume:
            state, frame, frame_stats = folder.load_checkpoint()
            self.solver.load_state_dict(state, self.state)
            self.frame = frame
            self.frame_stats = frame_stats
            writer = self._frame_writer(out_dir, formats, frame + 1)
        else:
            writer = self._frame_writer(out_dir, formats, None)
            self._write_current(writer)
            folder.save_checkpoint(self.checkpoint_state(), self.frame, self.frame_stats)
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=frames, initial=min(self.frame, frames), unit="frame", desc=self.scene.name,
                       dynamic_ncols=True)
        while self.frame < frames:
            record = self.step_frame()
            self._write_current(writer)
            if self.frame % checkpoint_every == 0 or self.frame == frames:
                folder.save_checkpoint(self.checkpoint_state(), self.frame, self.frame_stats)
            if bar is not None:
                bar.set_postfix(contacts=record["counts"]["contacts"], ccd_hits=record["counts"]["ccd_hits"],
                                halvings=record["counts"]["halvings"], refresh=False)
                bar.update(1)
        writer.close()
        if bar is not None:
            bar.close()
        stats = self.summary()
        write_json_atomic(out_dir / "stats.json", stats)
        return stats

    def summary(self) -> dict[str, Any]:
        """Scene, device, sizes and the per-frame stats."""
        solver = self.solver
        return {
            "scene": self.scene.name,
            "description": self.scene.description,
            "device": str(solver.device),
            "cloth_vertices": int(self.scene.vertices.shape[0]),
            "cloth_triangles": int(self.scene.faces.shape[0]),
            "obstacle_triangles": int(sum(o.faces.shape[0] for o in self.scene.obstacles)),
            "time_step": self.scene.time_step,
            "frame_time": self.scene.frame_time,
            "frames": self.frame_stats,
            "device_bytes": solver.device_bytes(),
        }


def _sum_steps(steps: list[dict[str, Any]]) -> dict[str, Any]:
    """Stage seconds and counts of a frame: sums over its steps (maxima for the sizes)."""
    seconds: dict[str, float] = {}
    counts: dict[str, int] = {}
    for stats in steps:
        for key, value in stats["seconds"].items():
            seconds[key] = seconds.get(key, 0.0) + float(value)
        for key, value in stats["counts"].items():
            if key in ("front_size", "contacts"):
                counts[key] = max(counts.get(key, 0), int(value))
            else:
                counts[key] = counts.get(key, 0) + int(value)
    return {"steps": len(steps), "seconds": seconds, "counts": counts}


def load_stats(path: Path) -> dict[str, Any]:
    """Read a ``stats.json``."""
    return json.loads(Path(path).read_text())
