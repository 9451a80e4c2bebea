"""Exceptions raised by pscc.

Every error a user can cause derives from :class:`PsccError`. Input problems raise
:class:`InputError`, whose message always names the file (or argument), the field and the fix;
outputs that cannot be written raise :class:`OutputError`, with a message of the same form.
"""

from __future__ import annotations


class PsccError(Exception):
    """Base class of every error pscc raises on purpose."""


class InputError(PsccError, ValueError):
    """Bad user input: a mesh file, an array argument or an option.

    Args:
        source: The file path or argument name the problem was found in.
        field: The field inside it (an NPZ key, an OBJ line, an array name).
        problem: What is wrong.
        fix: What the user should do about it.
    """

    def __init__(self, source: str, field: str, problem: str, fix: str) -> None:
        self.source = str(source)
        self.field = str(field)
        self.problem = problem
        self.fix = fix
        super().__init__(f"{self.source}: {self.field}: {problem}. Fix: {fix}")


class OutputError(PsccError):
    """An output file or folder cannot be written (full disk, no permission, a folder in the way).

    Args:
        target: The file or folder that could not be written.
        field: The option or field that named it (``--out``, ``--out-dir``, ``path``).
        problem: What went wrong.
        fix: What the user should do about it.
    """

    def __init__(self, target: str, field: str, problem: str, fix: str) -> None:
        self.source = str(target)
        self.field = str(field)
        self.problem = problem
        self.fix = fix
        super().__init__(f"{self.source}: {self.field}: {problem}. Fix: {fix}")


class CapacityError(PsccError, RuntimeError):
    """A device buffer could not be grown to the size a computation needs."""
