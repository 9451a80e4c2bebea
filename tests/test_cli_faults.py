"""The CLI under bad input and faults: one line on stderr, the right exit status, nothing lost or mixed.

Each test is a regression of a defect found by trying pscc as a new user would.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from pscc import cli
from pscc.cli import main
from pscc.io.run_folder import RunFolder
from pscc.mesh import folded_sheet
from tests.scene_texts import crossing_sheets

SMALL = ["--triangles", "100", "--no-progress"]


def _one_error_line(capsys: pytest.CaptureFixture[str], *words: str) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith("pscc: error: ") and "Fix:" in lines[0], lines[0]
    for word in words:
        assert word in lines[0], (word, lines[0])
    return lines[0]


def _files(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


@pytest.fixture(scope="module")
def mesh_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    sheet = folded_sheet(300, layers=2, seed=0)
    path = tmp_path_factory.mktemp("mesh") / "m.npz"
    np.savez(path, vertices=sheet.vertices, faces=sheet.faces, vertices_end=sheet.vertices_end)
    return path


# ------------------------------------------------------------------ detect: outputs


def test_detect_out_naming_the_input_mesh_is_refused(mesh_file: Path, capsys) -> None:
    before = mesh_file.read_bytes()
    assert main(["detect", str(mesh_file), "--out", str(mesh_file)]) == 2
    _one_error_line(capsys, "--out", "input file")
    assert mesh_file.read_bytes() == before
    end = mesh_file.parent / "end.npz"
    end.write_bytes(before)
    relative = os.path.relpath(end)
    assert main(["detect", str(mesh_file), "--end", relative, "--out", str(end)]) == 2
    _one_error_line(capsys, "--out")
    assert end.read_bytes() == before


def test_detect_out_naming_a_folder_is_refused(mesh_file: Path, tmp_path: Path, capsys) -> None:
    folder = tmp_path / "pairs.npz"
    folder.mkdir()
    assert main(["detect", str(mesh_file), "--out", str(folder)]) == 2
    _one_error_line(capsys, "--out", "is a folder")


@pytest.mark.parametrize(("code", "words"), [(errno.ENOSPC, "the disk is full"), (errno.EACCES, "permission denied")])
def test_detect_write_failures_are_one_line(mesh_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                            capsys, code: int, words: str) -> None:
    def failing_savez(stream: object, **arrays: object) -> None:
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(np, "savez", failing_savez)
    out = tmp_path / "pairs.npz"
    assert main(["detect", str(mesh_file), "--out", str(out)]) == 2
    _one_error_line(capsys, str(out), "--out", words)
    assert _files(tmp_path) == []


def test_detect_into_an_unwritable_folder_is_refused_before_detection(mesh_file: Path, tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch,
                                                                      capsys) -> None:
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda path, mode: False if Path(path) == tmp_path else real_access(path, mode))
    assert main(["detect", str(mesh_file), "--out", str(tmp_path / "pairs.npz")]) == 2
    _one_error_line(capsys, "not writable")


# ------------------------------------------------------------------ devices and Warp's own messages


@pytest.mark.parametrize("command", [["detect", "MESH"], ["simulate", "drape", "--frames", "1", "--out-dir", "OUT"],
                                     ["demo", "--frames", "1", "--out-dir", "OUT"]])
def test_a_missing_device_is_one_line_without_warp_warnings(mesh_file: Path, tmp_path: Path,
                                                            command: list[str]) -> None:
    args = [{"MESH": str(mesh_file), "OUT": str(tmp_path / "o")}.get(a, a) for a in command]
    result = subprocess.run([sys.executable, "-m", "pscc", *args, "--device", "cuda:99"], capture_output=True,
                            text=True, timeout=300)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pscc: error: argument: --device: 'cuda:99' is not available"), lines
    assert not (tmp_path / "o").exists()


# ------------------------------------------------------------------ simulate: run folders


def test_overwrite_removes_every_file_of_the_previous_run(tmp_path: Path, capsys) -> None:
    out = tmp_path / "r"
    (tmp_path / "r").mkdir()
    (out / "notes.txt").write_text("the user's own file")
    assert main(["simulate", "twist", "--frames", "2", *SMALL, "--format", "obj,ply,usd", "--render", "--out-dir",
                 str(out), "--overwrite"]) == 0
    assert {"obj/frame_00002.obj", "ply/frame_00002.ply", "animation.usd", "preview.png", "animation.mp4"} <= \
        set(_files(out))
    assert main(["simulate", "drape", "--frames", "1", "--triangles", "200", "--no-progress", "--out-dir", str(out),
                 "--overwrite"]) == 0
    assert _files(out) == ["checkpoint.npz", "frames/frame_00000.npz", "frames/frame_00001.npz", "manifest.json",
                           "notes.txt", "run.json", "scene.toml", "stats.json"]


def test_a_folder_owned_by_another_process_is_refused(tmp_path: Path, capsys) -> None:
    out = tmp_path / "r"
    with RunFolder(out, {"scene": "held"}).open(resume=False, overwrite=False):
        assert main(["simulate", "twist", "--frames", "1", *SMALL, "--out-dir", str(out), "--overwrite"]) == 2
        _one_error_line(capsys, "another pscc process", "--out-dir")
        assert main(["simulate", "twist", "--frames", "1", *SMALL, "--out-dir", str(out), "--resume"]) == 2
        _one_error_line(capsys, "another pscc process")
        assert _files(out) == [".pscc.lock"]


def test_two_runs_started_together_never_share_a_folder(tmp_path: Path) -> None:
    out = tmp_path / "r"
    runs = [subprocess.Popen([sys.executable, "-m", "pscc", "simulate", scene, "--frames", "2", "--triangles", size,
                              "--no-progress", "--out-dir", str(out)], stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True)
            for scene, size in (("drape", "300"), ("twist", "200"))]
    results = [(run.wait(timeout=300), run.stderr.read()) for run in runs]
    codes = sorted(code for code, _ in results)
    assert codes == [0, 2], results
    refused = next(err for code, err in results if code == 2)
    assert "already holds a run" in refused or "another pscc process" in refused
    sizes = set()
    for path in sorted((out / "frames").glob("frame_*.npz")):
        with np.load(path) as frame:
            sizes.add(frame["vertices"].shape[0])
    assert len(sizes) == 1  # one run's frames only


def _scene_file(folder: Path, density: float = 0.1, cells: str = "[6, 6]") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "piece.obj").write_text("v 0 0 0\nv 0.2 0 0\nv 0 0.2 0\nv 0.2 0.2 0\nf 1 2 3\nf 2 4 3\n")
    path = folder / "scene.toml"
    path.write_text(f"""[scene]
