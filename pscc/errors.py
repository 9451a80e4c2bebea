"""Exceptions raised by pscc.

Every error a user can cause derives from :class:`PsccError`. Input problems raise
:class:`InputError`, whose message always names the file (or argument), the field and the fix;
outputs that cannot be written raise :class:`OutputError`, with a message of the same form.
"""

from __future__ import annotations


class PsccError(Exception):
    """Base class of every error pscc raises on purpose."""


class _LocatedError(PsccError):
    """An error whose message reads ``SOURCE: FIELD: problem. Fix: fix``.

    Args:
        source: The file path or argument name the problem is about.
        field: The field inside it (an NPZ key, an OBJ line, an option such as ``--out-dir``).
        problem: What is wrong.
        fix: What the user should do about it.
    """

    def __init__(self, source: str, field: str, problem: str, fix: str) -> None:
        self.source = str(source)
        self.field = str(field)
        self.problem = problem
        self.fix = fix
        super().__init__(f"{self.source}: {self.field}: {problem}. Fix: {fix}")

    def __reduce__(self) -> tuple[type, tuple[str, str, str, str]]:
        """Pickle by the four parts (errors cross process boundaries in batch runs)."""
        return type(self), (self.source, self.field, self.problem, self.fix)


class InputError(_LocatedError, ValueError):
    """Bad user input: a mesh file, an array argument or an option (arguments as :class:`_LocatedError`)."""


class OutputError(_LocatedError):
    """An output file or folder cannot be written: a full disk, no permission, a folder in the way
    (arguments as :class:`_LocatedError`, ``source`` being the file or folder)."""


class CapacityError(PsccError, RuntimeError):
    """A device buffer could not be grown to the size a computation needs."""


class StaleGraphError(PsccError, RuntimeError):
    """A recorded graph was replayed after the buffers it writes had been replaced (a growth or a trim):
    its results are not in the detector's buffers. Record the call again after every check that returns
    False (:class:`pscc.collision.recorded.RecordedDetection` does)."""


def one_line(error: BaseException) -> str:
    """An error's message and notes (:meth:`BaseException.add_note`) on one line, as sentences."""
    parts = [" ".join(part.split()) for part in (str(error) or type(error).__name__,
                                                   *getattr(error, "__notes__", []))]
    return " ".join(part if part.endswith((".", "!", "?")) or k == len(parts) - 1 else part + "."
                    for k, part in enumerate(parts) if part)
