"""Per-world physical parameters (``RoverSim.params``): each reaches the physics it names, one world's
values never leak into another's, a world set to a config's values steps exactly as a simulator built
with that config, gradients reach a per-world mu and mass, and bad values are refused by name."""

import re
from pathlib import Path

import numpy as np
import pytest
import torch

from atrv_warp.sim import ContactConfig, RoverConfig, RoverSim
from atrv_warp.sim.diff import DiffRollout


def drive(sim: RoverSim, torque: float, steps: int) -> None:
    sim.reset()
    for _ in range(steps):
        sim.step(torch.full((2,), torque))


def test_a_world_set_to_a_config_steps_as_that_config():
    """World 1 with mu 0.8, a 15 kg payload, a weaker, slower motor and stiffer ground matches, bit for bit, a
    simulator built with those configs; world 0 keeps the defaults' trajectory. (The wheel radius is left out: a
    config's radius also sizes the wheels' inertia from their geometry.)"""
    values = {"friction": 0.8, "payload_mass": 15.0, "payload_offset": (0.1, -0.05, 0.05), "torque_scale": 0.8,
                  "speed_limit": 40.0, "stiffness": 2.0e5}
    mixed = RoverSim(2)
    mixed.set_params([1], **values)
    rover = RoverConfig(payload_mass=15.0, payload_offset=(0.1, -0.05, 0.05), torque_scale=0.8, wheel_speed_limit=40.0)
    alone = RoverSim(1, rover=rover, contact=ContactConfig(friction=0.8, stiffness=2.0e5))
    nominal = RoverSim(1)
    for sim in (mixed, alone, nominal):
        sim.reset(height=nominal.rest_height)
    for t in range(30):
        cmd = torch.tensor([[12.0, 4.0]]) if t < 15 else torch.tensor([[-3.0, 9.0]])
        mixed.step(cmd.expand(2, 2))
        alone.step(cmd)
        nominal.step(cmd)
    assert torch.equal(mixed.root_pose[1], alone.root_pose[0])
    assert torch.equal(mixed.root_pose[0], nominal.root_pose[0])
    assert not torch.equal(mixed.root_pose[0], mixed.root_pose[1])


def test_payload_and_torque_scale_set_the_rolling_acceleration():
    """Rolling without slip at 2 N·m a wheel: a = 4 s tau / r / (M + m_p + 4 I / r²)."""
    sim = RoverSim(3)
    sim.set_params([1], payload_mass=25.0)
    sim.set_params([2], torque_scale=0.5)
    drive(sim, 2.0, 10)
    v0 = sim.lin_vel[:, 0].clone()
    for _ in range(10):
        sim.step(torch.full((2,), 2.0))
    accel = (sim.lin_vel[:, 0] - v0) / 0.5
    desc = sim.description
    r = sim.rover_cfg.wheel_radius
    spin = sum(float(w.axis @ w.inertial.inertia @ w.axis) for w in desc.wheels)
    expected = [4 * s * 2.0 / r / (desc.total_mass + m + spin / r**2) for s, m in ((1, 0), (1, 25), (0.5, 0))]
    assert accel.tolist() == pytest.approx(expected, rel=0.03)


def test_wheel_radius_sets_the_distance_per_turn():
    """Distance rolled per wheel radian is the world's rolling radius."""
    sim = RoverSim(2)
    sim.set_params([1], wheel_radius=0.14)
    drive(sim, 2.0, 40)
    angle = torch.zeros(2)
    x0 = sim.root_pose[:, 0].clone()
    for _ in range(20):
        sim.step(torch.full((2,), 1.0))
        angle += sim.wheel_speed.mean(1) * 0.05
    per_radian = (sim.root_pose[:, 0] - x0) / angle
    assert per_radian.tolist() == pytest.approx([0.125, 0.14], rel=0.02)


def test_speed_limit_caps_the_top_speed():
    sim = RoverSim(2)
    sim.set_params([1], speed_limit=20.0)
    drive(sim, 6.0, 100)
    assert float(sim.wheel_speed[1].max()) <= 20.0 * 1.001
    assert float(sim.wheel_speed[0].max()) > 25.0


