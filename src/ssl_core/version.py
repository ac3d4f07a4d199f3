"""The installed version of the ``ssl-rescue`` distribution, for the command-line tools' ``--version``."""
from __future__ import annotations

from importlib import metadata

DISTRIBUTION = "ssl-rescue"


def version() -> str:
    """The version string from the installed distribution's metadata (``pyproject.toml``'s ``version``)."""
    try:
        return metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:  # sources on PYTHONPATH without an install
        return "unknown (not installed)"
