"""The error every problem with a scene raises (a subclass of the shared ``ReconError``)."""

from formats.errors import ReconError


class SceneError(ReconError, ValueError):
    """A scene file, preset name or ``--set`` override is unknown, mistyped or impossible."""
