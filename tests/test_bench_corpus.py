"""The realistic broad-phase corpus and its side-by-side section (issue 14), on small cases."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pscc.bench import broad_phase, corpus, corpus_bench

SHIRT = corpus.FrameSpec("usd", "unisex_shirt.usd")


def _twisted_frame(triangles: int) -> corpus.CorpusFrame:
    """A generated frame with rest coordinates (the corpus's own frames need a simulation)."""
    mesh = broad_phase.SCENES["twisted"](triangles)
    return corpus.CorpusFrame("twisted", "generated", mesh.vertices_end, mesh.faces, mesh.rest, None,
                              corpus.half_median_edge(mesh.vertices_end, mesh.faces))


def test_frames_round_trip_through_the_cache(tmp_path: Path) -> None:
    frame = _twisted_frame(600)
    path = tmp_path / "frame.npz"
    frame.save(path)
    loaded = corpus.CorpusFrame.load(path)
    assert loaded.name == frame.name and loaded.source == frame.source
    np.testing.assert_array_equal(loaded.positions, frame.positions)
    np.testing.assert_array_equal(loaded.faces, frame.faces)
    np.testing.assert_array_equal(loaded.rest, frame.rest)
    assert loaded.object_ids is None and loaded.radius == pytest.approx(frame.radius)
    assert frame.without_rest().rest is None
    # A cached frame is a check frame when its spec says so (the flag is not stored in the file).
    spec = corpus.FrameSpec("usd", "frame.usd", check=True)
    frame.save(tmp_path / spec.cache_name)
    assert corpus.load_frame(spec, "cpu", tmp_path).check
    assert not corpus.load_frame(replace(spec, check=False), "cpu", tmp_path).check


def test_half_median_edge_ignores_a_few_long_edges() -> None:
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [100, 0, 0]], dtype=np.float32)
    faces = np.array([[0, 1, 2], [1, 3, 2], [1, 4, 3]])
    # Edges 1, 1, 1, 1, sqrt 2, 99 and about 99: the median is 1 (the mean is about 29).
    assert corpus.half_median_edge(positions, faces) == pytest.approx(0.5)


def test_fan_triangles_split_polygons() -> None:
    faces = corpus.fan_triangles(np.array([3, 4]), np.array([0, 1, 2, 3, 4, 5, 6]))
    np.testing.assert_array_equal(faces, [[0, 1, 2], [3, 4, 5], [3, 5, 6]])


