"""The one exception tree of lfproc.

Every error lfproc raises on purpose derives from :class:`LfprocError`. Leaves also
derive from the matching builtin (``ValueError``, ``FileNotFoundError``...), so code
that catches builtins keeps working. The CLI turns any :class:`LfprocError` into a
one-line message and exit code 2.

Messages name the file or option, what was expected and what was found.
"""

from __future__ import annotations

import contextlib
import contextvars

__all__ = [
    "LfprocError",
    "InputError",
    "ShapeError",
    "FileFormatError",
    "MissingFileError",
    "UnsafeFileError",
    "LfpFormatError",
    "ChecksumError",
    "OutputExistsError",
    "CalibrationError",
    "ProfileError",
    "NoWhiteImageError",
    "DependencyError",
    "LfprocWarning",
    "SaturationWarning",
    "ConvergenceWarning",
    "ViewCountWarning",
    "SATURATION_WARNING_FRACTION",
    "option_name",
    "cli_interface",
]

#: Which interface is running: ``"python"`` (default) or ``"cli"`` (set by the ``lfproc`` command
#: with :func:`cli_interface`). Messages that name a setting use :func:`option_name`, so that the
#: command line says ``--force`` and Python says ``force=True``.
_INTERFACE: contextvars.ContextVar[str] = contextvars.ContextVar("lfproc_interface", default="python")


def option_name(python: str, cli: str) -> str:
    """The name of a setting for the interface that is running: ``cli`` inside the ``lfproc``
    command (:func:`cli_interface`), ``python`` otherwise.

    Examples
    --------
    >>> f"pass {option_name('force=True', '--force')} to overwrite it"
    'pass force=True to overwrite it'
    """
    return cli if _INTERFACE.get() == "cli" else python


@contextlib.contextmanager
def cli_interface():
    """Within this block, :func:`option_name` gives the command-line spelling."""
    token = _INTERFACE.set("cli")
    try:
        yield
    finally:
        _INTERFACE.reset(token)

#: :class:`SaturationWarning` is emitted when more than this share of the samples has lost its
#: radiance to saturation: in a coded capture (:func:`lfproc.camera.simulate.simulate_capture`,
#: :func:`lfproc.camera.capture.observations`) the share of its least sensitive pixels (lowest
#: ISO x exposure) that are saturated -- higher ISOs saturate in highlights by design; in an
#: exposure bracket (:mod:`lfproc.merge`) the share of samples saturated in every exposure.
#: Captures of the synthetic scenes with the automatic radiance scale have about 0.1 %.
SATURATION_WARNING_FRACTION = 0.10


class LfprocError(Exception):
    """Base class of every error lfproc raises on purpose."""


class InputError(LfprocError, ValueError):
    """A parameter or option has a value lfproc cannot use."""


class ShapeError(InputError):
    """An array or light field has the wrong shape, dtype or number of views."""


class FileFormatError(LfprocError, ValueError):
    """A file exists but is not in the format expected, or is corrupt or truncated."""


class UnsafeFileError(FileFormatError):
    """A file names something outside its folder, holds links or ``..`` members, or would
    expand beyond the limits (a compression bomb); lfproc refuses it."""


class MissingFileError(LfprocError, FileNotFoundError):
    """An input file or folder does not exist."""


class LfpFormatError(FileFormatError):
    """A Lytro LFP/LFR container or raw image is malformed."""


class ChecksumError(LfpFormatError):
    """A section of a Lytro container does not match its SHA-1."""


class OutputExistsError(LfprocError, FileExistsError):
    """An output exists and overwriting was not asked for (``force=True``/``--force``)."""


class CalibrationError(LfprocError, RuntimeError):
    """Calibration frames cannot give the quantity asked for."""


class ProfileError(InputError):
    """A camera profile is missing a field, or a field has a wrong value."""


class NoWhiteImageError(LfprocError, LookupError):
    """No white image in the database matches a capture."""


class DependencyError(LfprocError, ImportError):
    """An optional dependency needed by this function is not installed."""


class LfprocWarning(UserWarning):
    """Base class of lfproc's warnings."""


class SaturationWarning(LfprocWarning):
    """Input data are clipped (saturated) in a way that affects the result (more than
    :data:`SATURATION_WARNING_FRACTION` of the samples)."""


class ConvergenceWarning(LfprocWarning):
    """An iterative solver stopped before reaching its tolerance."""


class ViewCountWarning(LfprocWarning):
    """A light field or capture has a number of views the dictionary it is meant for cannot
    reconstruct (the dictionary's patch has another angular shape)."""
