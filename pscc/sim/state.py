"""The time-varying part of a cloth: positions and velocities (double-buffered by the solver)."""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from pscc._checks import check_points
from pscc.errors import InputError
from pscc.sim.model import ClothModel


class ClothState:
    """Positions and velocities of every vertex.

    Args:
        positions: (vertex_count,) vec3 positions [m].
        velocities: (vertex_count,) vec3 velocities [m/s] on the same device.

    The arrays are used as given (not copied). :meth:`ImplicitEuler.step
    <pscc.sim.ImplicitEuler.step>` reads one state and writes another, so a simulation keeps two
    and swaps them after every step.
    """

    def __init__(self, positions: wp.array, velocities: wp.array) -> None:
        for name, array in (("positions", positions), ("velocities", velocities)):
            if not isinstance(array, wp.array) or array.dtype != wp.vec3 or array.ndim != 1:
                raise InputError("argument", name, f"{type(array).__name__} is not a 1-D wp.array of vec3",
                                 f"pass wp.array(..., dtype=wp.vec3) for {name}")
        if positions.shape != velocities.shape or positions.device != velocities.device:
            raise InputError("argument", "velocities", f"shape {velocities.shape} on {velocities.device} does not "
                             f"match positions {positions.shape} on {positions.device}",
                             "allocate both arrays with the same length on the same device")
        self.positions = positions
        """(vertex_count,) vec3 positions [m]."""
        self.velocities = velocities
        """(vertex_count,) vec3 velocities [m/s]."""

    @property
    def vertex_count(self) -> int:
        """Number of vertices."""
        return int(self.positions.shape[0])

    @property
    def device(self) -> wp.Device:
        """The device both arrays live on."""
        return self.positions.device

    @classmethod
    def from_model(cls, model: ClothModel, *, positions: Any = None, velocities: Any = None) -> ClothState:
        """A new state for ``model`` on its device.

        Args:
            model: The cloth.
            positions: Optional (n, 3) positions [m]; default: the model's initial positions.
            velocities: Optional (n, 3) velocities [m/s]; default: zero.

        Raises:
            InputError: wrong shapes or non-finite values.

        Allocates: yes. Capture-safe: no.
        """
        n = model.vertex_count
        arrays = []
        for name, value in (("positions", positions), ("velocities", velocities)):
            if value is None:
                host = model.mesh.vertices if name == "positions" else np.zeros((n, 3), dtype=np.float32)
            else:
                host = check_points(value, name, shape_tail=(3,))
                if host.shape[0] != n:
                    raise InputError("argument", name, f"has {host.shape[0]} rows but the model has {n} vertices",
                                     "pass one row per vertex")
            arrays.append(wp.array(host, dtype=wp.vec3, device=model.device))
        return cls(arrays[0], arrays[1])

    def clone(self) -> ClothState:
        """A deep copy on the same device. Allocates: yes. Capture-safe: no."""
        return ClothState(wp.clone(self.positions), wp.clone(self.velocities))

