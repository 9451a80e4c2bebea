"""NormalConeFront's device path: same fronts as the sequential algorithm, graph replay, no host reads."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pscc.bench.host_traffic import count_host_traffic, device_path_traffic
from pscc.collision._front_kernels import NodeTestArgs, _node_passes
from pscc.collision.bvh import MaterialBvh
from pscc.collision.front import NormalConeFront
from pscc.errors import InputError
from pscc.mesh import MeshTopology, folded_sheet, twisted_sheet

wp.set_module_options({"enable_backward": False})


@wp.kernel
def _node_passes_all(args: NodeTestArgs, passes: wp.array(dtype=wp.int32)):
    """One thread per BVH node: 1 when the node passes PSCC's node test."""
    node = wp.tid()
    passes[node] = 0
    if _node_passes(args, node):
        passes[node] = 1


class _ReferenceFront:
    """The front algorithm as it ran on the host before the device path (level-synchronous sprout,
    a sequential shrink pass in front order, a host call counter), on node-test results."""

    def __init__(self, bvh: MaterialBvh, shrink_interval: int) -> None:
        self.bvh = bvh
        self.shrink_interval = shrink_interval
        self.front = [int(r) for r in bvh.roots]
        self.calls = 0

    def update(self, passes: np.ndarray) -> tuple[np.ndarray, dict[str, int]]:
        self.calls += 1
        rounds = self._shrink(passes) if self.calls % self.shrink_interval == 0 else 0
        frontier, new_front, tested, levels = self.front, [], 0, 0
        while frontier:
            tested += len(frontier)
            levels += 1
            following = []
            for node in frontier:
                if passes[node]:
                    new_front.append(node)
                else:
                    following += [int(self.bvh.left[node]), int(self.bvh.right[node])]
            frontier = following
        self.front = new_front
        node_id = np.full(self.bvh.face_count, -1, dtype=np.int32)
        for node in self.front:
            node_id[self.bvh.faces_of(node)] = node
        stats = {"front_size": len(self.front), "front_nodes_tested": tested, "sprout_levels": levels,
                 "shrink_rounds": rounds}
        return node_id, stats

    def _shrink(self, passes: np.ndarray) -> int:
        bvh = self.bvh
        rounds = 0
        while True:
            in_front = np.zeros(bvh.node_count, dtype=bool)
            in_front[self.front] = True
            lifted = False
            for node in self.front:
                parent = int(bvh.parent[node])
                if parent < 0 or int(bvh.left[parent]) != node:
                    continue
                sibling = int(bvh.right[parent])
                if in_front[sibling] and passes[parent]:
                    in_front[[node, sibling]] = False
                    in_front[parent] = True
                    lifted = True
            if not lifted:
                return rounds
            rounds += 1
            self.front = np.flatnonzero(in_front).tolist()


def _setup(device: str, triangles: int = 1500, maker: str = "folded",
           shrink_interval: int = 2) -> tuple[MaterialBvh, wp.array, object, NormalConeFront]:
    mesh = folded_sheet(triangles, layers=3, seed=0) if maker == "folded" else twisted_sheet(triangles, seed=1)
    topology = MeshTopology.from_faces(mesh.faces, len(mesh.vertices))
    rest = mesh.rest if mesh.rest is not None else mesh.vertices
    bvh = MaterialBvh.build(mesh.faces, rest, mesh.object_ids, topology, device)
    faces = wp.array(mesh.faces, dtype=wp.vec3i, device=device)
    return bvh, faces, mesh, NormalConeFront(bvh, faces, device, shrink_interval)


