"""The shipped example garment (examples/garment): a two-panel skirt cut from its UV layout and sewn by OBJ
stitch lines closes its side seams around a body, with no halved step and no crossing but the seams."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

from pscc.bench.oracle import crossings as ipctk_crossings
from pscc.scenes.scene_file import load_scene_file
from pscc.sim.simulation import Simulation

FOLDER = Path(__file__).resolve().parents[2] / "examples" / "garment"
THICKNESS = 0.002


def test_the_generator_writes_the_shipped_files(tmp_path: Path) -> None:
    spec = importlib.util.spec_from_file_location("make_skirt", FOLDER / "make_skirt.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.main(tmp_path)
    for name in ("skirt.obj", "body.obj"):
        assert (tmp_path / name).read_text() == (FOLDER / name).read_text(), name


def test_the_skirt_sews_its_seams_around_the_body() -> None:
    scene, contact, options = load_scene_file(FOLDER / "skirt.toml")
    assert scene.stitches.shape == (26, 4) and scene.rest.shape[1] == 2  # rest from the uv layout
    sim = Simulation(scene, device="cpu", contact=contact)
    stitches = scene.stitches
    i, j, k = (stitches[:, c].astype(int) for c in range(3))
    r = stitches[:, 3:4]
    cloth = len(scene.vertices)
    faces = sim.solver.collision_faces
    for frame in range(8):
        record = sim.step_frame()
        assert record["counts"]["halvings"] == 0
        x = sim.state.positions.numpy()
        gap = np.linalg.norm(x[i] - ((1.0 - r) * x[j] + r * x[k]), axis=1).max()
        if frame >= 2:
            assert gap < 2 * THICKNESS, (frame, gap)  # the bound: seams closed to 2 thicknesses
        assert sim.solver.intersection_check.find(x).shape == (0, 2)
        # The independent oracle: ipctk finds no crossing but at the seams.
        assert ipctk_crossings(x, faces, stitches).shape == (0, 3), frame
    radius = np.linalg.norm(x[:cloth, :2], axis=1)
    assert radius.min() > 0.16  # outside the body (radius 0.16 m)
    assert options["frames"] == 45


def test_a_run_records_the_seam_gap_of_every_frame(tmp_path: Path) -> None:
    import json

    scene, contact, _ = load_scene_file(FOLDER / "skirt.toml")
    Simulation(scene, device="cpu", contact=contact).run(3, tmp_path / "run", progress=False)
    frames = json.loads((tmp_path / "run" / "stats.json").read_text())["frames"]
    gaps = [record["seam_gap"] for record in frames]
    assert len(gaps) == 3 and gaps[0] < 0.02 and gaps[-1] < 2 * THICKNESS  # 2 cm open at the start
