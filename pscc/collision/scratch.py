"""Tables placed in memory that other buffers lend while they are dead.

A simulator step holds several large buffers that are live only in part of the step: the system
matrix's values during integration, the candidate pairs and times of impact from a broad phase to the
last narrow phase on its pairs. Tables that live within one call of another stage (the spatial hash's
entry, group and row tables) can be views into such a buffer instead of allocations of their own.

:func:`place_tables` decides where each table goes: first-fit decreasing over the lenders (outputs first), a
table that must outlive the call (an *output*, such as the hash's pairs) only in a lender that allows it.
The caller keeps the lenders' contract: nothing in a lent buffer is needed from the start of the
borrower's call until the borrower's outputs have been read.

:func:`held_arrays` lists the buffers an owner holds, so that an owner about to replace them can keep them
alive for a graph that was recorded with them (the detector's stale-graph guard, docs/pscc.md).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import warp as wp

from pscc.errors import InputError

ALIGNMENT = 16
"""Byte alignment of every table placed in a lent buffer."""


def aligned(size: int) -> int:
    """``size`` bytes rounded up to :data:`ALIGNMENT` (the offsets of tables placed one after another)."""
    return (int(size) + ALIGNMENT - 1) // ALIGNMENT * ALIGNMENT


def view(buffer: wp.array, byte_offset: int, count: int, dtype: type) -> wp.array:
    """``count`` values of ``dtype`` starting ``byte_offset`` bytes into ``buffer``'s memory (a view:
    ``buffer`` owns the memory, and the view keeps a reference to it)."""
    result = wp.array(ptr=buffer.ptr + byte_offset, dtype=dtype, shape=(count,), device=buffer.device)
    result._buffer = buffer
    return result


def strided_view(buffer: wp.array, byte_offset: int, count: int, dtype: type, stride: int) -> wp.array:
    """``count`` values of ``dtype``, one every ``stride`` bytes from ``byte_offset`` bytes into ``buffer``'s
    memory (a view, e.g. one half of each 8-byte value of an int64 array)."""
    result = wp.array(ptr=buffer.ptr + byte_offset, dtype=dtype, shape=(count,), strides=(stride,),
                      device=buffer.device)
    result._buffer = buffer
    return result


@dataclass(frozen=True)
class Lender:
    """A buffer whose memory a borrower may use between the lender's own uses.

    Attributes:
        buffer: the contiguous array lent.
        holds_outputs: whether tables that outlive the borrower's call may go there (False for a
            buffer that the consumer of those outputs writes, e.g. the candidate pairs that the hash's
            pairs are turned into).
    """

    buffer: wp.array
    holds_outputs: bool = True


@dataclass(frozen=True)
class TableSpec:
    """A table to place: ``count`` values of ``dtype``; ``output``: it outlives the borrower's call."""

    name: str
    count: int
    dtype: type
    output: bool = False

    @property
    def size(self) -> int:
        """Bytes, aligned."""
        return aligned(self.count * wp.types.type_size_in_bytes(self.dtype))


def check_lender(buffer: wp.array, device: wp.Device, name: str) -> None:
    """Raise :class:`InputError` unless ``buffer`` can be lent to a borrower on ``device``."""
    if not isinstance(buffer, wp.array) or buffer.device != device or not buffer.is_contiguous:
        raise InputError("argument", name, "is not a contiguous wp.array on the borrower's device",
                         "lend a contiguous wp.array allocated on the same device")


def scratch_lenders(source: Callable[[], Sequence[wp.array]] | None, device: wp.Device) -> list[Lender]:
    """The buffers ``source()`` gives now (checked), as lenders that hold no outputs; none without a
    source. Borrowers call the source again whenever they place tables: owners replace buffers that grow."""
    if source is None:
        return []
    if not callable(source):
        raise InputError("argument", "scratch", f"got {type(source).__name__}, not a function",
                         "pass a function that returns the lent wp.arrays, or None")
    lenders = []
    for k, array in enumerate(source()):
        check_lender(array, device, f"scratch[{k}]")
        lenders.append(Lender(array, holds_outputs=False))
    return lenders


def place_tables(tables: Sequence[TableSpec], lenders: Sequence[Lender],
                 device: wp.Device) -> tuple[dict[str, wp.array], set[str]]:
    """Make every table: a view into a lender where it fits (first-fit decreasing: the outputs, then the
    largest tables first, each into the first lender with room that may hold it), else an allocation of
    its own.

    Returns:
        The tables by name, and the names of those placed in lent memory.

    Allocates: the tables that fit nowhere. Capture-safe: no.
    """
    room = [int(lender.buffer.capacity) for lender in lenders]
    used = [0] * len(lenders)
    placed: dict[str, wp.array] = {}
    lent: set[str] = set()
    # Outputs first (fewer lenders may hold them), then the rest largest first.
    for k in sorted(range(len(tables)), key=lambda k: (not tables[k].output, -tables[k].size, k)):
        table = tables[k]
        for j, lender in enumerate(lenders):
            if (lender.holds_outputs or not table.output) and used[j] + table.size <= room[j]:
                placed[table.name] = view(lender.buffer, used[j], table.count, table.dtype)
                used[j] += table.size
                lent.add(table.name)
                break
        else:
            placed[table.name] = wp.empty(table.count, dtype=table.dtype, device=device)
    return placed, lent


def held_arrays(owners: list[Any]) -> list[Any]:
    """The ``wp.array`` and Warp struct values that ``owners`` and the pscc objects they hold (attributes,
    lists, tuples, dicts) refer to now: a list that keeps that memory alive however the owners replace it."""
    held: list[Any] = []
    seen: set[int] = set()
    stack = list(owners)
    while stack:
        value = stack.pop()
        if id(value) in seen:
            continue
        seen.add(id(value))
        if isinstance(value, wp.array) or type(value).__name__ == "StructInstance":
            held.append(value)
        elif isinstance(value, list | tuple):
            stack.extend(value)
        elif isinstance(value, dict):
            stack.extend(value.values())
        elif type(value).__module__.startswith("pscc.") and hasattr(value, "__dict__"):
            stack.extend(vars(value).values())
    return held