name = "edited"
frames = 2
[[cloth]]
translate = [0.0, 0.0, 0.3]
[cloth.sheet]
size = [0.4, 0.4]
cells = {cells}
[cloth.material]
density = {density}
[[cloth]]
mesh = "piece.obj"
translate = [0.0, 0.0, 0.6]
[[obstacle]]
sphere = {{ radius = 0.1, subdivisions = 1 }}
""")
    return path


def test_resume_refuses_an_edited_scene_and_names_the_setting(tmp_path: Path, capsys) -> None:
    scene = _scene_file(tmp_path / "in")
    out = tmp_path / "out"
    assert main(["simulate", str(scene), "--no-progress", "--out-dir", str(out)]) == 0
    frames_before = _files(out)
    _scene_file(tmp_path / "in", density=0.2)
    assert main(["simulate", str(scene), "--frames", "3", "--no-progress", "--out-dir", str(out), "--resume"]) == 2
    _one_error_line(capsys, "cloth[0].material.density: 0.2 here, 0.1 in the run")
    _scene_file(tmp_path / "in")
    with open(tmp_path / "in" / "piece.obj", "a") as stream:
        stream.write("# edited\n")  # the file's content changed (not its mesh)
    assert main(["simulate", str(scene), "--frames", "3", "--no-progress", "--out-dir", str(out), "--resume"]) == 2
    _one_error_line(capsys, "the content of", "piece.obj changed")
    assert _files(out) == frames_before
    _scene_file(tmp_path / "in")
    assert main(["simulate", str(scene), "--frames", "3", "--no-progress", "--out-dir", str(out), "--resume"]) == 0


def _rewrite_checkpoint(out: Path, frame: int) -> None:
    """A checkpoint whose frame was edited (its digest no longer matches)."""
    path = out / "checkpoint.npz"
    with np.load(path) as archive:
        arrays = {key: archive[key] for key in archive.files}
    arrays["frame"] = np.array([frame], dtype=np.int64)
    np.savez(path, **arrays)


@pytest.mark.parametrize("damage", ["truncated", "empty", "frame -7"])
def test_resume_from_a_damaged_checkpoint_is_one_line(tmp_path: Path, capsys, damage: str) -> None:
    out = tmp_path / "r"
    args = ["simulate", "twist", "--frames", "2", *SMALL, "--out-dir", str(out)]
    assert main(args) == 0
    checkpoint = out / "checkpoint.npz"
    if damage == "truncated":
        checkpoint.write_bytes(checkpoint.read_bytes()[:100])
    elif damage == "empty":
        checkpoint.write_bytes(b"")
    else:
        _rewrite_checkpoint(out, -7)
    before = _files(out)
    assert main([*args[:3], "3", *args[4:], "--resume"]) == 2
    _one_error_line(capsys, "checkpoint.npz: checkpoint:", "--overwrite")
    assert _files(out) == before and not (out / "frames" / "frame_-0001.npz").exists()


def test_resume_after_frames_were_deleted_is_refused(tmp_path: Path, capsys) -> None:
    out = tmp_path / "r"
    args = ["simulate", "twist", "--frames", "2", *SMALL, "--out-dir", str(out)]
    assert main(args) == 0
    for path in (out / "frames").iterdir():
        path.unlink()
    assert main([*args[:3], "4", *args[4:], "--resume"]) == 2
    _one_error_line(capsys, "frame_00000.npz", "missing")


def test_resume_with_fewer_frames_than_the_checkpoint_is_refused(tmp_path: Path, capsys) -> None:
    out = tmp_path / "r"
    assert main(["simulate", "twist", "--frames", "3", *SMALL, "--out-dir", str(out)]) == 0
    assert main(["simulate", "twist", "--frames", "2", *SMALL, "--out-dir", str(out), "--resume"]) == 2
    _one_error_line(capsys, "--frames", "checkpoint at frame 3")


@pytest.mark.parametrize("content", ["[1, 2]", "not json"])
def test_a_run_file_that_is_not_an_object_is_one_line(tmp_path: Path, capsys, content: str) -> None:
    out = tmp_path / "r"
    out.mkdir()
    (out / "run.json").write_text(content)
    assert main(["simulate", "twist", "--frames", "1", *SMALL, "--out-dir", str(out)]) == 2
    _one_error_line(capsys, "run.json: identity: unreadable run file")
    assert main(["simulate", "twist", "--frames", "1", *SMALL, "--out-dir", str(out), "--resume"]) == 2
    _one_error_line(capsys, "run.json")
    assert main(["simulate", "twist", "--frames", "1", *SMALL, "--out-dir", str(out), "--overwrite"]) == 0


def test_run_files_have_the_permissions_of_the_frames(tmp_path: Path) -> None:
    previous = os.umask(0o022)
    try:
        out = tmp_path / "r"
        assert main(["simulate", "twist", "--frames", "1", *SMALL, "--format", "npz,usd", "--out-dir", str(out)]) == 0
        modes = {name: (out / name).stat().st_mode & 0o777 for name in _files(out)}
        assert set(modes.values()) == {0o644}, modes
    finally:
        os.umask(previous)


# ------------------------------------------------------------------ failures during a run




def test_crossing_input_is_refused_with_the_scene_file_key(tmp_path: Path, capsys) -> None:
    scene = tmp_path / "crossing.toml"
    scene.write_text(crossing_sheets(allow=False))
    assert main(["simulate", str(scene), "--no-progress", "--out-dir", str(tmp_path / "out")]) == 2
    _one_error_line(capsys, "intersects itself", "allow_initial_intersections = true under [contact]")
    assert not (tmp_path / "out").exists()


def _hold_crossings(monkeypatch: pytest.MonkeyPatch) -> None:
    """Crossing features held by the collision response (their exemption switched off): the first step fails."""
    from pscc.sim.solver import ClothSolver

    monkeypatch.setattr(ClothSolver, "_join_crossings", lambda self, crossings: None)


def test_crossing_sheets_run_with_their_crossings_counted(tmp_path: Path) -> None:
    """Two sheets crossing at right angles: exempt from collision handling, they run (pushed apart slowly:
    still crossing after two frames), and every frame's stats count the crossings left."""
    scene = tmp_path / "crossing.toml"
    scene.write_text(crossing_sheets(allow=True))
    assert main(["simulate", str(scene), "--no-progress", "--out-dir", str(tmp_path / "out")]) == 0
    frames = json.loads((tmp_path / "out" / "stats.json").read_text())["frames"]
    assert len(frames) == 2 and all(f["counts"]["intersecting_pairs"] > 0 for f in frames)


