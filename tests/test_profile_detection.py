"""`tools/profile_detection.py`, the replay profile behind BENCHMARKS-cuda.md's per-kernel figures: it
reads frames as the bench's --frames does, times both methods on them, and ends with exit 2 naming a
missing frame file or a bad radius."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import profile_detection  # noqa: E402

from pscc.mesh import folded_sheet  # noqa: E402


def test_frame_specs() -> None:
    assert profile_detection.parse_frame("a.npz") == (Path("a.npz"), None, True)
    assert profile_detection.parse_frame("a.npz:0.01") == (Path("a.npz"), 0.01, True)
    assert profile_detection.parse_frame("a.npz:0.01:norest") == (Path("a.npz"), 0.01, False)


def test_both_methods_are_timed_on_a_frame_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    mesh = folded_sheet(300, layers=3, seed=2)
    path = tmp_path / "layers.npz"
    np.savez(path, positions=mesh.vertices_end, faces=mesh.faces, rest=mesh.rest)
    assert profile_detection.main(["--device", "cpu", "--replays", "1", str(path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == ["layers pscc", "layers spatial-hash"]
    assert all("replay + counter read" in line and " ms" in line for line in lines)


def test_a_missing_frame_file_or_a_bad_radius_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "nowhere.npz"
    assert profile_detection.main(["--device", "cpu", f"{missing}:0.01"]) == 2
    message = capsys.readouterr().err
    assert "nowhere.npz" in message and "Fix:" in message
    assert profile_detection.main(["--device", "cpu", f"{missing}:wide"]) == 2
    message = capsys.readouterr().err
    assert "'wide'" in message and "FILE[:RADIUS[:norest]]" in message
