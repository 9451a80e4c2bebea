"""Runs that survive: kill -9 mid-run, --resume, and the same frames as an uninterrupted run."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from pscc.cli import main

ARGS = ["simulate", "twist", "--frames", "30", "--triangles", "100", "--no-progress", "--checkpoint-every", "3"]


def _frames(folder: Path) -> list[Path]:
    return sorted((folder / "frames").glob("frame_*.npz"))


def test_killed_run_resumes_to_the_same_frames(tmp_path: Path) -> None:
    whole = tmp_path / "whole"
    assert main([*ARGS, "--out-dir", str(whole)]) == 0

    killed = tmp_path / "killed"
    process = subprocess.Popen([sys.executable, "-m", "pscc", *ARGS, "--out-dir", str(killed)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not (killed / "frames" / "frame_00008.npz").exists():
        assert process.poll() is None, "the run ended before it could be killed"
        assert time.monotonic() < deadline
        time.sleep(0.02)
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    assert len(_frames(killed)) < 31  # it really was interrupted

    assert main([*ARGS, "--out-dir", str(killed), "--resume"]) == 0
    names = [p.name for p in _frames(whole)]
    assert names == [p.name for p in _frames(killed)] and len(names) == 31
    for name in names:
        with np.load(whole / "frames" / name) as a, np.load(killed / "frames" / name) as b:
            for key in a.files:
                np.testing.assert_array_equal(a[key], b[key], err_msg=f"{name}:{key}")
    assert not list(killed.rglob(".*.tmp"))


def test_folder_of_another_run_is_refused_unless_overwritten(tmp_path: Path, capsys) -> None:
    out = tmp_path / "run"
    first = ["simulate", "twist", "--frames", "1", "--triangles", "100", "--no-progress", "--out-dir", str(out)]
    assert main(first) == 0
    before = (out / "frames" / "frame_00001.npz").read_bytes()
    other = ["simulate", "drape", "--frames", "1", "--triangles", "200", "--no-progress", "--out-dir", str(out)]
    assert main(other) == 2
    assert "already holds a run" in capsys.readouterr().err
    assert (out / "frames" / "frame_00001.npz").read_bytes() == before  # nothing written
    assert main([*other, "--resume"]) == 2
    assert "another run" in capsys.readouterr().err
    assert main([*other, "--overwrite"]) == 0
    with np.load(out / "frames" / "frame_00001.npz") as frame:
        assert frame["obstacle_faces"].shape[0] > 0  # now the drape run


def test_resume_without_checkpoint_is_refused(tmp_path: Path, capsys) -> None:
    assert main(["simulate", "twist", "--frames", "1", "--triangles", "100", "--no-progress", "--resume",
                 "--out-dir", str(tmp_path / "none")]) == 2
    assert "no checkpoint" in capsys.readouterr().err