def test_friction_sets_each_worlds_traction():
    """Full torque spins the wheels: each world accelerates near its own mu g (mu 0.6 and 0.15)."""
    sim = RoverSim(2)
    sim.set_params(friction=[0.6, 0.15])
    drive(sim, 20.0, 10)
    v0 = sim.lin_vel[:, 0].clone()
    for _ in range(10):
        sim.step(torch.full((2,), 20.0))
    accel = (sim.lin_vel[:, 0] - v0) / 0.5
    assert accel.tolist() == pytest.approx([0.6 * 9.81, 0.15 * 9.81], rel=0.2)


def test_stiffness_sets_the_rest_depth():
    """At rest the tyres sink to (load / kp)^(1/n), with each world's kp (0.5x and 1.5x the nominal)."""
    sim = RoverSim(3)
    cfg = sim.contact_cfg
    sim.set_params(stiffness=[cfg.stiffness, 0.5 * cfg.stiffness, 1.5 * cfg.stiffness])
    sim.reset()
    for _ in range(100):
        sim.step(torch.zeros(2))
    z = sim.root_pose[:, 2]
    load = sim.description.total_mass * 9.81 / 4
    depth = [(load / k) ** (1 / cfg.exponent) for k in (cfg.stiffness, 0.5 * cfg.stiffness, 1.5 * cfg.stiffness)]
    assert float(z[0]) == pytest.approx(sim.rest_height, abs=1e-5)
    assert (z - z[0]).tolist() == pytest.approx([0.0, depth[0] - depth[1], depth[0] - depth[2]], abs=5e-4)


@pytest.mark.parametrize("values,message", [
    ({"friction": 0.0}, "friction must be > 0"),
    ({"friction": float("nan")}, "friction must be finite"),
    ({"payload_mass": -1.0}, "payload_mass must be >= 0"),
    ({"wheel_radius": -0.1}, "wheel_radius must be > 0"),
    ({"grip": 1.0}, "unknown physical parameter 'grip'"),
    ({"friction": [0.5, 0.6, 0.7]}, "friction must be one value"),
])
def test_bad_parameters_are_refused_by_name(values, message):
    sim = RoverSim(2)
    before = sim.params.as_dict()
    with pytest.raises(ValueError, match=message):
        sim.set_params(**values)
    after = sim.params.as_dict()
    assert all(np.array_equal(before[k], after[k]) for k in before)  # nothing written


def test_gradients_reach_each_worlds_mu_and_mass():
    """Two worlds at different mu and mass: each world's final x depends on its own parameters only, and the
    tape agrees with central differences (mu: full torque, the wheels slipping; mass: rolling at 6 N·m)."""
    roll = DiffRollout(2, steps=10)
    state = roll.initial_state(torch.tensor([[0.0, -2.0, 0.0], [0.0, 2.0, 0.0]]))
    m0 = roll.nominal_chassis_mass

    def gradients(actions, mu, mass):
        mu, mass = mu.clone().requires_grad_(True), mass.clone().requires_grad_(True)
        roll(actions, state, mu, mass)[-1, 0, 0].backward()
        assert mu.grad[1].item() == 0.0 and mass.grad[1].item() == 0.0  # world 1 does not move world 0
        return mu.grad[0].item(), mass.grad[0].item()

    def x0(actions, mu, mass):
        return roll(actions, state, mu, mass)[-1, 0, 0].item()

    mu, mass = torch.tensor([0.25, 0.5]), torch.tensor([m0, m0 + 20.0])
    full, rolling = torch.ones(10, 2, 2), torch.full((10, 2, 2), 0.3)
    d = torch.tensor([1e-3, 0.0])
    fd_mu = (x0(full, mu + d, mass) - x0(full, mu - d, mass)) / 2e-3
    assert gradients(full, mu, mass)[0] == pytest.approx(fd_mu, rel=0.03)
    dm = torch.tensor([0.5, 0.0])
    fd_mass = (x0(rolling, mu, mass + dm) - x0(rolling, mu, mass - dm)) / 1.0
    assert gradients(rolling, mu, mass)[1] == pytest.approx(fd_mass, rel=0.03)
    assert fd_mu > 0 and fd_mass < 0  # more grip, further; heavier, less far


# ------------------------------------------------------------------ configs that cannot run, refused by name

