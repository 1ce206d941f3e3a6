"""A Nav2 ``map_server`` map read as ``map_server`` reads it (``atrv_warp.world.nav2_map``): the pixels at the
thresholds with both threshold pairs ``map_saver`` writes, negate, alpha, the scale and raw modes, the rows' order,
and every malformed map refused in one line naming the problem."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from atrv_warp.world import MapError, OccupancyMap, load_map
from atrv_warp.world.nav2_map import FREE, MAX_CELLS, OCCUPIED, UNKNOWN, cells_from_pixels

OLD_SAVER = {"free_thresh": 0.25, "occupied_thresh": 0.65}  # map_saver's defaults (Humble's and Jazzy's node)
NEW_SAVER = {"free_thresh": 0.196, "occupied_thresh": 0.65}  # Nav2's docs' and newer maps'


def write_map(folder, pixels, *, image_mode="L", name="site", image_name=None, **keys):
    """A map's image (``pixels``: rows from the top, as the image stores them) and its YAML; returns the YAML's
    path. ``keys`` override the YAML's values (``None`` leaves a key out)."""
    image_name = image_name or f"{name}.{'pgm' if image_mode == 'L' else 'png'}"
    Image.fromarray(np.asarray(pixels, dtype=np.uint8), mode=image_mode).save(folder / image_name)
    meta = {"image": image_name, "mode": "trinary", "resolution": 0.05, "origin": "[-1.0, -2.0, 0.0]", "negate": 0,
            **NEW_SAVER, **keys}
    text = "".join(f"{k}: {v}\n" for k, v in meta.items() if v is not None)
    (folder / f"{name}.yaml").write_text(text)
    return folder / f"{name}.yaml"


def test_the_pixels_map_saver_writes_read_with_both_threshold_pairs(tmp_path):
    """map_saver writes 0 (occupied), 254 (free) and 205 (unknown). With 0.196/0.65 the three read back as written;
    with the older 0.25/0.65 an unknown pixel (occupancy 0.196) reads as free, as map_server reads it."""
    row = [0, 205, 254, 255]
    new = load_map(write_map(tmp_path, [row], name="new", **NEW_SAVER))
    old = load_map(write_map(tmp_path, [row], name="old", **OLD_SAVER))
    assert new.cells.tolist() == [[OCCUPIED, UNKNOWN, FREE, FREE]]
    assert old.cells.tolist() == [[OCCUPIED, FREE, FREE, FREE]]
    assert new.walls.tolist() == [[True, True, False, False]]  # unknown is a wall for the laser and the chassis


def test_the_thresholds_include_their_boundary_in_float32():
    """``>= occupied_thresh`` and ``<= free_thresh`` (Jazzy's rule; Humble's is strict), compared in float32:
    occupancy 1 - 89/255 = 0.6510 is occupied at 0.65 and 90 (0.6471) is not; a threshold exactly on a pixel's
    float32 occupancy counts it (Humble would not)."""
    gray = np.array([[89, 90, 204, 205, 206]], dtype=np.uint8)
    assert cells_from_pixels(gray, None, occupied_thresh=0.65, free_thresh=0.196)[0].tolist() == [
        OCCUPIED, UNKNOWN, UNKNOWN, UNKNOWN, FREE]
    exact = float(np.float32(1.0) - np.float32(205) / np.float32(255.0))  # 205's occupancy, 0.19607842
    assert cells_from_pixels(gray, None, occupied_thresh=0.65, free_thresh=exact)[0].tolist() == [
        OCCUPIED, UNKNOWN, UNKNOWN, FREE, FREE]
    at_89 = float(np.float32(1.0) - np.float32(89) / np.float32(255.0))
    assert cells_from_pixels(gray, None, occupied_thresh=at_89, free_thresh=0.196)[0, 0] == OCCUPIED


def test_negate_reads_dark_as_free(tmp_path):
    for negate in ("1", "true"):
        site = load_map(write_map(tmp_path, [[0, 254]], name=f"n{negate}", negate=negate))
        assert site.cells.tolist() == [[FREE, OCCUPIED]]


def test_a_transparent_pixel_is_unknown_and_a_colour_pixel_is_the_mean_of_its_channels(tmp_path):
    la = np.array([[[254, 255], [254, 254], [0, 255]]], dtype=np.uint8)
    site = load_map(write_map(tmp_path, la, image_mode="LA", name="alpha"))
    assert site.cells.tolist() == [[FREE, UNKNOWN, OCCUPIED]]  # alpha 254: unknown (Jazzy), whatever its grey
    rgb = np.array([[[254, 254, 254], [0, 0, 30], [255, 255, 0]]], dtype=np.uint8)  # mean 254, 10, 170
    site = load_map(write_map(tmp_path, rgb, image_mode="RGB", name="rgb"))
    assert site.cells.tolist() == [[FREE, OCCUPIED, UNKNOWN]]


def test_scale_and_raw_modes(tmp_path):
    """scale: between the thresholds, the occupancy scaled from free (0) to occupied (100), rounded half up; raw: the
    value where it is 0 to 100, else unknown."""
    scale = load_map(write_map(tmp_path, [[0, 128, 254]], name="scale", mode="scale"))
    occupancy = np.float32(1.0) - np.float32(128) / np.float32(255.0)
    expected = int(np.floor((occupancy - np.float32(0.196)) / np.float32(0.65 - 0.196) * 100 + 0.5))
    assert scale.cells.tolist() == [[OCCUPIED, expected, FREE]] and 0 < expected < 100
    raw = load_map(write_map(tmp_path, [[0, 50, 100, 101, 205, 255]], name="raw", mode="raw"))
    assert raw.cells.tolist() == [[0, 50, 100, UNKNOWN, UNKNOWN, UNKNOWN]]
    assert raw.walls.tolist() == [[False, False, True, True, True, True]]  # 50: free space (trinary_costmap)


