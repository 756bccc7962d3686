"""The exception tree shared by every recon package: six classes, each meaning something a
caller can act on.

The CLI prints a ``ReconError``'s message on one line and exits with status 1; anything else is
a bug and keeps its traceback. Each class also subclasses the builtin a Python user would expect
to catch.

A message about one argument starts with the argument's name as the Python API spells it, and
the error carries that name as ``argument`` (``ParameterError("timeout must be positive, got
0", argument="timeout")``): a caller of ``recon.api`` reads the parameter it passed, and the CLI
prints the option it was given instead (``--timeout must be positive, got 0``; ``worded``). A
library message never names a command-line option.

==================  ====================  =================================================
class               builtin               what the caller can do
==================  ====================  =================================================
``InputError``      ``ValueError``        fix or replace the file or data named (a strike
                                          log, mesh, cloud, altimetry product, SPICE kernel,
                                          results directory)
``ParameterError``  ``ValueError``        change the argument, option or name (a method, a
                                          parameter, a limit, a scheduler, an output suffix)
``SceneError``      ``ValueError``        fix the scene file, preset or override
                                          (``section.key=value``)
``MethodFailed``    ``RuntimeError``      try another method or other parameters: the method
                                          ran, or declined, and gave no usable surface
``ResourceError``   ``OSError``           free or choose another disk or destination
==================  ====================  =================================================
"""

from __future__ import annotations

from collections.abc import Callable


class ReconError(Exception):
    """Base class of every error recon reports as one line (not a bug).

    Parameters
    ----------
    *args
        The message: one line naming the file, key or argument and what is wrong.
    argument : str, optional
        The API parameter the message is about, when the message starts with its name
        (``"resume"``, ``"overrides"``, ``"memory_limit"``).
    """

    def __init__(self, *args, argument: str | None = None):
        super().__init__(*args)
        self.argument = argument

    def worded(self, spell: Callable[[str], str]) -> str:
        """The message with its leading argument name replaced by ``spell(argument)``.

        The CLI passes the name of the option that sets the parameter (``"memory_limit"`` ->
        ``"--memory-limit"``). A message that does not start with its argument (as a whole
        word) is returned as it is.
        """
        text = str(self)
        if self.argument is None or not text.startswith(self.argument):
            return text
        rest = text[len(self.argument):]
        if rest[:1].isalnum() or rest[:1] == "_":   # a longer word: "timeouts", "k_max"
            return text
        return spell(self.argument) + rest


class InputError(ReconError, ValueError):
    """A file or the data in it is missing, unreadable, incomplete or breaks its format
    (formats/SPEC.md for strike logs), or is not enough for what was asked."""


class ParameterError(ReconError, ValueError):
    """An argument, option or name is unknown, out of range or does not go with the others."""


class SceneError(ReconError, ValueError):
    """A scene file, preset name or override (``section.key=value``) is unknown, mistyped or
    impossible."""


class MethodFailed(ReconError, RuntimeError):
    """A method ran, or declined to run, and produced no usable result (the message says why)."""


class ResourceError(ReconError, OSError):
    """No room or no way to write: the file system is full (or a quota or file-size limit was
    hit), or a destination cannot be written."""
