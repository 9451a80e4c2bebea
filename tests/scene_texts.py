"""Scene-file texts shared by the CLI and batch tests."""

from __future__ import annotations


def crossing_sheets(*, allow: bool | None = None, response_limits: bool = True) -> str:
    """Two 0.3 m sheets (4 x 4 cells) crossing at right angles through each other's middle, 2 frames.

    Args:
        allow: ``allow_initial_intersections`` (``None``: left out, the default).
        response_limits: add ``max_response_rounds = 3`` and ``max_step_halvings = 1`` (a run that cannot
            resolve its start fails fast).
    """
    contact = ["check_intersections = false"]
    if allow is not None:
        contact.insert(0, f"allow_initial_intersections = {str(allow).lower()}")
    if response_limits:
        contact += ["max_response_rounds = 3", "max_step_halvings = 1"]
    sheet = "[cloth.sheet]\nsize = [0.3, 0.3]\ncells = [4, 4]\n"
    return ('[scene]\nname = "crossing"\nframes = 2\n[contact]\n' + "\n".join(contact) + "\n"
            + "[[cloth]]\n" + sheet + "[[cloth]]\nrotate = [90.0, 0.0, 0.0]\n" + sheet)
