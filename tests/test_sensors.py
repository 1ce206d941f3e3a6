"""Sensors as units (atrv_warp.task.sensors): a second laser from the robot file alone, and a sensor kind of one's
own landing from a test file."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest
import torch
import warp as wp

from atrv_warp.core.robot import RobotFileError, load_robot, robot_from_record, robot_record
from atrv_warp.task.env import RoverEnv
from atrv_warp.task.spec import ObservationField

ROBOTS_DIR = Path(__file__).resolve().parents[1] / "atrv_warp" / "robots"
REAR_LASER = """  <link name="rear_laser"/>
  <joint name="rear_laser_joint" type="fixed">
    <parent link="center_link"/>
    <child link="rear_laser"/>
    <origin xyz="-0.3 0.0 0.19" rpy="0 0 3.14159265"/>
  </joint>
</robot>"""


def _robot(tmp_path: Path, sensors: str, *, rpy: str | None = None) -> Path:
    """The ATRV-Jr with a laser looking backwards on its URDF, and ``sensors`` before its [deploy] table."""
    urdf = (ROBOTS_DIR / "atrvjr.urdf").read_text()
    rear = REAR_LASER if rpy is None else REAR_LASER.replace('rpy="0 0 3.14159265"', f'rpy="{rpy}"')
    (tmp_path / "atrvjr.urdf").write_text(urdf.replace("</robot>", rear))
    text = (ROBOTS_DIR / "atrvjr.toml").read_text().replace('name = "atrvjr"', 'name = "atrvjr_two_lasers"')
    path = tmp_path / "atrvjr_two_lasers.toml"
    path.write_text(text.replace("[deploy]", sensors + "\n[deploy]"))
    return path


REAR = '[[sensors]]\nkind = "laser"\nname = "rear_scan"\nframe = "rear_laser"\n'


def _rollout(env: RoverEnv, steps: int = 6) -> list:
    gen = torch.Generator().manual_seed(3)
    tds = [env.reset()]
    for _ in range(steps):
        action = torch.rand(env.num_envs, 2, generator=gen) * 2 - 1
        tds.append(env.step(tds[-1].set("action", action))["next"])
        tds[-1] = tds[-1].clone()
    return tds


def test_a_second_laser_from_the_robot_file_alone_is_simulated_observed_and_reported(tmp_path):
    from atrv_warp.core.scan import sector_readings

    robot = load_robot(_robot(tmp_path, REAR))
    assert dataclasses.replace(robot, sensors=()) == robot  # what it carries is not the robot's identity
    assert "rear_laser" in robot.sensor_frames
    one = RoverEnv(3, task="nav", seed=5)
    two = RoverEnv(3, task="nav", seed=5, robot=str(robot.path))
    sectors = one.task_cfg.scan_sectors
    names = [f.name for f in two.sensors[1].fields]
    assert [s.name for s in two.sensors] == ["scan", "rear_scan"] and names == [f"rear_scan_{i}" for i in range(sectors)]
    assert two.obs_dim == one.obs_dim + sectors
    assert two.observation_spec["rear_scan"].shape == one.observation_spec["scan"].shape
    a, b = _rollout(one), _rollout(two)
    lead = one.obs_dim - 2 * one.task_cfg.action_history  # the leading fields and the first laser's sectors
    for x, y in zip(a, b, strict=True):
        # the rover drives the same; the first laser reads the same; the second's sectors sit before the actions
        assert torch.equal(x["scan"], y["scan"]) and torch.equal(x["observation"][:, :lead], y["observation"][:, :lead])
        assert torch.equal(x["observation"][:, lead:], y["observation"][:, lead + sectors:])
        rear = sector_readings(y["rear_scan"].double(), torch.as_tensor(two.sensors[1].scanner.cfg.angles),
                               two.scan_sectors, range_min=0.1, range_max=20.0)
        torch.testing.assert_close(y["observation"][:, lead:lead + sectors], rear.float(), rtol=0, atol=1e-6)
    # it looks backwards: its ranges are not the front one's
    assert not torch.equal(b[-1]["scan"], b[-1]["rear_scan"])
    # the snapshot keeps its noise stream; a restored env steps on the same
    state = two.state_dict()
    assert "task.rear_scan_count" in state and "task.scan_count" in state


def test_each_laser_draws_its_own_noise_and_the_snapshot_restores_both(tmp_path):
    path = str(_robot(tmp_path, REAR))
    env = RoverEnv(2, task="nav", seed=1, robot=path, randomization="wide")
    first, rear = env.sensors
    assert first.scanner.seed != rear.scanner.seed
    td = env.reset()
    state = env.state_dict()
    action = torch.full((2, 2), 0.3)
    want = env.step(td.clone().set("action", action))["next"]
    again = RoverEnv(2, task="nav", seed=9, robot=path, randomization="wide")
    again.load_state_dict(state)
    got = again.step(td.clone().set("action", action))["next"]
    assert torch.equal(want["rear_scan"], got["rear_scan"]) and torch.equal(want["observation"], got["observation"])


def test_the_robot_record_keeps_the_sensors_and_a_saved_policy_is_checked_and_refused_where_unsupported(tmp_path):
    from atrv_warp.policy import load_policy, make_actor, policy_payload, run_record
    from atrv_warp.rl.export import export_policy
    from atrv_warp.sim.config import nominal_rover_config
    from atrv_warp.storage import FileFormatError, atomic_save
    from atrv_warp.task.registry import resolve_task
    from atrv_warp.task.scaling import fit_task

    robot = load_robot(_robot(tmp_path, REAR))
    record = robot_record(robot)
    assert record["sensors"] == [{"kind": "laser", "name": "rear_scan", "frame": "rear_laser"}]
    assert "sensors" not in robot_record(load_robot("atrvjr"))  # the shipped policies' records are as they were
    assert robot_from_record(record, "r").sensors == robot.sensors
    env = RoverEnv(1, task="nav", robot=str(robot.path))
    task = fit_task(resolve_task("nav"), nominal_rover_config(str(robot.path)))
    path = tmp_path / "two.pt"
    atomic_save(policy_payload(make_actor(16, 1, obs_dim=env.obs_dim), width=16, depth=1, meta={"task": "nav"},
                               task=task, record=run_record(task, robot)), path)
    load_policy(path, task="nav")  # observes the two lasers' sectors: as its record says
    with pytest.raises(ValueError, match=r"\[\[sensors\]\] \(rear_scan\).*cannot be exported"):
        export_policy(path, tmp_path / "two.pt2")
    assert not (tmp_path / "two.pt2").exists()
    one = tmp_path / "one.pt"
    atomic_save(policy_payload(make_actor(16, 1, obs_dim=env.obs_dim), width=16, depth=1, meta={"task": "nav"},
                               task=task, record=run_record(task, load_robot("atrvjr"))), one)
    with pytest.raises(FileFormatError, match=f"observes {env.obs_dim} values, task 'nav' observes {env.obs_dim - env.task_cfg.scan_sectors}"):
        load_policy(one, task="nav")


@pytest.mark.parametrize(("sensors", "message"), [
    ('[[sensors]]\nkind = "laser"\nname = "rear_scan"\n', r"\[\[sensors\]\] entry 1: frame must be a non-empty string"),
    (REAR + REAR, r"name 'rear_scan' must be a Python identifier used once"),
    (REAR.replace("rear_scan", "scan"), r"name 'scan' must be a Python identifier used once \(scan is links.laser's\)"),
    (REAR.replace("rear_scan", "rear-scan"), r"name 'rear-scan' must be a Python identifier"),
    (REAR + "range = [1, 2]\n", r"\[\[sensors\]\] rear_scan: range must be text, a number or a switch"),
    ('sensors = "laser"\n', r"\[\[sensors\]\] must be a list of tables"),
])
def test_a_bad_sensors_list_is_named_by_the_robot_file(tmp_path, sensors, message):
    path = _robot(tmp_path, "")
    path.write_text(path.read_text().replace('urdf = "atrvjr.urdf"', 'urdf = "atrvjr.urdf"\n' + sensors)
                    if sensors.startswith("sensors =") else path.read_text().replace("[deploy]", sensors + "\n[deploy]"))
    with pytest.raises(RobotFileError, match=message):
        load_robot(path)


def test_a_sensor_the_environment_cannot_build_is_named(tmp_path):
    from atrv_warp.sim.robot_check import check_robot

    unknown = _robot(tmp_path, REAR.replace('"laser"', '"radar"'))
    with pytest.raises(ValueError, match=r"rear_scan: unknown kind 'radar'; known: .*laser"):
        RoverEnv(1, task="nav", robot=str(unknown))
    extra = _robot(tmp_path, REAR + "beams = 90\n")
    with pytest.raises(ValueError, match=r"laser 'rear_scan': unknown key\(s\) \['beams'\]"):
        RoverEnv(1, task="nav", robot=str(extra))
    reserved = _robot(tmp_path, REAR.replace("rear_scan", "reward"))
    with pytest.raises(ValueError, match=r"reward: the environment's own step entry"):
        RoverEnv(1, task="nav", robot=str(reserved))
    missing = _robot(tmp_path, REAR.replace('"rear_laser"', '"no_such_link"'))
    with pytest.raises(RobotFileError, match=re.escape("[[sensors]] rear_scan.frame (no_such_link)")):
        check_robot(missing)
    tilted = _robot(tmp_path, REAR, rpy="0 0.5 3.14159265")
    with pytest.raises(RobotFileError, match=r"rear_scan.frame \(rear_laser\): the frame's z is tilted 28.6 deg"):
        check_robot(tilted)
    check_robot(_robot(tmp_path, REAR))  # turned about z only: a laser looking backwards is fine


class Clock:
    """A sensor of one's own, from this file alone: each world's episode time [s], observed over 60 s."""

    kind = "test_clock"

    def __init__(self, sim, task, declaration, noise, index):
        self.name, self.sim = declaration["name"], sim
        self.fields = self.fields_of(task, declaration)
        self.time = torch.zeros(sim.num_worlds)

    @classmethod
    def active(cls, task) -> bool:
        return True

    @classmethod
    def fields_of(cls, task, declaration):
        return (ObservationField(f"{declaration['name']}_s", 60.0, "time since the episode began", "s", "-"),)

    def spec(self, n, device):
        from torchrl.data import Unbounded

        return Unbounded(shape=(n, 1), dtype=torch.float32, device=device)

    def read(self, mask=None):
        if mask is None:
            self.time += self.sim.sim_cfg.step_dt
        else:
            self.time[wp.to_torch(mask)] = 0.0

    def observe(self, obs, column, nonfinite):
        wp.to_torch(obs)[:, column] = self.time.clamp(max=60.0)

    def reading(self):
        return self.time[:, None]

    def reseed(self, seed):
        pass

    def state(self):
        return {f"{self.name}_time": self.time.clone()}

    def load_state(self, state):
        self.time.copy_(state[f"{self.name}_time"])


def test_a_sensor_kind_of_ones_own_lands_from_its_own_file(tmp_path):
    from atrv_warp.task.sensors import SENSOR_KINDS, register_sensor, sensor_fields
    from atrv_warp.task.spec import observation_fields

    register_sensor(Clock)
    try:
        path = _robot(tmp_path, REAR + '[[sensors]]\nkind = "test_clock"\nname = "clock"\nframe = "novatel"\n')
        env = RoverEnv(2, task="reach", robot=str(path))  # reach has no scanner: the clock alone
        assert [s.name for s in env.sensors] == ["clock"]
        assert len(sensor_fields(env.task_cfg, env.robot)) == 1
        assert env.obs_dim == len(observation_fields(env.task_cfg)) + 1 == 11
        td = env.reset()
        for _ in range(3):
            td = env.step(td.set("action", torch.zeros(2, 2)))["next"]
        dt = env.sim.sim_cfg.step_dt
        torch.testing.assert_close(td["clock"], torch.full((2, 1), 3 * dt))
        torch.testing.assert_close(td["observation"][:, 10], torch.full((2,), 3 * dt))
        assert "task.clock_time" in env.state_dict()
        with pytest.raises(ValueError, match="already registered"):
            register_sensor(type("Other", (Clock,), {}))
    finally:
        SENSOR_KINDS.pop("test_clock", None)
