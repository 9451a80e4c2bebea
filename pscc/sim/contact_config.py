"""Contact settings of the simulator: proximity distance, CCD minimum distance, response limits."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from pscc.collision.detector import METHODS
from pscc.errors import InputError

CCD_INSIDE_SHARE: float = 0.5
"""The response loop's CCD on a pair it finds at t = 0 (closer than the CCD distance, or so near it that the
rounding bound cannot tell): a contact only if the pair comes within this share of its start distance (at
most this share of the CCD distance) during the step (``inside_share`` of
:meth:`CollisionDetector.narrow_phase`). At 0, the CCD reports such a pair at t = 0 in every round, which
no end position can undo, so the step fails. Two ways in: a scene that starts with layers closer than the
CCD distance (0.1 mm apart at h = 2 mm failed its first step), and a step that ends with a pair inside it.
The culling certifies no intersection, not the CCD distance: on `twisting` at scale 0.026 a step ended with
a vertex 0.86 of the distance from the face across a nearly closed hinge (a pair that brute force reports
at that distance and pscc's culling does not), and the next step stopped the run at t = 3.20 s. In the
96-triangle `twist` strip an edge pair resting at 1.003 of the distance stopped the run at t = 5.14 s."""


@dataclass(frozen=True)
class ContactConfig:
    """How the solver finds and resolves contacts (see ``docs/simulator.md``).

    Distances are fractions of the cloth thickness h (:attr:`pscc.sim.ClothMaterial.thickness`), so
    one setting works at every scale.
    """

    renamed_fields: ClassVar[dict[str, str]] = {"impulse_rounds": "projection_rounds"}
    """Fields of earlier versions and their replacements (scene files get a pointed error)."""

    method: str = "pscc"
    """Collision detection method of :class:`pscc.CollisionDetector` (``pscc``, ``spatial-hash`` or
    ``brute-force``)."""
    ccd_distance_ratio: float = 0.1
    """CCD minimum distance delta = ratio x h: a pair coming closer than delta during a step is a
    collision to resolve (dimensionless, in (0, 1))."""
    separation_ratio: float = 0.2
    """The projection and the zones leave resolved pairs this far apart at the end of the step, as a
    fraction of h (dimensionless, > ccd_distance_ratio so resolved pairs are not found again)."""
    projection_rounds: int = 24
    """CCD rounds answered by the inelastic projection (:mod:`pscc.sim.inelastic_projection`) before
    switching to rigid impact zones."""
    proximity_constraints: bool = False
    """Give the first projection round of a step, besides the CCD's collisions, one proximity constraint per
    contact spring of the step's start (:meth:`pscc.sim.inelastic_projection.InelasticProjection.add_near`):
    a pair already within the thickness may not be pushed closer than it is (or than the separation), so a
    response does not push a vertex out of one collision into the surface it touches on its other side,
    which the next CCD round would find (tangled layers: fewer rounds per step). Off by default: on
    ``twisting`` at 5K it cut the CCD rounds per step from 5.4 to 3.9 and the time by a fifth, but one run
    stopped at frame 85 on a step that 4 halvings could not resolve (docs/simulator.md). A step rejected
    with them is now run again without them before it is halved. Since the CCD's conservative advancement
    they cost more than they save (``twisting``: 3.6 instead of 5.5 rounds per step, 1.41 instead of 1.12 s
    per frame)."""
    projection_iterations: int = 256
    """Dual iterations of one projection at most (it stops earlier once every gap is within
    :data:`pscc.sim.solver.RESPONSE_TOLERANCE_SHARE` of (separation - CCD distance) of the separation). A
    projection stopped here is not lost: its multipliers carry over, and the next CCD round adds what it
    left. On ``twisting`` at 5K (90 frames) 256 instead of 512 ran 264K projection iterations instead of
    293K, 3,928 CCD rounds instead of 3,973 and 1,420 broad phases instead of 1,466."""
    max_response_rounds: int = 100
    """CCD rounds per step (projection plus zones) before the step is rejected and retried with dt / 2."""
    max_step_halvings: int = 4
    """How often a rejected step may be split in two; beyond that the run stops with an error."""
    check_intersections: bool = True
    """Run the independent intersection check (:class:`pscc.collision.intersection.IntersectionCheck`)
    on every step's end state and reject the step when it finds a crossing."""
    allow_initial_intersections: bool = False
    """Start even when the initial state already intersects (otherwise an error names the pairs). The crossing
    pairs are then exempt from collision handling until they come apart, and the side of each crossing that
    passed through is pushed back at ``untangle_speed`` (:meth:`pscc.sim.solver.ClothSolver.update_tangles`,
    docs/simulator.md); new crossings are refused as always."""
    untangle_speed: float = 0.1
    """With ``allow_initial_intersections``: the speed [m/s] at which the side of a crossing that passed
    through is pushed back (:mod:`pscc.sim.untangle`, once per frame while crossings remain); 0 switches
    the push off (only the cloth's own forces then take crossings apart)."""

    def validate(self) -> ContactConfig:
        """Check every field; return ``self``.

        Raises:
            InputError: a field is out of range.
        """
        owner = "ContactConfig"
        if self.method not in METHODS:
            raise InputError(owner, "method", f"unknown method {self.method!r}", f"use one of {', '.join(METHODS)}")
        if not 0.0 < float(self.ccd_distance_ratio) < 1.0:
            raise InputError(owner, "ccd_distance_ratio", f"{self.ccd_distance_ratio!r} is not in (0, 1)",
                             "use a value such as 0.1")
        if not float(self.ccd_distance_ratio) < float(self.separation_ratio) <= 1.0:
            raise InputError(owner, "separation_ratio", f"{self.separation_ratio!r} is not in (ccd_distance_ratio, 1]",
                             "use a value such as 2 x ccd_distance_ratio")
        for name in ("projection_rounds", "projection_iterations", "max_response_rounds", "max_step_halvings"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise InputError(owner, name, f"{value!r} is not an integer >= 0", f"set {name} to an integer >= 0")
        speed = self.untangle_speed
        if isinstance(speed, bool) or not isinstance(speed, int | float) or not 0.0 <= float(speed) <= 1e3:
            raise InputError(owner, "untangle_speed", f"{speed!r} is not a speed in [0, 1000] m/s",
                             "use a value such as 0.1, or 0 to switch the push off")
        if not isinstance(self.proximity_constraints, bool):
            raise InputError(owner, "proximity_constraints", f"{self.proximity_constraints!r} is not a bool",
                             "use true or false")
        if self.max_response_rounds < 1:
            raise InputError(owner, "max_response_rounds", "0 rounds cannot resolve anything", "use at least 1")
        return self
