"""A detection recorded once into a graph and replayed safely.

A :class:`~pscc.collision.detector.CollisionDetector` call on device arrays records into a CUDA (or CPU)
graph (``wp.ScopedCapture``). A replay reads nothing back; the caller's
:meth:`~pscc.collision.detector.CollisionDetector.check_capacity` afterwards grows every buffer that
overflowed and returns False. The graph still holds the buffers it was recorded with, which the growth
replaced: replayed again it would write into them and leave the new buffers unread (on this project's CPU, a
`cloth_rollers` frame replayed that way once reported 0 triangle pairs and a capacity verdict that fits; the
check now raises :class:`~pscc.errors.StaleGraphError` for it). So after a False the detection must run again
and be recorded again.
:class:`RecordedDetection` does both: :meth:`RecordedDetection.replay` launches the graph, checks, and
on a False records a new graph and replays that, until the call fits. Before each recording it fits the
spatial hash's tables to the call (``fit``, on by default): a detector starts with 4 entry slots per face,
and a replay sorts, pads and scans all of them.

It covers the buffers the check grows. A caller that changes the detector otherwise between replays
(:meth:`~pscc.collision.detector.CollisionDetector.lend_scratch`, ``refresh_loans``, ``set_joined``, a
simulator's trim of the hash) calls :meth:`RecordedDetection.record` itself.
"""

from __future__ import annotations

from typing import Any

import warp as wp

from pscc.collision.contacts import DeviceContacts
from pscc.errors import InputError

__all__ = ["RecordedDetection"]


class RecordedDetection:
    """One detector call on fixed device arrays, recorded into a graph (module docstring).

    The positions are read in place at every replay: write new positions into the same arrays between
    replays, as a simulator does.

    Args:
        detector: the :class:`~pscc.collision.detector.CollisionDetector` to record.
        positions: ``wp.array`` of ``wp.vec3`` on the detector's device, positions at the start of the step.
        positions_end: the same at the end of the step (CCD), or ``None`` (DCD).
        thickness: the proximity distance, as for :meth:`~pscc.collision.detector.CollisionDetector.detect`.
        fit: shrink the hash's tables to what the call uses before each recording
            (:meth:`~pscc.collision.detector.CollisionDetector.fit_buffers`): a replay then sorts and scans
            no empty slots. Pass False to keep the detector's capacities as they are.

    Raises:
        InputError: positions that are not device arrays of the detector (as ``detect`` says).
    """

    def __init__(self, detector: Any, positions: wp.array, positions_end: wp.array | None = None,
                 thickness: float = 0.0, fit: bool = True) -> None:
        for name, value in (("positions", positions), ("positions_end", positions_end)):
            if value is not None and not isinstance(value, wp.array):
                raise InputError("argument", name, f"a recorded detection reads device arrays in place, got "
                                 f"{type(value).__name__}",
                                 "pass wp.array(..., dtype=wp.vec3) positions on the detector's device")
        if positions is None:
            raise InputError("argument", "positions", "missing", "pass the positions at the start of the step")
        self.detector = detector
        self.positions = positions
        self.positions_end = positions_end
        self.thickness = float(thickness)
        self.fit = bool(fit)
        self.graph: Any = None
        self.contacts: DeviceContacts | None = None
        self.recordings = 0
        """How many graphs were recorded (1 after construction; one more after every growth)."""
        self.record()

    def record(self) -> None:
        """Run the call once outside a capture (it grows what it needs and checks), fit the hash's tables
        to it (:meth:`~pscc.collision.detector.CollisionDetector.fit_buffers`; after a fit the call runs
        once more), then record it.

        Allocates: when a buffer grows or shrinks. Capture-safe: no.
        """
        detector = self.detector
        detector.detect(self.positions, self.positions_end, self.thickness)
        if self.fit and detector.fit_buffers():
            detector.detect(self.positions, self.positions_end, self.thickness)
        with wp.ScopedCapture(device=detector.device) as capture:
            self.contacts = detector.detect(self.positions, self.positions_end, self.thickness)
        self.graph = capture.graph
        self.recordings += 1

    def replay(self) -> DeviceContacts:
        """Launch the graph and check the call (one sync point). When a buffer overflowed, record the call
        again and replay the new graph, until it fits; a stale graph is never launched.

        Returns:
            The device contacts of the call (:meth:`~pscc.collision.detector.CollisionDetector.collect`
            gives the sorted host rows). The same object until a growth records the call again.

        Allocates: only when a buffer grows. Capture-safe: no.
        """
        while True:
            wp.capture_launch(self.graph)
            if self.detector.check_capacity():
                return self.contacts
            self.record()