def test_a_run_that_fails_at_its_first_step_leaves_nothing_and_says_why(tmp_path: Path, capsys,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    _hold_crossings(monkeypatch)
    scene = tmp_path / "crossing.toml"
    scene.write_text(crossing_sheets(allow=True))
    out = tmp_path / "out"
    assert main(["simulate", str(scene), "--no-progress", "--out-dir", str(out)]) == 2
    line = capsys.readouterr().err.strip()
    assert len(line.splitlines()) == 1
    assert "allow_initial_intersections" in line and "pushed back (untangle_speed" in line
    assert f"nothing was kept in {out}" in line
    assert not out.exists()


def test_a_run_that_fails_later_keeps_its_frames_and_status(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                            capsys) -> None:
    from pscc.sim.solver import ClothSolver, SimulationError

    real_frame = ClothSolver.advance_frame
    calls = {"n": 0}

    def advance_frame(self: ClothSolver, *args: object, **kwargs: object) -> dict:
        calls["n"] += 1
        if calls["n"] > 2:  # frame 3 fails
            raise SimulationError("step at t=0.07 s could not be made intersection-free (test); Fix: smaller steps")
        return real_frame(self, *args, **kwargs)

    monkeypatch.setattr(ClothSolver, "advance_frame", advance_frame)
    out = tmp_path / "r"
    assert main(["simulate", "twist", "--frames", "5", *SMALL, "--out-dir", str(out)]) == 2
    line = _one_error_line(capsys, "could not be made intersection-free", "keeps frames 0-2")
    assert "--overwrite" in line
    run = json.loads((out / "run.json").read_text())
    stats = json.loads((out / "stats.json").read_text())
    assert run["status"] == "failed" and "(test)" in run["error"] and run["frame"] == 2
    assert stats["status"] == "failed" and len(stats["frames"]) == 2
    monkeypatch.setattr(ClothSolver, "advance_frame", real_frame)
    assert main(["simulate", "twist", "--frames", "5", *SMALL, "--out-dir", str(out)]) == 2  # a run is there
    _one_error_line(capsys, "already holds a run")
    assert main(["simulate", "twist", "--frames", "5", *SMALL, "--out-dir", str(out), "--overwrite"]) == 0
    assert json.loads((out / "run.json").read_text())["status"] == "done"


def test_ctrl_c_exits_130_with_one_line_and_the_run_resumes(tmp_path: Path) -> None:
    out = tmp_path / "r"
    # Enough frames after the one awaited that the run cannot finish before the signal lands, even when
    # the machine is busy: a 100-triangle frame takes about 0.1 s, and 60 frames once finished first on a
    # loaded machine (returncode 0; the signal never reached a running process).
    args = ["simulate", "twist", "--frames", "200", *SMALL, "--checkpoint-every", "3", "--out-dir", str(out)]
    # SIGINT back to its default in the child: a shell that starts a job in the background (make test under
    # nohup ... &) hands its children SIGINT ignored, and Python then installs no KeyboardInterrupt.
    process = subprocess.Popen([sys.executable, "-m", "pscc", *args], stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 240
    while not (out / "frames" / "frame_00004.npz").exists():
        assert process.poll() is None, process.stderr.read()
        assert time.monotonic() < deadline
        time.sleep(0.02)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 130
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pscc: interrupted.") and "--resume" in lines[0], lines
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "interrupted" and run["checkpoint"] % 3 == 0
    assert main([*args, "--resume"]) == 0
    assert len(list((out / "frames").glob("frame_*.npz"))) == 201


@pytest.mark.parametrize("resume", [False, True])
def test_an_interrupt_right_after_the_folder_is_claimed_never_leaves_it_running(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys, resume: bool) -> None:
    # A cancelled batch task can be interrupted at any bytecode, also just after run.json says "running".
    out = tmp_path / "r"
    args = ["simulate", "twist", "--frames", "6", *SMALL, "--checkpoint-every", "3", "--out-dir", str(out)]
    if resume:
        assert main([*args[:2], "--frames", "3", *args[4:]]) == 0
    real_claim = RunFolder.claim

    def claim_then_interrupt(self: RunFolder) -> None:
        real_claim(self)
        raise KeyboardInterrupt

    monkeypatch.setattr(RunFolder, "claim", claim_then_interrupt)
    assert main([*args, "--resume"] if resume else args) == 130
    capsys.readouterr()
    if resume:  # the run keeps its frames and checkpoint, and says it was interrupted
        run = json.loads((out / "run.json").read_text())
        assert run["status"] == "interrupted" and run["checkpoint"] == 3
    else:  # nothing was written yet: nothing is kept
        assert not (out / "run.json").exists()
    monkeypatch.setattr(RunFolder, "claim", real_claim)
    assert main([*args, "--resume"] if resume else args) == 0
    assert json.loads((out / "run.json").read_text())["status"] == "done"


@pytest.mark.parametrize("during", ["checkpoint", "frame"])
def test_a_signal_during_a_write_lands_after_the_run_has_counted_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys, during: str) -> None:
    # Ctrl-C (or a batch's cancel) while frame 6's checkpoint or frame file is written: the write holds the
    # signal until it ends. The run must count the written file before the signal lands, so run.json names
    # the checkpoint on disk and the last frame on disk (it once named the ones before them).
    from pscc.io.formats import FrameWriter

    out = tmp_path / "r"
    args = ["simulate", "twist", "--frames", "9", *SMALL, "--checkpoint-every", "3", "--out-dir", str(out)]
    owner, name = (RunFolder, "save_checkpoint") if during == "checkpoint" else (FrameWriter, "write")
    real = getattr(owner, name)

    def write_then_signal(self: object, *call_args: object, **kwargs: object) -> None:
        real(self, *call_args, **kwargs)
        frame = call_args[1] if during == "checkpoint" else call_args[0]
        if frame == 6:
            os.kill(os.getpid(), signal.SIGINT)  # arrives as the write ends

    monkeypatch.setattr(owner, name, write_then_signal)
    # Python's own SIGINT handler, as in a terminal: a shell that starts the tests in the background hands
    # them SIGINT ignored, and an ignored signal would let the run finish.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        assert main(args) == 130
    finally:
        signal.signal(signal.SIGINT, previous)
    capsys.readouterr()
    run = json.loads((out / "run.json").read_text())
    with np.load(out / "checkpoint.npz") as checkpoint:
        on_disk = int(checkpoint["frame"][0])
    last_frame = max(int(p.stem.split("_")[1]) for p in (out / "frames").glob("frame_*.npz"))
    assert run["status"] == "interrupted"
    assert run["checkpoint"] == on_disk and run["frame"] == last_frame, (run, on_disk, last_frame)
    assert last_frame == 6
    monkeypatch.setattr(owner, name, real)
    assert main([*args, "--resume"]) == 0
    assert len(list((out / "frames").glob("frame_*.npz"))) == 10


def test_keyboard_interrupt_before_a_run_is_one_line(monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    def interrupted(args: object) -> int:
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "_scenes", interrupted)
    assert main(["scenes"]) == 130
    assert capsys.readouterr().err == "pscc: interrupted\n"


def test_an_internal_error_is_one_line_with_exit_1(monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    def broken(args: object) -> int:
        raise ZeroDivisionError("division by zero")

    monkeypatch.setattr(cli, "_scenes", broken)
    monkeypatch.delenv("PSCC_TRACEBACK", raising=False)
    assert main(["scenes"]) == 1
    line = capsys.readouterr().err.strip()
    assert line.startswith("pscc: internal error: ZeroDivisionError") and "PSCC_TRACEBACK=1" in line
    monkeypatch.setenv("PSCC_TRACEBACK", "1")
    with pytest.raises(ZeroDivisionError):
        main(["scenes"])


def test_argument_errors_are_one_line(capsys) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["simulate", "drape", "--frames", "x"])
    assert exited.value.code == 2
    _one_error_line(capsys, "--frames", "invalid int value")
    assert main(["simulate", "drape", "--resume", "--overwrite", "--out-dir", "unused"]) == 2
    _one_error_line(capsys, "--resume and --overwrite")


# ------------------------------------------------------------------ sizes that cannot fit


def test_a_sheet_too_large_for_memory_is_refused_before_allocation(tmp_path: Path, capsys) -> None:
    scene = _scene_file(tmp_path, cells="[100000, 100000]")
    started = time.monotonic()
    assert main(["simulate", str(scene), "--no-progress", "--out-dir", str(tmp_path / "out")]) == 2
    assert time.monotonic() - started < 30
    _one_error_line(capsys, "cloth[0].sheet.cells", "20,000,000,000 triangles", "TiB of memory", "available")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", [["demo", "--triangles", "100000000"],
                                     ["simulate", "drape", "--triangles", "100000000"],
                                     ["simulate", "sphere-drop", "--scale", "4000"]])