def test_the_image_top_row_is_the_maps_last_and_cells_are_placed_from_the_origin(tmp_path):
    pixels = [[0, 254, 254],  # the image's top row: y from 0.05 m above the origin
              [254, 254, 254]]
    site = load_map(write_map(tmp_path, pixels))
    assert site.cells.tolist() == [[FREE, FREE, FREE], [OCCUPIED, FREE, FREE]]
    assert site.shape == (2, 3) and site.size == pytest.approx((0.15, 0.10)) and site.origin == (-1.0, -2.0)
    row, col = site.cell_of(-1.0 + 0.025, -2.0 + 0.075)  # the occupied cell's centre
    assert (int(row), int(col)) == (1, 0) and site.cells[row, col] == OCCUPIED
    assert np.allclose(site.centre_of(1, 0), (-0.975, -1.925))
    assert site.name == "site" and len(site.digest) == 64


def test_the_image_is_found_beside_the_yaml_or_by_its_absolute_path(tmp_path):
    (tmp_path / "maps").mkdir()
    yaml_path = write_map(tmp_path / "maps", [[254, 0]])
    elsewhere = tmp_path / "copy.yaml"
    elsewhere.write_text(yaml_path.read_text().replace("image: site.pgm", f"image: {tmp_path / 'maps' / 'site.pgm'}"))
    assert load_map(elsewhere).cells.tolist() == load_map(yaml_path).cells.tolist() == [[FREE, OCCUPIED]]
    assert load_map(elsewhere).digest != load_map(yaml_path).digest  # another YAML: another record


def test_a_16_bit_pgm_reads_as_its_8_bit_quantum(tmp_path):
    values = [0, 205 * 257, 254 * 257]
    header = b"P5\n3 1\n65535\n"
    (tmp_path / "deep.pgm").write_bytes(header + b"".join(v.to_bytes(2, "big") for v in values))
    (tmp_path / "deep.yaml").write_text("image: deep.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 0\n"
                                        "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    assert load_map(tmp_path / "deep.yaml").cells.tolist() == [[OCCUPIED, UNKNOWN, FREE]]


@pytest.mark.parametrize(("change", "message"), [
    ({"image": "gone.pgm"}, "gone.pgm not found"),
    ({"image": '""'}, "image must be the image file's name"),
    ({"resolution": "0"}, "resolution must be > 0"),
    ({"resolution": "abc"}, "resolution must be a finite number, got 'abc'"),
    ({"resolution": ".nan"}, "resolution must be a finite number"),
    ({"origin": "[1.0, 2.0]"}, "origin must be three numbers [x, y, yaw], got [1.0, 2.0]"),
    ({"origin": "[0, 0, x]"}, "origin[2] must be a finite number, got 'x'"),
    ({"origin": "[0, 0, 0.5]"}, "origin yaw 0.5 is not 0: Nav2's costmaps ignore it"),
    ({"negate": "2"}, "negate must be 0, 1, true or false, got 2"),
    ({"free_thresh": "0.7"}, "0 <= free_thresh < occupied_thresh <= 1"),
    ({"occupied_thresh": None}, "missing occupied_thresh"),
    ({"mode": "fuzzy"}, "mode must be one of trinary, scale, raw, got 'fuzzy'"),
])
def test_a_malformed_yaml_is_one_line_naming_the_problem(tmp_path, change, message):
    with pytest.raises(MapError) as err:
        load_map(write_map(tmp_path, [[254, 0]], **change))
    assert message in str(err.value) and "\n" not in str(err.value) and "site.yaml" in str(err.value)


def test_a_file_that_is_not_a_map_is_one_line(tmp_path):
    (tmp_path / "text.yaml").write_text("just words\n")
    (tmp_path / "broken.yaml").write_text("image: [unclosed\n")
    (tmp_path / "object.yaml").write_text("!!python/object/apply:os.system ['true']\n")
    write_map(tmp_path, [[254]], name="notimage")
    (tmp_path / "notimage.pgm").write_text("P5 this is not an image")
    write_map(tmp_path, [[0, 0]], name="walls")
    big = tmp_path / "big.pgm"  # a header that claims more pixels than a map may have: refused before decoding
    big.write_bytes(b"P5\n5000 5000\n255\n" + bytes(10))
    (tmp_path / "big.yaml").write_text("image: big.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
                                       "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    cases = {"missing.yaml": "map not found", "text.yaml": "not a map_server YAML",
             "broken.yaml": "not valid YAML at line", "object.yaml": "not valid YAML",
             "notimage.yaml": "is not an image Pillow can read", "walls.yaml": "no free cell in walls.pgm",
             "big.yaml": f"5000 x 5000 = 25,000,000 pixels, over the {MAX_CELLS:,} a map may have", ".": "is a folder"}
    for name, message in cases.items():
        with pytest.raises(MapError) as err:
            load_map(tmp_path / name)
        assert message in str(err.value) and "\n" not in str(err.value), (name, str(err.value))


def test_a_map_can_be_built_from_cells():
    site = OccupancyMap(cells=np.zeros((4, 5), dtype=np.int8), resolution=0.1, origin=(0.0, 0.0))
    assert site.name == "map" and site.size == pytest.approx((0.5, 0.4)) and not site.walls.any()
