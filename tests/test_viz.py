"""Rerun recording: entities, row counts, logged poses equal to the simulator's; disabled = no work."""


import numpy as np
import pytest
import rerun as rr
import torch
from rerun.chunk import RrdReader

from atrv_warp import ATRVjrEnv
from atrv_warp.integrations.blueprint import PLOTS_SHARE, view_shares
from atrv_warp.integrations.recorder import RerunRecorder
from atrv_warp.integrations.rerun_logger import RerunLogger
from atrv_warp.task.baseline import scripted_policy
from atrv_warp.task.evaluation import evaluate


def read_rrd(path):
    """entity path -> list of pyarrow record batches."""
    out = {}
    for chunk in RrdReader(str(path)).stream().to_chunks():
        out.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    return out


def column(batches, name):
    """Every row of component ``name`` in an entity's batches (those that log it)."""
    rows = []
    for b in batches:
        if name in b.schema.names:
            rows.extend(b.column(name).to_pylist())
    return rows


def test_recorded_evaluation_matches_simulator(tmp_path):
    path = tmp_path / "eval.rrd"
    env = ATRVjrEnv(6)
    recorder = RerunRecorder(env.sim, path=path, worlds=[1, 4])
    truth = {1: [], 4: []}

    def on_step(e, td):
        recorder.env_hook()(e, td)
        for w, poses in truth.items():
            poses.append(e.sim.root_pose[w, :3].clone())

    result = evaluate(scripted_policy(), num_episodes=6, seed=3, env=env, on_step=on_step)
    recorder.close()
    steps = recorder.step
    assert steps == len(truth[1]) >= result.mean_steps  # one logged row per env step
    data = read_rrd(path)
    # static scene and every logged world's rover, drawn from the URDF's visuals; each world's arena on a grid
    offsets = {}
    for w in (1, 4):
        for ent in ("ground", "grid", "walls"):
            assert f"/world_{w}/arena/{ent}" in data
        offsets[w] = np.ravel(column(data[f"/world_{w}"], "Transform3D:translation")[0])
        for link in ("center_link", "left_front_wheel_link", "right_rear_wheel_link"):
            assert f"/world_{w}/rover/{link}" in data
        # the chassis box: the URDF's 0.64 x 0.39 x 0.22 m, 0.05 m above the link frame
        visual = f"/world_{w}/rover/center_link/visual_0"
        assert column(data[visual], "Boxes3D:half_sizes")[0][0] == pytest.approx([0.32, 0.195, 0.11])
        assert np.ravel(column(data[visual], "Transform3D:translation")[0]) == pytest.approx([0.0, 0.0, 0.05])
        wheel = [e for e in data if e.startswith(f"/world_{w}/rover/left_front_wheel_link/visual_")]
        assert f"{min(wheel, key=len)}/mark" in data  # the cross that shows the wheel turning
        for ent in ("target", "trajectory"):
            assert f"/world_{w}/{ent}" in data
        for plot in ("reward", "distance", "torque_left", "torque_right"):
            assert sum(b.num_rows for b in data[f"/plots/world_{w}/{plot}"]) == steps
        batches = data[f"/world_{w}/rover/center_link"]
        assert sum(b.num_rows for b in batches) == steps
        order = np.argsort(column(batches, "step"))
        logged = np.array(column(batches, "Transform3D:translation"), dtype=np.float64).reshape(-1, 3)[order]
        np.testing.assert_allclose(logged, torch.stack(truth[w]).numpy(), atol=1e-6)
    assert np.linalg.norm(offsets[4] - offsets[1]) >= 2 * env.sim.arena_cfg.half_size  # side by side, not overlaid
    assert "/world_0/rover/center_link" not in data  # only the chosen worlds are logged
    assert {"step", "sim_time"} <= set(data["/world_1/rover/center_link"][0].schema.names)


def test_disabled_recording_adds_no_step_work(monkeypatch):
    """With no recorder, stepping and evaluating never reach Rerun."""

    def boom(*args, **kwargs):
        raise AssertionError("Rerun was called on the step path")

    monkeypatch.setattr(rr.RecordingStream, "log", boom)
    monkeypatch.setattr(rr.RecordingStream, "set_time", boom)
    env = ATRVjrEnv(4)
    evaluate(scripted_policy(), num_episodes=4, seed=1, env=env)
    env.sim.step()


