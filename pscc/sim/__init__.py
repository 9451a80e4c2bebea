"""Cloth simulation: the implicit-integration core (PSCC section 6; Baraff & Witkin 1998).

Public API (one import path per name):

- :class:`ClothMaterial`, :class:`SolverConfig`: configuration (units on every field).
- :class:`ClothModel`: static cloth data (rest shape, masses, hinges, pinned and handle vertices).
- :class:`ClothState`: positions and velocities, double-buffered by the integrator.
- :class:`ImplicitEuler`, :class:`StepStats`: one linearised backward-Euler step per call.
- :class:`ContactSprings`: proximity contacts, included implicitly with friction.
"""

from __future__ import annotations

from pscc.sim.config import ClothMaterial as ClothMaterial
from pscc.sim.config import SolverConfig as SolverConfig
from pscc.sim.contact_springs import ContactSprings as ContactSprings
from pscc.sim.integrator import ImplicitEuler as ImplicitEuler
from pscc.sim.integrator import StepStats as StepStats
from pscc.sim.model import ClothModel as ClothModel
from pscc.sim.state import ClothState as ClothState

__all__ = [
    "ClothMaterial",
    "ClothModel",
    "ClothState",
    "ContactSprings",
    "ImplicitEuler",
    "SolverConfig",
    "StepStats",
]
