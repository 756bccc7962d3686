"""Warnings raised by the metrics package.

Every error caused by the caller's input is a ``formats.errors.InputError`` (a ``ReconError``,
which the CLI prints on one line with exit status 1, and a ``ValueError``).
"""


class ScaleMismatchWarning(UserWarning):
    """Test and truth differ in size by more than ``defaults.SCALE_MISMATCH_RATIO``.

    The usual cause is a model in kilometres scored against one in metres.
    """


class FrameAssumedWarning(UserWarning):
    """Test or truth records no frame (``"unknown"``: a file of another tool), so it is compared
    as if in the other's frame. The CLI prints it as one line on stderr."""
