"""Domain randomization in the training env: draws within their ranges, seeded and per world, on the schedule
asked for; the latency buffer and the motor lag; noisy observations; bad settings refused before anything
steps; the trainer's key; and a randomization centred on a (calibrated) simulator config."""

import json
import math

import pytest
import torch

from atrv_warp.rl.command_line import load_train_config
from atrv_warp.sim.config import SENSOR_NOISE
from atrv_warp.task.env import ATRVjrEnv
from atrv_warp.task.randomization import (
    AROUND_PRESETS,
    RANDOMIZATION_PRESETS,
    AroundConfig,
    Draw,
    RandomizationConfig,
    get_randomization,
    resolve_around,
)
from atrv_warp.task.spec import OBS_INDEX


def roll(env, steps, action=0.5):
    td = env.reset()
    out = []
    for _ in range(steps):
        td = env.step(td.set("action", torch.full((env.num_envs, 2), action)))["next"]
        out.append(td["observation"].clone())
    return torch.stack(out)


def test_none_steps_as_without_randomization():
    plain = roll(ATRVjrEnv(4, seed=1), 20)
    none = roll(ATRVjrEnv(4, seed=1, randomization="none"), 20)
    empty = roll(ATRVjrEnv(4, seed=1, randomization=RandomizationConfig()), 20)
    assert torch.equal(plain, none) and torch.equal(plain, empty)


def test_wide_draws_lie_in_their_ranges_and_follow_the_seed():
    wide = RANDOMIZATION_PRESETS["wide"]
    env = ATRVjrEnv(256, seed=5, randomization="wide")
    env.reset()
    p = env.sim.params
    for name, draw in wide.physics.items():
        values = p.view(name) if name != "payload_offset" else p.payload_offset[:, :2]
        assert float(values.min()) >= draw.low - 1e-6 and float(values.max()) <= draw.high + 1e-6, name
        assert float(values.std()) > 0.1 * (draw.high - draw.low) / 3.5, name  # spread, not one value
    # log-uniform friction: about as many worlds below the geometric mean as above it
    below = (p.friction < (0.2 * 1.0) ** 0.5).float().mean().item()
    assert 0.4 < below < 0.6
    assert sorted(set(env.latency.tolist())) == [0, 1, 2]
    # the payload reached the solver's model: chassis mass = nominal + payload
    body = env.sim.model.body_mass.numpy().reshape(256, -1)[:, env.sim.layout.chassis_body]
    assert body == pytest.approx(env.sim.nominal_chassis.mass + p.payload_mass.numpy(), rel=1e-6)
    again = ATRVjrEnv(256, seed=5, randomization="wide")
    again.reset()
    other = ATRVjrEnv(256, seed=6, randomization="wide")
    other.reset()
    assert torch.equal(again.sim.params.friction, p.friction) and torch.equal(again.latency, env.latency)
    assert not torch.equal(other.sim.params.friction, p.friction)


def test_same_seed_same_randomized_rollout():
    a = roll(ATRVjrEnv(4, seed=2, task="nav", randomization="wide"), 25)
    b = roll(ATRVjrEnv(4, seed=2, task="nav", randomization="wide"), 25)
    assert torch.equal(a, b)


@pytest.mark.parametrize("mode,changes_on_reset,changes_within", [
    ("startup", False, False), ("reset", True, False), ("interval", True, True)])
def test_draw_modes(mode, changes_on_reset, changes_within):
    cfg = RandomizationConfig(friction=Draw(0.2, 1.0, mode=mode, every=3))
    env = ATRVjrEnv(8, seed=0, randomization=cfg)
    td = env.reset()
    first = env.sim.params.friction.clone()
    for _ in range(3):
        td = env.step(td.set("action", torch.zeros(8, 2)))["next"]
    assert torch.equal(env.sim.params.friction, first) != changes_within
    within = env.sim.params.friction.clone()
    env.reset()
    assert torch.equal(env.sim.params.friction, within) != changes_on_reset


