"""Run folders: one owner at a time, a manifest of every file, identities, checkpoints that cannot lie."""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import numpy as np
import pytest

from pscc._atomic import write_atomic, write_text_atomic
from pscc.errors import InputError, OutputError
from pscc.io.run_folder import CHECKPOINT_FILE, LOCK_FILE, MANIFEST_FILE, RUN_FILE, RunFolder, identity_differences

IDENTITY = {"scene": "demo", "cloth_triangles": 8, "settings": {"cloth[0].material.density": 0.1}}
STATE = {"positions": np.arange(12, dtype=np.float32).reshape(4, 3), "time": np.array([0.5])}


def _claimed(out: Path, identity: dict = IDENTITY, **options: bool) -> RunFolder:
    folder = RunFolder(out, identity).open(resume=options.get("resume", False),
                                           overwrite=options.get("overwrite", False))
    folder.claim()
    return folder


def test_a_second_owner_is_refused_while_the_first_holds_the_folder(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with _claimed(out):
        assert (out / LOCK_FILE).is_file()
        with pytest.raises(InputError, match=rf"another pscc process \(pid {os.getpid()}\) is writing"):
            RunFolder(out, IDENTITY).open(resume=False, overwrite=True)
    assert not (out / LOCK_FILE).exists()  # released and removed
    with RunFolder(out, IDENTITY).open(resume=False, overwrite=True):
        pass


def test_open_creates_the_folder_and_close_removes_it_when_nothing_was_written(tmp_path: Path) -> None:
    out = tmp_path / "a" / "b"
    with RunFolder(out, IDENTITY).open(resume=False, overwrite=False):
        assert out.is_dir()
    assert not out.exists() and (tmp_path / "a").is_dir()


def test_manifest_lists_files_and_series_before_they_are_written(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with _claimed(out) as folder:
        folder.record("scene.toml", "stats.json")
        folder.record_series("frames/frame_{index:05d}.npz", 3)
        folder.record_series("frames/frame_{index:05d}.npz", 2)  # never shortened
        manifest = json.loads((out / MANIFEST_FILE).read_text())
        assert manifest == {"files": ["scene.toml", "stats.json"], "series": {"frames/frame_{index:05d}.npz": [0, 3]}}
        with pytest.raises(ValueError, match="inside the run folder"):
            folder.record("../outside.txt")
        with pytest.raises(ValueError, match="pattern"):
            folder.record_series("frames/frame.npz", 3)


def test_overwrite_removes_exactly_the_recorded_files(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with _claimed(out) as folder:
        folder.record("preview.png", "obj/extra.obj")
        folder.record_series("ply/frame_{index:05d}.ply", 2)
        for name in ("preview.png", "obj/extra.obj", "ply/frame_00000.ply", "ply/frame_00001.ply"):
            write_text_atomic(out / name, "x")
    (out / "notes.txt").write_text("mine")  # the user's own file
    (out / "ply" / "frame_00009.ply").write_text("not recorded")
    (out / "ply" / ".frame_00002.ply.abc.tmp.ply").write_text("left by kill -9")
    with _claimed(out, {"scene": "other"}, overwrite=True):
        pass
    left = sorted(str(p.relative_to(out)) for p in out.rglob("*"))
    assert left == ["manifest.json", "notes.txt", "ply", "ply/frame_00009.ply", "run.json"]


def test_overwrite_of_a_folder_without_manifest_removes_pscc_files_only(tmp_path: Path) -> None:
    out = tmp_path / "old"
    for name in ("frames/frame_00000.npz", "obj/frame_00000.obj", "preview.png", "animation.mp4", "animation.usd",
                 "notes.txt"):
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text("x")
    (out / RUN_FILE).write_text(json.dumps({"identity": {"scene": "old"}}))
    with pytest.raises(InputError, match="already holds a run"):
        RunFolder(out, IDENTITY).open(resume=False, overwrite=False)
    with _claimed(out, overwrite=True):
        pass
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "notes.txt", "run.json"]


@pytest.mark.parametrize("content", ["[1, 2]", "{\"identity\": 3}", "{broken", ""])
def test_a_run_file_that_is_not_a_run_is_an_input_error(tmp_path: Path, content: str) -> None:
    out = tmp_path / "run"
    out.mkdir()
    (out / RUN_FILE).write_text(content)
    for resume in (False, True):
        with pytest.raises(InputError, match="run.json: identity: unreadable run file"):
            RunFolder(out, IDENTITY).open(resume=resume, overwrite=False)
    with _claimed(out, overwrite=True):  # --overwrite replaces it
        pass
    assert json.loads((out / RUN_FILE).read_text())["identity"] == IDENTITY


def test_identity_differences_name_the_settings_and_files() -> None:
    old = {"scene": "s", "settings": {"cloth[0].material.density": 0.1, "obstacle[0].translate": [0, 0, 0]},
           "files": {"/m.obj": "aa"}, "scene_sha256": "1"}
    new = {"scene": "s", "settings": {"cloth[0].material.density": 0.2, "obstacle[0].translate": [0, 0, 0]},
           "files": {"/m.obj": "bb"}, "scene_sha256": "2"}
    assert identity_differences(old, new) == ["cloth[0].material.density: 0.2 here, 0.1 in the run",
                                              "the content of /m.obj changed"]
    assert identity_differences({**old, "files": new["files"], "settings": new["settings"]}, new) == [
        "scene_sha256 differs (the scene's arrays changed, though no setting did)"]
    assert identity_differences(new, new) == []
    assert identity_differences([1, 2], new) == ["the folder's run has no readable identity"]


def test_resume_refuses_a_changed_identity_naming_the_setting(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with _claimed(out) as folder:
        folder.save_checkpoint(STATE, 0, [])
    changed = {**IDENTITY, "settings": {"cloth[0].material.density": 0.3}}
    with pytest.raises(InputError, match=r"cloth\[0\].material.density: 0.3 here, 0.1 in the run"):
        RunFolder(out, changed).open(resume=True, overwrite=False)
    with RunFolder(out, IDENTITY).open(resume=True, overwrite=False) as folder:
        state, frame, stats = folder.load_checkpoint()
    assert frame == 0 and stats == [] and np.array_equal(state["positions"], STATE["positions"])


def _checkpoint_bytes(tmp_path: Path, frame: int, stats: list) -> bytes:
    with _claimed(tmp_path / "source") as folder:
        folder.save_checkpoint(STATE, frame, stats)
        return folder.checkpoint_path.read_bytes()


def _flip(data: bytes) -> bytes:
    """One bit flipped inside the stored positions (a flip in zip or header padding changes nothing read)."""
    at = data.index(STATE["positions"].tobytes()) + 5
    return data[:at] + bytes([data[at] ^ 0x10]) + data[at + 1:]


@pytest.mark.parametrize("damage", ["empty", "truncated", "bit-flipped", "edited frame", "negative frame",
                                    "stats of another length"])
def test_damaged_or_inconsistent_checkpoints_are_refused(tmp_path: Path, damage: str) -> None:
    good = _checkpoint_bytes(tmp_path, 2, [{}, {}])
    if damage == "empty":
        data = b""
    elif damage == "truncated":
        data = good[: len(good) // 3]
    elif damage == "bit-flipped":
        data = _flip(good)
    elif damage == "edited frame":  # a checkpoint re-saved with another frame but without a matching digest
        import io

        with np.load(io.BytesIO(good)) as archive:
            arrays = {key: archive[key] for key in archive.files}
        arrays["frame"] = np.array([-7], dtype=np.int64)
        buffer = io.BytesIO()
        np.savez(buffer, **arrays)
        data = buffer.getvalue()
    elif damage == "negative frame":
        data = _checkpoint_bytes(tmp_path / "neg", -7, [])
    else:
        data = _checkpoint_bytes(tmp_path / "len", 3, [{}])
    out = tmp_path / "run"
    with _claimed(out) as folder:
        folder.record(CHECKPOINT_FILE)
        folder.checkpoint_path.write_bytes(data)
    with RunFolder(out, IDENTITY).open(resume=True, overwrite=False) as folder, \
            pytest.raises(InputError, match="checkpoint.npz: checkpoint: .*Fix: run again with --overwrite"):
        folder.load_checkpoint()


def test_missing_frames_lists_recorded_frames_that_are_gone(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with _claimed(out) as folder:
        folder.record_series("frames/frame_{index:05d}.npz", 4)
        for index in (0, 2):
            write_text_atomic(out / f"frames/frame_{index:05d}.npz", "x")
        assert folder.missing_frames(2) == ["frames/frame_00001.npz"]
        assert folder.missing_frames(0) == []


def test_discard_removes_everything_the_run_wrote(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with _claimed(out) as folder:
        folder.record("stats.json")
        folder.record_series("frames/frame_{index:05d}.npz", 3)
        write_text_atomic(out / "frames/frame_00000.npz", "x")
        write_text_atomic(out / "stats.json", "{}")
        folder.discard()
    assert not out.exists()


def test_run_files_get_ordinary_permissions(tmp_path: Path) -> None:
    previous = os.umask(0o022)
    try:
        with _claimed(tmp_path / "run") as folder:
            folder.save_checkpoint(STATE, 0, [])
            write_text_atomic(folder.out_dir / "scene.toml", "x")
        for name in (RUN_FILE, MANIFEST_FILE, CHECKPOINT_FILE, "scene.toml"):
            assert (tmp_path / "run" / name).stat().st_mode & 0o777 == 0o644, name
    finally:
        os.umask(previous)


@pytest.mark.parametrize(("code", "words"), [(errno.ENOSPC, "the disk is full"),
                                             (errno.EACCES, "permission denied"),
                                             (errno.EROFS, "the file system is read-only")])
def test_os_failures_become_output_errors_and_leave_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                            code: int, words: str) -> None:
    target = tmp_path / "pairs.npz"
    target.write_bytes(b"old")

    def write(stream: object) -> None:
        raise OSError(code, os.strerror(code))

    with pytest.raises(OutputError, match=f"pairs.npz: --out: cannot be written: {words}.*Fix: "):
        write_atomic(target, write, field="--out")
    assert target.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pairs.npz"]


def test_atomic_write_to_a_folder_is_refused(tmp_path: Path) -> None:
    with pytest.raises(OutputError, match="is a folder"):
        write_text_atomic(tmp_path, "x")


def test_unused_object_ids_never_overflow() -> None:
    from pscc._checks import INT32_MAX, unused_object_ids

    assert unused_object_ids(np.array([0, 3]), 2).tolist() == [4, 5]
    assert unused_object_ids(np.array([], dtype=np.int32), 2).tolist() == [0, 1]
    assert unused_object_ids(np.array([0, 2, INT32_MAX]), 3).tolist() == [1, 3, 4]
    assert unused_object_ids(np.array([INT32_MAX - 1]), 2).tolist() == [0, 1]
