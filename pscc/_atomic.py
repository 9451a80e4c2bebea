"""Atomic file output: the one way pscc writes a file.

Every output goes to a temporary sibling (``.NAME.XXXXXX.tmpSUFFIX`` in the destination folder),
is flushed to disk and then renamed over the destination with ``os.replace``. A reader therefore
sees the old file or the new one, never half a file; a failed or interrupted write (an exception,
Ctrl-C) removes its temporary file; a process killed with ``kill -9`` leaves at most a hidden
``.*.tmp*`` file that :func:`is_temporary` recognises.

:func:`write_atomic` (and the ``write_*_atomic`` helpers) hold SIGINT and SIGTERM while they write,
in the main thread: a Ctrl-C or SIGTERM that arrives meanwhile is handled as soon as the file is in
place. A serializer interrupted half-way (``np.savez``'s zip file) could otherwise fail in its own
clean-up and replace the interrupt with that error.

Finished files get the permissions of an ordinary new file (``0666 & ~umask``, e.g. 0644), or
keep those of the file they replace. Operating-system failures (a full disk, a read-only or
missing folder, a path that is a folder) become :class:`pscc.errors.OutputError`, whose message
names the file and the fix.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import tempfile
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

from pscc.errors import OutputError

__all__ = [
    "atomic_output",
    "is_temporary",
    "output_error",
    "signals_held",
    "write_atomic",
    "write_bytes_atomic",
    "write_json_atomic",
    "write_text_atomic",
]

TEMPORARY_MARK = ".tmp"
"""Every temporary file name starts with ``.`` and holds this mark (see :func:`is_temporary`)."""


def is_temporary(name: str) -> bool:
    """Whether ``name`` (a file name, no folder) is a temporary file of an unfinished atomic write."""
    return name.startswith(".") and TEMPORARY_MARK in name


def _new_file_mode() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


_FIXES = {
    errno.ENOSPC: ("the disk is full", "free some space or write to another disk"),
    errno.EDQUOT: ("the disk quota is exceeded", "free some space or write to another disk"),
    errno.EACCES: ("permission denied", "make the folder writable or choose another output path"),
    errno.EPERM: ("permission denied", "make the folder writable or choose another output path"),
    errno.EROFS: ("the file system is read-only", "choose an output path on a writable disk"),
    errno.EISDIR: ("is a folder", "name a file, not a folder"),
    errno.ENOTDIR: ("a part of the path is not a folder", "check the output path"),
    errno.ENOENT: ("the folder does not exist", "create it first or choose another output path"),
    errno.ENAMETOOLONG: ("the file name is too long", "choose a shorter output path"),
}


def output_error(path: Path | str, error: OSError, field: str = "path", action: str = "written") -> OutputError:
    """An :class:`OutputError` for ``error`` raised while writing (or removing: ``action``) ``path``."""
    problem, fix = _FIXES.get(error.errno or 0, (None, "check the output path and the disk"))
    detail = error.strerror or str(error)
    problem = f"cannot be {action}: {problem} ({detail})" if problem else f"cannot be {action} ({detail})"
    return OutputError(str(path), field, problem, fix)


def _make_folder(folder: Path, field: str) -> None:
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise OutputError(str(folder), field, "exists and is not a folder", "choose another output path") from None
    except OSError as error:
        raise output_error(folder, error, field) from None


@contextmanager
def atomic_output(path: Path | str, *, field: str = "path") -> Iterator[Path]:
    """Yield a temporary path beside ``path``; when the block ends normally, it becomes ``path``.

    The temporary name keeps ``path``'s suffix (USD and imageio choose the format by it). The
    destination folder is created if needed. On an exception (Ctrl-C included) the temporary file
    is removed and nothing at ``path`` changes.

    Args:
        path: the destination file.
        field: the field an error message names (e.g. ``--out``).

    Raises:
        OutputError: the folder cannot be created, the file cannot be written or renamed, or
            ``path`` is a folder.
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise OutputError(str(path), field, "is a folder", "name a file, not a folder")
    _make_folder(folder, field)
    try:
        handle, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f"{TEMPORARY_MARK}{path.suffix}", dir=folder)
    except OSError as error:
        raise output_error(path, error, field) from None
    os.close(handle)
    temporary = Path(name)
    try:
        yield temporary
        mode = path.stat().st_mode & 0o777 if path.is_file() else _new_file_mode()
        os.chmod(temporary, mode)
        descriptor = os.open(temporary, os.O_RDONLY)
        try:
            os.fsync(descriptor)
        finally:
            os.close(descriptor)
        os.replace(temporary, path)
    except OSError as error:
        _remove_quietly(temporary)
        raise output_error(path, error, field) from None
    except BaseException:
        _remove_quietly(temporary)
        raise


def _remove_quietly(path: Path) -> None:
    try:
        path.unlink()
    except FileNotFoundError:
        pass


_HELD_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def signals_held() -> Iterator[None]:
    """Hold SIGINT and SIGTERM for the block (main thread only; elsewhere Python delivers no signals):
    one that arrives meanwhile goes to the handler it was meant for when the block ends, so its
    exception (``KeyboardInterrupt``, the CLI's ``Terminated``) is raised there. Handlers installed
    outside Python are left alone, and nothing is held then."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {number: signal.getsignal(number) for number in _HELD_SIGNALS}
    if any(handler is None for handler in previous.values()):
        yield
        return
    arrived: list[tuple[int, Any]] = []

    def hold(number: int, frame: Any) -> None:
        arrived.append((number, frame))

    try:
        for number in _HELD_SIGNALS:
            signal.signal(number, hold)
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
        if arrived:
            number, frame = arrived[0]
            handler = previous[number]
            if callable(handler):
                handler(number, frame)
            elif handler == signal.SIG_DFL:
                os.kill(os.getpid(), number)  # its default action, now that it is restored


def write_atomic(path: Path | str, write: Callable[[IO[bytes]], Any], *, field: str = "path") -> Path:
    """Write ``path`` atomically by calling ``write(stream)`` on a binary stream; return ``path``.

    SIGINT and SIGTERM are held until the file is in place (:func:`signals_held`).

    Raises:
        OutputError: see :func:`atomic_output`.
    """
    with signals_held(), atomic_output(path, field=field) as temporary, open(temporary, "wb") as stream:
        write(stream)
    return Path(path)


def write_bytes_atomic(path: Path | str, data: bytes, *, field: str = "path") -> Path:
    """Write ``data`` to ``path`` atomically; return ``path``."""
    return write_atomic(path, lambda stream: stream.write(data), field=field)


def write_text_atomic(path: Path | str, text: str, *, field: str = "path") -> Path:
    """Write a UTF-8 text file atomically; return ``path``."""
    return write_bytes_atomic(path, text.encode("utf-8"), field=field)


def write_json_atomic(path: Path | str, data: Any, *, field: str = "path") -> Path:
    """Write ``data`` as indented JSON, atomically; return ``path``."""
    return write_bytes_atomic(path, json.dumps(data, indent=1).encode("utf-8"), field=field)
