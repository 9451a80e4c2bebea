"""`tools/profile_cpu.py`, perf samples of CPU graph replays per Warp kernel: symbol tables and the load offset,
samples attributed to functions and kept to the replays' time window, the child's map of loaded kernels, and
exit 2 naming a missing `perf` or a bad frame."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import profile_cpu  # noqa: E402

from pscc.mesh import folded_sheet  # noqa: E402

NM = """0000000000000000 b _ZN2wpL19shared_tile_storageE
0000000000000000 T _fill_5d1c9a2e_cpu_forward
0000000000000400 t _ZL9helper_0N2wp5vec_tILj3EfEE
0000000000000550 T _test_8947fbbd_cpu_forward
"""


def test_symbol_table_keeps_text_symbols_with_offsets() -> None:
    nm = NM.replace("0000000000000000 T", "0000000000000000 0000000000000400 T")
    nm = nm.replace("0000000000000400 t", "0000000000000400 0000000000000150 t")
    nm = nm.replace("0000000000000550 T", "0000000000000550 0000000000000080 T")
    table = profile_cpu.symbol_table(nm)
    assert table == {"_fill_5d1c9a2e_cpu_forward": (0, 0x400), "_ZL9helper_0N2wp5vec_tILj3EfEE": (0x400, 0x150),
                     "_test_8947fbbd_cpu_forward": (0x550, 0x80)}


def test_samples_go_to_the_function_they_fall_in() -> None:
    table = {"_fill_5d1c9a2e_cpu_forward": (0, 0x400), "_ZL9helper": (0x400, 0x150),
             "_test_8947fbbd_cpu_forward": (0x550, 0x80), "_empty": (0x5d0, 0)}
    # The entry of _test lies at 0x10550 in the process, so the module was loaded at 0x10000.
    functions = profile_cpu.module_functions("pscc.collision.boxes", "_test_8947fbbd_cpu_forward", 0x10550, table)
    assert {(f.start, f.end, f.name) for f in functions} == {
        (0x10000, 0x10400, "_fill_5d1c9a2e_cpu_forward"), (0x10400, 0x10550, "_ZL9helper"),
        (0x10550, 0x105D0, "_test_8947fbbd_cpu_forward")}
    counts = profile_cpu.attribute([0x10000, 0x103FF, 0x10400, 0x10560, 0x105D0, 0x5], functions)
    assert counts == {"boxes:_fill": 2, "boxes:_ZL9helper": 1, "boxes:_test": 1, "outside": 2}


def test_only_samples_of_the_replays_count() -> None:
    script = "  100.500000:     7f00000010\n  101.250000:  7f00000020\nbad line\n  102.000001: 7f00000030\n"
    assert profile_cpu.replay_samples(script, 100.6, 102.0) == [0x7F00000020]
    assert profile_cpu.replay_samples(script, 100.0, 103.0) == [0x7F00000010, 0x7F00000020, 0x7F00000030]


def test_the_child_maps_every_loaded_kernel(tmp_path: Path) -> None:
    """The child mode (what runs under perf): one frame's replays, then where each loaded CPU kernel's entry
    lies; the module objects named there are found in the kernel cache with those entries."""
    mesh = folded_sheet(300, layers=3, seed=2)
    frame = tmp_path / "layers.npz"
    np.savez(frame, positions=mesh.vertices_end, faces=mesh.faces, rest=mesh.rest)
    kernel_map = tmp_path / "kernels.json"
    # In its own process, as the tool runs it under perf (an earlier test may have pointed this process's
    # Warp kernel cache elsewhere).
    tool = Path(profile_cpu.__file__)
    done = subprocess.run([sys.executable, str(tool), "--child", str(kernel_map), "--replays", "3", f"{frame}:0.01"],
                          capture_output=True, text=True, cwd=tool.parents[1])
    assert done.returncode == 0, done.stderr
    written = json.loads(kernel_map.read_text())
    assert written["frame"] == "layers" and written["seconds"] > 0.0 and written["last"] > written["first"]
    kernels = {(entry["module"], entry["symbol"].rsplit("_", 3)[0]) for entry in written["kernels"]}
    assert ("pscc.collision._hash_row_kernels", "_test_bounding_volumes") in kernels
    assert ("pscc.collision.feature_pairs", "_extract_features") in kernels
    assert all(isinstance(entry["address"], int) and entry["address"] > 0 for entry in written["kernels"])
    objects = list(Path(written["cache"]).glob("wp_pscc.collision.feature_pairs_*/*.o"))
    assert objects


def test_a_missing_perf_or_frame_is_named(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(profile_cpu.shutil, "which", lambda name: None)
    assert profile_cpu.main([str(tmp_path / "a.npz")]) == 2
    message = capsys.readouterr().err
    assert "`perf`" in message and "Fix:" in message
    monkeypatch.setattr(profile_cpu.shutil, "which", lambda name: "/usr/bin/perf")
    assert profile_cpu.main([f"{tmp_path / 'nowhere.npz'}:0.01"]) == 2
    message = capsys.readouterr().err
    assert "nowhere.npz" in message and "Fix:" in message


def test_a_missing_nm_or_a_failing_recording_is_named(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    mesh = folded_sheet(300, layers=3, seed=2)
    frame = tmp_path / "layers.npz"
    np.savez(frame, positions=mesh.vertices_end, faces=mesh.faces, rest=mesh.rest)
    monkeypatch.setattr(profile_cpu.shutil, "which", lambda name: None if name == "nm" else f"/usr/bin/{name}")
    assert profile_cpu.main([f"{frame}:0.01"]) == 2
    message = capsys.readouterr().err
    assert "`nm`" in message and "Fix: install binutils" in message
    monkeypatch.setattr(profile_cpu.shutil, "which", lambda name: f"/usr/bin/{name}")

    def refused(*args: object) -> None:
        raise subprocess.CalledProcessError(255, ["/usr/bin/perf", "record", "-q"],
                                            stderr="Error:\nAccess to performance monitoring is restricted.")

    monkeypatch.setattr(profile_cpu, "profile", refused)
    assert profile_cpu.main([f"{frame}:0.01"]) == 2
    message = capsys.readouterr().err
    assert "layers.npz:0.01" in message and "exit status 255" in message
    assert "Access to performance monitoring is restricted." in message and "perf_event_paranoid" in message
