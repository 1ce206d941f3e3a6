"""Reading and writing the package's files: atomic saves, and loads that name what is wrong.

Every file is read with ``torch.load(weights_only=True)``: tensors and plain containers only,
so a damaged or hostile file is refused without unpickling arbitrary objects.
"""

from __future__ import annotations

import pickle
import warnings
import zipfile
from pathlib import Path

import torch

__all__ = ["FileFormatError", "atomic_save", "load_weights"]


def _detail(err: Exception) -> str:
    lines = [line.strip() for line in str(err).splitlines() if line.strip()]
    useful = [line for line in lines if "WeightsUnpickler" not in line and "weights_only" not in line]
    return (useful or lines or [type(err).__name__])[0][:200]


class FileFormatError(ValueError):
    """A file that is not what it should be; the message names the file and the problem."""


def atomic_save(obj, path: str | Path) -> None:
    """``torch.save`` to a temporary file beside ``path``, then rename: a reader (or a crash)
    never sees a half-written file, and the previous version survives a failed save."""
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(obj, tmp)
    tmp.replace(path)


def load_weights(path: str | Path, what: str, required: tuple[str, ...] = ()) -> dict:
    """Load a ``torch.save``d dict with ``weights_only=True``.

    Raises ``FileNotFoundError`` for a missing file and :class:`FileFormatError` (naming
    ``path`` and saying what is wrong) for anything that is not a complete ``what`` holding the
    ``required`` keys: random bytes, a truncated file, a pickle of arbitrary objects.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{what} not found: {path}")
    if not zipfile.is_zipfile(path):  # torch.save writes a zip archive; a truncated one has lost its directory
        raise FileFormatError(f"{path}: not a {what}: not a complete file written by torch.save "
                              "(truncated, or another format)")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # e.g. the pickle-protocol notice; the error below says enough
            payload = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as err:
        if "Unsupported global" in str(err):
            raise FileFormatError(f"{path}: not a {what}: it holds Python objects other than tensors and plain "
                                  "containers, which are refused (nothing was unpickled)") from None
        raise FileFormatError(f"{path}: not a {what}: damaged ({_detail(err)})") from None
    except (RuntimeError, EOFError, zipfile.BadZipFile, ValueError, OSError) as err:
        raise FileFormatError(f"{path}: not a readable {what}: damaged or truncated ({_detail(err)})") from None
    if not isinstance(payload, dict):
        raise FileFormatError(f"{path}: not a {what}: it holds a {type(payload).__name__}, not a dict")
    missing = [k for k in required if k not in payload]
    if missing:
        raise FileFormatError(f"{path}: not a {what}: missing {missing}")
    return payload