def test_rerun_logger_scalars(tmp_path):
    path = tmp_path / "train.rrd"
    logger = RerunLogger("train", path=path)
    for i, v in enumerate((0.1, 0.5, 0.9)):
        logger.log_scalar("eval_success_rate", v, step=1000 * (i + 1))
    logger.log_hparams({"lr": 3e-4})
    logger.experiment.flush()
    logger.experiment.disconnect()
    data = read_rrd(path)
    batches = data["/train/eval_success_rate"]
    assert sorted(column(batches, "frames")) == [1000, 2000, 3000]
    values = [v[0] for v in column(batches, "Scalars:scalars")]
    assert sorted(values) == pytest.approx([0.1, 0.5, 0.9])


def test_evaluate_cli_writes_rrd(tmp_path, run_module):
    path = tmp_path / "cli.rrd"
    run_module("atrv_warp.evaluate", "--baseline", "--episodes", "3", "--rerun", str(path), "--worlds", "0", "2")
    data = read_rrd(path)
    assert "/world_2/rover/center_link" in data and "/world_1/rover/center_link" not in data


def test_served_viewer_is_localhost_only_and_stops():
    import socket
    import urllib.parse

    from atrv_warp import RoverSim

    sim = RoverSim(1)
    recorder = RerunRecorder(sim, serve=True)
    try:
        url = urllib.parse.urlparse(recorder.url)
        assert url.hostname == "127.0.0.1"
        grpc = urllib.parse.urlparse(urllib.parse.parse_qs(url.query)["url"][0].replace("rerun+", ""))
        sim.step()
        recorder.log_step()
        for port in (url.port, grpc.port):
            with socket.socket() as s:
                assert s.connect_ex(("127.0.0.1", port)) == 0
            # bound to loopback only: not reachable on another local address
            with socket.socket() as s:
                s.settimeout(1.0)
                other = socket.gethostbyname(socket.gethostname())
                if not other.startswith("127."):
                    assert s.connect_ex((other, port)) != 0
    finally:
        recorder.close()
    for port in (url.port, grpc.port):  # stop() returns once the whole process group is gone
        with socket.socket() as s:
            assert s.connect_ex(("127.0.0.1", port)) != 0, f"port {port} still bound"
    assert recorder.viewer.process is None


def test_served_viewer_context_manager_refuses_a_busy_port():
    import socket

    from atrv_warp.integrations.viewer import ServedViewer

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        with pytest.raises(RuntimeError, match=rf"port {busy.getsockname()[1]} on 127.0.0.1 is already in use"):
            ServedViewer(web_port=busy.getsockname()[1]).start()
    with ServedViewer() as viewer:
        assert viewer.healthy()
        ports = (viewer.grpc_port, viewer.web_port)
    for port in ports:
        with socket.socket() as s:
            assert s.connect_ex(("127.0.0.1", port)) != 0


def test_nav_recording_draws_terrain_obstacles_and_scan(tmp_path):
    path = tmp_path / "nav.rrd"
    env = ATRVjrEnv(3, task="nav", seed=5)
    recorder = RerunRecorder(env.sim, path=path, worlds=[0, 2])
    tiles = []
    evaluate(scripted_policy(), num_episodes=3, seed=5, env=env,
             on_step=lambda e, td: (recorder.env_hook()(e, td), tiles.append(e.sim.terrain.tile.clone())))
    recorder.close()
    data = read_rrd(path)
    assert "/world_0/arena/ground" not in data and "/world_0/arena/walls" in data  # terrain replaces flat ground
    grid = env.sim.terrain.grid
    for w in (0, 2):
        mesh = data[f"/world_{w}/terrain"]
        vertices = np.array(column(mesh, "Mesh3D:vertex_positions")[0]).reshape(-1, 3)
        tile = int(tiles[0][w])
        # the mesh's first vertex is the tile's corner sample (-15, -15) at ground_top + height
        assert vertices[0, :2] == pytest.approx([-grid.half_size, -grid.half_size])
        assert vertices[0, 2] == pytest.approx(env.sim.terrain.base + grid.heights[tile, 0, 0], abs=1e-5)
        assert f"/world_{w}/obstacles/boxes" in data and f"/world_{w}/obstacles/cylinders" in data
        assert sum(b.num_rows for b in data[f"/world_{w}/scan/rays"]) == recorder.step
        assert f"/world_{w}/scan/hits" in data