def test_a_sim_config_of_the_wrong_shape_is_named_with_its_file_and_key(tmp_path):
    from atrv_warp.sim.config_file import read_sim_config

    cases = {"[rover]\ninertial_overrides = [1, 2]\n": "[rover] inertial_overrides: entry 0 must be a table",
             "[robot]\nmass = 3\n": "unknown table(s) ['robot']; known: [rover], [contact]",
             "[rover]\nwheel_radius = 'big'\n": "[rover] RoverConfig.wheel_radius must be a number, got 'big'",
             "[rover]\nleft_wheels = [1, 2]\n": "[rover] RoverConfig.left_wheels must be a list of names",
             "[rover]\npayload_offset = [1, 2]\n": "[rover] RoverConfig.payload_offset must be a list of 3 numbers",
             "[contact]\nfriction = true\n": "[contact] ContactConfig.friction must be a number, got True",
             "[[rover.inertial_overrides]]\nlink = 'center_link'\nmass = -4.0\n":
                 "entry 0: InertialOverride.mass of 'center_link' must be a finite number > 0"}
    for k, (text, message) in enumerate(cases.items()):
        path = tmp_path / f"c{k}.toml"
        path.write_text(text)
        with pytest.raises(ValueError) as err:
            read_sim_config(path)
        assert str(err.value).startswith(f"sim config {path}: ") and message in str(err.value), str(err.value)
    binary = tmp_path / "binary.toml"
    binary.write_bytes(bytes(range(256)))
    with pytest.raises(ValueError, match=f"sim config {binary}: not a text file"):
        read_sim_config(binary)
    ok = tmp_path / "ok.toml"
    ok.write_text("[[rover.inertial_overrides]]\nlink = 'center_link'\nmass = 40.0\ninertia_diag = [1.0, 2.0, 2.5]\n")
    (override,) = read_sim_config(ok).rover.inertial_overrides
    assert override.mass == 40.0 and override.inertia_diag == (1.0, 2.0, 2.5)
    with pytest.raises(TypeError, match="RoverConfig.inertial_overrides must be InertialOverride entries"):
        RoverConfig(inertial_overrides=(1, 2))


def test_values_that_blow_the_state_up_are_refused_relative_to_the_robot(tmp_path):
    """Each value measured to make the state non-finite within 200 steps is refused, naming its bound and what it is
    relative to; a smaller robot's own wheel passes where the ATRV-Jr's would not."""
    from atrv_warp.sim.config import default_urdf_path

    for rover, message in [(RoverConfig(torque_scale=1e308), "RoverConfig.torque_scale 1e+308 is outside 0 … 5"),
                           (RoverConfig(wheel_radius=100.0), ("RoverConfig.wheel_radius 100 m is outside 0.0625 … "
                                                             "0.25 (0.5 to 2 times the robot's wheel radius, 0.125 m)")),
                           (RoverConfig(payload_mass=5.0, payload_offset=(1e9, 0.0, 0.0)),
                            "RoverConfig.payload_offset 1e+09 m away is outside 0 … 0.781"),
                           (RoverConfig(payload_mass=1e6), "RoverConfig.payload_mass 1e+06 kg is outside 0 … 174")]:
        with pytest.raises(ValueError, match=re.escape(message)):
            RoverSim(1, rover=rover)
    config = tmp_path / "huge.toml"
    config.write_text("[contact]\nstiffness = 1e12\n")
    with pytest.raises(ValueError, match=rf"sim config {re.escape(str(config))}: \[contact\] stiffness 1e\+12 is outside"):
        RoverSim(1, sim_config=config)
    sim = RoverSim(2)
    with pytest.raises(ValueError, match="payload_mass 1e\\+06 kg is outside"):
        sim.set_params(payload_mass=1e6)
    small = tmp_path / "small.urdf"  # the same rover with 5 cm wheels: its own radius passes, the ATRV-Jr's does not
    small.write_text(Path(default_urdf_path()).read_text().replace('radius="0.125"', 'radius="0.05"'))
    RoverSim(1, rover=RoverConfig(urdf=str(small), wheel_radius=0.05))
    with pytest.raises(ValueError, match=r"outside 0.025 … 0.1 \(0.5 to 2 times the robot's wheel radius, 0.05 m\)"):
        RoverSim(1, rover=RoverConfig(urdf=str(small), wheel_radius=0.125))


def test_a_world_count_is_an_integer_that_fits_in_memory():
    from atrv_warp import ATRVjrEnv

    with pytest.raises(TypeError, match=r"num_worlds must be an integer, got True \(bool\)"):
        RoverSim(True)
    with pytest.raises(ValueError, match=r"10,000,000 worlds need about 320.0 GB on cpu \(32 kB each\), more than the"):
        RoverSim(10**7)
    with pytest.raises(ValueError, match="worlds need about"):
        ATRVjrEnv(num_envs=10**7)
