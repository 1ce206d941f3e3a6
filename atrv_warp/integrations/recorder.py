"""Rerun recordings of the simulator: the arena, the rovers drawn from the model's own shapes, targets,
trajectories and per-world scalars, to an ``.rrd`` file or a live web viewer on localhost.

Entities (``W`` = world index)::

    world_W                                        static Transform3D: where the world is drawn (a grid)
    world_W/arena/{ground,grid,walls}              static (no ground box or grid on terrain)
    world_W/rover/<link>                           Transform3D per step; the URDF's visuals static below it
    world_W/terrain                                the world's terrain tile (mesh), when it changes
    world_W/obstacles/{boxes,cylinders}            the world's obstacles, when they change
    world_W/map/{occupied,unknown}                 the world's map's walls (a Nav2 map's cells), when it changes
    world_W/plan                                   the planner's path, per step (an env with a planner)
    world_W/scan/{hits,rays}                       the laser scan's returns and beams, per step
    world_W/target                                 target disc
    world_W/trajectory                             chassis path of the current episode
    plots/world_W/{reward,distance,torque_left,torque_right}   Scalars
    train/<name>                                   training scalars (:class:`~.rerun_logger.RerunLogger`)

Timelines: ``step`` (env steps since the recorder started), ``sim_time`` (seconds), and
``frames`` (training frames, for training scalars and the evaluations recorded during training).

Every recording opens with :func:`~.blueprint.viewer_blueprint`'s layout: the worlds side by side in a
3D view that fills most of the window, their plots in tabs beside it. The rovers are drawn from the
URDF's visual geometry (boxes, cylinders, spheres, mesh files), each wheel with a light cross on its
faces so that it is seen turning.

Nothing here runs unless a recorder is created and called: the simulator's step path has no
logging hook, so disabled logging costs nothing.

View a file with ``rerun FILE.rrd``.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rerun as rr

from atrv_warp.integrations.blueprint import viewer_blueprint, world_offsets
from atrv_warp.integrations.topdown import map_rectangles, terrain_colors
from atrv_warp.integrations.viewer import ServedViewer
from atrv_warp.world.nav2_map import OCCUPIED, UNKNOWN

__all__ = ["DEFAULT_WORLDS", "RECORDING_SUFFIX", "RerunRecorder", "check_recording_path", "rover_visuals"]

DEFAULT_WORLDS = 4
"""Worlds logged when none are named."""
RECORDING_SUFFIX = ".rrd"

_WHEEL_MARK_COLOR = (200, 200, 200)
_TARGET_COLOR = (40, 90, 230)
_GROUND_COLOR = (150, 150, 140)
_WALL_COLOR = (120, 120, 130)
_OBSTACLE_COLOR = (200, 140, 40)
_UNKNOWN_COLOR = (205, 205, 210)
_PLAN_COLOR = (40, 190, 90)
_SCAN_COLOR = (230, 30, 200)
_SCAN_RAY_COLOR = (250, 200, 245)
_TERRAIN_MAX_SIDE = 121
"""Terrain meshes are drawn from at most this many samples per side."""


def check_recording_path(path: str | os.PathLike) -> Path:
    """``path`` as a Rerun recording to write: it must end in ``.rrd``; its folder is created and the
    file opened for writing. A ``ValueError`` in one line naming the path otherwise, before any work."""
    path = Path(path)
    if path.suffix.lower() != RECORDING_SUFFIX:
        raise ValueError(f"recording {path}: must end in {RECORDING_SUFFIX}")
    if path.is_dir():
        raise ValueError(f"recording {path}: is a folder")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "ab"):
            pass
    except OSError as err:
        raise ValueError(f"recording {path}: cannot be written ({err.strerror or err})") from None
    return path


@dataclass(frozen=True)
class Visual:
    """One ``<visual>`` of a URDF link, in the frame of the simulated body it is drawn with."""

    body: str
    """The link whose simulated body carries it (a fixed link's visuals ride on the chassis)."""
    pose: np.ndarray
    """4x4 pose in the body frame."""
    kind: str
    """``box``, ``cylinder``, ``sphere`` or ``mesh``."""
    size: tuple[float, ...]
    """Box: full extents (x, y, z) [m]; cylinder: (radius, length) [m]; sphere: (radius,) [m]; mesh: scale."""
    color: tuple[int, int, int]
    mesh: str = ""
    """A mesh visual's file."""


def rover_visuals(description) -> list[Visual]:
    """The ``<visual>`` geometry of a :class:`~atrv_warp.sim.urdf.RoverDescription`'s URDF, on the bodies
    the simulator moves: the chassis (with the fixed links' visuals, through their frames) and the wheels.
    A mesh file that does not exist is left out, with one line saying so."""
    import yourdfpy

    urdf = yourdfpy.URDF.load(description.path, load_meshes=False, build_scene_graph=False)
    materials = {m.name: m for m in urdf.robot.materials}
    fixed = {f.name: f.transform for f in description.frames}
    wheels = {w.link for w in description.wheels}
    out = []
    for link in urdf.robot.links:
        if link.name == description.chassis or link.name in wheels:
            body, frame = link.name, np.eye(4)
        elif link.name in fixed:
            body, frame = description.chassis, np.asarray(fixed[link.name], dtype=float)
        else:
            continue
        for visual in link.visuals:
            material = visual.material
            if material is not None and material.color is None and material.name in materials:
                material = materials[material.name]
            rgba = material.color.rgba if material is not None and material.color is not None else (0.5, 0.5, 0.5, 1)
            color = tuple(round(255 * float(c)) for c in rgba[:3])
            pose = frame @ (np.eye(4) if visual.origin is None else np.asarray(visual.origin, dtype=float))
            g = visual.geometry
            if g.box is not None:
                out.append(Visual(body, pose, "box", tuple(float(v) for v in g.box.size), color))
            elif g.cylinder is not None:
                out.append(Visual(body, pose, "cylinder", (float(g.cylinder.radius), float(g.cylinder.length)), color))
            elif g.sphere is not None:
                out.append(Visual(body, pose, "sphere", (float(g.sphere.radius),), color))
            elif g.mesh is not None:
                file = Path(description.path).parent / g.mesh.filename.removeprefix("file://")
                if not file.is_file():
                    print(f"rover_visuals: mesh {g.mesh.filename} of link {link.name} not found; not drawn")
                    continue
                scale = tuple(float(v) for v in np.broadcast_to(g.mesh.scale if g.mesh.scale is not None else 1.0, 3))
                out.append(Visual(body, pose, "mesh", scale, color, str(file)))
    return out


def _log_visual(rec: rr.RecordingStream, entity: str, visual: Visual, *, wheel: bool) -> None:
    """A visual as a static shape under ``entity`` (its pose as a static transform); a wheel's cylinder
    gets a light cross through both faces, so that its turning shows."""
    scale = visual.size if visual.kind == "mesh" else None
    rec.log(entity, rr.Transform3D(translation=visual.pose[:3, 3], mat3x3=visual.pose[:3, :3], scale=scale),
            static=True)
    if visual.kind == "box":
        rec.log(entity, rr.Boxes3D(half_sizes=[[0.5 * v for v in visual.size]], colors=[visual.color],
                                   fill_mode="solid"), static=True)
    elif visual.kind == "cylinder":
        r, length = visual.size
        rec.log(entity, rr.Cylinders3D(lengths=[length], radii=[r], colors=[visual.color], fill_mode="solid"),
                static=True)
        if wheel:  # the cylinder's axis is its z: the cross lies across its faces
            t, half = 0.1 * r, 0.5 * length + 0.002
            rec.log(f"{entity}/mark", rr.Boxes3D(half_sizes=[(0.85 * r, t, half), (t, 0.85 * r, half)],
                                                 colors=[_WHEEL_MARK_COLOR], fill_mode="solid"), static=True)
    elif visual.kind == "sphere":
        rec.log(entity, rr.Ellipsoids3D(half_sizes=[[visual.size[0]] * 3], colors=[visual.color],
                                        fill_mode="solid"), static=True)
    else:
        rec.log(entity, rr.Asset3D(path=visual.mesh, albedo_factor=visual.color), static=True)


def _terrain_mesh(heights: np.ndarray, half: float, base: float) -> rr.Mesh3D:
    """A tile's height grid as a triangle mesh coloured by height."""
    step = max(1, int(np.ceil((heights.shape[0] - 1) / (_TERRAIN_MAX_SIDE - 1))))
    h = heights[::step, ::step]
    n = h.shape[0]
    axis = np.linspace(-half, half, heights.shape[0])[::step]
    x, y = np.meshgrid(axis, axis, indexing="ij")
    vertices = np.stack([x, y, base + h], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).reshape(-1)
    tris = np.concatenate([np.stack([a, a + n, a + n + 1], 1), np.stack([a, a + n + 1, a + 1], 1)])
    colors = terrain_colors(h).reshape(-1, 3)
    return rr.Mesh3D(vertex_positions=vertices, triangle_indices=tris, vertex_colors=colors)


class RerunRecorder:
    """Logs selected worlds of a :class:`~atrv_warp.sim.RoverSim` (or an env's ``.sim``) to Rerun.

    Args:
        sim: The simulator to read state and shapes from.
        path: Write an ``.rrd`` file here.
        serve: Also serve a live web viewer on 127.0.0.1 (the URL is printed and kept in ``url``).
        worlds: World indices to log (default: the first ``DEFAULT_WORLDS``).
        real_time: Sleep so that logged ``sim_time`` advances no faster than wall time.
        recording: Log into an existing ``RecordingStream`` instead of creating one.
        application_id: Rerun application id of a new recording.
        training: The recording also holds training scalars (``/train``): the layout gets a tab for them.

    Raises:
        ValueError: ``path`` does not end in ``.rrd`` or cannot be written (one line naming it), before
            anything is logged.
    """

    def __init__(self, sim, *, path: str | os.PathLike | None = None, serve: bool = False,
                 worlds: Sequence[int] | None = None, real_time: bool = False,
                 recording: rr.RecordingStream | None = None, application_id: str = "atrv_warp",
                 training: bool = False):
        self.sim = sim
        n = sim.num_worlds
        self.worlds = list(range(min(DEFAULT_WORLDS, n))) if worlds is None else [int(w) for w in worlds]
        bad = [w for w in self.worlds if not 0 <= w < n]
        if bad:
            raise ValueError(f"worlds {bad} out of range for {n} worlds")
        self.path = None if path is None else os.fspath(check_recording_path(path))
        self.rec = recording or rr.RecordingStream(application_id)
        self.viewer = ServedViewer().start() if serve else None
        """The served web viewer, if ``serve``; stopped by :meth:`close`."""
        sinks = ([rr.FileSink(self.path)] if self.path is not None else []) + \
            ([rr.GrpcSink(self.viewer.grpc_url)] if self.viewer is not None else [])
        if sinks:  # a file and a served viewer both get every row
            self.rec.set_sinks(*sinks)
        self.blueprint = viewer_blueprint(self.worlds, sim.arena_cfg.half_size, training=training)
        """The layout the recording opens with (:func:`~.blueprint.viewer_blueprint`)."""
        self.rec.send_blueprint(self.blueprint)
        self.offsets = world_offsets(self.worlds, sim.arena_cfg.half_size)
        """Where each recorded world is drawn [m] (:func:`~.blueprint.world_offsets`)."""
        self.url = self.viewer.url if self.viewer is not None else None
        if self.url:
            print(f"Rerun web viewer (localhost only): {self.url}", flush=True)
        self.real_time = real_time
        self.step = 0
        self._wall0 = None
        self._sim0 = sim.sim_time
        self._trails: dict[int, list[np.ndarray]] = {w: [] for w in self.worlds}
        self._drawn_tile: dict[int, int] = {}
        self._drawn_obstacles: dict[int, np.ndarray] = {}
        self._drawn_map: dict[int, int] = {}
        layout = sim.buffers.layout
        # world 0's bodies: the chassis, then the wheels (a rover's fixed frames are lumped into the chassis)
        self._bodies = [layout.chassis_body, *(b for b in range(layout.bodies_per_world) if b != layout.chassis_body)]
        labels = sim.model.body_label
        self._body_names = [labels[b].split("/")[-1] for b in self._bodies]
        self._log_static()

    # ------------------------------------------------------------------ static scene
    def _log_static(self) -> None:
        rec, arena = self.rec, self.sim.arena_cfg
        rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        h = arena.half_size
        (_, ground_centre, ground_half), *walls = arena.boxes()
        ticks = np.arange(-h, h + 0.5, 1.0)
        z = arena.ground_top + 0.002
        grid = [[(x, -h, z), (x, h, z)] for x in ticks] + [[(-h, y, z), (h, y, z)] for y in ticks]
        visuals = rover_visuals(self.sim.description)
        wheels = {w.link for w in self.sim.description.wheels}
        for w in self.worlds:
            rec.log(f"world_{w}", rr.Transform3D(translation=self.offsets[w]), static=True)
            if not self.sim.terrain.enabled:  # on terrain, each world's tile is drawn instead
                rec.log(f"world_{w}/arena/ground", rr.Boxes3D(centers=[ground_centre], half_sizes=[ground_half],
                                                              colors=[_GROUND_COLOR], fill_mode="solid"), static=True)
                rec.log(f"world_{w}/arena/grid", rr.LineStrips3D(grid, colors=[(90, 90, 90)], radii=0.005), static=True)
            if walls:  # an arena may have none (ArenaConfig.walls)
                rec.log(f"world_{w}/arena/walls", rr.Boxes3D(centers=[c for _, c, _ in walls],
                                                             half_sizes=[e for _, _, e in walls],
                                                             colors=[_WALL_COLOR], fill_mode="solid"), static=True)
            # every world's rover is the same: the URDF's visuals in the frame of their body
            for i, visual in enumerate(visuals):
                _log_visual(rec, f"world_{w}/rover/{visual.body}/visual_{i}", visual, wheel=visual.body in wheels)

    # ------------------------------------------------------------------ per step
    def _log_scene(self, w: int) -> None:
        """The world's terrain tile and obstacles, logged again only when they change (a new episode)."""
        rec, sim = self.rec, self.sim
        terrain = sim.terrain
        if terrain.enabled:
            tile = int(terrain.tile[w])
            if self._drawn_tile.get(w) != tile:
                self._drawn_tile[w] = tile
                rec.log(f"world_{w}/terrain", _terrain_mesh(terrain.grid.heights[tile], terrain.grid.half_size,
                                                            terrain.base))
        self._log_map(w)
        obstacles = sim.obstacles
        if not obstacles.slots:
            return
        kind, pose, size, tops = (t[w].detach().cpu().numpy().copy()
                                  for t in (obstacles.kind, obstacles.pose, obstacles.size, obstacles.height))
        layout = np.concatenate([kind[:, None], pose, size, tops[:, None]], axis=1)
        if w in self._drawn_obstacles and np.array_equal(self._drawn_obstacles[w], layout):
            return
        self._drawn_obstacles[w] = layout
        base = terrain.base - 0.5
        zc, hz = 0.5 * (base + tops), 0.5 * (tops - base)  # each obstacle from below the ground to its own top
        boxes, cyls = kind == 1, kind == 2
        yaw = pose[boxes, 2]
        rec.log(f"world_{w}/obstacles/boxes", rr.Boxes3D(
            centers=[(x, y, z) for (x, y), z in zip(pose[boxes, :2], zc[boxes], strict=True)],
            half_sizes=[(a, b, h) for (a, b), h in zip(size[boxes], hz[boxes], strict=True)],
            quaternions=[rr.Quaternion(xyzw=[0.0, 0.0, np.sin(0.5 * t), np.cos(0.5 * t)]) for t in yaw],
            colors=[_OBSTACLE_COLOR], fill_mode="solid"))
        rec.log(f"world_{w}/obstacles/cylinders", rr.Cylinders3D(
            lengths=2 * hz[cyls], radii=size[cyls, 0],
            centers=[(x, y, z) for (x, y), z in zip(pose[cyls, :2], zc[cyls], strict=True)],
            colors=[_OBSTACLE_COLOR], fill_mode="solid"))

    def _log_map(self, w: int) -> None:
        """The world's map, as boxes standing from the ground to the walls' top, when the world has one and it is
        not drawn yet: occupied cells dark, unknown ones pale (both are walls to the rover)."""
        grids = self.sim.maps
        m = int(grids.world_map[w]) if grids.maps else -1
        if m < 0 or self._drawn_map.get(w) == m:
            return
        self._drawn_map[w] = m
        site, base = grids.maps[m], self.sim.arena_cfg.ground_top
        top = grids.struct.top
        for name, mask, color in (("occupied", site.cells == OCCUPIED, _WALL_COLOR),
                                  ("unknown", site.cells == UNKNOWN, _UNKNOWN_COLOR)):
            rects = map_rectangles(mask, site.resolution, site.origin)
            self.rec.log(f"world_{w}/map/{name}", rr.Boxes3D(
                centers=[(0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.5 * (base + top)) for x0, y0, x1, y1 in rects],
                half_sizes=[(0.5 * (x1 - x0), 0.5 * (y1 - y0), 0.5 * (top - base)) for x0, y0, x1, y1 in rects],
                colors=[color], fill_mode="solid"))

    def _log_scan(self, w: int, scanner, points: np.ndarray) -> None:
        origin = self.sim.frame_pose(scanner.frame)[w, :3, 3].numpy()
        hit = scanner.ranges[w].detach().cpu().numpy() < scanner.cfg.max_range
        self.rec.log(f"world_{w}/scan/hits", rr.Points3D(points[hit], colors=[_SCAN_COLOR], radii=0.04))
        self.rec.log(f"world_{w}/scan/rays", rr.LineStrips3D([[origin, p] for p in points],
                                                             colors=[(*_SCAN_RAY_COLOR, 50)], radii=0.003))

    def log_step(self, *, targets=None, rewards=None, distances=None, reset_mask=None, scanner=None,
                 paths=None) -> None:
        """Log the current state of the selected worlds at the next ``step``.

        Args:
            targets: (N, 2) target positions [m] (drawn as discs).
            rewards: (N,) or (N, 1) per-world rewards to plot.
            distances: (N,) or (N, 1) per-world distances to the target [m] to plot.
            reset_mask: (N,) bool, worlds whose episode restarts here (their trail is cleared).
            scanner: A :class:`~atrv_warp.sim.scanner.LaserScanner` whose last scan is drawn.
            paths: (path (N, P, 2) [m], path_length (N,)): each world's plan (``RoverEnv.path``, ``.path_length``).
        """
        rec, sim = self.rec, self.sim
        rec.set_time("step", sequence=self.step)
        rec.set_time("sim_time", duration=sim.sim_time)
        scan_points = scanner.points(self.worlds) if scanner is not None else None
        bpw = sim.buffers.layout.bodies_per_world
        # .numpy() of a CPU array is a view of live simulator memory; Rerun may read it after the next
        # step, so take a copy (one per logged step).
        body_q = sim.buffers.body_q.numpy().reshape(sim.num_worlds, bpw, 7).copy()
        torques = sim.wheel_torque.detach().cpu().numpy()
        sides = np.array([w.side for w in sim.description.wheels])
        for i, w in enumerate(self.worlds):
            self._log_scene(w)
            if scan_points is not None:
                self._log_scan(w, scanner, scan_points[i])
            for body, name in zip(self._bodies, self._body_names):
                q = body_q[w, body]
                rec.log(f"world_{w}/rover/{name}", rr.Transform3D(translation=q[:3], quaternion=rr.Quaternion(xyzw=q[3:])))
            if reset_mask is not None and bool(reset_mask[w]):
                self._trails[w] = []
            self._trails[w].append(body_q[w, sim.layout.chassis_body, :3].copy())
            rec.log(f"world_{w}/trajectory", rr.LineStrips3D([np.array(self._trails[w])], colors=[(230, 160, 20)],
                                                             radii=0.02))
            if paths is not None:
                points, count = paths[0][w][:int(paths[1][w])].detach().cpu().numpy(), int(paths[1][w])
                z = np.full((count, 1), sim.arena_cfg.ground_top + 0.05)
                rec.log(f"world_{w}/plan", rr.LineStrips3D([np.concatenate([points, z], axis=1)] if count else [],
                                                           colors=[_PLAN_COLOR], radii=0.03))
            if targets is not None:
                tx, ty = (float(v) for v in targets[w][:2])
                rec.log(f"world_{w}/target", rr.Cylinders3D(lengths=[0.02], radii=[self.sim.arena_cfg.target_radius],
                                                            centers=[(tx, ty, sim.arena_cfg.ground_top + 0.01)],
                                                            colors=[_TARGET_COLOR], fill_mode="solid"))
            plots = f"plots/world_{w}"
            if rewards is not None:
                rec.log(f"{plots}/reward", rr.Scalars(float(np.asarray(rewards[w]).reshape(-1)[0])))
            if distances is not None:
                rec.log(f"{plots}/distance", rr.Scalars(float(np.asarray(distances[w]).reshape(-1)[0])))
            rec.log(f"{plots}/torque_left", rr.Scalars(float(torques[w][sides == 0].mean())))
            rec.log(f"{plots}/torque_right", rr.Scalars(float(torques[w][sides == 1].mean())))
        self.step += 1
        if self.real_time:
            now = time.monotonic()
            if self._wall0 is None:
                self._wall0, self._sim0 = now, sim.sim_time
            ahead = (sim.sim_time - self._sim0) - (now - self._wall0)
            if ahead > 0:
                time.sleep(ahead)

    def env_hook(self):
        """An ``on_step(env, tensordict)`` callback for :func:`atrv_warp.task.evaluation.evaluate`."""

        def on_step(env, td):
            base = getattr(env, "base_env", env)
            nxt = td["next"]
            planner = getattr(base, "planner", None)
            self.log_step(targets=base.target.cpu().numpy(), rewards=nxt["reward"].cpu().numpy(),
                          distances=nxt["distance"].cpu().numpy(), scanner=getattr(base, "scanner", None),
                          paths=(base.path, base.path_length) if planner is not None else None)

        return on_step

    def close(self) -> None:
        """Flush and close the recording (and stop a served viewer)."""
        self.rec.flush()
        if self.path is not None or self.viewer is not None:  # sinks this recorder opened
            self.rec.disconnect()
        if self.viewer is not None:
            self.viewer.stop()
