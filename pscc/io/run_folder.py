"""The output folder of a simulation run: one owner at a time, its identity, manifest and checkpoints.

A run folder ``DIR`` holds

================  ===========================================================================
``run.json``      the run's identity (scene, size, every resolved setting and the content hash of
                  each input file), its status (``running``, ``done``, ``failed``, ``interrupted``)
                  and, after a failure, the error
``manifest.json`` every file the run writes, recorded *before* it is written: single files by
                  name, frame series by pattern and index range
``checkpoint.npz`` the solver state of the last checkpointed frame (atomic, with a SHA-256 digest)
``.pscc.lock``    present while a process owns the folder (an OS-level ``flock``)
================  ===========================================================================

Rules (``pscc simulate``):

* One process at a time: :meth:`RunFolder.open` takes an exclusive, non-blocking lock; a second
  process is refused with the owner's process id.
* A new run refuses a folder that holds another run unless told to overwrite it. Overwriting
  removes exactly the files the old run's manifest lists (frames, OBJ/PLY/USD, pictures, stats,
  checkpoint), nothing else.
* ``--resume`` continues only the same run: its identity must be equal, and a difference is
  reported by setting (``cloth[0].material.density: 0.2 here, 0.1 in the run``). The checkpoint's
  digest, frame and stats must be consistent, and every frame file up to the checkpoint present.
* Every file is written atomically (:mod:`pscc._atomic`), so a run killed at any moment (even
  ``kill -9``) resumes from its last checkpoint and, on the CPU, writes the same frames an
  uninterrupted run writes.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
import shutil
import tempfile
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from pscc._atomic import (
    is_temporary,
    output_error,
    signals_held,
    write_bytes_atomic,
    write_json_atomic,
    write_text_atomic,
)
from pscc.errors import InputError

__all__ = ["CHECKPOINT_FILE", "LOCK_FILE", "MANIFEST_FILE", "RUN_FILE", "RunFolder", "identity_differences",
           "write_text_atomic"]

RUN_FILE = "run.json"
MANIFEST_FILE = "manifest.json"
CHECKPOINT_FILE = "checkpoint.npz"
LOCK_FILE = ".pscc.lock"

STATUSES: tuple[str, ...] = ("running", "done", "failed", "interrupted")
"""Values of ``run.json``'s ``status``."""

_LEGACY_OUTPUTS: tuple[str, ...] = ("frames/frame_*.npz", "obj/frame_*.obj", "ply/frame_*.ply", "animation.usd",
                                    "preview.png", "animation.mp4", CHECKPOINT_FILE, "stats.json", "scene.toml")
"""What pscc wrote into a run folder before manifests existed (removed by ``--overwrite`` there)."""

_SERIES = re.compile(r"^(?P<head>[^{}]*)\{index:0(?P<width>[1-9])d\}(?P<tail>[^{}]*)$")


MAX_FRAME_INDEX = 10**9
"""Largest frame index a manifest may record (a larger one marks the manifest as damaged)."""


def _series_names(pattern: str, first: int, last: int) -> list[str]:
    return [pattern.format(index=i) for i in range(first, last + 1)]


def _series_on_disk(out_dir: Path, pattern: str, first: int, last: int) -> list[Path]:
    """Files of a series that exist, found by listing their folder (never by enumerating the range)."""
    match = _SERIES.match(pattern)
    assert match is not None
    head = Path(match["head"])
    folder = out_dir / head.parent
    name = re.compile(rf"^{re.escape(head.name)}([0-9]{{{match['width']},}}){re.escape(match['tail'])}$")
    if not folder.is_dir():
        return []
    found = []
    for item in folder.iterdir():
        hit = name.match(item.name)
        if hit and first <= int(hit[1]) <= last and pattern.format(index=int(hit[1])) == str(item.relative_to(out_dir)):
            found.append(item)
    return sorted(found)


