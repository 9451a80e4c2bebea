"""One run of a sweep in its folder, called directly (what a Ray task executes): start, resume, done, failure."""

from __future__ import annotations

import json
import socket
from pathlib import Path

import numpy as np

from pscc.batch.sweep import Run, expand_runs, load_sweep
from pscc.batch.task import finished, run_task
from pscc.io.run_folder import RunFolder
from tests.scene_texts import crossing_sheets


def _runs(folder: Path, text: str) -> list[Run]:
    path = folder / "sweep.toml"
    path.write_text(text)
    return expand_runs(load_sweep(path))


def test_a_task_writes_a_run_folder_like_simulate_and_finds_it_done_the_second_time(tmp_path: Path) -> None:
    (run,) = _runs(tmp_path, '[batch]\nscenes = ["twist"]\nframes = 2\ntriangles = 100\n'
                             '[batch.vary]\n"cloth.material.friction" = [0.45]\n')
    out = tmp_path / "runs" / run.run_id
    record = run_task(run, str(out), "cpu")
    assert record["status"] == "done" and record["error"] is None and record["ran"] is True
    assert record["frames"] == 2 and record["device"] == "cpu" and record["host"] == socket.gethostname()
    assert record["seconds_per_frame"] > 0 and record["halvings"] == 0 and record["resumed_from"] is None
    assert sorted(p.name for p in (out / "frames").iterdir()) == [f"frame_{i:05d}.npz" for i in range(3)]
    assert "friction = 0.45" in (out / "scene.toml").read_text()
    assert json.loads((out / "run.json").read_text())["status"] == "done"
    assert finished(out, 2, run.identity) and not finished(out, 3, run.identity)
    assert not finished(out, 2, {**run.identity, "method": "brute-force"})
    stamp = (out / "stats.json").stat().st_mtime_ns
    again = run_task(run, str(out), "cpu")
    assert again["status"] == "done" and again["ran"] is False and again["host"] is None
    assert (out / "stats.json").stat().st_mtime_ns == stamp


def test_a_task_resumes_from_the_checkpoint_an_earlier_attempt_left(tmp_path: Path) -> None:
    (short,) = _runs(tmp_path, '[batch]\nscenes = ["twist"]\nframes = 2\ntriangles = 100\ncheckpoint_every = 2\n')
    (long,) = _runs(tmp_path, '[batch]\nscenes = ["twist"]\nframes = 4\ntriangles = 100\ncheckpoint_every = 2\n')
    assert short.identity == long.identity  # the frame count is not part of a run's identity
    out = tmp_path / "run"
    run_task(short, str(out), "cpu")
    before = json.loads((out / "stats.json").read_text())["frames"]
    record = run_task(long, str(out), "cpu")
    assert record["status"] == "done" and record["resumed_from"] == 2 and record["frames"] == 4
    after = json.loads((out / "stats.json").read_text())["frames"]
    assert after[:2] == before  # frames 1-2 came from the checkpoint, timings and all: not simulated again


def test_a_start_that_never_reached_a_checkpoint_is_started_over(tmp_path: Path) -> None:
    (run,) = _runs(tmp_path, '[batch]\nscenes = ["twist"]\nframes = 1\ntriangles = 100\n')
    out = tmp_path / "run"
    folder = RunFolder(out, run.identity).open(resume=False, overwrite=False)
    folder.claim()  # run.json says "running", and no checkpoint: a worker killed at once
    folder.close()
    assert json.loads((out / "run.json").read_text())["status"] == "running"
    record = run_task(run, str(out), "cpu")
    assert record["status"] == "done" and record["resumed_from"] is None
    with np.load(out / "checkpoint.npz") as data:
        assert int(data["frame"][0]) == 1


def test_a_run_that_fails_is_a_failed_record_not_an_exception(tmp_path: Path) -> None:
    (tmp_path / "crossing.toml").write_text(crossing_sheets(response_limits=False))
    (run,) = _runs(tmp_path, '[batch]\nscenes = ["crossing.toml"]\n')
    out = tmp_path / "run"
    record = run_task(run, str(out), "cpu")
    assert record["status"] == "failed" and "intersects itself" in record["error"] and "Fix:" in record["error"]
    assert record["frames"] == 0 and not out.exists()  # it failed before its first frame: nothing kept
