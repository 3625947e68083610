"""The installed package's version (``0.0.0+unknown`` in a source tree that was not installed)."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

__all__ = ["__version__"]

try:
    __version__ = version("jcrowd")
except PackageNotFoundError:
    __version__ = "0.0.0+unknown"