def test_built_in_sizes_too_large_for_memory_are_refused(tmp_path: Path, capsys, command: list[str]) -> None:
    if command[-2] == "--scale":
        assert main([*command, "--out-dir", str(tmp_path / "out")]) == 2
        _one_error_line(capsys, "--scale")  # beyond the largest scale
        return
    assert main([*command, "--out-dir", str(tmp_path / "out"), "--no-progress"]) == 2
    _one_error_line(capsys, "--triangles", "GiB of memory")
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------ found by a second round of bad input


def _finished_run(out: Path, frames: int = 2) -> list[str]:
    assert main(["simulate", "twist", "--frames", str(frames), *SMALL, "--out-dir", str(out)]) == 0
    return _files(out)


def test_a_manifest_with_a_huge_frame_range_is_overwritten_quickly(tmp_path: Path, capsys) -> None:
    out = tmp_path / "r"
    _finished_run(out)
    for last in (10**9, 10**14):  # the largest valid range, and one past it (a damaged manifest)
        manifest = json.loads((out / "manifest.json").read_text())
        manifest["series"]["frames/frame_{index:05d}.npz"] = [0, last]
        (out / "manifest.json").write_text(json.dumps(manifest))
        started = time.monotonic()
        assert main(["simulate", "twist", "--frames", "1", *SMALL, "--out-dir", str(out), "--overwrite"]) == 0
        assert time.monotonic() - started < 60
        assert not (out / ".pscc.lock").exists()