class RunFolder:
    """One run's output folder, owned by this process between :meth:`open` and :meth:`close`.

    Args:
        out_dir: the folder (created by :meth:`open` when missing).
        identity: JSON-serialisable description of the run; two runs are the same run when their
            identities are equal (:func:`identity_differences` names what differs).

    Use it as ``with RunFolder(dir, identity).open(resume=False, overwrite=False) as folder: ...``.
    """

    def __init__(self, out_dir: Path | str, identity: dict[str, Any]) -> None:
        self.out_dir = Path(out_dir)
        self.identity = json.loads(json.dumps(identity))  # normalised (tuples -> lists)
        self._lock: int | None = None
        self._created = False
        self._claimed = False
        self._resume = False
        self._overwrite = False
        self._manifest: dict[str, Any] = {"files": [], "series": {}}

    # ------------------------------------------------------------------ lifetime

    @property
    def checkpoint_path(self) -> Path:
        """``DIR/checkpoint.npz``."""
        return self.out_dir / CHECKPOINT_FILE

    @property
    def resuming(self) -> bool:
        """Whether the folder was opened to resume its run."""
        return self._resume

    def open(self, *, resume: bool, overwrite: bool) -> RunFolder:
        """Take the folder for this process and check it; nothing is written yet (see :meth:`claim`).

        Creates the folder when missing (removed again by :meth:`close` if the run never claims it).

        Raises:
            InputError: the path is not a folder; another process owns it; it holds another run
                (without ``overwrite``) or any run (without ``resume`` or ``overwrite``); ``resume``
                without a checkpoint of this run, or of a changed scene (the message names the
                settings that differ); an unreadable ``run.json``.
            OutputError: the folder cannot be created.
        """
        if self._lock is not None:
            raise RuntimeError(f"{self.out_dir}: the run folder is open already")
        out = self.out_dir
        if not str(out).strip() or str(out) != str(out).strip():
            raise InputError(repr(str(out)), "--out-dir", "is empty or starts or ends with spaces",
                             "name a folder for the run, e.g. --out-dir runs/drape")
        try:
            if out.resolve() == Path(out.resolve().anchor):
                raise InputError(str(out), "--out-dir", "is the root of the file system",
                                 "name a folder of its own for the run")
            if out.exists() and not out.is_dir():
                raise InputError(str(out), "--out-dir", "exists and is not a folder", "pick another --out-dir")
            if not out.exists():
                try:
                    out.mkdir(parents=True)
                except FileExistsError:
                    pass
                else:
                    self._created = True
        except OSError as error:
            raise output_error(out, error, "--out-dir") from None
        try:
            self._lock = _acquire_lock(out / LOCK_FILE, out)
            self._check(resume=resume, overwrite=overwrite)
        except OSError as error:
            self.close()
            raise output_error(out, error, "--out-dir") from None
        except BaseException:
            self.close()
            raise
        self._resume, self._overwrite = resume, overwrite
        return self

    def _check(self, *, resume: bool, overwrite: bool) -> None:
        out = self.out_dir
        old = self._read_run_file(tolerate_damage=overwrite and not resume)
        if resume:
            if old is None and self.checkpoint_path.exists():
                raise InputError(str(out / RUN_FILE), "--resume", "the folder has a checkpoint but no run.json "
                                 "(the run's identity), so it cannot be checked to be this run",
                                 "start the run over with --overwrite")
            if old is None or not self.checkpoint_path.exists():
                raise InputError(str(out), "--resume", "the folder holds no checkpoint to resume",
                                 "run without --resume to start the run")
            differences = identity_differences(old.get("identity"), self.identity)
            if differences:
                shown = "; ".join(differences[:4]) + (f"; and {len(differences) - 4} more" if len(differences) > 4
                                                      else "")
                raise InputError(str(out / RUN_FILE), "identity",
                                 f"the folder holds another run or the scene changed since it started ({shown})",
                                 "resume with the same scene file, scene and options, or start a new run with "
                                 "--overwrite or another --out-dir")
            self._manifest = self._read_manifest(tolerate_damage=False) or self._legacy_manifest()
            return
        stale = old is not None or (out / "frames").exists() or (out / MANIFEST_FILE).exists()
        if stale and not overwrite:
            what = _describe(old.get("identity") if old else None) if old is not None else \
                "frames of an unknown run"
            raise InputError(str(out), "--out-dir", f"already holds a run ({what})",
                             "pass --resume to continue it, --overwrite to replace it, or another --out-dir")

    def claim(self) -> None:
        """Write ``run.json`` (status ``running``) and the manifest; with ``overwrite``, first remove
        every file of the previous run. Idempotent.

        Raises:
            OutputError: a file cannot be written or removed.
        """
        self._require_open()
        if self._claimed:
            return
        self._check_contained(self._manifest)
        if self._resume:
            self._remove_temporaries()
        else:
            if self._overwrite:
                self._clear_previous()
            self._manifest = {"files": [], "series": {}}
        self._claimed = True
        self._write_manifest()
        self.set_status("running")

    def close(self) -> None:
        """Release the folder (and remove it when :meth:`open` created it and the run left nothing); idempotent."""
        if self._lock is not None:
            _release_lock(self._lock, self.out_dir / LOCK_FILE)
            self._lock = None
        if self._created:
            try:
                self.out_dir.rmdir()  # only when empty
            except OSError:
                pass
            else:
                self._created = False

    def __enter__(self) -> RunFolder:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

    def _require_open(self) -> None:
        if self._lock is None:
            raise RuntimeError(f"{self.out_dir}: open the run folder first (RunFolder.open)")

    # ------------------------------------------------------------------ run.json and status

    def _read_run_file(self, *, tolerate_damage: bool) -> dict[str, Any] | None:
        path = self.out_dir / RUN_FILE
        if not path.exists():
            return None
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            if not isinstance(data, dict) or not isinstance(data.get("identity"), dict):
                raise ValueError("it is not a JSON object with an 'identity' object")
        except (OSError, ValueError) as error:
            if tolerate_damage:
                return {"identity": None}
            raise InputError(str(path), "identity", f"unreadable run file ({error})",
                             "pass --overwrite to replace the run, or pick another --out-dir") from None
        return data

    def set_status(self, status: str, **details: Any) -> None:
        """Rewrite ``run.json`` with ``status`` (one of :data:`STATUSES`) and ``details`` (e.g. ``error``)."""
        if status not in STATUSES:
            raise ValueError(f"unknown status {status!r}")
        self._require_open()
        write_json_atomic(self.out_dir / RUN_FILE, {"identity": self.identity, "status": status, **details},
                          field="--out-dir")

    # ------------------------------------------------------------------ manifest

    def _read_manifest(self, *, tolerate_damage: bool) -> dict[str, Any] | None:
        path = self.out_dir / MANIFEST_FILE
        if not path.exists():
            return None
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            files, series = data["files"], data["series"]
            if not (isinstance(files, list) and all(isinstance(f, str) and _safe_name(f) for f in files)):
                raise ValueError("'files' is not a list of relative file names")
            if not isinstance(series, dict):
                raise ValueError("'series' is not an object")
            for pattern, span in series.items():
                if not (_SERIES.match(pattern) and _safe_name(pattern) and isinstance(span, list) and len(span) == 2
                        and all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= MAX_FRAME_INDEX
                                for v in span)):
                    raise ValueError(f"series {pattern!r} is not a pattern with a [first, last] range")
        except (OSError, ValueError, KeyError, TypeError) as error:
            if tolerate_damage:
                return None
            raise InputError(str(path), "manifest", f"unreadable ({error})",
                             "pass --overwrite to start the run over, or pick another --out-dir") from None
        return {"files": list(files), "series": {p: list(s) for p, s in series.items()}}

    def _legacy_manifest(self) -> dict[str, Any]:
        """The manifest of a folder written before manifests: pscc's own file names found there."""
        files: list[str] = []
        for pattern in _LEGACY_OUTPUTS:
            files += sorted(str(p.relative_to(self.out_dir)) for p in self.out_dir.glob(pattern) if p.is_file())
        return {"files": files, "series": {}}

    def _write_manifest(self) -> None:
        write_json_atomic(self.out_dir / MANIFEST_FILE, self._manifest, field="--out-dir")

    def record(self, *names: str) -> None:
        """Add files (paths relative to the folder) to the manifest before they are written."""
        self._require_open()
        self.claim()
        new = [name for name in names if name not in self._manifest["files"]]
        for name in new:
            if not _safe_name(name):
                raise ValueError(f"{name!r} is not a relative path inside the run folder")
        if new:
            self._manifest["files"] += new
            self._write_manifest()

    def record_series(self, pattern: str, last: int) -> None:
        """Add frame files ``pattern.format(index=i)`` for ``i`` in ``0..last`` to the manifest.

        ``pattern`` holds one ``{index:0Nd}`` field, e.g. ``"frames/frame_{index:05d}.npz"``; a
        series already recorded is extended to ``last`` (never shortened).
        """
        self._require_open()
        self.claim()
        if not _SERIES.match(pattern) or not _safe_name(pattern):
            raise ValueError(f"{pattern!r} is not a relative pattern with one {{index:0Nd}} field")
        first, old_last = self._manifest["series"].get(pattern, [0, -1])
        if last > old_last:
            self._manifest["series"][pattern] = [first, int(last)]
            self._write_manifest()

    def recorded_series(self) -> dict[str, tuple[int, int]]:
        """``{pattern: (first, last)}`` of the manifest."""
        return {p: (int(s[0]), int(s[1])) for p, s in self._manifest["series"].items()}

    def missing_frames(self, last: int) -> list[str]:
        """Recorded frame files with an index up to ``last`` that are not on disk (relative paths)."""
        missing = []
        for pattern, (first, recorded) in self.recorded_series().items():
            top = min(last, recorded)
            present = {str(p.relative_to(self.out_dir)) for p in _series_on_disk(self.out_dir, pattern, first, top)}
            if len(present) < top - first + 1:
                missing += [n for n in _series_names(pattern, first, top) if n not in present]
        return missing

    def _recorded_paths(self, manifest: dict[str, Any]) -> list[Path]:
        """The files of ``manifest`` that exist (series found by listing their folders)."""
        paths = [self.out_dir / name for name in manifest["files"] if os.path.lexists(self.out_dir / name)]
        for pattern, (first, last) in manifest["series"].items():
            paths += _series_on_disk(self.out_dir, pattern, first, last)
        return paths

    def _check_contained(self, manifest: dict[str, Any]) -> None:
        """Refuse a run whose recorded files would lie outside the folder (a sub-folder that is a link)."""
        root = self.out_dir.resolve()
        folders = {Path(name).parent for name in manifest["files"]} | {Path(p).parent for p in manifest["series"]}
        folders |= {Path(name) for name in ("frames", "obj", "ply")}
        for folder in sorted(folders):
            path = self.out_dir / folder
            if folder != Path(".") and (path.is_symlink() or (path.exists() and not path.resolve().is_relative_to(
                    root))):
                raise InputError(str(path), "--out-dir", f"is a link to {path.resolve()}, outside the run folder, "
                                 "so the run would write or delete files there", "remove the link or pick another "
                                 "--out-dir")

    def _clear_previous(self) -> None:
        """Remove exactly the files the previous run recorded (or pscc's legacy names), then its folders if empty.

        The files are first moved into a hidden folder inside the run folder; if one cannot be moved,
        the ones moved so far go back and nothing is lost. Only then is the hidden folder deleted.
        """
        manifest = self._read_manifest(tolerate_damage=True) or self._legacy_manifest()
        self._check_contained(manifest)
        paths = self._recorded_paths(manifest)
        self._remove_temporaries(manifest)
        trash = Path(tempfile.mkdtemp(prefix=".pscc-removed.", dir=self.out_dir))
        moved: list[tuple[Path, Path]] = []
        current = self.out_dir
        try:
            for number, current in enumerate([*paths, *(self.out_dir / n for n in (MANIFEST_FILE, RUN_FILE)
                                                        if (self.out_dir / n).exists())]):
                target = trash / f"{number}"
                os.rename(current, target)
                moved.append((current, target))
        except OSError as error:
            for original, target in reversed(moved):
                os.rename(target, original)
            shutil.rmtree(trash, ignore_errors=True)
            raise output_error(current, error, "--overwrite", action="removed") from None
        shutil.rmtree(trash, ignore_errors=True)
        folders = {path.parent for path, _ in moved if path.parent != self.out_dir}
        folders |= {self.out_dir / name for name in ("frames", "obj", "ply")}  # legacy runs: their frame folders
        for folder in sorted(folders, key=lambda p: len(p.parts), reverse=True):
            try:
                folder.rmdir()
            except OSError:
                pass

    def _remove_temporaries(self, manifest: dict[str, Any] | None = None) -> None:
        """Delete temporary files a killed run left beside the files it recorded (never a finished file)."""
        manifest = manifest or self._manifest
        names = {Path(name).name for name in manifest["files"]} | {MANIFEST_FILE, RUN_FILE, CHECKPOINT_FILE}
        folders = {self.out_dir} | {(self.out_dir / p).parent for p in manifest["series"]}
        heads = {Path(_SERIES.match(p)["head"]).name for p in manifest["series"] if _SERIES.match(p)}
        for folder in folders:
            if not folder.is_dir():
                continue
            for item in folder.iterdir():
                if is_temporary(item.name) and item.is_file() and (
                        any(item.name.startswith(f".{name}.") for name in names)
                        or (heads and any(item.name.startswith(f".{head}") for head in heads))):
                    item.unlink()

    def discard(self) -> None:
        """Remove everything this run wrote (the run stopped before its first simulated frame)."""
        self._require_open()
        if not self._claimed or self._resume:
            return
        self._clear_previous()
        self._claimed = False

    # ------------------------------------------------------------------ checkpoints

    def _identity_digest(self) -> bytes:
        return hashlib.sha256(json.dumps(self.identity, sort_keys=True).encode()).digest()

    def save_checkpoint(self, state: dict[str, np.ndarray], frame: int, frame_stats: list[dict[str, Any]]) -> None:
        """Write the checkpoint of ``frame`` atomically (replacing the previous one)."""
        self.record(CHECKPOINT_FILE)
        arrays = {f"state_{key}": np.asarray(value) for key, value in state.items()}
        arrays["frame"] = np.array([frame], dtype=np.int64)
        arrays["frame_stats"] = np.frombuffer(json.dumps(frame_stats).encode(), dtype=np.uint8)
        arrays["identity"] = np.frombuffer(self._identity_digest(), dtype=np.uint8)
        arrays["digest"] = np.frombuffer(_digest(arrays), dtype=np.uint8)
        buffer = io.BytesIO()
        with signals_held():  # np.savez interrupted half-way fails in its clean-up, hiding the interrupt
            np.savez(buffer, **arrays)
            write_bytes_atomic(self.checkpoint_path, buffer.getvalue(), field="--out-dir")

    def load_checkpoint(self) -> tuple[dict[str, np.ndarray], int, list[dict[str, Any]]]:
        """``(state, frame, frame_stats)`` of the last checkpoint.

        Raises:
            InputError: the checkpoint is missing, damaged (unreadable, or its digest does not match
                its content) or inconsistent (a negative frame, stats for another number of frames).
        """
        path = self.checkpoint_path

        def damaged(problem: str) -> InputError:
            return InputError(str(path), "checkpoint", problem,
                              "run again with --overwrite to start over (the checkpoint cannot be trusted)")

        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {key: data[key] for key in data.files}
        except Exception as error:  # BadZipFile, EOFError, zlib.error, OSError, ValueError: a damaged file
            raise damaged(f"unreadable ({type(error).__name__}: {error})") from None
        stored = arrays.pop("digest", None)
        if stored is None or bytes(stored.astype(np.uint8)) != _digest(arrays):
            raise damaged("its content does not match its digest (damaged or edited)")
        owner = arrays.pop("identity", None)
        if owner is None or bytes(owner.astype(np.uint8)) != self._identity_digest():
            raise damaged("it belongs to another run (its identity differs from run.json's)")
        try:
            frame = int(np.asarray(arrays["frame"]).reshape(-1)[0])
            stats = json.loads(bytes(arrays["frame_stats"].astype(np.uint8)).decode())
        except (KeyError, IndexError, ValueError, TypeError) as error:
            raise damaged(f"unreadable frame or stats ({error})") from None
        if frame < 0:
            raise damaged(f"frame {frame} is negative")
        if not isinstance(stats, list) or len(stats) != frame or not all(isinstance(s, dict) for s in stats):
            raise damaged(f"its stats do not cover frames 1..{frame}")
        state = {key[len("state_"):]: value for key, value in arrays.items() if key.startswith("state_")}
        return state, frame, stats


