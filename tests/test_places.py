"""Procedural places (``atrv_warp.world.places``): buildings and yards drawn from a seed, sized for the robot, every
room reached, and read back as map_server reads them."""

from __future__ import annotations

import numpy as np
import pytest

from atrv_warp.sim.maps import distance_field, spawn_cells
from atrv_warp.world import load_map, save_map
from atrv_warp.world.nav2_map import FREE, OCCUPIED
from atrv_warp.world.places import DOOR_WIDTHS, draw_building, draw_yard, place

ROBOTS = {"jackal": (0.416, 0.208, 0.309), "atrvjr": (0.575, 0.2875, 0.4265), "husky": (0.669, 0.3347, 0.5703)}
"""Width [m] and the (inscribed, circumscribed) radii [m] of the shipped robots' footprints
(``RoverSim.footprint_radii``)."""


@pytest.mark.parametrize("draw", [draw_building, draw_yard])
def test_a_place_is_its_seeds_and_every_doorway_fits_the_robot(draw):
    """Same seed, same map; another seed, another; each doorway or gate 1.5-3 robot widths (to a cell) and open:
    the cells across its middle are free, the wall beside it is not."""
    width = ROBOTS["atrvjr"][0]
    site, doors = draw(4, width)
    again, _ = draw(4, width)
    assert np.array_equal(site.cells, again.cells) and not np.array_equal(site.cells, draw(5, width)[0].cells)
    assert doors
    for door in doors:
        assert DOOR_WIDTHS[0] * width - site.resolution <= door.width <= DOOR_WIDTHS[1] * width + site.resolution
        along = np.array([1.0, 0.0]) if door.along_x else np.array([0.0, 1.0])
        middle = np.array([door.x, door.y]) + along * np.linspace(-0.4, 0.4, 9)[:, None] * door.width
        row, col = site.cell_of(middle[:, 0], middle[:, 1])
        assert (site.cells[row, col] == FREE).all(), door
        beyond = np.array([door.x, door.y]) + along * (door.width / 2 + 2 * site.resolution)
        assert site.cells[site.cell_of(*beyond)] == OCCUPIED, door


@pytest.mark.parametrize("draw", [draw_building, draw_yard])
def test_every_room_is_reached_by_every_shipped_robot(draw):
    """Ten places of each kind for each shipped robot: at least 97 % of the cells where the robot may start lie in
    one group it can drive between (furniture may wall off a corner, a doorway never a room)."""
    for name, (width, inscribed, circumscribed) in ROBOTS.items():
        for seed in range(10):
            site, _ = draw(seed, width)
            field = distance_field(site.walls)
            cells, _, count = spawn_cells(field, site.resolution, circumscribed, inscribed)
            assert count.max() >= 0.97 * len(cells), (name, seed)


def test_a_place_saves_as_a_map_and_an_unknown_kind_is_named(tmp_path):
    site = place("building", 1, 0.5)
    assert np.array_equal(load_map(save_map(site, tmp_path / "b.yaml")).cells, site.cells)
    assert abs(site.origin[0] + site.size[0] / 2) < 1e-6 and abs(site.origin[1] + site.size[1] / 2) < 1e-6
    with pytest.raises(ValueError, match="unknown place 'castle'; known: building, yard"):
        place("castle", 0, 0.5)


def test_a_file_named_like_a_place_is_read_as_the_file(tmp_path, monkeypatch):
    """``place_entry``: ``building:2`` is a place unless a file of that name is there, which every command then reads
    as a map (``read_map_files`` reads files now and keeps places for the robot's width)."""
    from atrv_warp.world import OccupancyMap
    from atrv_warp.world.places import place_entry, read_map_files

    monkeypatch.chdir(tmp_path)
    assert place_entry("building:2")["count"] == "2" and place_entry("rooms.yaml") is None
    site = place("yard", 3, 0.5)
    yaml_text = save_map(site, tmp_path / "saved.yaml").read_text()
    (tmp_path / "building:2").write_text(yaml_text)
    assert place_entry("building:2") is None
    read = read_map_files(["building:2", "yard:1", site])
    assert np.array_equal(read[0].cells, site.cells) and read[1] == "yard:1" and isinstance(read[2], OccupancyMap)


def test_procedural_entries_are_drawn_for_the_robot_that_drives_them():
    """``building:2@7`` is seeds 7 and 8, ``yard:1`` seed 0, each named and hashed; a simulator draws them at its
    robot's width (twice its inscribed radius); a bad entry is one line."""
    from atrv_warp.sim import RoverSim
    from atrv_warp.world import MapError, resolve_sites
    from atrv_warp.world.places import building

    sites = resolve_sites(["building:2@7", "yard:1"], 0.5)
    assert [s.name for s in sites] == ["building_7", "building_8", "yard_0"]
    assert np.array_equal(sites[0].cells, building(7, 0.5).cells) and len({s.digest for s in sites}) == 3
    sim = RoverSim(2, maps=["building:1"])
    width = 2 * sim.footprint_radii[0]
    assert sim.maps.maps[0].name == "building_0" and np.array_equal(sim.maps.maps[0].cells, building(0, width).cells)
    with pytest.raises(MapError, match="unknown place 'castle' .*and no such file"):
        resolve_sites(["castle:3"], 0.5)
    with pytest.raises(MapError, match="at least one place"):
        resolve_sites(["yard:0"], 0.5)
    with pytest.raises(MapError, match="map not found: nowhere.yaml"):
        resolve_sites(["nowhere.yaml"], 0.5)
