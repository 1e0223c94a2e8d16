"""Errors clpost raises on purpose.

Everything a user can cause (bad input file, bad parameter, missing OpenCL driver) is a
:class:`ClpostError`; the CLI prints its message as one line and exits with status 2. The
message names the file or parameter and says how to fix it.
"""


class ClpostError(Exception):
    """A user-facing error: the message is the whole report (no traceback needed)."""


class InputError(ClpostError, ValueError):
    """Invalid input data or parameter (also a ``ValueError`` for library callers)."""


class OpenCLUnavailableError(ClpostError, RuntimeError):
    """No usable OpenCL platform/device; the message says what to install."""


class KernelBuildError(ClpostError, RuntimeError):
    """An OpenCL program failed to build; carries the kernel name, options and compiler log."""


class OutputError(ClpostError, OSError):
    """An output could not be written (directory not writable, disk full); nothing was lost."""
