"""The exception tree shared by every recon package: six classes, each meaning something a
caller can act on.

The CLI prints a ``ReconError``'s message on one line and exits with status 1; anything else is
a bug and keeps its traceback. Each class also subclasses the builtin a Python user would expect
to catch.

==================  ====================  =================================================
class               builtin               what the caller can do
==================  ====================  =================================================
``InputError``      ``ValueError``        fix or replace the file or data named (a strike
                                          log, mesh, cloud, altimetry product, SPICE kernel,
                                          results directory)
``ParameterError``  ``ValueError``        change the argument, option or name (a method, a
                                          parameter, a limit, a scheduler, an output suffix)
``SceneError``      ``ValueError``        fix the scene file, preset or ``--set`` override
``MethodFailed``    ``RuntimeError``      try another method or other parameters: the method
                                          ran, or declined, and gave no usable surface
``ResourceError``   ``OSError``           free or choose another disk or destination
==================  ====================  =================================================
"""


class ReconError(Exception):
    """Base class of every error recon reports as one line (not a bug)."""


class InputError(ReconError, ValueError):
    """A file or the data in it is missing, unreadable, incomplete or breaks its format
    (formats/SPEC.md for strike logs), or is not enough for what was asked."""


class ParameterError(ReconError, ValueError):
    """An argument, option or name is unknown, out of range or does not go with the others."""


class SceneError(ReconError, ValueError):
    """A scene file, preset name or ``--set`` override is unknown, mistyped or impossible."""


class MethodFailed(ReconError, RuntimeError):
    """A method ran, or declined to run, and produced no usable result (the message says why)."""


class ResourceError(ReconError, OSError):
    """No room or no way to write: the file system is full (or a quota or file-size limit was
    hit), or a destination cannot be written."""
