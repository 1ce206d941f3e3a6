"""Reading and writing the package's files: atomic saves, and loads that name what is wrong.

Every file is read with ``torch.load(weights_only=True)``: tensors and plain containers only, so a damaged or hostile
file is refused without unpickling arbitrary objects. Before that, every member's CRC-32 (which ``torch.save``'s zip
archive records and ``torch.load`` does not check) is checked, so that a changed byte is refused by name rather than
loaded as a wrong weight.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import warnings
import zipfile
from pathlib import Path

import torch

__all__ = ["FileFormatError", "atomic_save", "atomic_write_text", "file_sha256", "load_weights"]


def _detail(err: Exception) -> str:
    lines = [line.strip() for line in str(err).splitlines() if line.strip()]
    useful = [line for line in lines if "WeightsUnpickler" not in line and "weights_only" not in line]
    return (useful or lines or [type(err).__name__])[0][:200]


class FileFormatError(ValueError):
    """A file that is not what it should be; the message names the file and the problem."""


def atomic_save(obj, path: str | Path) -> None:
    """``torch.save`` to a temporary file beside ``path``, flushed to the disk, then renamed over ``path`` (and the
    folder's entry flushed): a reader, a kill or a power cut never sees a half-written file, and the previous version
    survives a failed save."""
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    with open(tmp, "wb") as f:
        torch.save(obj, f)
        f.flush()
        os.fsync(f.fileno())
    tmp.replace(path)
    sync_folder(path.parent)


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) as :func:`atomic_save` writes: a temporary file beside ``path``, flushed, renamed over it."""
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    tmp.replace(path)
    sync_folder(path.parent)


def sync_folder(folder: str | Path) -> None:
    """Flush a folder's entries (a rename in it) to the disk, where the system allows it."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def file_sha256(path: str | Path) -> str:
    """The SHA-256 of a file's bytes, in hex."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def load_weights(path: str | Path, what: str, required: tuple[str, ...] = ()) -> dict:
    """Load a ``torch.save``d dict with ``weights_only=True``.

    Raises ``FileNotFoundError`` for a missing file and :class:`FileFormatError` (naming
    ``path`` and saying what is wrong) for anything that is not a complete ``what`` holding the
    ``required`` keys: random bytes, a truncated file, a changed byte, a pickle of arbitrary objects.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{what} not found: {path}")
    if not zipfile.is_zipfile(path):  # torch.save writes a zip archive; a truncated one has lost its directory
        raise FileFormatError(f"{path}: not a {what}: not a complete file written by torch.save "
                              "(truncated, or another format)")
    try:
        with zipfile.ZipFile(path) as archive:
            bad = archive.testzip()
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, RuntimeError) as err:
        raise FileFormatError(f"{path}: not a readable {what}: damaged ({_detail(err)})") from None
    if bad is not None:
        raise FileFormatError(f"{path}: not a readable {what}: damaged (the checksum of its member {bad} does not "
                              "match: a byte changed)")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # e.g. the pickle-protocol notice; the error below says enough
            payload = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as err:
        if "unsupported global" in str(err).lower():  # "Unsupported global: …", or "unsupported GLOBAL posix.system
            # whose module posix is blocked" (torch 2.13)
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
