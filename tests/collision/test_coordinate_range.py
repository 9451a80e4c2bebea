"""The documented coordinate range of the collision detector (``pscc.tolerances.MAX_COORDINATE`` and
``MIN_COORDINATE_SCALE``, ``MAX_THICKNESS``): the same pairs at both ends of the range for every
method, DCD and CCD, and a clear :class:`InputError` just outside it (API, mesh loading and CLI)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from pscc import tolerances
from pscc.cli import main
from pscc.collision.detector import METHODS, CollisionDetector
from pscc.errors import InputError
from pscc.mesh import folded_sheet, load_mesh, validate_mesh

_MESH = folded_sheet(200, layers=3, seed=0)
_X0 = _MESH.vertices.astype(np.float64)
_X1 = _MESH.vertices_end.astype(np.float64)
_EDGES = np.concatenate([_MESH.faces[:, [0, 1]], _MESH.faces[:, [1, 2]], _MESH.faces[:, [2, 0]]])
_MEAN_EDGE = float(np.linalg.norm(_X0[_EDGES[:, 0]] - _X0[_EDGES[:, 1]], axis=1).mean())
_LARGEST = max(np.abs(_X0).max(), np.abs(_X1).max())
_SMALLEST_LARGEST = min(np.abs(_X0).max(), np.abs(_X1).max())

# Powers of two scale float32 exactly, so any change in the pairs comes from the arithmetic at that
# magnitude (overflow, underflow), not from rounding the input differently.
_LOW = 2.0 ** math.ceil(math.log2(tolerances.MIN_COORDINATE_SCALE / _SMALLEST_LARGEST))
_HIGH = 2.0 ** math.floor(math.log2(tolerances.MAX_COORDINATE / _LARGEST))

# (label, end positions?, DCD thickness in mean edges, which positions the DCD runs on)
_QUERIES = [("dcd_start", False, 1.0, _X0), ("dcd_end", False, 0.3, _X1), ("ccd", True, 0.0, _X0)]


def _pairs(result) -> tuple[set, set]:
    return ({tuple(int(x) for x in r) for r in result.vertex_face},
            {tuple(int(x) for x in r) for r in result.edge_edge})


def _detect(method: str, device: str, scale: float, query: tuple) -> tuple[set, set]:
    _, ccd, thickness, x = query
    detector = CollisionDetector(_MESH.faces, method=method, device=device, rest=_MESH.rest)
    x1 = (_X1 * scale).astype(np.float32) if ccd else None
    return _pairs(detector.detect((x * scale).astype(np.float32), x1, thickness=thickness * _MEAN_EDGE * scale))


def test_scales_reach_both_ends_of_the_range() -> None:
    assert tolerances.MIN_COORDINATE_SCALE <= _LOW * _SMALLEST_LARGEST < 2 * tolerances.MIN_COORDINATE_SCALE
    assert tolerances.MAX_COORDINATE / 2 < _HIGH * _LARGEST <= tolerances.MAX_COORDINATE


@pytest.mark.parametrize("method", METHODS)
def test_same_pairs_at_both_ends_of_the_range(device: str, method: str) -> None:
    for query in _QUERIES:
        reference = _detect(method, device, 1.0, query)
        assert reference[0] and reference[1], f"{query[0]}: the mesh must give pairs of both kinds"
        for scale in (_LOW, _HIGH):
            assert _detect(method, device, scale, query) == reference, f"{method} {query[0]} at scale {scale:g}"


def _scaled_to(largest: float) -> np.ndarray:
    return (_X0 * (largest / np.abs(_X0).max())).astype(np.float32)


@pytest.mark.parametrize("largest", [1.01 * tolerances.MAX_COORDINATE, 1e20, 0.99 * tolerances.MIN_COORDINATE_SCALE])
def test_positions_outside_the_range_are_refused(largest: float) -> None:
    inside = _scaled_to(1.0)
    outside = _scaled_to(largest)
    limit = tolerances.MAX_COORDINATE if largest > 1 else tolerances.MIN_COORDINATE_SCALE
    detector = CollisionDetector(_MESH.faces, method="pscc", device="cpu", rest=_MESH.rest)
    calls = [
        ("positions", lambda: detector.prepare(outside)),
        ("positions", lambda: detector.detect(outside, thickness=0.01)),
        ("positions_end", lambda: detector.detect(inside, outside)),
        ("positions", lambda: detector.broad_phase(outside, inside, 0.01)),
    ]
    for field, call in calls:
        with pytest.raises(InputError) as caught:
            call()
        error = caught.value
        assert error.field == field
        assert f"{float(np.float32(np.abs(outside).max())):.4g}" in error.problem
        assert f"{limit:g}" in error.problem and f"{limit:g}" in error.fix
    detector.broad_phase(inside, inside, 0.01)
    with pytest.raises(InputError) as caught:
        detector.narrow_phase(outside, None, 0.01)
    assert caught.value.field == "positions"


def test_edges_of_the_range_are_accepted() -> None:
    detector = CollisionDetector(_MESH.faces, method="brute-force", device="cpu")
    detector.prepare(_scaled_to(0.999 * tolerances.MAX_COORDINATE))
    detector.prepare(_scaled_to(1.001 * tolerances.MIN_COORDINATE_SCALE))
    detector.prepare(np.zeros_like(_X0))  # every point at the origin: nothing to overflow or underflow
    detector.detect(_scaled_to(1.0), thickness=tolerances.MAX_THICKNESS)


def test_thickness_outside_the_range_is_refused() -> None:
    detector = CollisionDetector(_MESH.faces, method="spatial-hash", device="cpu")
    with pytest.raises(InputError) as caught:
        detector.detect(_scaled_to(1.0), thickness=1.01 * tolerances.MAX_THICKNESS)
    assert caught.value.field == "thickness"
    assert f"{tolerances.MAX_THICKNESS:g}" in str(caught.value)


def test_mesh_validation_names_the_source_and_field() -> None:
    with pytest.raises(InputError) as caught:
        validate_mesh(_X0 * 1e20, _MESH.faces, source="big.npz")
    assert (caught.value.source, caught.value.field) == ("big.npz", "vertices")
    with pytest.raises(InputError) as caught:
        validate_mesh(_X0, _MESH.faces, vertices_end=_X1 * 1e-9)
    assert caught.value.field == "vertices_end"


def test_cli_refuses_a_mesh_outside_the_range(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "far.npz"
    np.savez(path, vertices=_X0 * 1e20, faces=_MESH.faces)
    out = tmp_path / "pairs.npz"
    assert main(["detect", str(path), "--thickness", str(_MEAN_EDGE * 1e20), "--out", str(out)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "Fix:" in lines[0] and str(path) in lines[0] and "vertices" in lines[0]
    assert captured.out == ""
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["far.npz"]
    with pytest.raises(InputError):
        load_mesh(path)


def test_cli_refuses_a_thickness_outside_the_range(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "sheet.npz"
    np.savez(path, vertices=_X0, faces=_MESH.faces)
    out = tmp_path / "pairs.npz"
    assert main(["detect", str(path), "--thickness", "1e20", "--out", str(out)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "Fix:" in lines[0] and "thickness" in lines[0]
    assert not out.exists()
