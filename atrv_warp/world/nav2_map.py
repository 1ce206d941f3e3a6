"""A Nav2 ``map_server`` map, read as ``map_server`` reads it: the YAML beside its PGM or PNG.

    from atrv_warp.world import load_map
    site = load_map("mymap.yaml")          # what `ros2 run nav2_map_server map_saver_cli -f mymap` wrote
    site.cells                             # (rows, cols) int8, OccupancyGrid's values: 0 free, 100 occupied, -1 unknown
    site.walls                             # (rows, cols) bool: what the simulator's laser and collision hit

The YAML's keys are ``map_server``'s: ``image`` (relative to the YAML's folder, or absolute), ``resolution`` [m per
cell], ``origin`` (x [m], y [m], yaw [rad] of the lower-left cell's corner), ``negate`` (an int or a bool),
``occupied_thresh``, ``free_thresh`` and ``mode`` (``trinary``, the default; ``scale``; ``raw``). Each pixel becomes a
cell as in Nav2 Jazzy and Kilted (``nav2_map_server/src/map_io.cpp``, Jazzy at 768947d of 2025-08-20; Kilted reads it
alike), which :data:`NAV2_MAP_IO` cites:

- the pixel's shade ``p / 255`` in float32; its occupancy ``1 - p / 255`` (``negate``: the shade itself), compared
  with the thresholds in float32;
- ``trinary`` and ``scale``: occupied (100) where the occupancy is ``>= occupied_thresh``, free (0) where it is
  ``<= free_thresh``, else unknown (-1), or in ``scale`` the occupancy scaled linearly from the free threshold (0) to
  the occupied one (100); a pixel with any transparency (alpha < 255) is unknown;
- ``raw``: the pixel's value itself where it is 0 to 100, else unknown;
- the image's top row is the map's last row (an OccupancyGrid's row 0 is at the origin, the image's bottom).

Humble's ``map_server`` compares the thresholds strictly and averages alpha into the shade: the two agree on every
pixel ``map_saver`` writes (0 occupied, 254 free, 205 unknown) except where a threshold falls exactly on a shade. A
colour image's shade is the mean of its three channels (Humble's rule; Jazzy asks ImageMagick for a grey, which
weighs the channels: the two differ only on coloured pixels, which ``map_saver`` never writes). Note what
``map_saver``'s defaults mean: with its older ``free_thresh`` 0.25 an unknown pixel (205, occupancy 0.196) reads as
free; with 0.196 (newer) it stays unknown. Both are read as written.

A wall (:attr:`OccupancyMap.walls`) is an occupied or an unknown cell, as the simulator treats them (the laser and
the chassis meet them); a cell between free and occupied (``scale`` and ``raw`` maps) is free space, as Nav2's static
layer reads it by default (``trinary_costmap``: below ``lethal_threshold`` 100 is free). A non-zero origin yaw is
refused: Nav2's costmaps ignore it (their grid is axis-aligned at the origin), so a world that applied it would not
be the one the user's Nav2 plans on.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["FREE", "MAX_CELLS", "MODES", "NAV2_MAP_IO", "OCCUPIED", "UNKNOWN", "MapError", "OccupancyMap",
           "load_map", "save_map"]

FREE, OCCUPIED, UNKNOWN = 0, 100, -1
"""An OccupancyGrid cell's values (``nav2_util/occ_grid_values.hpp``)."""
MODES = ("trinary", "scale", "raw")
"""``map_server``'s modes, its default first."""
MAX_CELLS = 4096 * 4096
"""The most cells a map may have (16.8 M: a 200 m square at 0.05 m; a 100 m square at 0.05 m is 4 M). Each world's
grid lives in memory once per map, with a distance field of four bytes a cell beside it."""
NAV2_MAP_IO = ("ros-navigation/navigation2, branch jazzy, nav2_map_server/src/map_io.cpp at "
               "768947d1db2acce4776518b03b3f513bb411429c (2025-08-20)")
"""The ``map_server`` this module reads maps as."""
REQUIRED_KEYS = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
"""Keys ``map_server`` requires in a map's YAML (``mode`` is optional)."""


class MapError(ValueError):
    """A map that cannot be read, or a value in it that is wrong; the message names the file and the problem."""


