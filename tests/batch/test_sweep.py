"""Sweep files: their runs (ids, documents, identities) and one-line errors before Ray or any file."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from pscc.batch import runner
from pscc.batch.sweep import expand_runs, load_sweep, run_id
from pscc.cli import main

SHEET_SCENE = """[scene]
name = "{name}"
frames = 3
[[cloth]]
name = "top"
translate = [0.0, 0.0, 0.1]
[cloth.sheet]
size = [0.3, 0.3]
cells = [4, 4]
[[cloth]]
name = "bottom"
[cloth.sheet]
size = [0.3, 0.3]
cells = [4, 4]
"""


def _write(folder: Path, text: str, name: str = "sweep.toml") -> Path:
    path = folder / name
    path.write_text(text)
    return path


def test_a_2x2_sweep_expands_into_stable_named_runs_with_the_values_applied(tmp_path: Path) -> None:
    path = _write(tmp_path, '[batch]\nscenes = ["drape", "twist"]\nframes = 2\ntriangles = 100\n'
                            '[batch.vary]\n"cloth.material.friction" = [0.1, 0.5]\n')
    runs = expand_runs(load_sweep(path))
    assert [r.run_id for r in runs] == ["drape-friction=0.1", "drape-friction=0.5", "twist-friction=0.1",
                                        "twist-friction=0.5"]
    assert [r.run_id for r in expand_runs(load_sweep(path))] == [r.run_id for r in runs]  # same every time
    for run, friction in zip(runs, [0.1, 0.5, 0.1, 0.5], strict=True):
        assert run.values == {"cloth.material.friction": friction} and run.frames == 2
        assert run.document["material"]["friction"] == friction and run.document["builtin"]["triangles"] == 100
        assert run.identity["settings"]["material.friction"] == friction
    assert runs[0].identity != runs[1].identity


def test_a_scene_file_is_found_beside_the_sweep_and_keeps_its_own_frames(tmp_path: Path) -> None:
    _write(tmp_path, SHEET_SCENE.format(name="sheets"), "sheets.toml")
    path = _write(tmp_path, '[batch]\nscenes = ["sheets.toml"]\n[batch.vary]\n"cloth[1].material.density" = [0.1]\n'
                            '"solver.gravity[2]" = [-1.62]\n')
    (run,) = expand_runs(load_sweep(path))
    assert run.run_id == "sheets-density=0.1-gravity_2=-1.62" and run.frames == 3
    assert run.origin == str(tmp_path / "sheets.toml") and run.identity["file"] == run.origin
    assert [c["material"]["density"] for c in run.document["cloth"]] == [0.187, 0.1]
    assert run.document["solver"]["gravity"][2] == -1.62


def test_run_ids_are_safe_folder_names_and_unique() -> None:
    assert run_id("drape", {"contact.method": "brute-force"}) == "drape-method=brute-force"
    odd = run_id("drape", {"scene.name": "a/b c"})
    assert "/" not in odd and " " not in odd and odd.startswith("drape-name=a_b_c-") and len(odd) == len(
        "drape-name=a_b_c-") + 8
    assert run_id("drape", {"scene.name": "a/b c"}) != run_id("drape", {"scene.name": "a_b c"})
    assert len(run_id("drape", {"scene.description": "x" * 300})) <= 100


def test_keys_ending_alike_are_named_by_their_whole_paths(tmp_path: Path) -> None:
    _write(tmp_path, SHEET_SCENE.format(name="sheets"), "sheets.toml")
    path = _write(tmp_path, '[batch]\nscenes = ["sheets.toml"]\n[batch.vary]\n"cloth[0].material.friction" = [0.1]\n'
                            '"cloth[1].material.friction" = [0.2]\n')
    (run,) = expand_runs(load_sweep(path))
    assert run.run_id == "sheets-cloth_0.material.friction=0.1-cloth_1.material.friction=0.2"


def _no_ray(monkeypatch: pytest.MonkeyPatch) -> None:
    def fail() -> None:
        raise AssertionError("Ray was imported before the sweep was checked")

    monkeypatch.setattr(runner, "_import_ray", fail)


BAD_SWEEPS = [
    ("not toml [", "file", "is not valid TOML"),
    ('[other]\nx = 1\n', "other", "is not a table of a sweep file"),
    ('[batch]\nframes = 2\n', "batch.scenes", "is missing"),
    ('[batch]\nscenes = ["drape"]\nframe = 2\n', "batch.frame", "did you mean 'frames'"),
    ('[batch]\nscenes = ["drape"]\ntriangles = 100\nscale = 0.5\n', "batch.scale", "both triangles and scale"),
    ('[batch]\nscenes = ["drape"]\nframes = 0\n', "batch.frames", "0 is not an integer >= 1"),
    ('[batch]\nscenes = ["drape", "drape"]\n', "batch.scenes[1]", "repeats 'drape'"),
    ('[batch]\nscenes = ["drap"]\n', "batch.scenes[0]", "did you mean 'drape'"),
    ('[batch]\nscenes = ["missing.toml"]\n', "batch.scenes[0]", "file does not exist"),
    ('[batch]\nscenes = ["drape"]\ntriangles = 3\n', "batch.triangles", "(scene drape)"),
    ('[batch]\nscenes = ["drape"]\nformats = ["gif"]\n', "batch.formats", "unknown format 'gif'"),
    ('[batch]\nscenes = ["drape"]\ncheckpoint_every = 0\n', "batch.checkpoint_every", "is not an integer >= 1"),
    ('[batch]\nscenes = ["drape"]\n[batch.vary]\n"cloth.material.friction" = []\n',
     'batch.vary."cloth.material.friction"', "is not a non-empty array"),
    ('[batch]\nscenes = ["drape"]\n[batch.vary]\n"cloth.material.friction" = 0.1\n',
     'batch.vary."cloth.material.friction"', "is not a non-empty array"),
    ('[batch]\nscenes = ["drape"]\n[batch.vary]\ncloth.material.friction = [0.1]\n',
     'batch.vary."cloth"', "written without quotes"),
    ('[batch]\nscenes = ["drape"]\n[batch.vary]\n"cloth.material.friction" = [0.1, 0.1]\n',
     'batch.vary."cloth.material.friction"[1]', "repeats the value 0.1"),
    ('[batch]\nscenes = ["drape"]\n[batch.vary]\n"cloth.material.frction" = [0.1]\n',
     'batch.vary."cloth.material.frction"[0]', "material.frction: is not a field of ClothMaterial"),
    ('[batch]\nscenes = ["drape"]\n[batch.vary]\n"cloth.material.friction" = [0.1, "high"]\n',
     'batch.vary."cloth.material.friction"[1]', "\"high\" in scene drape: material.friction"),
    ('[batch]\nscenes = ["drape"]\n[batch.vary]\n"cloth.material.friction" = [0.2, -0.5]\n',
     'batch.vary."cloth.material.friction"[1]', "-0.5 is negative"),
    ('[batch]\nscenes = ["drape"]\n[batch.vary]\n"solver.gravity[3]" = [1.0]\n',
     'batch.vary."solver.gravity[3]"', "so [3] does not exist"),
    ('[batch]\nscenes = ["drape"]\n[batch.vary]\n"scene.frames" = [3]\n',
     'batch.vary."scene.frames"', "cannot be varied"),
    ('[batch]\nscenes = ["drape"]\n[batch.vary]\n"material.stretch_uv" = [900.0]\n'
     '"material.stretch_u" = [1000.0, 500.0]\n',
     "batch.vary", "the combination material.stretch_uv = 900.0, material.stretch_u = 500.0 in scene drape"),
    ('[batch]\nscenes = ["sheets.toml"]\n[batch.vary]\n"cloth[0].sheet.cells" = [[4, 0]]\n',
     'batch.vary."cloth[0].sheet.cells"[0]', "[4, 0] in scene sheets: cloth[0].sheet.cells"),
    ('[batch]\nscenes = ["sheets.toml", "other/sheets.toml"]\n', "batch.scenes[1]", "is named 'sheets' like"),
]


@pytest.mark.parametrize(("text", "field", "words"), BAD_SWEEPS)
def test_a_bad_sweep_is_one_line_before_ray_starts_or_anything_is_written(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, text: str, field: str,
        words: str) -> None:
    _no_ray(monkeypatch)
    _write(tmp_path, SHEET_SCENE.format(name="sheets"), "sheets.toml")
    (tmp_path / "other").mkdir()
    _write(tmp_path / "other", SHEET_SCENE.format(name="sheets"), "sheets.toml")
    sweep = _write(tmp_path, text)
    out = tmp_path / "out"
    assert main(["batch", str(sweep), "--out-dir", str(out), "--no-progress"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"pscc: error: {sweep}: {field}: ") and ". Fix: " in lines[0], lines[0]
    assert words in lines[0], lines[0]
    assert not out.exists()


def test_a_missing_sweep_file_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                       monkeypatch: pytest.MonkeyPatch) -> None:
    _no_ray(monkeypatch)
    assert main(["batch", str(tmp_path / "none.toml"), "--out-dir", str(tmp_path / "out")]) == 2
    assert "none.toml: path: file does not exist. Fix:" in capsys.readouterr().err


def test_workers_with_an_address_and_ray_missing_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    sweep = _write(tmp_path, '[batch]\nscenes = ["drape"]\nframes = 1\ntriangles = 100\n')
    out = tmp_path / "out"
    assert main(["batch", str(sweep), "--out-dir", str(out), "--workers", "2", "--address", "auto"]) == 2
    assert "--workers: --workers sizes a local Ray instance" in capsys.readouterr().err
    assert main(["batch", str(sweep), "--out-dir", str(out), "--workers", "0"]) == 2
    assert "--workers: 0 is below 1" in capsys.readouterr().err
    monkeypatch.setitem(__import__("sys").modules, "ray", None)  # `import ray` fails as if it were not installed
    assert main(["batch", str(sweep), "--out-dir", str(out)]) == 2
    line = capsys.readouterr().err.strip()
    assert "Ray is not installed" in line and 'pip install "pscc[batch]"' in line and not out.exists()


def test_the_resolved_documents_load_as_scene_files(tmp_path: Path) -> None:
    """What a task receives is a scene file: written out, `pscc simulate` could run it."""
    path = _write(tmp_path, '[batch]\nscenes = ["twist"]\nframes = 1\ntriangles = 100\n'
                            '[batch.vary]\n"contact.method" = ["brute-force"]\n')
    (run,) = expand_runs(load_sweep(path))
    from pscc.scenes.registry import open_scene
    from pscc.scenes.toml_text import dump_toml

    scene_file = tmp_path / "run.toml"
    scene_file.write_text(dump_toml(run.document))
    source = open_scene(str(scene_file))
    assert source.contact.method == "brute-force" and tomllib.loads(scene_file.read_text())["builtin"]["frames"] == 1