def _digest(arrays: dict[str, np.ndarray]) -> bytes:
    """SHA-256 over the names, dtypes, shapes and bytes of ``arrays`` (key order independent)."""
    digest = hashlib.sha256()
    for key in sorted(arrays):
        value = np.ascontiguousarray(arrays[key])
        digest.update(f"{key}|{value.dtype.str}|{value.shape}|".encode())
        digest.update(value.tobytes())
    return digest.digest()


def _safe_name(name: str) -> bool:
    """A relative path that stays inside the run folder."""
    path = Path(name)
    return bool(name) and not path.is_absolute() and ".." not in path.parts


def identity_differences(old: Any, new: Any) -> list[str]:
    """What differs between two run identities, one line each, most telling first (empty when equal).

    The ``settings`` object is compared key by key (``cloth[0].material.density: 0.2 here, 0.187 in
    the run``), ``files`` by path (``the content of /path/body.obj changed``); a fingerprint such as
    ``scene_sha256`` is reported only when nothing else explains the difference.
    """
    if not isinstance(old, dict):
        return ["the folder's run has no readable identity"]
    lines: list[str] = []
    fingerprints: list[str] = []
    for key in [*new, *(k for k in old if k not in new)]:
        before, after = old.get(key), new.get(key)
        if _same(before, after):
            continue
        if key == "settings" and isinstance(before, dict) and isinstance(after, dict):
            lines += _compare(before, after, "")
        elif key == "files" and isinstance(before, dict) and isinstance(after, dict):
            for path in [*after, *(p for p in before if p not in after)]:
                if path not in before:
                    lines.append(f"reads {path}, which the run did not")
                elif path not in after:
                    lines.append(f"does not read {path}, which the run did")
                elif before[path] != after[path]:
                    lines.append(f"the content of {path} changed")
        elif key.endswith("sha256"):
            fingerprints.append(f"{key} differs (the scene's arrays changed, though no setting did)")
        else:
            lines += _compare({key: before} if key in old else {}, {key: after} if key in new else {}, "")
    return lines + (fingerprints if not lines else [])