def test_recording_opens_with_the_3d_view_leading(tmp_path):
    """The layout stored in the file: the 3D view is the largest, framing every recorded world; the
    per-world plots are tabs beside it; a training recording gets a tab for its scalars."""
    path = tmp_path / "layout.rrd"
    env = ATRVjrEnv(3)
    recorder = RerunRecorder(env.sim, path=path, worlds=[0, 2])
    evaluate(scripted_policy(), num_episodes=3, seed=1, env=env, on_step=recorder.env_hook())
    recorder.close()
    views = view_shares(path)
    assert views[0].kind == "3D" and views[0].share == pytest.approx(1 - PLOTS_SHARE)
    assert all(v.share < views[0].share for v in views[1:])
    assert [(v.kind, v.origin) for v in views[1:]] == [("TimeSeries", "/plots/world_0"), ("TimeSeries", "/plots/world_2")]
    # the eye looks at the middle of the two arenas, from farther back than their extent
    reader = RrdReader(str(path))
    eye = next(c.to_record_batch() for c in reader.stream(store=reader.blueprints()[-1]).to_chunks()
               if str(c.entity_path).endswith("/EyeControls3D"))
    target = np.array(eye.column("EyeControls3D:look_target").to_pylist()[0][0])
    position = np.array(eye.column("EyeControls3D:position").to_pylist()[0][0])
    np.testing.assert_allclose(target, 0.5 * (recorder.offsets[0] + recorder.offsets[2]), atol=1e-6)
    extent = np.abs(recorder.offsets[2] - recorder.offsets[0]).max() + 2 * env.sim.arena_cfg.half_size
    assert np.linalg.norm(position - target) > extent and position[2] > 0
    rec = rr.RecordingStream("atrv_warp")
    train = tmp_path / "train.rrd"
    rec.save(str(train))
    RerunRecorder(env.sim, recording=rec, worlds=[1], training=True).close()
    rec.flush()
    rec.disconnect()
    assert [(v.name, v.origin) for v in view_shares(train)[1:]] == [("training", "/train"), ("world 1", "/plots/world_1")]


@pytest.mark.parametrize(("name", "message"), [("eval.txt", "must end in .rrd"), ("folder.rrd", "is a folder")])
def test_unwritable_recording_fails_before_any_simulation(tmp_path, name, message, run_module):
    (tmp_path / "folder.rrd").mkdir()
    proc = run_module("atrv_warp.evaluate", "--baseline", "--episodes", "2", "--rerun", str(tmp_path / name),
                      check=False)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert lines == [f"python -m atrv_warp.evaluate: error: --rerun: recording {tmp_path / name}: {message}"], lines
    assert "device" not in proc.stdout  # stopped before the simulator was built (its device line)


def test_a_map_world_records_its_walls_and_plan_and_its_video_draws_them(tmp_path):
    """A world in a map: the recording holds its occupied and unknown cells as boxes covering exactly those cells
    (merged rectangles), and the planner's path each step from the robot to the target; the top-down video draws the
    walls over the ground."""
    from test_map_worlds import two_rooms

    from atrv_warp.integrations.video import EvalVideo
    from atrv_warp.sim.planner import PlannerConfig
    from atrv_warp.task.env import RoverEnv
    from atrv_warp.world.nav2_map import OCCUPIED

    site = two_rooms()
    env = RoverEnv(2, task="nav_deploy", seed=3, maps=[site], planner=PlannerConfig())
    path = tmp_path / "map.rrd"
    recorder = RerunRecorder(env.sim, path=path, worlds=[0])
    video = EvalVideo(env, episodes=1, panel=240)
    hooks = (recorder.env_hook(), video.env_hook())
    td = env.reset()
    for _ in range(3):
        td = env.step(td.set("action", torch.zeros(2, 2)))
        for hook in hooks:
            hook(env, td)
        td = td["next"]
    recorder.close()
    data = read_rrd(path)
    halves = np.array(column(data["/world_0/map/occupied"], "Boxes3D:half_sizes")[0]).reshape(-1, 3)
    assert 4 * (halves[:, 0] * halves[:, 1]).sum() == pytest.approx((site.cells == OCCUPIED).sum() * 0.01, rel=1e-4)
    assert "/world_0/map/unknown" in data
    strips = column(data["/world_0/plan"], "LineStrips3D:strips")
    last = np.array(strips[-1][0]).reshape(-1, 3)
    assert len(strips) == 3 and last[-1, :2] == pytest.approx(env.target[0].tolist(), abs=1e-5)
    frame = next(iter(video.frames()))
    row, col = site.cell_of(0.05, 6.0)  # the middle wall, away from the doorway: dark in the panel
    assert site.walls[row, col]
    x, y = int((0.05 + video.view) * video.scale), int((video.view - 6.0) * video.scale)  # its pixel in the panel
    assert frame[y, x].tolist() == [70, 70, 80]