def test_overwrite_never_follows_a_linked_sub_folder_out_of_the_run(tmp_path: Path, capsys) -> None:
    out = tmp_path / "r"
    _finished_run(out)
    victims = tmp_path / "victims"
    victims.mkdir()
    for name in ("frame_00000.npz", "frame_00001.npz"):
        (victims / name).write_text("precious")
    for path in (out / "frames").iterdir():
        path.unlink()
    (out / "frames").rmdir()
    (out / "frames").symlink_to(victims)
    assert main(["simulate", "twist", "--frames", "1", *SMALL, "--out-dir", str(out), "--overwrite"]) == 2
    _one_error_line(capsys, "frames", "is a link to", "outside the run folder")
    assert [p.read_text() for p in sorted(victims.iterdir())] == ["precious", "precious"]


def test_a_format_added_on_resume_is_filled_in_for_the_earlier_frames(tmp_path: Path) -> None:
    out = tmp_path / "r"
    _finished_run(out, frames=2)
    assert main(["simulate", "twist", "--frames", "3", *SMALL, "--out-dir", str(out), "--resume", "--format",
                 "npz,obj"]) == 0
    assert [p.name for p in sorted((out / "obj").iterdir())] == [f"frame_{i:05d}.obj" for i in range(4)]
    assert main(["simulate", "twist", "--frames", "4", *SMALL, "--out-dir", str(out), "--resume"]) == 0


