"""ClothModel construction (masses, frames, hinges, scripted vertices), configs and input validation."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pscc.errors import InputError
from pscc.mesh.generate import grid_sheet
from pscc.sim import ClothMaterial, ClothModel, ClothState, ContactSprings, ImplicitEuler, SolverConfig
from pscc.sim.model import VERTEX_FREE, VERTEX_MASSLESS, VERTEX_SCRIPTED


def test_masses_hinges_and_kinds_of_a_grid(device: str) -> None:
    vertices, faces, rest = grid_sheet(4, 3, width=2.0, height=1.5)
    material = ClothMaterial(density=0.2)
    model = ClothModel(vertices, faces, rest=rest, materials=material, pinned=[0, 4], handles=[19], device=device)
    assert model.total_mass == pytest.approx(0.2 * 2.0 * 1.5, rel=1e-6)
    assert model.mass_host.sum() == pytest.approx(0.2 * 3.0, rel=1e-5)
    cell = (2.0 / 4) * (1.5 / 3)
    # Every vertex gets a third of the mass of each of its triangles (area cell / 2).
    valence = np.bincount(faces.reshape(-1), minlength=20)
    np.testing.assert_allclose(model.mass_host, 0.2 * cell / 2 / 3 * valence, rtol=1e-5)
    # Interior edges: all edges minus the boundary ones.
    edge_count = 4 * 4 + 3 * 5 + 4 * 3
    assert model.hinge_count == edge_count - 2 * (4 + 3)
    assert model.face_count == 24 and model.vertex_count == 20
    assert np.all(model.hinges.rest_angle.numpy() == 0.0)
    kinds = model.kind_host
    assert kinds[0] == VERTEX_SCRIPTED and kinds[4] == VERTEX_SCRIPTED and kinds[19] == VERTEX_SCRIPTED
    assert np.count_nonzero(kinds == VERTEX_FREE) == 17
    assert model.handle_count == 1 and model.handle_ids.numpy().tolist() == [19]
    # Each hinge: x0 -> x1 appears in that order in a face that also holds x2, and x3 lies across.
    hinges = model.hinges_host
    face_set = {tuple(np.roll(f, k)) for f in faces.tolist() for k in range(3)}
    for x0, x1, x2, x3 in hinges.tolist():
        assert (x0, x1, x2) in face_set
        assert (x1, x0, x3) in face_set
    # Bending weight 3 |e|^2 / (A1 + A2) times the material stiffness.
    stiffness = model.hinges.stiffness.numpy()
    lengths = np.linalg.norm(rest[hinges[:, 1]] - rest[hinges[:, 0]], axis=1)
    expected = material.bending * 3 * lengths**2 / cell
    np.testing.assert_allclose(stiffness, expected, rtol=1e-5)


def test_flat_3d_rest_gives_the_same_frames_as_uv(device: str) -> None:
    vertices, faces, rest = grid_sheet(3, 3)
    from_uv = ClothModel(vertices, faces, rest=rest, device=device)
    from_3d = ClothModel(vertices, faces, device=device)  # rest = the flat initial shape
    np.testing.assert_allclose(from_3d.faces.inv_rest.numpy(), from_uv.faces.inv_rest.numpy(), atol=1e-5)
    np.testing.assert_allclose(from_3d.faces.rest_area.numpy(), from_uv.faces.rest_area.numpy(), rtol=1e-6)


def test_rest_angles_of_a_folded_rest_shape(device: str) -> None:
    vertices, faces, _ = grid_sheet(4, 2)
    folded = vertices.astype(np.float64).copy()
    right = folded[:, 0] > 0.5
    folded[right, 2] = folded[right, 0] - 0.5  # fold up by 45 degrees along x = 0.5
    model = ClothModel(vertices, faces, rest=folded, device=device)
    hinges = model.hinges_host
    angles = model.hinges.rest_angle.numpy()
    on_fold = np.all(np.isclose(vertices[hinges[:, :2], 0], 0.5), axis=1)
    assert on_fold.sum() == 2
    np.testing.assert_allclose(np.abs(angles[on_fold]), np.pi / 4, atol=1e-5)
    assert np.abs(angles[~on_fold]).max() < 1e-6
    # A sheet built at its folded rest shape feels no force: one step without gravity does nothing.
    model = ClothModel(folded, faces, device=device)
    integrator = ImplicitEuler(model, SolverConfig(gravity=(0.0, 0.0, 0.0)))
    state = ClothState.from_model(model)
    out = state.clone()
    integrator.step(state, out, 0.01)
    assert np.abs(out.positions.numpy() - folded).max() < 1e-6


def test_anisotropic_materials_per_object(device: str) -> None:
    vertices, faces, rest = grid_sheet(2, 1)
    stiff = ClothMaterial(stretch_u=2000.0, stretch_v=500.0, stretch_uv=0.0, density=0.3)
    soft = ClothMaterial()
    model = ClothModel(vertices, faces, rest=rest, materials=[soft, stiff], object_ids=[0, 0, 1, 1], device=device)
    stiffness = model.faces.stiffness.numpy()
    np.testing.assert_allclose(stiffness[2], [2000.0, 500.0, 0.0, 300.0])
    np.testing.assert_allclose(stiffness[0], [soft.stretch_u, soft.stretch_v, soft.stretch_uv, soft.shear])
    assert model.total_mass == pytest.approx(0.187 * 0.5 + 0.3 * 0.5, rel=1e-6)


def test_isolated_vertex_is_massless_and_falls_ballistically(device: str) -> None:
    vertices, faces, rest = grid_sheet(1, 1)
    vertices = np.concatenate([vertices, [[5.0, 5.0, 5.0]]]).astype(np.float32)
    model = ClothModel(vertices, faces, pinned=[0, 1, 2, 3], device=device)
    assert model.kind_host[4] == VERTEX_MASSLESS
    integrator = ImplicitEuler(model)
    state = ClothState.from_model(model)
    out = state.clone()
    integrator.step(state, out, 0.1)
    np.testing.assert_allclose(out.positions.numpy()[4], [5.0, 5.0, 5.0 - 9.81 * 0.01], rtol=1e-6)
    assert np.array_equal(out.positions.numpy()[:4], vertices[:4])


@pytest.mark.parametrize(
    ("kwargs", "field", "text"),
    [
        ({"rest": np.array([[0, 0], [1, 0], [2, 1], [3, 0]], np.float32)}, "rest", "face 0 [0, 1, 3]"),
        ({"rest": np.zeros((3, 2), np.float32)}, "rest", "rows"),
        ({"pinned": [7]}, "pinned", "outside"),
        ({"handles": np.array([0.5])}, "handles", "dtype"),
        ({"materials": [ClothMaterial(), ClothMaterial()], "object_ids": [0, 2]}, "object_ids", "object id 2"),
        ({"materials": ClothMaterial(stretch_uv=5000.0)}, "stretch_uv", "convex"),
        ({"materials": ClothMaterial(density=0.0)}, "density", "> 0"),
    ],
)
def test_model_input_errors_name_the_field(device: str, kwargs: dict, field: str, text: str) -> None:
    vertices = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]], np.float32)
    faces = np.array([[0, 1, 3], [1, 2, 3]], np.int32)
    with pytest.raises(InputError) as info:
        ClothModel(vertices, faces, device=device, **kwargs)
    assert info.value.field == field
    assert text in str(info.value)
    assert info.value.fix


def test_nan_and_degenerate_inputs(device: str) -> None:
    vertices, faces, rest = grid_sheet(2, 2)
    bad = vertices.copy()
    bad[3, 1] = np.nan
    with pytest.raises(InputError, match="NaN"):
        ClothModel(bad, faces, device=device)
    with pytest.raises(InputError, match="faces"):
        ClothModel(vertices, faces[:, :2], device=device)
    flat_rest = rest.copy()
    flat_rest[:, 1] = 0.0  # every triangle collinear
    with pytest.raises(InputError, match="zero area"):
        ClothModel(vertices, faces, rest=flat_rest, device=device)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"cg_tolerance": 0.0}, "cg_tolerance"),
        ({"cg_tolerance": 2.0}, "cg_tolerance"),
        ({"cg_max_iterations": 0}, "cg_max_iterations"),
        ({"gravity": (0.0, 1.0)}, "gravity"),
        ({"wind": (0.0, float("nan"), 0.0)}, "wind[1]"),
        ({"air_drag": -1.0}, "air_drag"),
        ({"contact_stiffness": -5.0}, "contact_stiffness"),
        ({"friction_velocity_epsilon": 0.0}, "friction_velocity_epsilon"),
        ({"preconditioner": "ilu"}, "preconditioner"),
    ],
)
def test_solver_config_validation(kwargs: dict, field: str) -> None:
    with pytest.raises(InputError) as info:
        SolverConfig(**kwargs).validate()
    assert info.value.field == field
    assert SolverConfig().validate() == SolverConfig()
    assert ClothMaterial().validate() == ClothMaterial()


def test_step_input_errors(device: str) -> None:
    vertices, faces, rest = grid_sheet(2, 2)
    model = ClothModel(vertices, faces, rest=rest, handles=[0, 8], device=device)
    integrator = ImplicitEuler(model)
    state = ClothState.from_model(model)
    with pytest.raises(InputError, match="dt"):
        integrator.step(state, state, 0.0)
    with pytest.raises(InputError, match="dt"):
        integrator.step(state, state, float("inf"))
    small = ClothState(wp.zeros(3, dtype=wp.vec3, device=device), wp.zeros(3, dtype=wp.vec3, device=device))
    with pytest.raises(InputError, match="state_out"):
        integrator.step(state, small, 0.01)
    with pytest.raises(InputError, match="handle_targets"):
        integrator.step(state, state, 0.01, handle_targets=np.zeros((3, 3)))
    with pytest.raises(InputError, match="positions"):
        ClothState.from_model(model, positions=np.zeros((2, 3)))


def test_contact_springs_grow_and_report_overflow(device: str) -> None:
    springs = ContactSprings(1, rest_gap=0.001, device=device)
    ids = np.tile(np.array([[0, 1, 2, 3]], np.int32), (5, 1))
    weights = np.tile(np.array([[1.0, -0.2, -0.3, -0.5]], np.float32), (5, 1))
    springs.set(ids, weights, np.tile([[0.0, 0.0, 2.0]], (5, 1)))
    assert springs.capacity >= 5 and springs.host_count == 5
    np.testing.assert_allclose(springs.normals.numpy()[:5], np.tile([[0.0, 0.0, 1.0]], (5, 1)))
    # A device producer that appended past the capacity: fits() grows and asks for a re-run.
    springs.count.assign(np.array([springs.capacity + 3], np.int32))
    old = springs.capacity
    assert not springs.fits()
    assert springs.capacity >= old + 3
    np.testing.assert_array_equal(springs.vertices.numpy()[:5], ids)  # contents kept
    assert springs.fits()
    springs.reset()
    assert springs.count.numpy()[0] == 0
    with pytest.raises(InputError, match="normal"):
        springs.set(ids[:1], weights[:1], [[0.0, 0.0, 0.0]])
    with pytest.raises(InputError):
        ContactSprings(-1, device=device)
