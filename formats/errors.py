"""The exception tree shared by every recon package.

Every error caused by the user's input (a bad file, key or argument) is a ``ReconError``; the CLI
prints its message on one line and exits with status 1. Anything else is a bug and keeps its
traceback. Each class also subclasses the builtin a Python user would expect to catch.
"""


class ReconError(Exception):
    """Base class of every error caused by bad input to recon."""


class StrikeLogError(ReconError, ValueError):
    """A strike log is missing, unreadable, incomplete or breaks formats/SPEC.md."""


class MeshFormatError(ReconError, ValueError):
    """A mesh or point-cloud file is missing, unreadable or not what was expected."""