def test_a_checkpoint_of_another_run_is_refused(tmp_path: Path, capsys) -> None:
    ours, theirs = tmp_path / "ours", tmp_path / "theirs"
    _finished_run(ours)
    assert main(["simulate", "twist", "--frames", "2", *SMALL, "--method", "spatial-hash", "--out-dir",
                 str(theirs)]) == 0
    (ours / "checkpoint.npz").write_bytes((theirs / "checkpoint.npz").read_bytes())
    assert main(["simulate", "twist", "--frames", "3", *SMALL, "--out-dir", str(ours), "--resume"]) == 2
    _one_error_line(capsys, "checkpoint.npz", "belongs to another run")


def test_run_json_missing_beside_a_checkpoint_is_named(tmp_path: Path, capsys) -> None:
    out = tmp_path / "r"
    _finished_run(out)
    (out / "run.json").unlink()
    assert main(["simulate", "twist", "--frames", "3", *SMALL, "--out-dir", str(out), "--resume"]) == 2
    _one_error_line(capsys, "run.json", "no run.json")


@pytest.mark.parametrize("folder", ["", " ", "/"])
def test_an_empty_or_root_out_dir_is_refused(folder: str, capsys) -> None:
    assert main(["simulate", "twist", "--frames", "1", *SMALL, "--out-dir", folder]) == 2
    _one_error_line(capsys, "--out-dir")