def test_latency_delays_the_commands_by_whole_steps():
    env = ATRVjrEnv(2, seed=0, randomization=RandomizationConfig(latency=(2, 2)))
    td = env.reset()
    applied = []
    for t in range(5):
        action = torch.full((2, 2), 0.1 * (t + 1))
        td = env.step(td.set("action", action))["next"]
        applied.append(env.sim.commands[0, 0].item())
    scale = env.task_cfg.action_scale
    assert applied == pytest.approx([0.0, 0.0, 0.1 * scale, 0.2 * scale, 0.3 * scale])


def test_the_observation_shows_the_pending_actions():
    """The nav task observes its last three actions, newest first: under a latency of L steps, the command the
    motors apply next is the one the observation shows L steps back. A reset clears a world's history, and the
    history is part of the env's state."""
    from atrv_warp.task.spec import observation_fields

    env = ATRVjrEnv(3, seed=0, task="nav", randomization=RandomizationConfig(latency=(2, 2)))
    names = [f.name for f in observation_fields(env.task_cfg)]
    cols = [names.index(f"last_action_{k}_{side}") for k in (1, 2, 3) for side in ("left", "right")]
    assert cols == list(range(env.obs_dim - 6, env.obs_dim))  # after the scan sectors
    td = env.reset()
    assert torch.equal(td["observation"][:, cols], torch.zeros(3, 6))
    actions = [torch.tensor([[0.1 * t, -0.2 * t]] * 3) for t in range(1, 6)]
    actions[-1] = torch.tensor([[3.0, -3.0]] * 3)  # observed as the motors take it: clipped to [-1, 1]
    for action in actions:
        shown = td["observation"][:, cols].reshape(3, 3, 2)
        td = env.step(td.set("action", action))["next"]
        # latency 2: this step applied the action shown two steps back (none, zero torque, at first)
        assert torch.allclose(env.sim.commands, shown[:, 1] * env.task_cfg.action_scale)
    expected = torch.stack([actions[-1].clamp(-1, 1), actions[-2], actions[-3]], 1).reshape(3, 6)
    assert torch.allclose(td["observation"][:, cols], expected)
    saved = env.state_dict()
    reset = env.reset(td.set("_reset", torch.tensor([[True], [False], [False]])))
    assert torch.equal(reset["observation"][0, cols], torch.zeros(6))
    assert torch.equal(reset["observation"][1:, cols], expected[1:])
    env.load_state_dict(saved)
    assert torch.equal(env.observe(env.target.clone())[:, cols], expected)
    env.record_actions(torch.full((3, 2), 0.5))  # driving outside the step loop (the ROS node)
    assert torch.allclose(env.observe(env.target.clone())[:, cols[:2]], torch.full((3, 2), 0.5))
    assert ATRVjrEnv(2).obs_dim == len(OBS_INDEX)  # the reference task observes no actions


def test_motor_lag_is_first_order():
    tau = 0.1
    env = ATRVjrEnv(1, seed=0, randomization=RandomizationConfig(motor_lag=Draw(tau, tau)))
    td = env.reset()
    applied = []
    for _ in range(4):
        td = env.step(td.set("action", torch.ones(1, 2)))["next"]
        applied.append(env.sim.commands[0, 0].item())
    scale, keep = env.task_cfg.action_scale, torch.exp(torch.tensor(-0.05 / tau)).item()
    assert applied == pytest.approx([scale * (1 - keep ** (n + 1)) for n in range(4)], rel=1e-5)


def test_observation_and_scan_noise():
    clean = ATRVjrEnv(512, seed=4, task="nav")
    noisy = ATRVjrEnv(512, seed=4, task="nav", randomization=RandomizationConfig(noise=SENSOR_NOISE))
    a, b = roll(clean, 3, 0.0)[-1], roll(noisy, 3, 0.0)[-1]
    dv = (b - a)[:, OBS_INDEX["rover_vx"]]
    assert float(dv.std()) == pytest.approx(SENSOR_NOISE.velocity, rel=0.15)
    dr = (b - a)[:, OBS_INDEX["yaw_rate"]]
    assert float(dr.std()) == pytest.approx(SENSOR_NOISE.gyro, rel=0.15)
    assert torch.equal(a[:, OBS_INDEX["target_x"]], b[:, OBS_INDEX["target_x"]])  # the target is not sensed
    assert noisy.scanner.cfg.noise_std == SENSOR_NOISE.scan_range


