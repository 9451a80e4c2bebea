"""`tools/compile_cuda.py`, the ahead-of-time CUDA compile of `make test`: a module that compiles is
reported with its architectures, one that does not gives its error, and the script fails on it."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

# The script lives in tools/, not in a package: importable by name (also in the script's spawned workers,
# which inherit this sys.path).
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import compile_cuda  # noqa: E402


def test_a_small_module_compiles_for_both_architectures(tmp_path: Path) -> None:
    arches, error, seconds = compile_cuda.compile_module("pscc.sim.pcg", [80, 90], str(tmp_path))
    assert error is None
    assert arches == "sm80, sm90"
    assert seconds > 0.0


def test_an_architecture_nvrtc_refuses_is_an_error(tmp_path: Path) -> None:
    arches, error, _ = compile_cuda.compile_module("pscc.sim.pcg", [5], str(tmp_path))
    assert arches == ""
    assert error is not None and "failed" in error


def test_the_script_fails_on_a_module_that_does_not_compile(monkeypatch: pytest.MonkeyPatch,
                                                            capsys: pytest.CaptureFixture) -> None:
    monkeypatch.setattr(compile_cuda, "kernel_modules", lambda: ["pscc.sim.pcg"])
    # The module list is patched in this process only; the one spawned worker compiles pscc.sim.pcg for an
    # architecture NVRTC refuses.
    assert compile_cuda.main(["--arch", "5", "--jobs", "1"]) == 1
    captured = capsys.readouterr()
    assert "FAILED  pscc.sim.pcg" in captured.err
    assert "0 of 1 kernel modules compiled" in captured.out


def test_jobs_below_one_are_refused() -> None:
    with pytest.raises(SystemExit) as exc:
        compile_cuda.main(["--jobs", "0"])
    assert exc.value.code == 2


def test_a_kernel_cache_is_filled_in_warps_layout(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """--cache: the module's cubin and metadata land where Warp looks for them under WARP_CACHE_PATH."""
    monkeypatch.setattr(compile_cuda, "kernel_modules", lambda: ["pscc.sim.pcg"])
    # With one job the tool points this process's Warp kernel cache at tmp_path: put it back afterwards, or
    # the later tests of this worker compile their kernels again there.
    compile_cuda.wp.init()  # sets the cache path that is kept
    monkeypatch.setattr(compile_cuda.wp.config, "kernel_cache_dir", compile_cuda.wp.config.kernel_cache_dir)
    assert compile_cuda.main(["--arch", "90", "--jobs", "1", "--cache", str(tmp_path)]) == 0
    (version,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    (module,) = [p for p in version.iterdir() if p.name.startswith("wp_pscc.sim.pcg_")]
    assert (module / f"{module.name}.sm90.cubin").stat().st_size > 0
    assert (module / f"{module.name}.meta").is_file()


def test_out_and_cache_are_exclusive(tmp_path: Path) -> None:
    with pytest.raises(SystemExit) as exc:
        compile_cuda.main(["--out", str(tmp_path), "--cache", str(tmp_path)])
    assert exc.value.code == 2