def test_an_overwrite_that_cannot_remove_a_file_leaves_the_old_run_whole(tmp_path: Path,
                                                                         monkeypatch: pytest.MonkeyPatch,
                                                                         capsys) -> None:
    out = tmp_path / "r"
    before = _finished_run(out)
    contents = {name: (out / name).read_bytes() for name in before}
    real_rename = os.rename

    def rename(source: object, target: object) -> None:
        if Path(source).name == "frame_00001.npz":
            raise OSError(errno.EPERM, "Operation not permitted")
        real_rename(source, target)

    monkeypatch.setattr(os, "rename", rename)
    assert main(["simulate", "twist", "--frames", "1", *SMALL, "--out-dir", str(out), "--overwrite"]) == 2
    _one_error_line(capsys, "frame_00001.npz: --overwrite: cannot be removed: permission denied")
    assert _files(out) == before
    assert all((out / name).read_bytes() == data for name, data in contents.items())


def test_a_full_disk_mid_run_reports_the_frames_really_kept(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                            capsys) -> None:
    real_savez = np.savez
    frames_written = {"n": 0}

    def savez(stream: object, **arrays: object) -> None:
        if "obstacle_faces" in arrays:  # a frame file
            frames_written["n"] += 1
            if frames_written["n"] == 3:  # frame 2: the disk is full
                raise OSError(errno.ENOSPC, "No space left on device")
        real_savez(stream, **arrays)

    monkeypatch.setattr(np, "savez", savez)
    out = tmp_path / "r"
    assert main(["simulate", "twist", "--frames", "4", *SMALL, "--out-dir", str(out)]) == 2
    _one_error_line(capsys, "frame_00002.npz: path: cannot be written: the disk is full", "keeps frames 0-1")
    assert json.loads((out / "run.json").read_text())["frame"] == 1


@pytest.mark.parametrize(("table", "key"), [
    ("[scene]\nsteps_per_frame = 99999999999999999", "scene.steps_per_frame"),
    ("[scene]\nframe_rate = 1e300", "scene.frame_rate"),
    ("[solver]\ngravity = [0.0, 0.0, 1e30]", "solver.gravity"),
    ("[scene]\nname = \"x\"\n[[cloth]]\nrotate = [1e308, 1e308, 1e308]\n[cloth.sheet]\nsize = [0.3, 0.3]\n"
     "cells = [4, 4]", "cloth[0].rotate[0]"),
    ("[scene]\nname = \"x\"\n[[cloth]]\ntranslate = [1e300, 0.0, 0.0]\n[cloth.sheet]\nsize = [0.3, 0.3]\n"
     "cells = [4, 4]", "cloth[0].translate[0]"),
    ("[scene]\nname = \"x\"\n[[cloth]]\n[cloth.sheet]\nsize = [1e-300, 1e-300]\ncells = [4, 4]",
     "cloth[0].sheet.size"),
    ("[scene]\nname = \"x\"\n[[cloth]]\n[cloth.sheet]\nsize = [0.3, 0.3]\ncells = [4, 4]\n[cloth.material]\n"
     "thickness = 1e10", "cloth[0].material.thickness"),
    ("[scene]\nname = \"x\"\n[[cloth]]\n[cloth.sheet]\nsize = [0.3, 0.3]\ncells = [4, 4]\n[cloth.material]\n"
     "bending = 1e300", "cloth[0].material.bending"),
    ("[scene]\nname = \"x\"\n[[cloth]]\n[cloth.sheet]\nsize = [0.3, 0.3]\ncells = [4, 4]\n[[obstacle]]\n"
     "sphere = { radius = 0.1, subdivisions = 1 }\nrotate = [1e300, 0.0, 0.0]", "obstacle[0].rotate[0]"),
    ("[scene]\nname = \"x\"\n[[cloth]]\n[cloth.sheet]\nsize = [0.3, 0.3]\ncells = [4, 4]\n[[obstacle]]\n"
     "sphere = { radius = 0.1, subdivisions = 1 }\nkeyframes = { times = [0.0, 1.0], translations = [[0.0, 0.0, 0.0], "
     "[1e300, 0.0, 0.0]], rotations = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]] }",
     "obstacle[0].keyframes.translations[1][0]"),
])
def test_absurd_scene_numbers_are_refused_by_key_without_warnings(tmp_path: Path, capsys, table: str,
                                                                  key: str) -> None:
    scene = tmp_path / "scene.toml"
    text = table if "[[cloth]]" in table else table + "\n[[cloth]]\n[cloth.sheet]\nsize = [0.3, 0.3]\ncells = [4, 4]"
    scene.write_text(text + "\n")
    assert main(["simulate", str(scene), "--frames", "1", "--no-progress", "--out-dir", str(tmp_path / "o")]) == 2
    _one_error_line(capsys, f"{scene}: {key}")
    assert not (tmp_path / "o").exists()


