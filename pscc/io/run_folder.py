"""The output folder of a simulation run: its identity, checkpoints and the refusal to mix runs.

``DIR/run.json`` names the run (scene, size, settings: whatever the caller puts in ``identity``).
A new run refuses a folder that already holds a run unless told to overwrite it; ``--resume``
continues only the same run. ``DIR/checkpoint.npz`` is written atomically every K frames: the
solver's state (:meth:`pscc.sim.solver.ClothSolver.state_dict`), the frame index and the per-frame
stats so far, so a run killed at any moment (even ``kill -9``) resumes from its last checkpoint and,
on the CPU, writes the same frames an uninterrupted run writes.
"""

from __future__ import annotations

import io
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from pscc.errors import InputError

RUN_FILE = "run.json"
CHECKPOINT_FILE = "checkpoint.npz"


def _write_bytes_atomic(path: Path, data: bytes) -> None:
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(handle, "wb") as stream:
            stream.write(data)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temporary, path)
    except BaseException:
        if os.path.exists(temporary):
            os.unlink(temporary)
        raise


def write_text_atomic(path: Path, text: str) -> None:
    """Write a UTF-8 text file atomically."""
    _write_bytes_atomic(Path(path), text.encode())


class RunFolder:
    """One run's output folder.

    Args:
        out_dir: the folder (created when the run starts).
        identity: JSON-serialisable description of the run; two runs are the same run when their
            identities are equal.
    """

    def __init__(self, out_dir: Path, identity: dict[str, Any]) -> None:
        self.out_dir = Path(out_dir)
        self.identity = json.loads(json.dumps(identity))  # normalised (tuples -> lists)

    @property
    def checkpoint_path(self) -> Path:
        """``DIR/checkpoint.npz``."""
        return self.out_dir / CHECKPOINT_FILE

    def _existing_identity(self) -> dict[str, Any] | None:
        path = self.out_dir / RUN_FILE
        if not path.exists():
            return None
        try:
            return json.loads(path.read_text())["identity"]
        except (ValueError, KeyError) as error:
            raise InputError(str(path), "identity", f"unreadable run file ({error})",
                             "delete the folder or pick another --out-dir") from None

    def prepare(self, *, resume: bool, overwrite: bool) -> None:
        """Check the folder before anything is written, then claim it.

        Raises:
            InputError: the folder holds another run (without ``overwrite``), holds any run and
                neither ``resume`` nor ``overwrite`` is given, ``resume`` without a checkpoint of
                this run, or the path is not a folder.
        """
        out = self.out_dir
        if out.exists() and not out.is_dir():
            raise InputError(str(out), "--out-dir", "exists and is not a folder", "pick another --out-dir")
        existing = self._existing_identity()
        if resume:
            if existing is None or not self.checkpoint_path.exists():
                raise InputError(str(out), "--resume", "the folder holds no checkpoint to resume",
                                 "run without --resume to start the run")
            if existing != self.identity:
                raise InputError(str(out), "--resume", f"the folder holds another run ({_describe(existing)})",
                                 "resume with the same scene and options, or pick another --out-dir")
            self._remove_temporaries()
            return
        stale = existing is not None or (out / "frames").exists()
        if stale and not overwrite:
            what = _describe(existing) if existing is not None else "frames of an unknown run"
            raise InputError(str(out), "--out-dir", f"already holds a run ({what})",
                             "pass --resume to continue it, --overwrite to replace it, or another --out-dir")
        out.mkdir(parents=True, exist_ok=True)
        if stale:
            self._clear()
        _write_bytes_atomic(out / RUN_FILE, json.dumps({"identity": self.identity}, indent=1).encode())

    def _remove_temporaries(self) -> None:
        """Delete temporary files a killed run left behind (never a finished file: those are renamed)."""
        for folder in (self.out_dir, self.out_dir / "frames"):
            if folder.is_dir():
                for item in folder.glob(".*.tmp"):
                    item.unlink()

    def _clear(self) -> None:
        """Remove what earlier runs wrote here (only pscc's own file names)."""
        for folder in ("frames",):
            path = self.out_dir / folder
            if path.is_dir():
                for item in path.glob("frame_*.npz"):
                    item.unlink()
        for name in (CHECKPOINT_FILE, "stats.json"):
            path = self.out_dir / name
            if path.exists():
                path.unlink()
        self._remove_temporaries()

    def save_checkpoint(self, state: dict[str, np.ndarray], frame: int, frame_stats: list[dict[str, Any]]) -> None:
        """Write the checkpoint of ``frame`` atomically (replacing the previous one)."""
        buffer = io.BytesIO()
        arrays = {f"state_{key}": value for key, value in state.items()}
        arrays["frame"] = np.array([frame], dtype=np.int64)
        arrays["frame_stats"] = np.frombuffer(json.dumps(frame_stats).encode(), dtype=np.uint8)
        np.savez(buffer, **arrays)
        _write_bytes_atomic(self.checkpoint_path, buffer.getvalue())

    def load_checkpoint(self) -> tuple[dict[str, np.ndarray], int, list[dict[str, Any]]]:
        """``(state, frame, frame_stats)`` of the last checkpoint.

        Raises:
            InputError: the checkpoint is unreadable.
        """
        try:
            with np.load(self.checkpoint_path) as data:
                state = {key[len("state_"):]: data[key] for key in data.files if key.startswith("state_")}
                frame = int(data["frame"][0])
                stats = json.loads(bytes(data["frame_stats"]).decode())
        except (OSError, ValueError, KeyError) as error:
            raise InputError(str(self.checkpoint_path), "checkpoint", f"unreadable ({error})",
                             "run again with --overwrite to start over") from None
        return state, frame, stats


def _describe(identity: dict[str, Any] | None) -> str:
    if not identity:
        return "unknown"
    return ", ".join(f"{key}={value}" for key, value in identity.items() if not isinstance(value, dict | list))