@pytest.mark.parametrize("make,message", [
    (lambda: get_randomization("wild"), "unknown randomization preset 'wild'; known: \\['around', 'mild', 'none', 'wide', 'wide_slip', 'wide_slip_gain'\\]"),
    (lambda: RandomizationConfig(friction=Draw(0.8, 0.2)), "randomization.friction: low 0.8 > high 0.2"),
    (lambda: RandomizationConfig(friction=Draw(0.0, 0.5)), "randomization.friction: friction must be > 0"),
    (lambda: RandomizationConfig(payload_mass=Draw(-5.0, 5.0)), "randomization.payload_mass: payload_mass must be >= 0"),
    (lambda: RandomizationConfig(latency=(0, 20)), "randomization.latency: 20 steps exceed the action buffer"),
    (lambda: RandomizationConfig(odometry_scale=Draw(0.0, 1.2)), "randomization.odometry_scale: a scale must be > 0"),
    (lambda: RandomizationConfig(odometry_scale=Draw(1.0, math.inf)),
     "randomization.odometry_scale: low and high must be finite"),
    (lambda: RandomizationConfig(odometry_slip_gain=Draw(-0.5, 1.0)), "randomization.odometry_slip_gain: a gain must be >= 0"),
    (lambda: RandomizationConfig(friction=Draw(0.2, 1.0, mode="sometimes")), "unknown mode 'sometimes'"),
    (lambda: ATRVjrEnv(2, randomization="wild"), "unknown randomization preset"),
])
def test_bad_settings_are_one_line_errors(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_state_dict_restores_the_draws():
    env = ATRVjrEnv(4, seed=3, randomization="wide")
    roll(env, 5)
    saved = env.state_dict()
    roll_from(env, 10)  # wander off before restoring
    env.load_state_dict(saved)
    fresh = ATRVjrEnv(4, seed=9, randomization="wide")
    fresh.load_state_dict(saved)
    for e in (env, fresh):
        assert torch.equal(e.sim.params.friction, saved["sim.params.friction"])
        assert torch.equal(e.latency, saved["task.delay.latency"])
    assert torch.equal(roll_from(env, 10), roll_from(fresh, 10))


def roll_from(env, steps):
    from tensordict import TensorDict

    td = TensorDict({}, batch_size=env.batch_size)
    out = []
    for _ in range(steps):
        td = env.step(td.set("action", torch.full((env.num_envs, 2), 0.3)))["next"]
        out.append(td["observation"].clone())
    return torch.stack(out)


def test_train_config_key():
    assert load_train_config("smoke", {"env.randomization": "wide"}).env.randomization == "wide"
    with pytest.raises(ValueError, match="randomization: unknown randomization preset 'wild'"):
        load_train_config("smoke", {"randomization": "wild"})
    with pytest.raises(ValueError, match="train config: eval_randomization: unknown randomization preset 'wild'"):
        load_train_config("smoke", {"eval_randomization": "wild"})
    # trains wider than it is judged on
    deploy = load_train_config("nav_deploy", {"env.randomization": "wide_slip", "env.eval_randomization": "wide"})
    assert (deploy.env.randomization, deploy.env.eval_randomization) == ("wide_slip", "wide")
    assert dict(deploy.env.eval_env_kwargs())["randomization"] == "wide"
    assert dict(deploy.env.env_kwargs())["randomization"] == "wide_slip"
    assert dict(load_train_config("smoke").env.eval_env_kwargs()) == dict(load_train_config("smoke").env.env_kwargs())


# ------------------------------------------------------------------ around a simulator config
CALIBRATED = """\
[rover]
torque_scale = 0.79
payload_mass = 10.3
wheel_radius = 0.126
[contact]
friction = 0.51
[calibration]
bag = "drive.mcap"
[calibration.standard_error]
friction = 0.004
torque_scale = 0.05
payload_mass = 0.6
wheel_radius = nan
"""
"""What ``atrv-calibrate`` writes (``benchmarks/results/calibration_console.txt``'s fit, torque's error widened)."""


@pytest.fixture
def calibrated(tmp_path):
    path = tmp_path / "calibrated.toml"
    path.write_text(CALIBRATED)
    return path


def test_around_resolves_to_ranges_centred_on_the_file(calibrated, tmp_path):
    from atrv_warp.sim.sysid.config import DEFAULT_FIT

    assert set(AroundConfig().parameters) == set(DEFAULT_FIT)  # what atrv-calibrate fits by default, as documented
    r = get_randomization("around", sim_config=calibrated)
    assert r == resolve_around(AROUND_PRESETS["around"], calibrated)
    half = {"friction": 0.1 * 0.51,  # 2 standard errors (0.008) < 10 % of the value
            "torque_scale": 2 * 0.05,  # 2 standard errors > 10 %
            "payload_mass": 2 * 0.6,
            "wheel_radius": 0.1 * 0.126}  # no standard error (nan): 10 %
    centre = {"friction": 0.51, "torque_scale": 0.79, "payload_mass": 10.3, "wheel_radius": 0.126}
    assert set(r.physics) == set(half)
    for name, draw in r.physics.items():
        assert (draw.low + draw.high) / 2 == pytest.approx(centre[name]), name
        assert (draw.high - draw.low) / 2 == pytest.approx(half[name]), name
        assert draw.mode == "reset" and not draw.log
    mild = RANDOMIZATION_PRESETS["mild"]
    assert r.latency == mild.latency and r.noise == mild.noise  # what is not fitted: as mild
    # a file written by hand, no standard errors: the stated fraction; clipped to each parameter's valid values
    hand = tmp_path / "hand.toml"
    hand.write_text("[rover]\npayload_mass = 0.0\n[contact]\nfriction = 0.05\n[calibration.standard_error]\n"
                    "friction = 0.05\npayload_mass = 1.0\n")
    wide = resolve_around(AroundConfig(parameters=("friction", "payload_mass"), fraction=0.2), hand)
    assert (wide.friction.low, wide.friction.high) == pytest.approx((0.005, 0.15))  # > 0: a tenth of the centre
    assert (wide.payload_mass.low, wide.payload_mass.high) == pytest.approx((0.0, 2.0))  # >= 0
    # the fraction alone where the file records no standard error
    hand.write_text("[contact]\nfriction = 0.6\n")
    alone = resolve_around(AroundConfig(parameters=("friction",), fraction=0.25), hand)
    assert (alone.friction.low, alone.friction.high) == pytest.approx((0.45, 0.75))


def test_around_draws_stay_around_the_calibrated_rover(calibrated):
    """A real env: every world's drawn physics lies in the resolved ranges around the file's values, spread within
    them, not over ``wide``'s absolute ranges; what ``around`` does not draw keeps the file's (and the rover's)
    value; the draws follow the seed."""
    r = get_randomization("around", sim_config=calibrated)
    env = ATRVjrEnv(16, seed=4, randomization="around", sim_config=calibrated)
    assert env.randomization == r
    env.reset()
    p = env.sim.params
    for name, draw in r.physics.items():
        values = p.view(name)
        assert float(values.min()) >= draw.low - 1e-6 and float(values.max()) <= draw.high + 1e-6, name
        assert float(values.std()) > 0.15 * (draw.high - draw.low), name  # drawn, not one value
    wide = RANDOMIZATION_PRESETS["wide"]
    # the same 16 worlds under wide: mu over 0.2-1.0 and payload over 0-25 kg; around them, within 10 % and 1.2 kg
    assert float((p.friction - 0.51).abs().max()) <= 0.051 + 1e-6
    assert float((p.payload_mass - 10.3).abs().max()) <= 1.2 + 1e-5
    under_wide = ATRVjrEnv(16, seed=4, randomization="wide", sim_config=calibrated)
    under_wide.reset()
    assert float((under_wide.sim.params.friction - 0.51).abs().max()) > 0.1
    assert wide.friction.low < 0.4 and wide.payload_mass.low == 0.0
    assert torch.equal(p.speed_limit, torch.full((16,), 50.0))  # not drawn: the rover's
    assert torch.all(p.payload_offset == 0)
    body = env.sim.model.body_mass.numpy().reshape(16, -1)[:, env.sim.layout.chassis_body]
    assert body == pytest.approx(env.sim.nominal_chassis.mass + p.payload_mass.numpy(), rel=1e-6)
    again = ATRVjrEnv(16, seed=4, randomization="around", sim_config=calibrated)
    again.reset()
    assert torch.equal(again.sim.params.payload_mass, p.payload_mass)


def test_around_a_config_that_lacks_a_drawn_parameter_is_one_line(tmp_path, monkeypatch):
    """Bad input: a file without a parameter ``around`` draws is named, with the parameter, before any simulator
    is built; ``around`` without a file says it needs one."""
    import atrv_warp.task.env as env_module

    lacking = tmp_path / "no_payload.toml"
    lacking.write_text("[rover]\ntorque_scale = 0.8\nwheel_radius = 0.125\n[contact]\nfriction = 0.5\n")

    def no_simulator(*args, **kwargs):
        raise AssertionError("a simulator was built")

    monkeypatch.setattr(env_module, "RoverSim", no_simulator)
    with pytest.raises(ValueError) as err:
        ATRVjrEnv(2, randomization="around", sim_config=lacking)
    line = str(err.value)
    assert "\n" not in line and str(lacking) in line and "payload_mass ([rover] payload_mass)" in line
    with pytest.raises(ValueError, match="randomization 'around' is centred on a simulator config: give one"):
        ATRVjrEnv(2, randomization="around")
    with pytest.raises(ValueError, match="train config: randomization: randomization around sim config .*"
                                         "does not set payload_mass"):
        load_train_config("smoke", {"randomization": "around", "sim_config": str(lacking)})
    with pytest.raises(ValueError, match="train config: randomization: .* give one"):
        load_train_config("smoke", {"randomization": "around"})
    with pytest.raises(ValueError, match="payload_offset cannot be drawn around a value"):
        AroundConfig(parameters=("payload_offset",))
    with pytest.raises(ValueError, match="unknown physical parameter 'mu'"):
        AroundConfig(parameters=("mu",))


def test_evaluate_reports_the_calibrated_rover_and_the_spread_around_it(calibrated, tmp_path, capsys):
    """``evaluate --sim-config F --randomization around``: two rows on the same episodes, the rover of the file and
    across the spread, and the JSON holds both, the ranges and success by bins across them."""
    from atrv_warp.cli.evaluate import main

    out = tmp_path / "around.json"
    assert main(["--baseline", "--episodes", "8", "--sim-config", str(calibrated), "--randomization", "around",
                 "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"on {calibrated}: success" in printed and f"around {calibrated}: success" in printed
    assert "randomization around" in printed and "success by payload_mass" in printed
    result = json.loads(out.read_text())
    assert result["randomization"] == "around" and result["on_sim_config"]["episodes"] == 8
    assert result["ranges"]["payload_mass"] == pytest.approx([9.1, 11.5])
    bins = result["success_by_bin"]
    assert set(bins) == {"friction", "payload_mass", "torque_scale", "wheel_radius", "latency"}
    assert all(sum(row["episodes"] for row in rows) == 8 for rows in bins.values())
    assert bins["payload_mass"][0]["low"] == pytest.approx(9.1) and math.isclose(bins["payload_mass"][-1]["high"], 11.5)
    assert main(["--baseline", "--episodes", "2", "--randomization", "around"]) == 2
    assert "give it with --sim-config FILE" in capsys.readouterr().err
    lacking = tmp_path / "lacking.toml"
    lacking.write_text("[contact]\nfriction = 0.5\n")
    assert main(["--baseline", "--episodes", "2", "--sim-config", str(lacking), "--randomization", "around"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and str(lacking) in err and "payload_mass" in err
