"""Contact settings of the simulator: proximity distance, CCD minimum distance, response limits."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from pscc.collision.detector import METHODS
from pscc.errors import InputError


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
    projection_iterations: int = 512
    """Dual iterations of one projection at most (it stops earlier once every gap is within half of
    (separation - CCD distance) of the separation)."""
    max_response_rounds: int = 100
    """CCD rounds per step (projection plus zones) before the step is rejected and retried with dt / 2."""
    max_step_halvings: int = 4
    """How often a rejected step may be split in two; beyond that the run stops with an error."""
    check_intersections: bool = True
    """Run the independent intersection check (:class:`pscc.collision.intersection.IntersectionCheck`)
    on every step's end state and reject the step when it finds a crossing."""
    allow_initial_intersections: bool = False
    """Start even when the initial state already intersects (otherwise an error names the pairs). This skips
    the refusal and nothing else: the response keeps crossing features from crossing further but cannot
    pull them apart, so crossing surfaces that move usually make the first steps fail (docs/simulator.md)."""

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
        if self.max_response_rounds < 1:
            raise InputError(owner, "max_response_rounds", "0 rounds cannot resolve anything", "use at least 1")
        return self
