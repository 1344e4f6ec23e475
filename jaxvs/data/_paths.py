"""The one check every loader starts with: the path names an existing regular file."""

import os
from pathlib import Path

from .._files import regular_file

PathLike = str | os.PathLike[str]


def existing_file(path: PathLike) -> Path:
    """`path` as a `Path` when it names an existing regular file; every loader starts here
    (FIFOs, devices, folders and link loops are refused before opening, see `regular_file`)."""
    return regular_file(path, "load")
