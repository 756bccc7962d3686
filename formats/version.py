"""The installed version of recon, recorded as ``producer_version`` in every log it writes."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("recon")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0+source"
