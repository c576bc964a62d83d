"""contactfem: frictionless contact of a 2D linear elastic body on a rigid flat obstacle."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("contactfem")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
