"""The CCD's distance tolerance (``CCD_DISTANCE_TOLERANCE``, 0.1 by default) in the simulator: the twisting
strip that a first version of it could not finish.

That version reported a box below the tolerance at its start time whatever its length in time, up to
half a step before the contact, and reported pairs that rest just beyond the minimum distance at t = 0.
At frame 43 of ``twist`` at 2K triangles one collision survived 100 response rounds and 4 halvings. Now
pairs that start within the tolerance's band are searched exactly, the others are decided by conservative
advancement, and boxes below the tolerance are refined in time down to ``CCD_TOI_TOLERANCE`` first
(docs/ccd.md).
"""

from __future__ import annotations

import numpy as np
import pytest

from pscc.bench.oracle import cloth_crossings
from pscc.scenes import build_scene
from pscc.sim.simulation import Simulation
from pscc.sim.solver import RESPONSE_TOLERANCE_SHARE, response_tolerance
from pscc.tolerances import CCD_DISTANCE_TOLERANCE


def test_the_twisting_strip_runs_through_with_the_distance_tolerance() -> None:
    scene = build_scene("twist", 2000)
    sim = Simulation(scene, device="cpu")
    assert CCD_DISTANCE_TOLERANCE > 0.0
    assert sim.solver.detector.narrow.params.distance_tolerance == pytest.approx(CCD_DISTANCE_TOLERANCE)
    halvings = 0
    for _ in range(45):
        record = sim.step_frame()
        halvings += record["counts"]["halvings"]
    assert sim.frame == 45 and halvings == 0
    cloth = sim.state.positions.numpy()[: sim.solver.cloth_vertex_count].astype(np.float64)
    assert np.isfinite(cloth).all()
    assert cloth_crossings(cloth, scene.faces, cloth.shape[0], scene.faces.shape[0]).shape[0] == 0


def test_the_projection_leaves_solved_pairs_beyond_the_ccd_band() -> None:
    # The projection stops with every gap at least separation - response_tolerance; the CCD may report a
    # pair up to ccd_distance (1 + sqrt 3 x CCD_DISTANCE_TOLERANCE) away (docs/ccd.md). A solved pair left
    # inside that band would be found again in the next round, so the default tolerance must end short of it.
    solver = Simulation(build_scene("twist", 100), device="cpu").solver
    band = solver.ccd_distance * (1.0 + np.sqrt(3.0) * CCD_DISTANCE_TOLERANCE)
    share = RESPONSE_TOLERANCE_SHARE * (solver.separation - solver.ccd_distance)
    assert solver.response_tolerance == share  # the defaults clear the band with the share itself
    assert solver.separation - solver.response_tolerance > band


@pytest.mark.parametrize("separation", [0.105, 0.12, 0.15, 0.18, 0.2, 0.3, 1.0])
def test_a_close_separation_gets_no_looser_tolerance_than_the_band_allows(separation: float) -> None:
    # Separations closer to the CCD distance than the defaults: the share is used only where its gaps clear the
    # CCD's band (by 15 % of the rest), otherwise at most the earlier half of the band, never less.
    ccd_distance = 0.1
    tolerance = response_tolerance(separation, ccd_distance)
    band = ccd_distance * (1.0 + np.sqrt(3.0) * CCD_DISTANCE_TOLERANCE)
    half = 0.5 * (separation - ccd_distance)
    assert half - 1e-12 <= tolerance <= RESPONSE_TOLERANCE_SHARE * (separation - ccd_distance) + 1e-12
    if tolerance > half + 1e-12:
        assert separation - tolerance >= band + 0.15 * (separation - band) - 1e-12
    if separation - half > band:  # where the earlier rule cleared the band, this one does too
        assert separation - tolerance > band
