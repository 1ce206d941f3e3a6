"""Rerun visualisation: the arena, the rovers drawn from the model's own shapes, targets,
trajectories and per-world scalars, to an ``.rrd`` file or a live web viewer on localhost.

Entities (``W`` = world index)::

    arena/ground, arena/grid, arena/walls          static (no ground box or grid on terrain)
    world_W/rover/<link>                           Transform3D per step; shapes static below it
    world_W/terrain                                the world's terrain tile (mesh), when it changes
    world_W/obstacles/{boxes,cylinders}            the world's obstacles, when they change
    world_W/scan/{hits,rays}                       the laser scan's returns and beams, per step
    world_W/target                                 target disc
    world_W/trajectory                             chassis path of the current episode
    plots/world_W/{reward,distance,torque_left,torque_right}   Scalars
    train/<name>                                   training scalars (:class:`RerunLogger`)

Timelines: ``step`` (env steps since the recorder started), ``sim_time`` (seconds), and
``frames`` (training frames, for training scalars and the evaluations recorded during training).

Nothing here runs unless a recorder is created and called: the simulator's step path has no
logging hook, so disabled logging costs nothing.

View a file with ``rerun FILE.rrd``.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Self

import numpy as np
import rerun as rr
from torchrl.record.loggers import Logger

__all__ = ["DEFAULT_WORLDS", "RerunLogger", "RerunRecorder", "ServedViewer"]

DEFAULT_WORLDS = 4
"""Worlds logged when none are named."""

_CHASSIS_COLOR = (190, 30, 30)
_WHEEL_COLOR = (25, 25, 25)
_TARGET_COLOR = (40, 90, 230)
_GROUND_COLOR = (150, 150, 140)
_WALL_COLOR = (120, 120, 130)
_OBSTACLE_COLOR = (200, 140, 40)
_SCAN_COLOR = (230, 30, 200)
_TERRAIN_MAX_SIDE = 121
"""Terrain meshes are drawn from at most this many samples per side."""


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
    t = (h - h.min()) / max(float(np.ptp(h)), 1e-6)
    colors = np.stack([110 + 70 * t, 140 + 50 * t, 90 + 40 * t], axis=-1).reshape(-1, 3).astype(np.uint8)
    return rr.Mesh3D(vertex_positions=vertices, triangle_indices=tris, vertex_colors=colors)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _port_open(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


class ServedViewer:
    """Rerun's web viewer and gRPC proxy, bound to 127.0.0.1 only, as a context manager.

    ``start()`` launches ``rerun --serve-web`` in its own process session and waits until the
    gRPC proxy accepts connections and the web page answers; ``stop()`` signals the whole process
    group (a launcher may exit before the viewer binary it started) and waits until both ports
    are free. The SDK's own ``serve_grpc`` binds every interface, so it is not used.

    Example::

        with ServedViewer() as viewer:
            viewer.connect(rec)            # a rr.RecordingStream
            print(viewer.url)              # open in a browser
    """

    def __init__(self, *, grpc_port: int | None = None, web_port: int | None = None, timeout_s: float = 20.0):
        self.grpc_port = grpc_port or _free_port()
        self.web_port = web_port or _free_port()
        self.timeout_s = timeout_s
        self.process: subprocess.Popen | None = None

    @property
    def grpc_url(self) -> str:
        """The proxy a recording streams to, and the viewer reads from."""
        return f"rerun+http://127.0.0.1:{self.grpc_port}/proxy"

    @property
    def url(self) -> str:
        """The web page to open: the viewer, pointed at the proxy."""
        return f"http://127.0.0.1:{self.web_port}/?url={self.grpc_url.replace('+', '%2B')}"

    def start(self) -> Self:
        # the venv's own script first: a venv's python run without activating the venv has no bin/ on PATH
        exe = shutil.which("rerun", path=str(Path(sys.executable).parent)) or shutil.which("rerun")
        if exe is None:
            raise RuntimeError(f"the 'rerun' command (installed with rerun-sdk) is neither beside {sys.executable} "
                               "nor on PATH")
        for port in (self.grpc_port, self.web_port):
            if _port_open(port):
                raise RuntimeError(f"port {port} on 127.0.0.1 is already in use")
        self.process = subprocess.Popen(
            [exe, "--serve-web", "--bind", "127.0.0.1", "--port", str(self.grpc_port),
             "--web-viewer-port", str(self.web_port)],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        deadline = time.monotonic() + self.timeout_s
        while not self.healthy():
            if self.process.poll() is not None:
                code = self.process.returncode
                self.stop()
                raise RuntimeError(f"rerun viewer server exited with code {code}")
            if time.monotonic() > deadline:
                self.stop()
                raise RuntimeError(f"rerun viewer server did not answer within {self.timeout_s:g} s")
            time.sleep(0.1)
        return self

    def healthy(self) -> bool:
        """The proxy accepts connections and the web page answers HTTP 200."""
        import urllib.request

        if not (_port_open(self.grpc_port) and _port_open(self.web_port)):
            return False
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{self.web_port}/", timeout=2.0) as resp:
                return resp.status == 200
        except OSError:
            return False

    def connect(self, rec: rr.RecordingStream) -> None:
        """Stream ``rec`` to the proxy (the viewer shows it live)."""
        rec.connect_grpc(self.grpc_url)

    def stop(self) -> None:
        """Stop the server's whole process group and wait until its ports are free (idempotent)."""
        proc, self.process = self.process, None
        if proc is None:
            return
        for sig, wait in ((signal.SIGTERM, 5.0), (signal.SIGKILL, None)):
            try:
                os.killpg(proc.pid, sig)
            except ProcessLookupError:
                break
            if wait is not None:
                try:
                    proc.wait(timeout=wait)
                except subprocess.TimeoutExpired:
                    pass
        proc.wait()
        deadline = time.monotonic() + 10.0
        while (_port_open(self.grpc_port) or _port_open(self.web_port)) and time.monotonic() < deadline:
            time.sleep(0.1)

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


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
    """

    def __init__(self, sim, *, path: str | os.PathLike | None = None, serve: bool = False,
                 worlds: Sequence[int] | None = None, real_time: bool = False,
                 recording: rr.RecordingStream | None = None, application_id: str = "atrv_warp"):
        self.sim = sim
        n = sim.num_worlds
        self.worlds = list(range(min(DEFAULT_WORLDS, n))) if worlds is None else [int(w) for w in worlds]
        bad = [w for w in self.worlds if not 0 <= w < n]
        if bad:
            raise ValueError(f"worlds {bad} out of range for {n} worlds")
        self.rec = recording or rr.RecordingStream(application_id)
        self.path = None if path is None else os.fspath(path)
        if self.path is not None:
            self.rec.save(self.path)
        self.viewer = ServedViewer().start() if serve else None
        """The served web viewer, if ``serve``; stopped by :meth:`close`."""
        if self.viewer is not None:
            self.viewer.connect(self.rec)
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
        built = sim.built
        self._bodies = [built.chassis_body, *built.wheel_bodies]
        labels = built.rover_builder.body_label
        self._body_names = [labels[b].split("/")[-1] for b in self._bodies]
        self._log_static()

    # ------------------------------------------------------------------ static scene
    def _log_static(self) -> None:
        rec, arena = self.rec, self.sim.arena_cfg
        rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        h = arena.half_size
        (_, ground_centre, ground_half), *walls = arena.boxes()
        if not self.sim.terrain.enabled:  # on terrain, each world's tile is drawn instead
            rec.log("arena/ground", rr.Boxes3D(centers=[ground_centre], half_sizes=[ground_half],
                                               colors=[_GROUND_COLOR], fill_mode="solid"), static=True)
            ticks = np.arange(-h, h + 0.5, 1.0)
            z = arena.ground_top + 0.002
            lines = [[(x, -h, z), (x, h, z)] for x in ticks] + [[(-h, y, z), (h, y, z)] for y in ticks]
            rec.log("arena/grid", rr.LineStrips3D(lines, colors=[(90, 90, 90)], radii=0.005), static=True)
        rec.log("arena/walls", rr.Boxes3D(centers=[c for _, c, _ in walls], half_sizes=[e for _, _, e in walls],
                                          colors=[_WALL_COLOR],
                                          fill_mode="solid"), static=True)
        # Rover shapes from the model (a different URDF draws right): local frames of each body.
        rb = self.sim.built.rover_builder
        import newton

        for w in self.worlds:
            for body, name in zip(self._bodies, self._body_names):
                for s in range(rb.shape_count):
                    if rb.shape_body[s] != body:
                        continue
                    xf = rb.shape_transform[s]
                    pos, quat = list(xf.p), list(xf.q)
                    scale = rb.shape_scale[s]
                    ent = f"world_{w}/rover/{name}/shape_{s}"
                    if rb.shape_type[s] == newton.GeoType.BOX:
                        rec.log(ent, rr.Boxes3D(centers=[pos], half_sizes=[tuple(scale)],
                                                quaternions=[rr.Quaternion(xyzw=quat)], colors=[_CHASSIS_COLOR],
                                                fill_mode="solid"), static=True)
                    elif rb.shape_type[s] == newton.GeoType.CYLINDER:
                        rec.log(ent, rr.Cylinders3D(lengths=[2 * scale[1]], radii=[scale[0]], centers=[pos],
                                                    quaternions=[rr.Quaternion(xyzw=quat)], colors=[_WHEEL_COLOR],
                                                    fill_mode="solid"), static=True)

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
        obstacles = sim.obstacles
        if not obstacles.slots:
            return
        kind, pose, size = (t[w].detach().cpu().numpy().copy() for t in (obstacles.kind, obstacles.pose, obstacles.size))
        layout = np.concatenate([kind[:, None], pose, size], axis=1)
        if w in self._drawn_obstacles and np.array_equal(self._drawn_obstacles[w], layout):
            return
        self._drawn_obstacles[w] = layout
        base, top = terrain.base - 0.5, obstacles.kernel.top
        zc, hz = 0.5 * (base + top), 0.5 * (top - base)
        boxes, cyls = kind == 1, kind == 2
        yaw = pose[boxes, 2]
        rec.log(f"world_{w}/obstacles/boxes", rr.Boxes3D(
            centers=[(x, y, zc) for x, y in pose[boxes, :2]], half_sizes=[(a, b, hz) for a, b in size[boxes]],
            quaternions=[rr.Quaternion(xyzw=[0.0, 0.0, np.sin(0.5 * t), np.cos(0.5 * t)]) for t in yaw],
            colors=[_OBSTACLE_COLOR], fill_mode="solid"))
        rec.log(f"world_{w}/obstacles/cylinders", rr.Cylinders3D(
            lengths=[2 * hz] * int(cyls.sum()), radii=size[cyls, 0], centers=[(x, y, zc) for x, y in pose[cyls, :2]],
            colors=[_OBSTACLE_COLOR], fill_mode="solid"))

    def _log_scan(self, w: int, scanner, points: np.ndarray) -> None:
        origin = self.sim.frame_pose(scanner.cfg.frame)[w, :3, 3].numpy()
        hit = scanner.ranges[w].detach().cpu().numpy() < scanner.cfg.max_range
        self.rec.log(f"world_{w}/scan/hits", rr.Points3D(points[hit], colors=[_SCAN_COLOR], radii=0.04))
        self.rec.log(f"world_{w}/scan/rays", rr.LineStrips3D([[origin, p] for p in points],
                                                             colors=[(*_SCAN_COLOR, 60)], radii=0.004))

    def log_step(self, *, targets=None, rewards=None, distances=None, reset_mask=None, scanner=None) -> None:
        """Log the current state of the selected worlds at the next ``step``.

        Args:
            targets: (N, 2) target positions [m] (drawn as discs).
            rewards, distances: (N,) or (N, 1) per-world scalars to plot.
            reset_mask: (N,) bool, worlds whose episode restarts here (their trail is cleared).
            scanner: A :class:`~atrv_warp.sim.scanner.LaserScanner` whose last scan is drawn.
        """
        rec, sim = self.rec, self.sim
        rec.set_time("step", sequence=self.step)
        rec.set_time("sim_time", duration=sim.sim_time)
        scan_points = scanner.points(self.worlds) if scanner is not None else None
        bpw = sim.layout.bodies_per_world
        # .numpy() of a CPU array is a view of live simulator memory; Rerun may read it after the next
        # step, so take a copy (one per logged step).
        body_q = sim.state_0.body_q.numpy().reshape(sim.num_worlds, bpw, 7).copy()
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
            self.log_step(targets=base.target.cpu().numpy(), rewards=nxt["reward"].cpu().numpy(),
                          distances=nxt["distance"].cpu().numpy(), scanner=getattr(base, "scanner", None))

        return on_step

    def close(self) -> None:
        """Flush and close the recording (and stop a served viewer)."""
        self.rec.flush()
        if self.path is not None or self.viewer is not None:  # sinks this recorder opened
            self.rec.disconnect()
        if self.viewer is not None:
            self.viewer.stop()


class RerunLogger(Logger):
    """A TorchRL ``Logger`` writing training scalars into a Rerun recording (``frames`` timeline),
    so that they share one recording with the evaluation episodes a :class:`RerunRecorder` logs."""

    def __init__(self, exp_name: str = "train", *, recording: rr.RecordingStream | None = None,
                 path: str | os.PathLike | None = None):
        self._recording, self._path = recording, path
        super().__init__(exp_name=exp_name, log_dir=None if path is None else os.fspath(path))

    @property
    def path(self) -> str | os.PathLike | None:
        """The ``.rrd`` file the scalars are saved to (``None`` when writing to a given recording)."""
        return self._path

    def _create_experiment(self) -> rr.RecordingStream:
        rec = self._recording or rr.RecordingStream("atrv_warp")
        if self._recording is None and self._path is not None:
            rec.save(os.fspath(self._path))
        return rec

    def log_scalar(self, name: str, value: float, step: int | None = None) -> None:
        if step is not None:
            self.experiment.set_time("frames", sequence=int(step))
        self.experiment.log(f"{self.exp_name}/{name}", rr.Scalars(float(value)))

    def log_video(self, name: str, video, step: int | None = None, **kwargs) -> None:
        raise NotImplementedError("RerunLogger logs scalars; record rollouts with RerunRecorder")

    def log_hparams(self, cfg) -> None:
        items = cfg.items() if isinstance(cfg, dict) else vars(cfg).items()
        text = "\n".join(f"- **{k}**: {v}" for k, v in items)
        self.experiment.log(f"{self.exp_name}/hparams", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN),
                            static=True)

    def log_histogram(self, name: str, data, **kwargs) -> None:
        raise NotImplementedError("RerunLogger does not log histograms")

    def __repr__(self) -> str:
        return f"RerunLogger(exp_name={self.exp_name!r}, path={self._path!r})"
