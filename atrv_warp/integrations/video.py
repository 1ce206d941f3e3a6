"""Evaluation videos: a few episodes of an evaluation, drawn top down side by side, as an MP4.

:class:`EvalVideo` records the first episode of a few worlds while :func:`~atrv_warp.task.evaluation.evaluate`
runs (its :meth:`~EvalVideo.env_hook`: a few numbers per step and world, nothing drawn), then
:meth:`~EvalVideo.write` draws every step with Pillow and encodes the frames with PyAV (FFmpeg's
H.264, ``yuv420p``, which every player and browser plays). Each panel shows the arena and its walls,
the world's terrain shaded by height, its obstacles, the target disc, the path so far, the laser
scan (on a task with a scanner) and the rover's footprint; the caption gives the world, the time
and, once the episode ended, why.

:func:`log_video` sends a written video to a TorchRL logger that takes one: TensorBoard (an
animated GIF, encoded in the same pass), W&B (the MP4), MLflow (the MP4 as an artifact) and Rerun
(the MP4 as a video asset). The CSV logger takes none: the file in the run folder is the video.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from atrv_warp.integrations.topdown import box_corners, map_rectangles, obstacle_shapes, terrain_colors
from atrv_warp.world.nav2_map import OCCUPIED, UNKNOWN

__all__ = ["VIDEO_SUFFIX", "EvalVideo", "VideoFile", "check_video_path", "log_video", "read_video"]

VIDEO_SUFFIX = ".mp4"
_BACKGROUND = (255, 255, 255)
_GROUND = (150, 150, 140)
_GRID = (135, 135, 126)
_WALL = (70, 70, 80)
_OBSTACLE = (55, 55, 55)
_UNKNOWN = (190, 190, 195)
_PLAN = (40, 190, 90)
_TARGET = (120, 160, 240)
_PATH = (230, 140, 20)
_ROVER = (200, 30, 30)
_SCAN = (215, 40, 190)
_RAY = (250, 215, 245)
_RAY_ALPHA = 90
"""Opacity of a drawn beam [0-255]."""
_TEXT = (20, 20, 20)


@dataclass(frozen=True)
class VideoFile:
    """A written video: where, how many frames of what size, and what it cost."""

    path: Path
    frames: int
    width: int
    height: int
    fps: float
    render_s: float
    """Wall time of drawing and encoding [s] (the recording during the evaluation not included)."""
    gif: bytes | None = None
    """The same video as an animated GIF at half size (TensorBoard shows GIFs), if asked for."""


def check_video_path(path: str | Path) -> Path:
    """``path`` as a video file to write: it must end in ``.mp4``; its folder is created. A ``ValueError``
    in one line otherwise, before any work."""
    path = Path(path)
    if path.suffix.lower() != VIDEO_SUFFIX:
        raise ValueError(f"video {path}: must end in {VIDEO_SUFFIX}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ValueError(f"video {path}: cannot create its folder {path.parent} ({err.strerror or err})") from None
    if path.is_dir():
        raise ValueError(f"video {path}: is a folder")
    return path


class EvalVideo:
    """The first episode of ``episodes`` worlds of an evaluation, drawn top down.

    Args:
        env: The :class:`~atrv_warp.task.env.RoverEnv` the evaluation steps (or a transformed env
            around one).
        episodes: Worlds recorded: the first ones, drawn in a grid of two columns.
        panel: Side of one world's panel [px] (even).
        every: Draw every ``every``-th step (the video still plays in real time).
        follow: Side of the square of ground each panel shows, centred on its rover [m] (a camera that
            follows it, so that the rover is tens of pixels long); ``None``: the whole arena.
    """

    def __init__(self, env, *, episodes: int = 4, panel: int = 256, every: int = 2, follow: float | None = None):
        self.env = getattr(env, "base_env", env)
        n = self.env.sim.num_worlds
        if episodes < 1 or panel < 16 or every < 1:
            raise ValueError(f"EvalVideo needs episodes >= 1, panel >= 16 and every >= 1; got {episodes}, {panel}, {every}")
        if follow is not None and not follow > 0:
            raise ValueError(f"EvalVideo follow must be a positive side in metres, got {follow}")
        self.worlds = list(range(min(episodes, n)))
        self.panel = panel + panel % 2
        self.every = every
        self.follow = follow
        arena = self.env.sim.arena_cfg.half_size + 0.5
        self.scale = self.panel / (follow if follow is not None else 2 * arena)
        """Pixels per metre [px/m]."""
        self.view = arena + (0.5 * follow if follow is not None else 0.0)
        """Half side of the drawn background [m]: the arena, and with ``follow`` half a panel of margin."""
        self.size = self.panel if follow is None else 2 * int(np.ceil(self.view * self.scale))
        """Side of each world's background image [px] (a panel's crop of it, when following)."""
        self.step_dt = self.env.sim.sim_cfg.step_dt
        chassis = self.env.sim.description.chassis_box
        self.footprint = tuple(chassis[1][:2]) if chassis is not None else (0.3, 0.2)
        self.clear()

    def clear(self) -> None:
        """Forget what was recorded (a new evaluation starts)."""
        k = len(self.worlds)
        self.scene: dict | None = None
        self.poses: list[np.ndarray] = []
        self.scans: list[tuple[np.ndarray, np.ndarray]] = []
        self.ended = np.zeros(k, dtype=bool)
        self.end_step = np.zeros(k, dtype=np.int64)
        self.reason = [""] * k

    def env_hook(self):
        """An ``on_step(env, tensordict)`` callback for :func:`~atrv_warp.task.evaluation.evaluate` that
        records this evaluation (what an earlier one recorded is cleared)."""
        self.clear()
        from atrv_warp.task.spec import END_REASONS

        sim, worlds = self.env.sim, self.worlds

        def on_step(env, td):
            if self.ended.all():
                return
            if self.scene is None:
                self.scene = self._scene()
            pose = np.concatenate([sim.root_pose[worlds, :2].cpu().numpy(), sim.rpy[worlds, 2:3].cpu().numpy()], -1)
            if self.poses:  # a world whose episode ended stays where it ended
                pose = np.where(self.ended[:, None], self.poses[-1], pose)
            self.poses.append(pose.astype(np.float32))
            scanner = self.env.scanner
            if scanner is not None:
                hits = scanner.ranges[worlds].cpu().numpy() < scanner.cfg.max_range
                self.scans.append((scanner.points(worlds)[..., :2].astype(np.float32), hits))
            nxt = td["next"]
            done = nxt["done"].reshape(-1)[worlds].cpu().numpy()
            reason = nxt["end_reason"].reshape(-1)[worlds].cpu().numpy()
            for i in np.flatnonzero(done & ~self.ended):
                self.reason[i], self.end_step[i] = END_REASONS[int(reason[i])], len(self.poses) - 1
            self.ended |= done

        return on_step

    def _scene(self) -> dict:
        """What stays put during an episode: targets, terrain tiles and obstacles of the recorded worlds."""
        sim, worlds = self.env.sim, self.worlds
        scene = {"target": self.env.target[worlds].cpu().numpy().copy(), "heights": [None] * len(worlds),
                 "obstacles": [[] for _ in worlds]}
        terrain = sim.terrain
        if terrain.enabled:
            scene["heights"] = [terrain.grid.heights[int(terrain.tile[w])] for w in worlds]
            scene["terrain_half"] = terrain.grid.half_size
        obstacles = sim.obstacles
        if obstacles.slots:
            kind, pose, size = (t[worlds].cpu().numpy() for t in (obstacles.kind, obstacles.pose, obstacles.size))
            scene["obstacles"] = [list(obstacle_shapes(kind[i], pose[i], size[i])) for i in range(len(worlds))]
        scene["map"] = [None] * len(worlds)  # each world's map's (occupied, unknown) rectangles
        for i, w in enumerate(worlds):
            m = int(sim.maps.world_map[w]) if sim.maps.maps else -1
            if m >= 0:
                site = sim.maps.maps[m]
                scene["map"][i] = tuple(map_rectangles(site.cells == value, site.resolution, site.origin)
                                        for value in (OCCUPIED, UNKNOWN))
        planner = getattr(self.env, "planner", None)  # the plan each episode started with
        scene["plan"] = [self.env.path[w, :int(self.env.path_length[w])].cpu().numpy().copy() if planner else None
                         for w in worlds]
        return scene

    # ------------------------------------------------------------------ drawing
    @property
    def steps(self) -> int:
        """Steps recorded (until the last recorded world's episode ended)."""
        return len(self.poses)

    def _to_px(self, xy: np.ndarray) -> np.ndarray:
        """World x, y [m] (..., 2) to background pixels (y down)."""
        view, s = self.view, self.scale
        return np.stack([(xy[..., 0] + view) * s, (view - xy[..., 1]) * s], axis=-1)

    def _background(self, i: int):
        """World ``i``'s panel without the rover: ground or terrain, grid, walls, obstacles, target."""
        from PIL import Image, ImageDraw

        p, arena = self.size, self.env.sim.arena_cfg
        heights = self.scene["heights"][i]
        rgb = np.empty((p, p, 3), dtype=np.uint8)
        rgb[:] = _GROUND
        if heights is not None:  # sample the tile at every pixel's centre (rows: y down, columns: x)
            half, n = self.scene["terrain_half"], heights.shape[0]
            xy = self._from_px(np.arange(p) + 0.5)
            idx = np.rint((xy + half) / (2 * half) * (n - 1)).astype(int)
            inside = (idx >= 0) & (idx < n)
            colors = terrain_colors(heights)[np.clip(idx[:, 0], 0, n - 1)[None, :], np.clip(idx[:, 1], 0, n - 1)[:, None]]
            mask = inside[:, 1][:, None] & inside[:, 0][None, :]
            rgb[mask] = colors[mask]
        image = Image.fromarray(rgb)
        draw = ImageDraw.Draw(image)
        h = arena.half_size
        if heights is None:
            for tick in np.arange(-np.floor(h), np.floor(h) + 1):
                (a, b), (c, d) = self._to_px(np.array([[tick, -h], [tick, h]]))
                draw.line([(a, b), (c, d)], fill=_GRID)
                (a, b), (c, d) = self._to_px(np.array([[-h, tick], [h, tick]]))
                draw.line([(a, b), (c, d)], fill=_GRID)
        if arena.walls:
            (x0, y0), (x1, y1) = self._to_px(np.array([[-h, h], [h, -h]]))
            draw.rectangle([x0, y0, x1, y1], outline=_WALL, width=max(2, p // 80))
        if self.scene["map"][i] is not None:  # the map's walls: occupied dark, unknown pale
            for rects, fill in zip(self.scene["map"][i], (_WALL, _UNKNOWN), strict=True):
                for x0, y0, x1, y1 in rects:
                    (a, b), (c, d) = self._to_px(np.array([[x0, y1], [x1, y0]]))
                    draw.rectangle([a, b, max(a, c - 1), max(b, d - 1)], fill=fill)
        plan = self.scene["plan"][i]
        if plan is not None and len(plan) > 1:
            draw.line([tuple(c) for c in self._to_px(plan)], fill=_PLAN, width=max(1, p // 128))
        for kind, shape in self.scene["obstacles"][i]:
            if kind == "box":
                draw.polygon([tuple(c) for c in self._to_px(shape)], fill=_OBSTACLE)
            else:
                (cx, cy), r = self._to_px(shape[:2]), shape[2] * self.scale
                draw.ellipse([cx - r, cy - r, cx + r, cy + r], fill=_OBSTACLE)
        (tx, ty), r = self._to_px(self.scene["target"][i]), self.env.task_cfg.reach_radius * self.scale
        draw.ellipse([tx - r, ty - r, tx + r, ty + r], outline=_TARGET, width=2)
        draw.ellipse([tx - 3, ty - 3, tx + 3, ty + 3], fill=_TARGET)
        return image

    def _from_px(self, px: np.ndarray) -> np.ndarray:
        """Background pixel centres along an axis to world (x, y) [m] pairs (n, 2): x of the column, y of the row."""
        view, s = self.view, 1.0 / self.scale
        return np.stack([px * s - view, view - px * s], axis=-1)

    def frames(self) -> Iterator[np.ndarray]:
        """The video's frames (height, width, 3) uint8: one per ``every`` recorded steps, and the last."""
        from PIL import Image, ImageDraw

        if not self.poses:
            return
        k, p = len(self.worlds), self.panel
        cols = min(k, 2)
        rows = (k + cols - 1) // cols
        backgrounds = [self._background(i) for i in range(k)]
        poses = np.stack(self.poses)  # (T, k, 3)
        path_px = self._to_px(poses[..., :2])
        hx, hy = self.footprint
        canvas = Image.new("RGB", (cols * p, rows * p), _BACKGROUND)
        steps = list(range(0, len(poses), self.every))
        if steps[-1] != len(poses) - 1:
            steps.append(len(poses) - 1)
        for t in steps:
            for i in range(k):
                x, y, yaw = poses[t, i]
                # the panel's corner in its background: the origin, or (following) half a panel up-left of the rover
                corner = np.zeros(2) if self.follow is None else np.round(path_px[t, i] - p / 2)
                panel = backgrounds[i].crop((*corner.astype(int), *(corner + p).astype(int)))
                draw = ImageDraw.Draw(panel)

                def px(xy, corner=corner):
                    return [tuple(c) for c in np.reshape(xy - corner, (-1, 2))]

                if self.scans and not (self.ended[i] and t > self.end_step[i]):
                    points, hits = self.scans[t]
                    (origin,) = px(path_px[t, i])
                    ends = self._to_px(points[i])
                    rays = Image.new("L", panel.size, 0)  # the beams, faint: the ground stays readable
                    ray_draw = ImageDraw.Draw(rays)
                    for end in px(ends):
                        ray_draw.line([origin, end], fill=_RAY_ALPHA)
                    panel.paste(_RAY, mask=rays)
                    draw.point(px(ends[hits[i]]), fill=_SCAN)
                if t > 0:
                    draw.line(px(path_px[: t + 1, i]), fill=_PATH, width=2)
                draw.polygon(px(self._to_px(box_corners(x, y, yaw, hx, hy))), fill=_ROVER)
                nose = self._to_px(np.array([[x, y], [x + 1.2 * hx * np.cos(yaw), y + 1.2 * hx * np.sin(yaw)]]))
                draw.line(px(nose), fill=(255, 255, 255), width=2)
                ended = self.ended[i] and t >= self.end_step[i]
                shown = (self.end_step[i] if ended else t) + 1  # steps driven
                caption = f"world {self.worlds[i]}  {shown * self.step_dt:5.2f} s" + (f"  {self.reason[i]}" if ended else "")
                draw.text((6, 4), caption, fill=_TEXT)
                canvas.paste(panel, ((i % cols) * p, (i // cols) * p))
            yield np.asarray(canvas)

    def write(self, path: str | Path, *, gif: bool = False) -> VideoFile:
        """Draw the recorded episodes and encode them to ``path`` (H.264 MP4, written beside and renamed);
        with ``gif``, also an animated GIF at half size (:attr:`VideoFile.gif`)."""
        import io

        import av

        t0 = time.perf_counter()
        path = check_video_path(path)
        if not self.poses:
            raise RuntimeError("EvalVideo.write: nothing recorded (pass env_hook() to evaluate first)")
        fps = 1.0 / (self.step_dt * self.every)
        rate = round(fps)
        tmp = path.with_name(f".{path.stem}.tmp{VIDEO_SUFFIX}")
        gif_buffer = io.BytesIO() if gif else None
        count, size = 0, (0, 0)
        with av.open(str(tmp), "w", format="mp4") as out, \
                (av.open(gif_buffer, "w", format="gif") if gif else _nothing()) as gif_out:
            stream, gif_stream = None, None
            for frame in self.frames():
                if stream is None:
                    size = (frame.shape[1], frame.shape[0])
                    stream = out.add_stream("libx264", rate=rate)
                    stream.width, stream.height, stream.pix_fmt = size[0], size[1], "yuv420p"
                    stream.thread_count = 1  # the trainer's core only
                    stream.options = {"preset": "ultrafast", "crf": "30"}
                    if gif:
                        gif_stream = gif_out.add_stream("gif", rate=rate)
                        gif_stream.width, gif_stream.height, gif_stream.pix_fmt = size[0] // 2, size[1] // 2, "rgb8"
                video_frame = av.VideoFrame.from_ndarray(frame, format="rgb24")
                out.mux(stream.encode(video_frame))
                if gif:
                    small = video_frame.reformat(width=size[0] // 2, height=size[1] // 2, format="rgb8")
                    gif_out.mux(gif_stream.encode(small))
                count += 1
            out.mux(stream.encode(None))
            if gif:
                gif_out.mux(gif_stream.encode(None))
        tmp.replace(path)
        return VideoFile(path, count, size[0], size[1], rate, time.perf_counter() - t0,
                         gif_buffer.getvalue() if gif else None)


class _nothing:
    def __enter__(self):
        return None

    def __exit__(self, *exc):
        return False


def read_video(path: str | Path) -> tuple[int, int, int]:
    """(frames, width, height) of a video file, by decoding every frame (a check that it plays)."""
    import av

    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        count = sum(1 for _ in container.decode(stream))
        return count, stream.codec_context.width, stream.codec_context.height


def log_video(logger, name: str, video: VideoFile, step: int) -> bool:
    """Send ``video`` to ``logger`` if it takes videos; returns whether it did.

    TensorBoard gets :attr:`VideoFile.gif` as an image summary (TorchRL's ``log_video`` needs moviepy 1),
    W&B the MP4 as a ``wandb.Video``, MLflow the MP4 as an artifact under ``videos/``, a
    :class:`~atrv_warp.integrations.rerun_logger.RerunLogger` the MP4 as a video asset.
    """
    from torchrl.record.loggers import TensorboardLogger, WandbLogger

    from atrv_warp.integrations.rerun_logger import RerunLogger
    from atrv_warp.integrations.tracking import MLflowLogger

    if isinstance(logger, TensorboardLogger):
        if video.gif is None:
            return False
        from tensorboard.compat.proto.summary_pb2 import Summary

        image = Summary.Image(height=video.height // 2, width=video.width // 2, colorspace=3,
                              encoded_image_string=video.gif)
        logger.experiment.file_writer.add_summary(Summary(value=[Summary.Value(tag=name, image=image)]), step)
        logger.experiment.flush()
        return True
    if isinstance(logger, WandbLogger):
        import wandb

        # "step": the x axis TorchRL's WandbLogger gives every scalar
        logger.experiment.log({name: wandb.Video(str(video.path), format="mp4"), "step": step})
        return True
    if isinstance(logger, MLflowLogger):
        logger.log_file(video.path, "videos")
        return True
    if isinstance(logger, RerunLogger):
        logger.log_video(name, video.path, step=step)
        return True
    return False
