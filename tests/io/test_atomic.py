"""Atomic writes hold SIGINT and SIGTERM until the file is in place (pscc._atomic)."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import numpy as np
import pytest

from pscc._atomic import signals_held, write_atomic


class _Stopped(Exception):
    pass


def _stop(number: int, frame: object) -> None:
    raise _Stopped(number)


@pytest.mark.parametrize("number", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_during_a_write_is_handled_once_the_file_is_in_place(tmp_path: Path, number: int) -> None:
    previous = signal.signal(number, _stop)
    try:
        target = tmp_path / "frame.npz"

        def write(stream) -> None:
            stream.write(b"")
            os.kill(os.getpid(), number)  # Python runs its handler at the next bytecode: held here
            np.savez(stream, x=np.arange(1000.0), y=np.ones(3))

        with pytest.raises(_Stopped):
            write_atomic(target, write)
        with np.load(target) as data:  # the whole file, not half of it
            assert data["x"].shape == (1000,) and data["y"].sum() == 3.0
        assert sorted(p.name for p in tmp_path.iterdir()) == ["frame.npz"]
        assert signal.getsignal(number) is _stop  # the handler is back
    finally:
        signal.signal(number, previous)


def test_nothing_is_held_outside_the_block_and_a_quiet_block_raises_nothing(tmp_path: Path) -> None:
    previous = signal.signal(signal.SIGTERM, _stop)
    try:
        with signals_held():
            pass
        with pytest.raises(_Stopped):
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):  # give the interpreter bytecodes to run the handler on
                pass
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_without_a_signal_the_write_is_unchanged(tmp_path: Path) -> None:
    target = tmp_path / "a.bin"
    write_atomic(target, lambda stream: stream.write(b"abc"))
    assert target.read_bytes() == b"abc"
