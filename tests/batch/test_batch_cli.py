"""``pscc batch`` as a command, on the local Ray instance it starts itself: Ctrl-C, then ``--resume``."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("ray")

SWEEP = """[batch]
scenes = ["twist"]
frames = 20
triangles = 100
checkpoint_every = 3

[batch.vary]
"cloth.material.friction" = [0.1, 0.2]
"""


def _batch(*args: str) -> subprocess.Popen[str]:
    # SIGINT back to its default in the child (a shell that starts make test in the background hands it ignored).
    return subprocess.Popen([sys.executable, "-m", "pscc", "batch", *args, "--no-progress"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def test_ctrl_c_stops_the_batch_and_its_local_instance_and_resume_finishes_it(tmp_path: Path) -> None:
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(SWEEP)
    out = tmp_path / "out"
    process = _batch(str(sweep), "--out-dir", str(out), "--workers", "2")
    deadline = time.monotonic() + 240
    while not list(out.glob("runs/*/frames/frame_00004.npz")):
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.02)
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr
    assert "on a local Ray instance with 2 workers, cpu, Ray 2.60.0" in stdout
    data = json.loads((out / "summary.json").read_text())
    # A run may end in the instant before the signal lands (a busy machine): it is then done, and kept.
    done = {r["id"] for r in data["runs"] if r["status"] == "done"}
    stopped = {r["id"] for r in data["runs"] if r["status"] == "interrupted"}
    assert data["status"] == "interrupted" and len(stopped) >= 1 and len(done | stopped) == 2
    last = stderr.strip().splitlines()[-1]
    assert last.startswith("pscc: interrupted. ") and f"summary.json lists {len(done)} done run(s); pass --resume" \
        in last, last
    checkpoints = {}
    for run_id in stopped:
        path = out / "runs" / run_id / "run.json"
        if not path.exists():  # cancelled before its worker had started it
            checkpoints[run_id] = None
            continue
        run = json.loads(path.read_text())  # the task recorded its stop
        assert run["status"] == "interrupted" and run["checkpoint"] % 3 == 0 and run["checkpoint"] < 20
        checkpoints[run_id] = run["checkpoint"]
    assert not _named_processes("ray::pscc-batch:twist")  # no worker of the instance goes on simulating

    process = _batch(str(sweep), "--out-dir", str(out), "--workers", "2", "--resume")
    stdout, stderr = process.communicate(timeout=300)
    assert process.returncode == 0, stderr
    assert f"2 runs done ({len(stopped)} run now)" in stdout
    data = json.loads((out / "summary.json").read_text())
    assert data["status"] == "done" and data["counts"]["done"] == 2
    for record in data["runs"]:
        assert record["frames"] == 20 and record["ran"] is (record["id"] in stopped)
        if record["id"] in stopped:
            assert record["resumed_from"] == checkpoints[record["id"]]
        assert len(list((out / record["out_dir"] / "frames").glob("frame_*.npz"))) == 21


def test_an_address_where_nothing_answers_is_one_line_at_once(tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    from pscc.cli import main

    sweep = tmp_path / "sweep.toml"
    sweep.write_text('[batch]\nscenes = ["drape"]\nframes = 1\ntriangles = 100\n')
    started = time.monotonic()
    assert main(["batch", str(sweep), "--out-dir", str(tmp_path / "out"), "--address", "127.0.0.1:1"]) == 2
    line = capsys.readouterr().err.strip()
    assert line.startswith("pscc: error: argument: --address: nothing answers at 127.0.0.1:1") and "Fix:" in line
    assert time.monotonic() - started < 30 and not (tmp_path / "out").exists()


def _named_processes(prefix: str) -> list[int]:
    """Processes whose title starts with ``prefix`` (Ray names a worker after the task it runs)."""
    found = []
    for path in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            if path.read_bytes().startswith(prefix.encode()):
                found.append(int(path.parent.name))
        except OSError:
            continue
    return found
