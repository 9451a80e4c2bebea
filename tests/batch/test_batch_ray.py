"""``pscc batch`` on a local Ray instance of 2 workers (one per module): a 2 x 2 sweep, a failed run, ``--resume``,
and a worker killed in the middle of its run."""

from __future__ import annotations

import csv
import json
import logging
import os
import signal
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pscc.batch.runner import run_batch
from pscc.cli import main
from pscc.errors import InputError
from tests.scene_texts import crossing_sheets

ray = pytest.importorskip("ray")

SWEEP_2X2 = """[batch]
scenes = ["drape", "twist"]
frames = 2
triangles = 100

[batch.vary]
"cloth.material.friction" = [0.1, 0.5]
"""


@pytest.fixture(scope="module", autouse=True)
def ray_instance() -> Any:
    """Two CPU workers for the module; the batches below use this connection."""
    handler, environment = signal.getsignal(signal.SIGTERM), dict(os.environ)
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level=logging.ERROR)
    signal.signal(signal.SIGTERM, handler)
    yield
    ray.shutdown()
    os.environ.clear()  # ray.init sets RAY_AUTH_MODE, PYTHONBREAKPOINT, ...: leave the other tests as they were
    os.environ.update(environment)


@pytest.fixture(scope="module")
def batch_2x2(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("batch")
    sweep = folder / "sweep.toml"
    sweep.write_text(SWEEP_2X2)
    out = folder / "out"
    assert main(["batch", str(sweep), "--out-dir", str(out), "--no-progress"]) == 0
    return sweep, out


RUN_IDS = ["drape-friction=0.1", "drape-friction=0.5", "twist-friction=0.1", "twist-friction=0.5"]


def test_a_2x2_sweep_writes_a_run_folder_per_run_and_the_summary(batch_2x2: tuple[Path, Path]) -> None:
    sweep, out = batch_2x2
    data = json.loads((out / "summary.json").read_text())
    assert data["engine"] == "ray" and data["ray_version"] == ray.__version__ and data["status"] == "done"
    assert data["devices"] == "cpu" and data["sweep"] == str(sweep)
    assert data["counts"] == {"done": 4, "failed": 0, "pending": 0, "interrupted": 0}
    assert [r["id"] for r in data["runs"]] == RUN_IDS
    for record, friction in zip(data["runs"], [0.1, 0.5, 0.1, 0.5], strict=True):
        assert record["out_dir"] == f"runs/{record['id']}" and record["values"] == {"cloth.material.friction": friction}
        assert record["status"] == "done" and record["error"] is None and record["ran"] is True
        assert record["frames"] == 2 and record["seconds_per_frame"] > 0
        assert record["intersecting_frames"] == 0 and record["halvings"] == 0 and record["device"] == "cpu"
        folder = out / record["out_dir"]
        assert sorted(p.name for p in (folder / "frames").iterdir()) == [f"frame_{i:05d}.npz" for i in range(3)]
        stats = json.loads((folder / "stats.json").read_text())
        assert stats["status"] == "done" and len(stats["frames"]) == 2
        assert f"friction = {friction}\n" in (folder / "scene.toml").read_text()
        assert (folder / "checkpoint.npz").is_file()
        assert json.loads((folder / "run.json").read_text())["status"] == "done"
        with np.load(folder / "frames" / "frame_00002.npz") as frame:
            assert np.isfinite(frame["vertices"]).all()
    with open(out / "summary.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    assert [row["id"] for row in rows] == RUN_IDS
    assert [row["cloth.material.friction"] for row in rows] == ["0.1", "0.5", "0.1", "0.5"]
    assert {row["status"] for row in rows} == {"done"} and {row["frames"] for row in rows} == {"2"}
    assert float(rows[0]["seconds_per_frame"]) == data["runs"][0]["seconds_per_frame"]


def test_the_folder_of_a_batch_is_refused_without_resume_and_resume_runs_nothing_done(
        batch_2x2: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    sweep, out = batch_2x2
    capsys.readouterr()
    assert main(["batch", str(sweep), "--out-dir", str(out), "--no-progress"]) == 2
    assert "already holds a batch" in capsys.readouterr().err
    stamps = {p: p.stat().st_mtime_ns for p in out.glob("runs/*/stats.json")}
    assert main(["batch", str(sweep), "--out-dir", str(out), "--no-progress", "--resume"]) == 0
    assert "all 4 runs of the sweep are done already" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in out.glob("runs/*/stats.json")} == stamps
    data = json.loads((out / "summary.json").read_text())
    assert data["counts"]["done"] == 4 and not any(r["ran"] for r in data["runs"])
    assert all(r["host"] for r in data["runs"])  # kept from the summary of the batch that ran them


def test_cuda_on_a_cluster_without_gpus_is_refused_before_anything_runs(tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(SWEEP_2X2)
    assert main(["batch", str(sweep), "--out-dir", str(tmp_path / "out"), "--devices", "cuda"]) == 2
    assert "--devices: cuda asks each task for a GPU, but the Ray cluster has none" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()




def test_a_failed_run_does_not_stop_the_others_and_resume_runs_only_the_runs_not_done(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two sheets that cross: allowed to start, they run with their crossings counted; refused, the run fails
    (at its start, in the worker: the sweep itself is valid)."""
    (tmp_path / "crossing.toml").write_text(crossing_sheets())
    sweep = tmp_path / "sweep.toml"
    sweep.write_text('[batch]\nscenes = ["crossing.toml", "twist"]\nframes = 2\ntriangles = 100\n[batch.vary]\n'
                     '"contact.allow_initial_intersections" = [true, false]\n')
    out = tmp_path / "out"
    assert main(["batch", str(sweep), "--out-dir", str(out), "--no-progress"]) == 2
    line = capsys.readouterr().err.strip()
    assert len(line.splitlines()) == 1 and "runs: 1 of 4 runs failed" in line and "--resume" in line, line
    data = json.loads((out / "summary.json").read_text())
    assert data["status"] == "failed" and data["counts"]["done"] == 3 and data["counts"]["failed"] == 1
    records = {r["id"]: r for r in data["runs"]}
    failed = records["crossing-allow_initial_intersections=false"]
    assert failed["status"] == "failed" and "intersects itself" in failed["error"] and failed["frames"] == 0
    crossing = records["crossing-allow_initial_intersections=true"]
    assert crossing["status"] == "done" and crossing["intersecting_frames"] == 2  # crossings left in both frames
    with open(out / "summary.csv", newline="") as stream:
        rows = {row["id"]: row for row in csv.DictReader(stream)}
    assert "intersects itself" in rows[failed["id"]]["error"] and rows[crossing["id"]]["intersecting_frames"] == "2"

    stamps = {p: p.stat().st_mtime_ns for p in out.glob("runs/*/stats.json")}
    assert len(stamps) == 3
    assert main(["batch", str(sweep), "--out-dir", str(out), "--no-progress", "--resume"]) == 2
    assert "1 of 4 runs failed" in capsys.readouterr().err
    assert {p: p.stat().st_mtime_ns for p in out.glob("runs/*/stats.json")} == stamps  # done runs untouched
    again = {r["id"]: r for r in json.loads((out / "summary.json").read_text())["runs"]}
    assert [i for i, r in again.items() if r["ran"]] == [failed["id"]] and again[failed["id"]]["status"] == "failed"


class _Driver(threading.Thread):
    """``run_batch`` in a thread, so that the test can kill the worker of its run meanwhile."""

    def __init__(self, sweep: Path, out: Path) -> None:
        super().__init__()
        self.sweep, self.out = sweep, out
        self.summary: dict[str, Any] | None = None
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            self.summary = run_batch(self.sweep, self.out, progress=False)
        except BaseException as error:  # reported by the test's assertions
            self.error = error


def _kill_worker_after_checkpoint(driver: _Driver, folder: Path, frame: int) -> tuple[int, list[dict], float]:
    """SIGKILL the worker that owns the run folder (its pid is in the folder's lock) once the folder holds a
    checkpoint at ``frame`` or later; return the checkpoint left (frame and stats) and the time of the kill."""
    deadline = time.monotonic() + 120
    found = -1
    while found < frame:
        assert driver.is_alive() and time.monotonic() < deadline, driver.error
        time.sleep(0.02)
        try:
            with np.load(folder / "checkpoint.npz") as data:
                found = int(data["frame"][0])
        except (OSError, ValueError, KeyError):
            continue
    worker = int((folder / ".pscc.lock").read_text())
    assert worker != os.getpid()
    os.kill(worker, signal.SIGKILL)
    killed_at = time.time()
    while os.path.exists(f"/proc/{worker}") and _state(worker) not in ("Z", "X"):
        time.sleep(0.01)
    with np.load(folder / "checkpoint.npz") as data:  # the checkpoint a retry starts from
        return int(data["frame"][0]), json.loads(bytes(data["frame_stats"]).decode()), killed_at


def _state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return "X"


def test_a_killed_worker_is_retried_and_its_run_resumes_from_the_checkpoint(tmp_path: Path) -> None:
    """The worker simulating the run is killed (SIGKILL, from outside: no hook in pscc) after its checkpoint at
    frame 2 or later; Ray starts the task again and the run continues from its last checkpoint."""
    sweep = tmp_path / "sweep.toml"
    sweep.write_text('[batch]\nscenes = ["twist"]\nframes = 40\ntriangles = 100\ncheckpoint_every = 2\n')
    out = tmp_path / "out"
    driver = _Driver(sweep, out)
    driver.start()
    folder = out / "runs" / "twist"
    checkpoint, kept, killed_at = _kill_worker_after_checkpoint(driver, folder, 2)
    driver.join(timeout=240)
    assert not driver.is_alive() and driver.error is None and driver.summary is not None, driver.error
    (record,) = driver.summary["runs"]
    assert record["status"] == "done" and record["frames"] == 40 and record["resumed_from"] == checkpoint >= 2
    stats = json.loads((folder / "stats.json").read_text())
    assert stats["status"] == "done" and stats["frames"][:checkpoint] == kept  # not simulated again
    assert (folder / "frames" / "frame_00001.npz").stat().st_mtime < killed_at  # written before the kill, kept
    assert (folder / "frames" / "frame_00040.npz").stat().st_mtime > killed_at
    assert json.loads((out / "summary.json").read_text())["runs"][0]["status"] == "done"


def test_a_run_whose_worker_dies_more_often_than_max_retries_fails_and_the_batch_says_so(tmp_path: Path) -> None:
    sweep = tmp_path / "sweep.toml"
    sweep.write_text('[batch]\nscenes = ["twist"]\nframes = 40\ntriangles = 100\ncheckpoint_every = 2\n'
                     'max_retries = 0\n')
    out = tmp_path / "out"
    driver = _Driver(sweep, out)
    driver.start()
    checkpoint, _, _ = _kill_worker_after_checkpoint(driver, out / "runs" / "twist", 2)
    driver.join(timeout=240)
    assert not driver.is_alive() and isinstance(driver.error, InputError), driver.error
    assert "1 of 1 runs failed" in str(driver.error) and "its worker died 1 time(s)" in str(driver.error)
    (record,) = json.loads((out / "summary.json").read_text())["runs"]
    assert record["status"] == "failed" and record["error"].startswith("its worker died 1 time(s)")
    assert record["frames"] == checkpoint  # stats.json is the checkpoint's: the killed attempt never wrote one