def _positions(mesh: object, s: float, noise: float = 0.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Between the flat rest sheet (s = 0) and the folded one (s = 1), start and end of a step."""
    rest = mesh.rest
    flat = np.concatenate([rest[:, :2], np.zeros((len(rest), 1), np.float32)], axis=1) if rest.shape[1] == 2 else rest
    jitter = np.random.default_rng(seed).normal(0.0, noise, size=flat.shape)
    x0 = (1 - s) * flat + s * mesh.vertices + jitter
    x1 = (1 - s) * flat + s * mesh.vertices_end
    return x0.astype(np.float32), x1.astype(np.float32)


# A fold cycle: sprouting while folding, shrinking while unfolding, some calls with noise.
_CYCLE = [(0.0, 0.0), (0.5, 0.0), (1.0, 0.002), (1.0, 0.0), (0.7, 0.0), (0.3, 0.003), (0.0, 0.0), (0.0, 0.0),
          (0.6, 0.0), (0.2, 0.0), (0.0, 0.0)]


def _state(front: NormalConeFront) -> dict[str, np.ndarray]:
    """Everything a call leaves behind, as host arrays (bit patterns for the floats)."""
    return {"front": front.front.numpy()[: front.front_size], "front_count": front.front_count.numpy(),
            "node_id": front.node_id.numpy(), "calls": front.calls.numpy(),
            "node_mask": front.node_mask.numpy().view(np.uint32),
            "node_normal": front.node_normal.numpy().view(np.uint32), "counters": front._counters.numpy()}


@pytest.mark.parametrize("shrink_interval", [1, 3])
def test_update_matches_the_sequential_algorithm(device: str, shrink_interval: int) -> None:
    bvh, _, mesh, front = _setup(device, shrink_interval=shrink_interval)
    reference = _ReferenceFront(bvh, shrink_interval)
    passes = wp.zeros(bvh.node_count, dtype=wp.int32, device=device)
    sizes, rounds = [], 0
    for step, (s, noise) in enumerate(_CYCLE):
        x0, x1 = _positions(mesh, s, noise, seed=step)
        p0 = wp.array(x0, dtype=wp.vec3, device=device)
        p1 = wp.array(x1, dtype=wp.vec3, device=device) if step % 2 else None
        node_id = front.update(p0, p1).numpy()
        wp.launch(_node_passes_all, dim=bvh.node_count, inputs=[front.args], outputs=[passes], device=device)
        expected_node_id, expected_stats = reference.update(passes.numpy())
        assert front.front.numpy()[: front.front_size].tolist() == reference.front, f"call {step}"
        assert np.array_equal(node_id, expected_node_id), f"call {step}"
        assert front.stats == expected_stats, f"call {step}"
        assert front.call_count == step + 1
        sizes.append(expected_stats["front_size"])
        rounds += expected_stats["shrink_rounds"]
    assert max(sizes) > 50 and sizes[-1] < max(sizes) / 5 and rounds > 0, "the cycle sprouts and shrinks"


@pytest.mark.parametrize("swept", [True, False])
def test_captured_update_replays_bit_identically(device: str, swept: bool) -> None:
    _, faces, mesh, eager = _setup(device, maker="twisted" if not swept else "folded", shrink_interval=2)
    replayed = NormalConeFront(eager.bvh, faces, device, 2)
    x0, x1 = _positions(mesh, 0.0)
    p0 = wp.array(x0, dtype=wp.vec3, device=device)
    p1 = wp.array(x1, dtype=wp.vec3, device=device)
    ends = p1 if swept else None
    eager.update(p0, ends)
    replayed.update(p0, ends)  # loads the modules and records the launches before the capture
    with wp.ScopedCapture(device=device) as capture:
        replayed.update(p0, ends)
    assert replayed.call_count == 1, "nothing runs during the capture"
    changed, rounds = 0, 0
    for step, (s, noise) in enumerate(_CYCLE):
        x0, x1 = _positions(mesh, s, noise, seed=step)
        p0.assign(x0)
        p1.assign(x1)
        eager.update(p0, ends)
        wp.capture_launch(capture.graph)
        a, b = _state(eager), _state(replayed)
        for key in a:
            assert np.array_equal(a[key], b[key]), f"{key} after call {step + 2}"
        changed += int(a["front_count"][0] != 1)
        rounds += int(a["counters"][2])
    assert changed > 0 and rounds > 0, "the replays sprout and shrink"




def test_update_reads_nothing_back(device: str) -> None:
    _, _, mesh, front = _setup(device, shrink_interval=1)
    steps = [_positions(mesh, s) for s in (1.0, 0.6, 0.0)]
    p0 = wp.array(steps[0][0], dtype=wp.vec3, device=device)
    p1 = wp.array(steps[0][1], dtype=wp.vec3, device=device)
    sources = [(wp.array(a, dtype=wp.vec3, device=device), wp.array(b, dtype=wp.vec3, device=device))
               for a, b in steps]
    front.update(p0, p1)  # warm-up: modules loaded, launches recorded
    traffic = {"reads": 0, "syncs": 0, "uploads": 0, "allocations": 0}
    rounds = 0
    for source_t0, source_t1 in sources:
        wp.copy(p0, source_t0)
        wp.copy(p1, source_t1)
        counts = device_path_traffic(device, lambda: front.update(p0, p1))
        traffic = {key: traffic[key] + counts[key] for key in traffic}
        rounds += front.stats["shrink_rounds"]
    assert traffic == {"reads": 0, "syncs": 0, "uploads": 0, "allocations": 0}
    assert rounds > 0, "the counted calls include shrinking ones"
    with count_host_traffic() as counts:
        assert front.front_size >= 1
    assert counts["reads"] > 0, "the counter sees a sync read"


def test_state_dict_round_trip_continues_identically(device: str) -> None:
    bvh, faces, mesh, first = _setup(device, shrink_interval=3)
    for step, (s, noise) in enumerate(_CYCLE[:4]):
        first.update(wp.array(_positions(mesh, s, noise, seed=step)[0], dtype=wp.vec3, device=device))
    state = first.state_dict()
    assert state["front"].shape == (first.front_size,) and int(state["calls"][0]) == 4
    second = NormalConeFront(bvh, faces, device, 3)
    second.load_state_dict(state)
    for step, (s, noise) in enumerate(_CYCLE[4:]):
        x0, x1 = _positions(mesh, s, noise, seed=step)
        p0 = wp.array(x0, dtype=wp.vec3, device=device)
        p1 = wp.array(x1, dtype=wp.vec3, device=device)
        first.update(p0, p1)
        second.update(p0, p1)
        a, b = _state(first), _state(second)
        for key in a:
            assert np.array_equal(a[key], b[key]), f"{key} after call {step + 5}"
    with pytest.raises(InputError):
        second.load_state_dict({"front": np.array([bvh.node_count]), "calls": np.array([0])})
    with pytest.raises(InputError):
        second.load_state_dict({"front": np.array([0]), "calls": np.array([-1])})
    # Node ids in range that are not a cut (a face in two nodes, faces in none): refused, the front kept.
    kept = second.front.numpy()[: second.front_size].copy()
    root, child = int(bvh.roots[0]), int(bvh.left[bvh.roots[0]])
    for nodes in ([root, child], [child]):
        with pytest.raises(InputError, match="do not cover each of the"):
            second.load_state_dict({"front": np.array(nodes), "calls": np.array([0])})
        assert np.array_equal(second.front.numpy()[: second.front_size], kept)


def test_largest_front_fills_the_buffers(device: str) -> None:
    """Every face its own front node (the largest cut): the capacity-sized sort and frontier hold it."""
    bvh, _, mesh, front = _setup(device, triangles=600, shrink_interval=2)
    leaves = np.unique(bvh.face_leaf)
    assert leaves.size == bvh.face_count
    reference = _ReferenceFront(bvh, 2)
    reference.front = leaves.tolist()
    front.load_state_dict({"front": leaves, "calls": np.array([0])})
    passes = wp.zeros(bvh.node_count, dtype=wp.int32, device=device)
    crumpled = np.random.default_rng(5).normal(0.0, 1.0, size=mesh.vertices.shape).astype(np.float32)
    sizes = []
    for x in (crumpled, _positions(mesh, 0.0)[0]):
        node_id = front.update(wp.array(x, dtype=wp.vec3, device=device)).numpy()
        wp.launch(_node_passes_all, dim=bvh.node_count, inputs=[front.args], outputs=[passes], device=device)
        expected_node_id, expected_stats = reference.update(passes.numpy())
        assert front.front.numpy()[: front.front_size].tolist() == reference.front
        assert np.array_equal(node_id, expected_node_id) and front.stats == expected_stats
        sizes.append(front.front_size)
    assert sizes[0] == leaves.size and sizes[1] < leaves.size // 4, "leaves stay leaves; flat: shrunk"


def test_per_call_tables_in_lent_memory_give_the_same_fronts_and_follow_a_replaced_lender(device: str) -> None:
    # The detector lends the front what it lends its hash: whatever the lender writes between calls is
    # rewritten by the next update before it is read.
    _, faces, mesh, own = _setup(device, shrink_interval=2)
    lent = NormalConeFront(own.bvh, faces, device, 2)
    buffers = [wp.zeros(8 * own.bvh.node_count, dtype=wp.vec3, device=device)]  # room for every table
    lent.lend_scratch(lambda: buffers)
    assert {"node_mask", "_range_marks", "_range_owner", "_frontier"} <= lent._lent_names
    assert lent.device_bytes < own.device_bytes
    for step, (s, noise) in enumerate(_CYCLE):
        x0, x1 = _positions(mesh, s, noise, seed=step)
        p0 = wp.array(x0, dtype=wp.vec3, device=device)
        p1 = wp.array(x1, dtype=wp.vec3, device=device) if step % 2 else None
        np.testing.assert_array_equal(lent.update(p0, p1).numpy(), own.update(p0, p1).numpy(), f"call {step}")
        assert lent.front.numpy()[: lent.front_size].tolist() == own.front.numpy()[: own.front_size].tolist()
        buffers[0].fill_(wp.vec3(-1.0e30, 7.0, -3.0))  # the lender's own use between calls
        if step == 4:
            buffers[0] = wp.zeros(8 * own.bvh.node_count, dtype=wp.vec3, device=device)  # the lender regrows
    start = buffers[0].ptr
    assert start <= lent.node_mask.ptr < start + buffers[0].capacity, "the tables moved to the new buffer"
    lent.lend_scratch(None)
    assert not lent._lent_names and lent.device_bytes == own.device_bytes


@pytest.mark.parametrize("swept", [True, False])
def test_the_cpu_refit_in_one_thread_equals_the_per_level_launches(swept: bool) -> None:
    """On the CPU the front refits every node in one launch (one thread, deepest nodes first) instead of one
    launch per BVH level; the masks and normals must be the same bits as the level launches give."""
    from pscc.collision._front_kernels import _refit_all_in_order, _refit_level

    bvh, _, mesh, front = _setup("cpu", maker="twisted")
    x0, x1 = _positions(mesh, 0.8, 0.002, seed=3)
    end = wp.array(x1, dtype=wp.vec3, device="cpu") if swept else None
    front.update(wp.array(x0, dtype=wp.vec3, device="cpu"), end)
    args = front.args
    count = bvh.node_count
    by_level = (wp.zeros_like(front.node_mask), wp.zeros_like(front.node_normal))
    offsets = bvh.level_offsets
    for depth in range(len(offsets) - 2, -1, -1):
        first, last = int(offsets[depth]), int(offsets[depth + 1])
        if last > first:
            wp.launch(_refit_level, dim=last - first, inputs=[args, first], outputs=list(by_level), device="cpu")
    in_order = (wp.zeros_like(front.node_mask), wp.zeros_like(front.node_normal))
    wp.launch(_refit_all_in_order, dim=1, inputs=[args, count], outputs=list(in_order), device="cpu")
    for a, b in zip(by_level, in_order, strict=True):
        assert np.array_equal(a.numpy().view(np.uint32), b.numpy().view(np.uint32))
    assert np.array_equal(front.node_mask.numpy().view(np.uint32), in_order[0].numpy().view(np.uint32))
    assert (in_order[0].numpy().view(np.uint32) != 0).any()
