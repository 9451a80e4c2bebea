"""Key paths of [batch.vary]: parsing, setting values in scene-file and built-in documents, and their errors."""

from __future__ import annotations

import pytest

from pscc.batch.key_paths import KeyPathError, Segment, format_key_path, parse_key_path, set_key_path


def _file_document() -> dict:
    return {
        "scene": {"name": "s", "frame_rate": 30.0, "steps_per_frame": 8, "frames": 2},
        "solver": {"gravity": [0.0, 0.0, -9.81]},
        "cloth": [{"name": "a", "material": {"friction": 0.3}, "handles": []},
                  {"name": "b", "material": {"friction": 0.3}, "handles": []}],
    }


def _builtin_document() -> dict:
    return {"builtin": {"scene": "stack", "triangles": 300, "frames": 2},
            "scene": {"frame_time": 1.0 / 30.0, "steps_per_frame": 8},
            "material": {"friction": 0.3, "density": 0.187}, "solver": {"gravity": [0.0, 0.0, -9.81]},
            "contact": {"method": "pscc"}}


def test_key_paths_parse_into_segments_and_back() -> None:
    path = parse_key_path("cloth[1].material.density")
    assert path == (Segment("cloth", 1), Segment("material"), Segment("density"))
    assert format_key_path(path) == "cloth[1].material.density"


@pytest.mark.parametrize(("text", "words"), [
    ("", "empty key path"),
    ("cloth..material", "is not a key"),
    ("cloth[-1].material", "is not a key"),
    ("cloth[x]", "is not a key"),
    ("scene.frames", "cannot be varied"),
    ("builtin.triangles", "cannot be varied"),
])
def test_malformed_or_reserved_key_paths_are_refused(text: str, words: str) -> None:
    with pytest.raises(KeyPathError, match=words):
        parse_key_path(text)


def test_a_path_without_an_index_sets_every_piece_and_an_index_one() -> None:
    document = _file_document()
    set_key_path(document, parse_key_path("cloth.material.friction"), 0.1)
    assert [c["material"]["friction"] for c in document["cloth"]] == [0.1, 0.1]
    set_key_path(document, parse_key_path("cloth[1].material.friction"), 0.7)
    assert [c["material"]["friction"] for c in document["cloth"]] == [0.1, 0.7]
    set_key_path(document, parse_key_path("solver.gravity[2]"), -1.62)
    assert document["solver"]["gravity"] == [0.0, 0.0, -1.62]


def test_a_value_is_copied_in() -> None:
    document, value = _file_document(), [0.0, 0.0, -1.0]
    set_key_path(document, parse_key_path("solver.gravity"), value)
    value[2] = 5.0
    assert document["solver"]["gravity"] == [0.0, 0.0, -1.0]


def test_material_spellings_are_interchangeable_between_files_and_built_in_scenes() -> None:
    document = _file_document()
    set_key_path(document, parse_key_path("material[0].friction"), 0.2)  # a built-in spelling in a scene file
    assert [c["material"]["friction"] for c in document["cloth"]] == [0.2, 0.3]
    builtin = _builtin_document()
    set_key_path(builtin, parse_key_path("cloth.material.friction"), 0.4, pieces=3)
    assert builtin["material"] == {"friction": 0.4, "density": 0.187}
    set_key_path(builtin, parse_key_path("cloth[2].material.density"), 0.5, pieces=3)  # split per piece first
    assert [m["density"] for m in builtin["material"]] == [0.187, 0.187, 0.5]
    assert [m["friction"] for m in builtin["material"]] == [0.4, 0.4, 0.4]


def test_frame_time_and_frame_rate_replace_each_other() -> None:
    document = _file_document()
    set_key_path(document, parse_key_path("scene.frame_time"), 0.02)
    assert document["scene"]["frame_time"] == 0.02 and "frame_rate" not in document["scene"]
    builtin = _builtin_document()
    set_key_path(builtin, parse_key_path("scene.frame_rate"), 50)
    assert builtin["scene"]["frame_time"] == pytest.approx(0.02) and "frame_rate" not in builtin["scene"]


def test_a_missing_key_is_created_for_the_reader_to_judge() -> None:
    document = _file_document()
    set_key_path(document, parse_key_path("contact.max_step_halvings"), 2)
    assert document["contact"] == {"max_step_halvings": 2}


@pytest.mark.parametrize(("document", "text", "words"), [
    (_file_document(), "cloth[2].material.friction", "has 2 element(s), so [2] does not exist"),
    (_file_document(), "solver.gravity[3]", "has 3 element(s)"),
    (_file_document(), "scene.name.first", "is a string, not a table"),
    (_file_document(), "cloth.handles.times", "is an empty array"),
    (_file_document(), "obstacle[0].keyframes", "does not exist, so it has no element [0]"),
    (_builtin_document(), "cloth.sheet.cells", "does not exist in a built-in scene"),
    (_builtin_document(), "cloth[3].material.friction", "the scene has 3 cloth piece(s)"),
    (_builtin_document(), "scene.frame_rate", "is not a frame rate > 0"),
])
def test_paths_that_do_not_fit_the_document_say_why(document: dict, text: str, words: str) -> None:
    value = 0 if text == "scene.frame_rate" else 1.0
    with pytest.raises(KeyPathError) as caught:
        set_key_path(document, parse_key_path(text), value, pieces=3)
    assert words in caught.value.problem and caught.value.fix