def test_unknown_kind_and_skipped_examples_say_why(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown corpus frame kind"):
        corpus.load_frame(corpus.FrameSpec("obj", "x"), "cpu", tmp_path)
    frames, skipped = corpus.load_corpus((corpus.FrameSpec("newton", "style3d", 5),), "cpu", tmp_path)
    assert frames == []
    assert any(s["spec"] == "newton style3d" and "network" in s["reason"] for s in skipped)


def test_with_ground_adds_a_ground_piece_below_the_frame() -> None:
    frame = _twisted_frame(500)
    grounded = frame.with_ground()
    assert grounded.face_count == frame.face_count + 2 and grounded.rest is None
    assert grounded.name == "twisted + ground" and grounded.radius == frame.radius
    assert list(grounded.object_ids[-2:]) == [1, 1] and not grounded.object_ids[:-2].any()
    ground = grounded.positions[-4:]
    assert np.all(ground[:, 1] == frame.positions[:, 1].min() - 2 * np.float32(frame.radius))
    extent = float(np.ptp(frame.positions, axis=0).max())
    assert np.ptp(ground[:, 0]) == pytest.approx(100 * extent)


def test_moved_keeps_the_shape_and_moves_every_vertex() -> None:
    frame = _twisted_frame(500)
    moved = frame.moved(1000.0)
    assert moved.name == "twisted moved 1000" and moved.radius == frame.radius
    assert moved.positions.dtype == np.float32
    np.testing.assert_array_equal(moved.positions, (frame.positions.astype(np.float64) + 1000.0).astype(np.float32))
    assert moved.faces is frame.faces and moved.rest is frame.rest and moved.object_ids is frame.object_ids


def test_pscc_with_and_without_rest_against_spatial_hash() -> None:
    result = corpus_bench.bench_frame(_twisted_frame(2000), "cpu", repeats=1, with_newton=False, with_ipctk=False)
    methods = [r["method"] for r in result["rows"]]
    assert methods == ["pscc", "pscc-no-rest", "spatial-hash", "spatial-hash-dop"]
    rows = {r["method"]: r for r in result["rows"]}
    assert rows["spatial-hash"]["triangle_pairs"] > 0
    # The 26-DOP face test only drops box pairs, and finds the same colliding pairs.
    assert 0 < rows["spatial-hash-dop"]["triangle_pairs"] < rows["spatial-hash"]["triangle_pairs"]
    for key in ("vertex_face_pairs", "edge_edge_pairs"):
        assert rows["spatial-hash-dop"][key] == rows["spatial-hash"][key]
    for name in ("pscc", "pscc-no-rest"):
        # DCD: pscc returns a subset of the exact pairs (pairs inside one front node are culled).
        assert result["ratios"][name]["subset_of_spatial_hash"]
        assert 0.0 < result["ratios"][name]["found_vs_spatial_hash"] <= 1.0
        assert 0 < rows[name]["triangle_pairs"] <= rows["spatial-hash"]["triangle_pairs"]
        assert rows[name]["vertex_face_pairs"] + rows[name]["edge_edge_pairs"] > 0
        assert result["ratios"][name]["pairs_vs_spatial_hash_dop"] > 0
        assert result["ratios"][name]["time_vs_spatial-hash"] > 0
        assert result["ratios"][name]["host_vs_spatial-hash"] > 0
    for row in rows.values():
        # The recorded graph replays the detection: the same rows as the host call, every time.
        assert row["graph_matches"] and row["graph_seconds"] > 0
    # pscc's broad phase alone is timed too (the product ipctk's row times); plain hashing's is not.
    assert rows["pscc"]["broad_seconds"] > 0 and rows["pscc-no-rest"]["broad_seconds"] > 0
    assert "broad_seconds" not in rows["spatial-hash"]


def test_broad_phase_replay_gives_the_candidates_of_the_call() -> None:
    frame = _twisted_frame(1500)
    runner = corpus_bench._PsccRunner(frame, "pscc", frame.rest, "cpu")
    result = runner.run()
    runner.record()
    runner.record_broad()
    runner.detector.candidates.counts.zero_()
    runner.replay_broad()
    counts = runner.detector.candidates.counts.numpy()
    assert int(counts[0]) + int(counts[1]) == result.stats["candidate_pairs"] > 0
    runner.replay()  # the full graph still gives the call's rows after the broad one ran
    found = runner.replayed()
    np.testing.assert_array_equal(found.vertex_face, result.vertex_face)
    np.testing.assert_array_equal(found.edge_edge, result.edge_edge)


def test_check_frames_are_marked_and_tallied_apart() -> None:
    frame = replace(_twisted_frame(1000), check=True)
    checked = corpus_bench.bench_frame(frame, "cpu", repeats=1, with_newton=False, with_ipctk=False)
    assert checked["check"] is True
    tuned = {**checked, "frame": "tuned", "check": False}
    results = {"frames": [tuned, checked], "skipped": [], "repeats": 1, "seconds": 1.0, "corpus_seconds": 0.0}
    text = "\n".join(corpus_bench.report(results))
    pairs = checked["ratios"]["pscc"]["pairs_vs_spatial_hash"]
    met = int(pairs <= corpus_bench.TARGETS["pairs_rest"])
    # Each tally counts one frame with rest coordinates: the tuned frame's and the check frame's apart.
    assert f"Targets met: pairs with rest <= 0.4: {met} of 1;" in text
    assert f"(marked *check* below): pairs with rest <= 0.4: {met} of 1;" in text
    assert "- `twisted` *check*: generated;" in text and "- `tuned`: generated;" in text
    # A corpus with no check frame has no second tally.
    alone = "\n".join(corpus_bench.report({**results, "frames": [tuned]}))
    assert "marked *check*" not in alone


def test_quick_corpus_case_end_to_end(tmp_path: Path) -> None:
    pytest.importorskip("newton", reason="the shirt ships with newton (a bench extra)")
    pytest.importorskip("ipctk", reason="ipctk is a test extra")
    import ipctk

    results = corpus_bench.run((SHIRT,), "cpu", repeats=1, cache_dir=tmp_path)
    assert (tmp_path / SHIRT.cache_name).exists()
    (entry,) = results["frames"]
    assert entry["faces"] == 12736 and not entry["rest"] and entry["missing"] == []
    rows = {r["method"]: r for r in entry["rows"]}
    assert list(rows) == ["pscc-no-rest", "spatial-hash", "spatial-hash-dop", "newton", "newton-rebuild",
                          "ipctk-lbvh-1", "ipctk-lbvh-2"]
    pscc, spatial = rows["pscc-no-rest"], rows["spatial-hash"]
    assert entry["ratios"]["pscc-no-rest"]["subset_of_spatial_hash"]
    assert 0 < pscc["triangle_pairs"] <= spatial["triangle_pairs"]
    assert pscc["vertex_face_pairs"] > 0 and pscc["edge_edge_pairs"] > 0
    assert rows["ipctk-lbvh-1"]["candidate_pairs"] == rows["ipctk-lbvh-2"]["candidate_pairs"] > 0
    assert rows["newton"]["vertex_face_pairs"] > 0 and rows["newton"]["graph_seconds"] > 0
    # The rebuilding detector finds the same pairs, and has no graph (a rebuild is not recorded).
    assert rows["newton-rebuild"]["vertex_face_pairs"] == rows["newton"]["vertex_face_pairs"]
    assert rows["newton-rebuild"]["edge_edge_pairs"] == rows["newton"]["edge_edge_pairs"]
    assert "graph_seconds" not in rows["newton-rebuild"]
    assert pscc["graph_matches"] and spatial["graph_matches"]
    for key in ("time_vs_newton", "time_vs_newton-rebuild", "time_vs_ipctk-lbvh-1", "time_vs_ipctk-lbvh-2",
                "host_vs_newton"):
        assert entry["ratios"]["pscc-no-rest"][key] > 0
    assert entry["ratios"]["pscc-no-rest"]["broad_vs_ipctk-lbvh-1"] > 0
    # Every pair pscc reports is an ipctk candidate: the two radius conventions agree.
    frame = corpus.CorpusFrame.load(tmp_path / SHIRT.cache_name)
    runner = corpus_bench.IpctkLbvh(frame, 1)
    candidates = runner.run()
    detector = corpus_bench._PsccRunner(frame, "pscc", None, "cpu")
    found = detector.run()
    vertex_face = {(c.vertex_id, c.face_id) for c in candidates.fv_candidates}
    assert {(int(v), int(f)) for v, f in found.vertex_face} <= vertex_face
    edges = np.asarray(ipctk.edges(frame.faces))
    edge_edge = {tuple(sorted((tuple(sorted(edges[c.edge0_id])), tuple(sorted(edges[c.edge1_id])))))
                 for c in candidates.ee_candidates}
    assert {((int(a0), int(a1)), (int(b0), int(b1))) for a0, a1, b0, b1 in found.edge_edge} <= edge_edge
    (grounded,) = results["grounded"]  # the shirt is one of GROUND_FRAMES
    ground_rows = {r["method"]: r for r in grounded["rows"]}
    assert grounded["frame"] == "unisex_shirt + ground" and grounded["faces"] == 12738
    assert ground_rows["pscc-no-rest"]["wide_faces"] == ground_rows["spatial-hash"]["wide_faces"] == 2
    assert ground_rows["pscc-no-rest"]["cell_size"] == pscc["cell_size"]  # the ground does not set the cell
    assert ground_rows["pscc-no-rest"]["entries"] == pscc["entries"]
    for key in ("vertex_face_pairs", "edge_edge_pairs"):  # two radii below the shirt: no contact added
        assert ground_rows["spatial-hash"][key] == spatial[key]
    assert grounded["ratios"]["pscc-no-rest"]["subset_of_spatial_hash"]
    text = "\n".join(corpus_bench.report(results))
    assert "| unisex_shirt | 12,736 | pscc (no rest) |" in text and "Targets met:" in text
    assert "| unisex_shirt + ground | 2 |" in text
    (moved,) = results["moved"]  # the shirt is one of MOVED_FRAMES
    moved_rows = {r["method"]: r for r in moved["rows"]}
    assert moved["frame"] == "unisex_shirt moved 1000" and moved["faces"] == 12736
    # 1,000 units away the culling stays (6,497 pairs at the origin, 6,625 moved; 6,793 with world-frame slabs).
    assert moved_rows["pscc-no-rest"]["triangle_pairs"] <= 1.03 * pscc["triangle_pairs"]
    assert moved["ratios"]["pscc-no-rest"]["subset_of_spatial_hash"]
    assert "| unisex_shirt moved 1000 | pscc (no rest) |" in text
    assert "left out: newton style3d" in text