def test_sigterm_stops_the_run_like_ctrl_c(tmp_path: Path) -> None:
    out = tmp_path / "r"
    # Far more frames than reach the signal: the run must not finish first on a busy machine.
    process = subprocess.Popen([sys.executable, "-m", "pscc", "simulate", "twist", "--frames", "400", *SMALL,
                                "--checkpoint-every", "2", "--out-dir", str(out)], stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 240
    while not (out / "frames" / "frame_00004.npz").exists():
        assert process.poll() is None, process.stderr.read()
        assert time.monotonic() < deadline
        time.sleep(0.02)
    process.terminate()
    _, err = process.communicate(timeout=120)
    assert process.returncode == 143 and err.startswith("pscc: terminated."), err
    assert json.loads((out / "run.json").read_text())["status"] == "interrupted"
    assert not (out / ".pscc.lock").exists()


def test_size_options_name_the_option_the_user_gave(tmp_path: Path, capsys) -> None:
    assert main(["simulate", "sphere", "--triangles", "100", "--out-dir", str(tmp_path / "o")]) == 2
    _one_error_line(capsys, "--triangles", "outside")
    assert main(["simulate", "drape", "--scale", "1e-300", "--out-dir", str(tmp_path / "o")]) == 2
    _one_error_line(capsys, "--scale", "fewer than")


def test_paths_that_are_not_files_say_what_they_are(mesh_file: Path, tmp_path: Path, capsys) -> None:
    folder = tmp_path / "dir.toml"
    folder.mkdir()
    assert main(["simulate", str(folder), "--out-dir", str(tmp_path / "o")]) == 2
    _one_error_line(capsys, "is a folder")
    loop = tmp_path / "loop.obj"
    loop.symlink_to(loop)
    assert main(["detect", str(loop)]) == 2
    _one_error_line(capsys, "broken or looping link")
    plain = tmp_path / "afile"
    plain.write_text("x")
    assert main(["detect", str(mesh_file), "--out", str(plain / "x.npz")]) == 2
    _one_error_line(capsys, "is not a folder")


def test_a_sequence_pattern_that_cannot_be_searched_is_named(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                             capsys) -> None:
    from pscc.scenes import obstacle_tables

    def unsearchable(pattern: Path) -> list[Path]:
        raise OSError(errno.EINVAL, "Invalid argument", "/proc/1/task/1/net")

    monkeypatch.setattr(obstacle_tables, "_glob", unsearchable)
    scene = tmp_path / "scene.toml"
    scene.write_text("[[cloth]]\n[cloth.sheet]\nsize = [0.3, 0.3]\ncells = [4, 4]\n[[obstacle]]\n"
                     "sequence = \"/**/*.obj\"\n")
    assert main(["simulate", str(scene), "--no-progress", "--out-dir", str(tmp_path / "o")]) == 2
    _one_error_line(capsys, f"{scene}: obstacle[0].sequence", "cannot be searched", "/proc/1/task/1/net")


def test_an_out_dir_name_too_long_is_one_line(tmp_path: Path, capsys) -> None:
    out = tmp_path / ("a" * 300)
    assert main(["simulate", "twist", "--frames", "1", *SMALL, "--out-dir", str(out)]) == 2
    _one_error_line(capsys, "--out-dir: cannot be written: the file name is too long")


def test_a_step_failure_names_the_scene_and_the_step(tmp_path: Path, capsys, monkeypatch: pytest.MonkeyPatch) -> None:
    _hold_crossings(monkeypatch)
    scene = tmp_path / "crossing.toml"
    scene.write_text(crossing_sheets(allow=True))
    assert main(["simulate", str(scene), "--no-progress", "--out-dir", str(tmp_path / "out")]) == 2
    _one_error_line(capsys, "pscc: error: crossing: step at t=0 s: could not be made intersection-free",
                    "Fix: separate the surfaces")
