"""The project's exceptions.

Every failure a user can cause or meet is one of these; the CLI turns them into a one-line message and an
exit code (:attr:`Hot2ColdError.exit_code`).  Kernel (OpenCascade) failures are caught inside
:mod:`hot2cold.kernel` and re-raised as :class:`KernelError`.
"""


class Hot2ColdError(Exception):
    """Base class of all hot2cold errors."""

    exit_code = 1


class InputError(Hot2ColdError, ValueError):
    """The user's input (STEP file, field file, options) is unusable."""

    exit_code = 2


class StepReadError(InputError):
    """A STEP file is missing, unreadable or holds no solid."""


class FieldError(InputError):
    """A displacement field is malformed, empty, non-finite or does not fit the part."""


class KernelError(Hot2ColdError, RuntimeError):
    """OpenCascade failed on an operation that should have succeeded."""

    exit_code = 3


class MorphError(Hot2ColdError, RuntimeError):
    """The morph ran but its result is not a valid solid."""

    exit_code = 4


class OutputError(Hot2ColdError, OSError):
    """An output file could not be written (nothing of it is left behind)."""

    exit_code = 6


def one_line(exc: BaseException) -> str:
    """The message of ``exc`` on one line (its whitespace runs made single spaces), else its class's name."""
    return " ".join(str(exc).split()) or type(exc).__name__
