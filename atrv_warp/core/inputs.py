"""Input files read safely: only from a regular file, and only up to a stated size (the standard library alone, so the
robot-side install reads robot files with it before torch is there).

A device, a pipe or a folder is refused before a byte is read (``/dev/zero`` would be read until memory ran out, a
FIFO would wait for ever), and so is a file over its kind's limit (:data:`MAX_INPUT_BYTES`).
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

__all__ = ["MAX_INPUT_BYTES", "InputFileError", "read_input"]


class InputFileError(ValueError):
    """An input file that is refused before it is read (not a regular file, or too large); the message names it."""


MAX_INPUT_BYTES = {"robot file": 1 << 20, "URDF": 10 << 20, "simulator config": 1 << 20}
"""The largest input of each kind read [bytes]: 1 MiB for a robot file or a simulator config (a few kB each), 10 MiB
for a URDF (the shipped ones are 6-20 kB; meshes are files of their own, never read). A larger file is refused
before a byte is read, as a device, a pipe or a folder is: a ``/dev/zero`` would be read until memory ran out, a
FIFO would wait for ever."""


def read_input(path: str | Path, what: str) -> bytes:
    """The bytes of the ``what`` (a :data:`MAX_INPUT_BYTES` key) at ``path``, read only from a regular file within its
    size.

    Raises:
        FileNotFoundError: No such file.
        InputFileError: Not a regular file (a device, a pipe, a folder), or larger than its kind's limit (named).
    """
    path = Path(path)
    limit = MAX_INPUT_BYTES[what]
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise FileNotFoundError(f"{what} not found: {path}") from None
    except OSError as err:
        raise InputFileError(f"{path}: cannot read the {what}: {err.strerror or err}") from None
    if not stat.S_ISREG(info.st_mode):
        raise InputFileError(f"{path}: the {what} is not a regular file (a device, a pipe or a folder)")
    if info.st_size > limit:
        raise InputFileError(f"{path}: the {what} is {info.st_size / 2**20:.1f} MiB, over the {limit >> 20} MiB a "
                             f"{what} may be")
    with open(path, "rb") as f:
        data = f.read(limit + 1)  # a file that grew since: still bounded
    if len(data) > limit:
        raise InputFileError(f"{path}: the {what} is over the {limit >> 20} MiB a {what} may be")
    return data