@dataclass(frozen=True, eq=False)
class OccupancyMap:
    """A site as Nav2's ``map_server`` serves it: OccupancyGrid cells and the metadata that places them.

    Row ``i`` of :attr:`cells` is ``y = origin_y + (i + 0.5) * resolution`` at its cells' centres, column ``j`` is
    ``x = origin_x + (j + 0.5) * resolution``: the layout of ``nav_msgs/OccupancyGrid``'s ``data``.
    """

    cells: np.ndarray  # (rows, cols) int8: FREE, OCCUPIED, UNKNOWN, or 1..99 between (scale, raw)
    resolution: float  # [m per cell]
    origin: tuple[float, float]  # the lower-left cell's outer corner (x, y) [m], in the map frame
    source: Path | None = None  # the YAML it was read from
    mode: str = "trinary"
    digest: str = field(default="")  # sha256 of the YAML and image bytes (of a drawn map, its cells): which map it is
    label: str = ""  # a name where there is no file (a procedural place's ``building_3``)

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols): (height, width) in cells."""
        return self.cells.shape

    @property
    def size(self) -> tuple[float, float]:
        """(width, height) [m]."""
        return self.cells.shape[1] * self.resolution, self.cells.shape[0] * self.resolution

    @property
    def walls(self) -> np.ndarray:
        """(rows, cols) bool: occupied or unknown cells, which the simulator's laser and chassis meet."""
        return (self.cells == OCCUPIED) | (self.cells == UNKNOWN)

    @property
    def name(self) -> str:
        """The YAML's file name without its suffix, else :attr:`label`, else ``"map"``."""
        return self.source.stem if self.source is not None else (self.label or "map")

    def record(self) -> dict:
        """Which map this is, as a results file or a policy records it: its :attr:`name`, its YAML (``None`` for a
        drawn place) and its :attr:`digest`."""
        return {"name": self.name, "file": str(self.source) if self.source else None, "sha256": self.digest}

    def cell_of(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """The (row, col) indices of the cells holding the points ``(x, y)`` [m] (outside the map: out of range)."""
        col = np.floor((np.asarray(x, dtype=float) - self.origin[0]) / self.resolution).astype(np.int64)
        row = np.floor((np.asarray(y, dtype=float) - self.origin[1]) / self.resolution).astype(np.int64)
        return row, col

    def centre_of(self, row, col) -> tuple[np.ndarray, np.ndarray]:
        """The (x, y) [m] of the centres of cells ``(row, col)``."""
        return (self.origin[0] + (np.asarray(col) + 0.5) * self.resolution,
                self.origin[1] + (np.asarray(row) + 0.5) * self.resolution)


def load_map(path: str | Path) -> OccupancyMap:
    """Read a ``map_server`` map's YAML and its image (see the module's docstring); :class:`MapError` naming the file
    and the problem where it cannot."""
    yaml_path = Path(path).expanduser()
    text = _read_bytes(yaml_path, f"map {yaml_path}:", missing=f"map not found: {yaml_path}",
                       folder=f"map {yaml_path}: is a folder; give the map's YAML file")
    meta = _read_yaml(yaml_path, text)
    image_path = Path(meta["image"]).expanduser()
    if not image_path.is_absolute():
        image_path = yaml_path.parent / image_path
    gray, alpha, image_bytes = _read_image(yaml_path, image_path)
    cells = cells_from_pixels(gray, alpha, mode=meta["mode"], negate=meta["negate"],
                              occupied_thresh=meta["occupied_thresh"], free_thresh=meta["free_thresh"])
    if not (cells == FREE).any() and not ((cells > FREE) & (cells < OCCUPIED)).any():
        raise MapError(f"map {yaml_path}: no free cell in {image_path.name} ({gray.shape[1]} x {gray.shape[0]} "
                       f"pixels): check negate ({meta['negate']}) and the thresholds")
    digest = hashlib.sha256(hashlib.sha256(text).digest() + hashlib.sha256(image_bytes).digest()).hexdigest()
    return OccupancyMap(cells=cells, resolution=meta["resolution"], origin=(meta["origin"][0], meta["origin"][1]),
                        source=yaml_path, mode=meta["mode"], digest=digest)


def save_map(site: OccupancyMap, path: str | Path) -> Path:
    """Write ``site`` as ``map_saver_cli`` does in ``trinary`` mode: ``path`` (a ``.yaml``) beside a binary PGM of the
    same stem, free 254, occupied 0, unknown 205 (and a cell between the thresholds unknown), with ``free_thresh``
    0.196 and ``occupied_thresh`` 0.65, so that :func:`load_map` (and ``map_server``) reads back the same cells.
    Returns the YAML's path."""
    yaml_path = Path(path).expanduser()
    if yaml_path.suffix not in (".yaml", ".yml"):
        raise MapError(f"map {yaml_path}: give the YAML's path (.yaml)")
    cells = np.asarray(site.cells)
    pixels = np.full(cells.shape, 205, dtype=np.uint8)
    pixels[(cells >= 0) & (cells <= 19)] = 254  # occupancy <= free_thresh 0.196
    pixels[(cells >= 65) & (cells <= 100)] = 0  # occupancy >= occupied_thresh 0.65
    image = yaml_path.with_suffix(".pgm")
    rows, cols = cells.shape
    image.write_bytes(f"P5\n{cols} {rows}\n255\n".encode() + pixels[::-1].tobytes())  # the top row is the last
    x, y = site.origin
    yaml_path.write_text(f"image: {image.name}\nmode: trinary\nresolution: {site.resolution!r}\n"
                         f"origin: [{float(x)!r}, {float(y)!r}, 0.0]\nnegate: 0\noccupied_thresh: 0.65\n"
                         "free_thresh: 0.196\n")
    return yaml_path


def cells_from_pixels(gray: np.ndarray, alpha: np.ndarray | None, *, mode: str = "trinary", negate: bool = False,
                      occupied_thresh: float = 0.65, free_thresh: float = 0.196) -> np.ndarray:
    """OccupancyGrid cells (rows from the bottom) from an image's 8-bit grey (rows from the top) and its alpha
    (``None``: opaque), as :data:`NAV2_MAP_IO` computes them."""
    if mode == "raw":
        cells = np.where(gray <= OCCUPIED, gray, UNKNOWN).astype(np.int8)
    else:  # in float32, as Eigen computes it (a double threshold is converted to the array's float)
        shade = gray.astype(np.float32) / np.float32(255.0)
        occupancy = shade if negate else np.float32(1.0) - shade
        occupied_f, free_f = np.float32(occupied_thresh), np.float32(free_thresh)
        cells = np.full(gray.shape, UNKNOWN, dtype=np.int8)
        cells[occupancy >= occupied_f] = OCCUPIED
        cells[occupancy <= free_f] = FREE
        if mode == "scale":
            between = (occupancy > free_f) & (occupancy < occupied_f)
            scaled = (occupancy - free_f) / np.float32(occupied_thresh - free_thresh) * np.float32(100.0)
            cells[between] = np.floor(scaled[between] + np.float32(0.5)).astype(np.int8)  # Eigen's round: half up
        if alpha is not None:
            cells[alpha < 255] = UNKNOWN
    return np.ascontiguousarray(cells[::-1])


def _read_yaml(yaml_path: Path, text: bytes) -> dict:
    import yaml

    where = f"map {yaml_path}"
    try:
        doc = yaml.safe_load(text)  # plain data only: a tag that would build an object is refused
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        at = f" at line {mark.line + 1}" if mark is not None else ""
        raise MapError(f"{where}: not valid YAML{at}: {getattr(err, 'problem', None) or err}") from None
    if not isinstance(doc, dict):
        raise MapError(f"{where}: not a map_server YAML (a mapping with {', '.join(REQUIRED_KEYS)})")
    missing = [key for key in REQUIRED_KEYS if key not in doc]
    if missing:
        raise MapError(f"{where}: missing {', '.join(missing)} (map_server requires {', '.join(REQUIRED_KEYS)})")
    image = doc["image"]
    if not isinstance(image, str) or not image.strip():
        raise MapError(f"{where}: image must be the image file's name, got {image!r}")
    resolution = _number(where, "resolution", doc["resolution"])
    if not resolution > 0:
        raise MapError(f"{where}: resolution must be > 0 [m per cell], got {doc['resolution']!r}")
    origin = doc["origin"]
    if not isinstance(origin, list) or len(origin) != 3:
        raise MapError(f"{where}: origin must be three numbers [x, y, yaw], got {origin!r}")
    origin = [_number(where, f"origin[{i}]", v) for i, v in enumerate(origin)]
    if origin[2] != 0.0:
        raise MapError(f"{where}: origin yaw {origin[2]} is not 0: Nav2's costmaps ignore it (their grid is "
                       "axis-aligned), so the simulator would not match your Nav2; set it to 0")
    negate = doc["negate"]
    if not isinstance(negate, int) or negate not in (0, 1):  # (a bool is an int: true and false pass)
        raise MapError(f"{where}: negate must be 0, 1, true or false, got {negate!r}")
    negate = bool(negate)
    occupied, free = (_number(where, key, doc[key]) for key in ("occupied_thresh", "free_thresh"))
    if not 0.0 <= free < occupied <= 1.0:
        raise MapError(f"{where}: the thresholds must satisfy 0 <= free_thresh < occupied_thresh <= 1, got "
                       f"free_thresh {doc['free_thresh']!r}, occupied_thresh {doc['occupied_thresh']!r}")
    mode = doc.get("mode", "trinary")
    if mode not in MODES:
        raise MapError(f"{where}: mode must be one of {', '.join(MODES)}, got {mode!r}")
    return {"image": image, "resolution": resolution, "origin": origin, "negate": negate,
            "occupied_thresh": occupied, "free_thresh": free, "mode": mode}


def _number(where: str, key: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise MapError(f"{where}: {key} must be a finite number, got {value!r}")
    return float(value)


def _read_bytes(path: Path, where: str, *, missing: str, folder: str) -> bytes:
    """``path``'s bytes, or :class:`MapError`: ``missing`` where there is no file, ``folder`` where it is a folder,
    else ``where`` and why it cannot be read."""
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise MapError(missing) from None
    except IsADirectoryError:
        raise MapError(folder) from None
    except OSError as err:
        raise MapError(f"{where} cannot be read ({err.strerror})") from None


def _read_image(yaml_path: Path, image_path: Path) -> tuple[np.ndarray, np.ndarray | None, bytes]:
    """The image's 8-bit grey and alpha (``None`` where it has none), and its bytes."""
    from PIL import Image, UnidentifiedImageError

    where = f"map {yaml_path}: image {image_path}"
    data = _read_bytes(image_path, where, missing=f"{where} not found", folder=f"{where} is a folder")
    import io

    try:
        with Image.open(io.BytesIO(data)) as img:
            width, height = img.size  # from the header: a map too large is refused before it is decoded
            if width * height > MAX_CELLS:
                raise MapError(f"{where} has {width} x {height} = {width * height:,} pixels, over the "
                               f"{MAX_CELLS:,} a map may have; save it coarser or crop it")
            if width == 0 or height == 0:
                raise MapError(f"{where} is empty ({width} x {height} pixels)")
            gray, alpha = _gray_and_alpha(img)
    except MapError:
        raise
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError) as err:
        raise MapError(f"{where} is not an image Pillow can read ({type(err).__name__}: "
                       f"{str(err).splitlines()[0][:120] if str(err) else 'no detail'})") from None
    return gray, alpha, data


def _gray_and_alpha(img) -> tuple[np.ndarray, np.ndarray | None]:
    if img.mode.startswith("I"):  # a 16-bit PGM: its 8-bit quantum, as ImageMagick gives it
        wide = np.asarray(img, dtype=np.int64)
        return np.clip(np.rint(wide * 255.0 / 65535.0), 0, 255).astype(np.uint8), None
    if img.mode == "P":
        img = img.convert("RGBA")
    if img.mode == "1":
        img = img.convert("L")
    if img.mode == "L":
        return np.asarray(img, dtype=np.uint8), None
    if img.mode == "LA":
        both = np.asarray(img, dtype=np.uint8)
        return both[..., 0].copy(), both[..., 1].copy()
    rgba = np.asarray(img.convert("RGBA"), dtype=np.uint16)
    gray = np.rint(rgba[..., :3].sum(-1) / 3.0).astype(np.uint8)
    alpha = rgba[..., 3].astype(np.uint8) if "A" in img.mode else None
    return gray, alpha