def _same(a: Any, b: Any) -> bool:
    return json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


def _compare(before: dict[str, Any], after: dict[str, Any], prefix: str) -> list[str]:
    lines = []
    for key in [*after, *(k for k in before if k not in after)]:
        name = f"{prefix}{key}"
        if key not in before:
            lines.append(f"{name}: {_short(after[key])} here, not set in the run")
        elif key not in after:
            lines.append(f"{name}: not set here, {_short(before[key])} in the run")
        elif not _same(before[key], after[key]):
            lines.append(f"{name}: {_short(after[key])} here, {_short(before[key])} in the run")
    return lines


def _short(value: Any) -> str:
    text = json.dumps(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _describe(identity: dict[str, Any] | None) -> str:
    if not identity:
        return "unknown"
    return ", ".join(f"{key}={value}" for key, value in identity.items() if not isinstance(value, dict | list))


# ---------------------------------------------------------------------------------------------------
# The folder lock: flock on DIR/.pscc.lock; the file is removed on release.
# ---------------------------------------------------------------------------------------------------


def _acquire_lock(path: Path, out: Path) -> int:
    """Lock ``path`` exclusively without waiting; return its descriptor.

    The lock file is removed on release, so after locking we check that ``path`` still names the
    locked file (another process may have removed it in between) and retry otherwise.
    """
    import fcntl

    while True:
        try:
            handle = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as error:
            raise output_error(out, error, "--out-dir") from None
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            owner = _read_owner(handle)
            os.close(handle)
            raise InputError(str(out), "--out-dir", f"another pscc process{owner} is writing to this folder",
                             "wait for it to finish, or pick another --out-dir") from None
        try:
            same = os.path.samestat(os.fstat(handle), os.stat(path))
        except FileNotFoundError:
            same = False
        if same:
            os.ftruncate(handle, 0)
            os.write(handle, f"{os.getpid()}\n".encode())
            return handle
        os.close(handle)


def _read_owner(handle: int) -> str:
    try:
        text = os.pread(handle, 32, 0).decode().strip()
    except (OSError, UnicodeDecodeError):
        return ""
    return f" (pid {int(text)})" if text.isdigit() else ""


def _release_lock(handle: int, path: Path) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass
    os.close(handle)

