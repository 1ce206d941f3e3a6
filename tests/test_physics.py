"""Physics of the simulator against the reference's figures and analytic answers."""

import numpy as np
import pytest
import torch

from atrv_warp import RoverSim
from atrv_warp.sim import FAST_SIM_DT, REFERENCE_SIM_DT, SimConfig, protocols

STEP = 0.05  # [s] per env step


def run(sim, seconds):
    for _ in range(round(seconds / STEP)):
        sim.step()


@pytest.fixture(scope="module")
def reference_drive():
    """Reference variant dropped 2 cm above rest, settled 1 s, then +4 N·m on all wheels."""
    run = protocols.reference_drive()
    return run.sim, run.settle_z, run.track


def test_settles_level_at_rest_height(reference_drive):
    _sim, z, _ = reference_drive
    # Drop transient: the reference oscillated between about 0.125 and 0.150 m.
    assert 0.120 < z.min() < 0.130 and 0.145 < z.max() < 0.160
    sim2 = RoverSim(1)  # realistic, 58 kg
    sim2.reset(height=sim2.rest_height + 0.02)
    run(sim2, 3.0)
    zs = []
    for _ in range(20):  # average over 1 s: the lightly damped bounce (zeta ~ 0.03) is still ringing
        sim2.step()
        zs.append(sim2.root_pose[0, 2].item())
    zr = float(np.mean(zs))
    # Static equilibrium of the Hunt–Crossley law: d = (m g / 4 kp)^(1/n) below the 0.15 m axle.
    assert zr == pytest.approx(sim2.rest_height, abs=1e-4)
    assert zr == pytest.approx(0.137, abs=1.5e-3)  # reference: 0.137 m
    roll, pitch, _ = sim2.rpy[0].tolist()
    assert abs(roll) < 1e-3 and abs(pitch) < 2e-3
    assert sim2.lin_vel[0, :2].abs().max().item() < 1e-4  # no horizontal motion
    assert sim2.lin_vel[0, 2].abs().item() < 0.02  # what is left of the bounce


def test_reference_variant_drives_like_reference(reference_drive):
    _, _, track = reference_drive
    x3, x49 = track[59, 0], track[97, 0]  # after 3.0 s and 4.9 s of driving
    assert x3 == pytest.approx(1.72, rel=0.10)
    assert x49 == pytest.approx(4.70, rel=0.10)
    assert np.abs(track[:, 1]).max() < 0.02  # lateral drift
    # height steady once the 2 cm drop has rung out (the first 2 s of driving still carry it)
    assert track[40:, 2].std() < 5e-4 and track[40:, 2].mean() == pytest.approx(0.137, abs=2e-3)


def test_realistic_acceleration_matches_analytic():
    sim = RoverSim(1)
    run(sim, 0.5)
    tau = 2.0  # [N·m] per wheel, below the slip limit
    sim.set_commands([tau, tau])
    run(sim, 0.5)
    v0, t0 = sim.lin_vel[0, 0].item(), sim.sim_time
    run(sim, 1.5)
    accel = (sim.lin_vel[0, 0].item() - v0) / (sim.sim_time - t0)
    assert accel == pytest.approx(protocols.rolling_acceleration(sim, tau), rel=0.05)


def test_rotate_left_turns_in_place():
    sim = RoverSim(2)
    run(sim, 0.5)
    start = sim.root_pose[:, :2].clone()
    yaw0 = sim.rpy[:, 2].clone()
    sim.set_mode("rotate_left", worlds=[0])
    sim.set_mode("rotate_right", worlds=[1])
    yaw = [sim.rpy[:, 2].clone()]
    for _ in range(40):
        sim.step()
        yaw.append(sim.rpy[:, 2].clone())
    dyaw = torch.diff(torch.stack(yaw), dim=0)
    dyaw = torch.remainder(dyaw + np.pi, 2 * np.pi) - np.pi  # unwrap
    turned = dyaw.sum(0)
    assert turned[0] > 1.0 and turned[1] < -1.0  # left = counter-clockwise
    assert (dyaw[5:, 0] > 0).all() and (dyaw[5:, 1] < 0).all()  # yaw grows monotonically
    assert (sim.root_pose[:, :2] - start).norm(dim=-1).max() < 0.10
    assert abs((yaw0[0] - yaw0[1]).item()) < 1e-6


def test_zero_torque_no_creep():
    sim = RoverSim(1)
    run(sim, 0.5)
    p0 = sim.root_pose[0, :3].clone()
    run(sim, 5.0)
    assert (sim.root_pose[0, :3] - p0).norm().item() < 1e-4
    assert sim.wheel_speed.abs().max().item() < 1e-3


def test_wall_contact_flags_only_that_world():
    sim = RoverSim(3)
    # world 0 faces the +x wall 0.5 m away; world 1 drives in the open; world 2 backs into -y wall
    sim.reset(poses=[[14.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, -14.2, np.pi / 2]])
    sim.set_commands([[6.0, 6.0], [6.0, 6.0], [-6.0, -6.0]])
    seen = torch.zeros(3, dtype=torch.bool)
    first = [None] * 3
    for i in range(60):
        sim.step()
        for w in range(3):
            if sim.wall_contact[w] and first[w] is None:
                first[w] = i
        seen |= sim.collision
    assert seen.tolist() == [True, False, True]
    assert sim.root_pose[0, 0].item() < 15.0 - 0.3  # the wall stops the chassis (front 0.32 m ahead)
    assert not sim.body_ground_contact.any()


def test_worlds_are_independent():
    torch.manual_seed(1)
    poses = torch.tensor([[0.0, 0.0, 0.3], [5.0, -3.0, -1.0], [-8.0, 2.0, 2.5]])
    cmds = (torch.rand(30, 3, 2) * 2 - 1) * 20
    batch = RoverSim(3)
    batch.reset(poses=poses)
    for c in cmds:
        batch.step(c)
    for w in range(3):
        alone = RoverSim(1)
        alone.reset(poses=poses[w:w + 1])
        for c in cmds:
            alone.step(c[w:w + 1])
        assert torch.equal(alone.root_pose[0], batch.root_pose[w])
        assert torch.equal(alone.wheel_speed[0], batch.wheel_speed[w])


def test_same_inputs_bit_identical():
    torch.manual_seed(2)
    cmds = (torch.rand(50, 4, 2) * 2 - 1) * 20
    poses = (torch.rand(4, 3) * 2 - 1) * torch.tensor([12.0, 12.0, np.pi])
    out = []
    for use_graph in (True, True, False):
        from atrv_warp import SimConfig
        sim = RoverSim(4, sim=SimConfig(use_graph=use_graph))
        sim.reset(poses=poses)
        for c in cmds:
            sim.step(c)
        out.append(torch.cat([sim.root_pose, sim.lin_vel, sim.wheel_speed], -1).clone())
    assert torch.equal(out[0], out[1])
    assert torch.equal(out[0], out[2])  # the recorded graph replays exactly the eager step


def test_separate_cholesky_drives_as_the_fused_one():
    """``SimConfig.fuse_cholesky`` reaches Newton's solver and changes only where the factorisation runs."""
    from atrv_warp import SimConfig

    torch.manual_seed(2)
    cmds = (torch.rand(30, 4, 2) * 2 - 1) * 20
    poses = (torch.rand(4, 3) * 2 - 1) * torch.tensor([12.0, 12.0, np.pi])
    assert SimConfig().resolve_fuse_cholesky(on_cpu=True) is False  # the CPU default: separate
    assert SimConfig().resolve_fuse_cholesky(on_cpu=False) is True  # elsewhere Newton's fused kernel
    out = []
    for fuse in (True, False):
        sim = RoverSim(4, sim=SimConfig(fuse_cholesky=fuse))
        assert sim.solver.fuse_cholesky is fuse
        sim.reset(poses=poses)
        for c in cmds:
            sim.step(c)
        out.append(torch.cat([sim.root_pose, sim.lin_vel, sim.wheel_speed], -1).clone())
    torch.testing.assert_close(out[1], out[0], rtol=0.0, atol=1e-5)


@pytest.mark.slow
def test_random_actions_no_nan():
    gen = torch.Generator().manual_seed(3)
    sim = RoverSim(64)
    sim.reset(poses=(torch.rand(64, 3, generator=gen) * 2 - 1) * torch.tensor([12.0, 12.0, np.pi]))
    for _ in range(2000):
        sim.commands.copy_((torch.rand(64, 2, generator=gen) * 2 - 1) * 20)
        sim.step()
        assert sim.nonfinite.sum().item() == 0
    state = torch.cat([sim.root_pose, sim.lin_vel, sim.ang_vel, sim.rpy, sim.wheel_speed], -1)
    assert torch.isfinite(state).all()
    assert sim.wheel_speed.abs().max().item() <= sim.rover_cfg.wheel_speed_limit * 1.2
    inside = sim.root_pose[:, :2].abs().max().item()
    assert inside < 15.0  # walls keep every rover in the arena


def test_bad_commands_are_named():
    sim = RoverSim(2)
    with pytest.raises(ValueError, match=r"shape \(2, 2\) or \(2,\), got \(3,\)"):
        sim.set_commands([1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match=r"NaN/inf in world\(s\) \[1\]"):
        sim.set_commands([[0.0, 0.0], [float("nan"), 0.0]])
    with pytest.raises(ValueError, match="unknown driving mode 'fly'"):
        sim.set_mode("fly")


def test_reset_outside_the_arena_is_refused():
    sim = RoverSim(3)
    sim.reset(poses=[[14.5, 0.0, 0.0], [0.0, -14.5, 1.0], [0.0, 0.0, 0.0]])  # inside, near the walls
    before = sim.get_state()
    with pytest.raises(ValueError, match=r"outside the arena in world\(s\) \[1\]: \(x, y\) = \(0, 15\.5\) m; "
                                         r"\|x\| and \|y\| must be below 15 m"):
        sim.reset(poses=[[0.0, 0.0, 0.0], [0.0, 15.5, 0.0], [1.0, 1.0, 0.0]])
    with pytest.raises(ValueError, match=r"outside the arena in world\(s\) \[0\]"):
        sim.reset(mask=[0], poses=[[-20.0, 0.0, 0.0]])
    after = sim.get_state()
    assert all(torch.equal(before[k], after[k]) for k in before)  # a refused reset changes nothing


def test_masked_reset_leaves_others_untouched():
    sim = RoverSim(3)
    sim.set_commands([[5.0, 5.0], [5.0, -5.0], [-3.0, 4.0]])
    run(sim, 1.0)
    before = sim.get_state()
    pose_before = sim.root_pose.clone()
    sim.reset(mask=[False, True, False], poses=[[3.0, 4.0, 1.0]])
    assert torch.equal(sim.root_pose[[0, 2]], pose_before[[0, 2]])
    assert sim.root_pose[1, :2].tolist() == pytest.approx([3.0, 4.0])
    assert sim.rpy[1, 2].item() == pytest.approx(1.0, abs=1e-6)
    assert sim.lin_vel[1].abs().max().item() == 0.0 and sim.wheel_speed[1].abs().max().item() == 0.0
    # snapshot round trip: continuing from a restored state reproduces the original continuation
    sim.set_state(before)
    run(sim, 0.5)
    a = sim.root_pose.clone()
    sim.set_state(before)
    run(sim, 0.5)
    assert torch.equal(a, sim.root_pose)


def test_sensor_frames_follow_chassis():
    sim = RoverSim(1)
    sim.reset(poses=[[1.0, 2.0, np.pi / 2]])
    lrf = sim.frame_pose("lrf_frame")[0]
    # lrf sits 0.30 m ahead of the chassis origin; yaw 90 deg turns "ahead" into +y
    assert lrf[:3, 3].tolist() == pytest.approx([1.0, 2.3, sim.rest_height + 0.19], abs=1e-5)
    assert "novatel" in sim.frame_names


@pytest.mark.parametrize("sim_dt", [REFERENCE_SIM_DT, FAST_SIM_DT], ids=["default", "three-substeps"])
def test_wall_impacts_at_top_speed_stay_under_1_2x_top_speed(sim_dt):
    """Three substeps with the plain Hunt–Crossley law threw rovers off walls at up to 1.4x top speed
    (and one blew up); ``ContactConfig.damping_limit`` keeps every impact under 1.2x. At five substeps
    no rover passes top speed; at three a few still leave a wall a little faster than they hit it."""
    got = protocols.wall_impacts(sim=SimConfig(sim_dt=sim_dt))
    assert got.nonfinite_worlds == 0
    assert got.overspeed_worlds == 0, f"{got.overspeed_worlds} worlds left a wall faster than 1.2x top speed"
    assert got.max_speed < 1.2 * got.top_speed


@pytest.mark.parametrize("mu", [0.3, 0.8])
def test_skid_steer_turns_as_coulomb_friction_predicts(mu):
    """The effective track ratio chi = r (w_right - w_left) / (yaw rate x track) under the base's motor driver,
    in place and on an arc: inside 1.3-2.0 (a Pioneer 3-AT measured about
    1.5) and within 5 % of pure Coulomb friction on the same wheel speeds. The 0.1.x viscous law gave
    8.28 whatever mu."""
    from atrv_warp.sim import ContactConfig
    from atrv_warp.sim.driver import DriverConfig

    contact = ContactConfig(friction=mu)
    sim = RoverSim(1, contact=contact)
    xy = protocols.wheel_contact_xy(sim)
    track = float(xy[:, 1].max() - xy[:, 1].min())
    r = sim.rover_cfg.wheel_radius
    side = np.array([w.side for w in sim.description.wheels])
    driver = DriverConfig(wheel_radius=r, track_width=track, effective_track_factor=1.0)
    for row in protocols.turning_response([(0.0, 0.5), (0.5, 0.5)], driver=driver, contact=contact, seconds=6.0,
                                       average=2.0):
        left, right = row["wheel_left"], row["wheel_right"]
        chi = r * (right - left) / (row["yaw_rate"] * track)
        coulomb = r * (right - left) / (protocols.coulomb_twist(xy, r * np.where(side == 0, left, right))[2] * track)
        assert 1.3 <= chi <= 2.0, row
        assert chi == pytest.approx(coulomb, rel=0.05), row


def test_rolls_without_slip_below_the_traction_limit_and_saturates_at_mu_g():
    from atrv_warp.sim import ContactConfig

    assert protocols.slip_ratio(2.0) < 0.03  # +2 N·m per wheel, far below mu N r
    for mu in (0.3, 0.5):  # full torque: the wheels spin, the tyres slide (the chassis pitching as they do)
        assert protocols.full_torque_acceleration(ContactConfig(friction=mu)) == pytest.approx(mu * 9.81, rel=0.15)


@pytest.mark.parametrize(("field", "value"), [("friction", 0.0), ("friction", -0.3), ("friction", float("nan")),
                                              ("friction", float("inf")), ("stiffness", -1.0),
                                              ("friction_law", "sticky"), ("friction_rise", -0.1),
                                              ("friction_rise", float("nan"))])
def test_bad_contact_config_is_named(field, value):
    from atrv_warp.sim import ContactConfig

    with pytest.raises(ValueError, match=f"ContactConfig.{field}"):
        ContactConfig(**{field: value})


def test_friction_rising_with_slip_caps_a_brisk_turn_near_the_torque_limit():
    """A heavy, weak-motored rover at high µ turns in place near its torque limit. Under Coulomb's law the
    resistance does not depend on the turn's rate, so it turns at 1 rad/s as at 0.25; with the sliding friction
    rising with slip (ContactConfig.friction_rise) the brisk turn is capped where the motors run out, the slow one
    hardly changes (calibration_twin.py: the MuJoCo twin's turns on such a rover)."""
    from atrv_warp.sim import ContactConfig, RoverConfig
    from atrv_warp.sim.driver import DriverConfig

    rover = RoverConfig(torque_scale=0.62, payload_mass=18.0, wheel_radius=0.1185)
    driver = DriverConfig(wheel_radius=RoverConfig().wheel_radius)
    commands = torch.tensor([[0.0, 0.25], [0.0, 1.0]])
    rates = {}
    for rise in (0.0, 0.3):
        sim = RoverSim(2, rover=rover, contact=ContactConfig(friction=0.886, friction_rise=rise), driver=driver)
        yaw = torch.zeros(2)
        for k in range(60):
            sim.set_twist(commands)
            sim.step()
            if k >= 40:
                yaw += sim.ang_vel[:, 2] / 20
        rates[rise] = yaw / commands[:, 1]
    assert torch.isfinite(rates[0.3]).all()
    assert float(rates[0.0][1]) > 0.85  # Coulomb: the brisk turn as the slow one
    assert float(rates[0.3][1]) < 0.8 * float(rates[0.0][1])
    assert float(rates[0.3][0]) == pytest.approx(float(rates[0.0][0]), rel=0.1)


def _fused_error_on_an_arc(accel_time: float | None, seconds: float = 4.0) -> float:
    """How far [m] the base's fused odometry ends from the chassis' true displacement after a launch onto a tight
    arc (0.5 m/s, 1.5 rad/s) at µ 0.3, where the wheels slip."""
    from atrv_warp.sim import ContactConfig
    from atrv_warp.sim.driver import DRIVE_TWIST, DriverConfig

    sim = RoverSim(1, contact=ContactConfig(friction=0.3), driver=DriverConfig(odometry_accel_time=accel_time))
    sim.driver.mode.fill_(int(DRIVE_TWIST))
    start = sim.root_pose[0, :2].clone()
    for _ in range(round(seconds / sim.sim_cfg.step_dt)):
        sim.set_twist(torch.tensor([[0.5, 1.5]]))
        sim.step()
    return float((sim.driver.fused[0, :2] - (sim.root_pose[0, :2] - start)).norm())


def test_the_accelerometer_aided_odometry_follows_the_chassis_where_the_wheels_slip():
    """``DriverConfig.odometry_accel_time``: the fused odometry blends the integrated accelerometer with the
    encoders, so on a slippery arc it ends nearer the chassis than the encoders' distance does (ours slips there
    too); a time constant the substep cannot resolve, or one <= 0, is refused by name."""
    from atrv_warp.sim.driver import DriverConfig

    encoders, aided = _fused_error_on_an_arc(None), _fused_error_on_an_arc(3.0)
    assert encoders > 0.1  # the wheels slip on the arc and the encoders' distance runs ahead
    assert aided < 0.6 * encoders, (encoders, aided)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="DriverConfig.odometry_accel_time"):
            DriverConfig(odometry_accel_time=bad)
    with pytest.raises(ValueError, match="odometry_accel_time must be at least two substeps"):
        RoverSim(1, driver=DriverConfig(odometry_accel_time=0.001))
    # the simulator node's parameter of the same name: 0 is off, a bad value is named as the node's
    from atrv_warp.integrations.ros.parameters import PARAMETERS, driver_config

    params = {p.name: p.default for p in PARAMETERS}
    assert driver_config(params).odometry_accel_time is None
    assert driver_config({**params, "odometry_accel_time": 3.0}).odometry_accel_time == 3.0
    with pytest.raises(ValueError, match="parameter odometry_accel_time: must be a finite number > 0"):
        driver_config({**params, "odometry_accel_time": -1.0})


def test_an_implicit_speed_loop_holds_gains_that_make_the_explicit_loop_oscillate():
    """The Jackal's light wheels (0.0024 kg·m²) at four times the explicit rule's gains, ``kp x sim_dt / J`` about 6:
    turning in place at µ 0.3 its slipping wheels make the explicit loop oscillate for good, while the implicit one
    (``DriverConfig.implicit_speed_loop``, its proportional action on the substep's end speed, solved with the
    friction) settles within 0.2 s; at the explicit rule's gains the two agree within 1 % of the command."""
    from atrv_warp.sim.config import RoverConfig
    from atrv_warp.sim.driver import DriverConfig
    from atrv_warp.sim.robot_check import check_robot, driver_gains

    rover = RoverConfig(robot="jackal")
    kp, ki = driver_gains(check_robot("jackal")[1], implicit=False)

    def step(gain: float, implicit: bool) -> dict:
        driver = DriverConfig(kp=gain * kp, ki=gain * ki, implicit_speed_loop=implicit)
        return protocols.step_response(((0.0, 0.5),), (0.3,), seconds=2.0, rover=rover, driver=driver)[0]

    explicit, implicit = step(4.0, False), step(4.0, True)
    assert explicit["ripple"] > 0.1 and explicit["settle"] == float("inf")
    assert implicit["settle"] <= 0.2 and implicit["ripple"] < 0.01
    assert step(1.0, True)["steady"] == pytest.approx(step(1.0, False)["steady"], abs=0.01)


def test_the_implicit_loop_does_not_chatter_at_its_torque_limit():
    """The Jackal at µ 0.3 sent (1 m/s, 1 rad/s) from rest with a driver of factor 1: its 0.0024 kg·m² wheels, when
    they slip under the full 5 N·m, change speed by about 21 rad/s in a 0.01 s substep, and at its gain (``kp dt / J``
    3.9) that error saturated the output the other way: an output past its limit driven explicitly flipped between
    +5 and -5 N·m every substep, and the robot stopped turning. The loop is now solved implicitly through its limit
    (the unclamped output with its damping, held at the limit inside the friction solve: ``relax_drive``)."""
    from atrv_warp.core.kinematics import track_width
    from atrv_warp.sim.config import ContactConfig, RoverConfig
    from atrv_warp.sim.driver import DriverConfig
    from atrv_warp.sim.urdf import load_rover

    rover = RoverConfig(robot="jackal")
    driver = DriverConfig(wheel_radius=rover.wheel_radius, track_width=track_width(load_rover(rover), rover),
                          effective_track_factor=1.0)
    sim = RoverSim(1, rover=rover, contact=ContactConfig(friction=0.3), sim=SimConfig(step_dt=0.01), driver=driver)
    sim.reset(poses=[[0.0, -1.6, 0.0]])
    flips, last = 0, 0.0
    for _ in range(100):
        sim.set_twist([[1.0, 1.0]])
        sim.step()
        applied = float(sim.driver.state.applied.numpy()[0, 0])
        flips += abs(applied - last) > 9.0  # from one limit to the other in a substep
        last = applied
    assert flips < 5, f"the left side's output flipped between its limits {flips} times in 1 s"


def test_a_drive_is_a_smooth_function_of_the_rovers_parameters():
    """The Jackal driven 2 s through ``/cmd_vel`` at its rule's gain, its loop meeting the torque limit: the end pose
    moves smoothly with the motor's torque scale and the payload (the calibration differentiates it by forward
    differences). The loop's integral stops where the output meets the limit (``pi_side``) and the limit is held inside
    the friction solve's contact updates (``relax_drive``); with a hold that switched on past the limit and a slope
    that switched off at it, the second differences over these 21 values were 14 % of the change across them, and the
    fits stalled; with the limit imposed after the solve's sweep, 2.4 and 3.0 %."""
    from atrv_warp.sim.config import RoverConfig

    n, steps = 21, 40
    t = torch.arange(steps) * 0.05
    twist = torch.stack([0.6 + 0.5 * torch.sin(1.3 * t), 1.2 * torch.sin(0.9 * t + 0.5)], -1)
    for name, values in (("torque_scale", np.linspace(0.75, 0.85, n)), ("payload_mass", np.linspace(10.0, 14.0, n))):
        sim = RoverSim(n, rover=RoverConfig(robot="jackal"))
        sim.set_params(friction=0.5, **{"torque_scale": 0.8, "payload_mass": 12.0, name: values})
        sim.reset()
        for k in range(steps):
            sim.set_twist(twist[k].expand(n, 2))
            sim.step()
        end = torch.cat([sim.root_pose[:, :2], sim.rpy[:, 2:3]], -1).double().numpy()
        second = end[2:] - 2.0 * end[1:-1] + end[:-2]
        assert np.sqrt((second ** 2).mean()) < 0.01 * np.abs(end[-1] - end[0]).max(), name


def test_the_default_loop_is_implicit_under_coulomb_friction_and_explicit_under_the_viscous_law():
    """``DriverConfig.implicit_speed_loop`` left ``None``: implicit wherever the friction solve can take it (the default
    law), explicit under the viscous law, which has no solve; asked for under the viscous law, it is refused."""
    from atrv_warp.sim.config import ContactConfig
    from atrv_warp.sim.driver import DriverConfig

    assert ContactConfig().solve_geared_sides  # and a geared side's chain is solved with its friction
    assert DriverConfig().implicit_under("coulomb") and not DriverConfig().implicit_under("viscous")
    assert not DriverConfig(implicit_speed_loop=False).implicit_under("coulomb")
    assert RoverSim(1).driver_cfg.implicit_speed_loop is True
    viscous = ContactConfig(friction_law="viscous")
    assert RoverSim(1, contact=viscous).driver_cfg.implicit_speed_loop is False
    with pytest.raises(ValueError, match="implicit_speed_loop solves the drive with the wheels' Coulomb friction"):
        RoverSim(1, contact=viscous, driver=DriverConfig(implicit_speed_loop=True))


def test_geared_sides_solved_in_the_friction_solve_converge_in_the_substep_and_keep_one_speed():
    """The Jackal on the nav terrain (``ContactConfig.solve_geared_sides``, the chain inside the friction solve):
    its turn at the 0.01 s substep is the 0.0025 s one within 2 %, where the explicit chain's differs by over 5 %
    (``benchmarks/physics/contact_stiffness.py``), and each side's wheels still turn at one speed."""
    import math

    from atrv_warp.sim.config import ContactConfig, RoverConfig
    from atrv_warp.task.env import RoverEnv
    from atrv_warp.task.evaluation import EVAL_SEED

    def turned(dt: float, chain: bool) -> tuple[float, float]:
        env = RoverEnv(8, task="nav_deploy", robot="jackal", contact=ContactConfig(solve_geared_sides=chain),
                       sim=SimConfig(sim_dt=dt))
        env.set_seed(EVAL_SEED)
        td = env.reset()
        sim, cfg = env.sim, env.task_cfg
        action = torch.tensor([[0.5 / cfg.max_linear, 0.5 / cfg.max_angular]]).expand(8, 2)
        previous, yaw, spread = sim.rpy[:, 2].clone(), torch.zeros(8), 0.0
        for _ in range(round(6.0 / sim.sim_cfg.step_dt)):
            td["action"] = action
            td = env.step(td)["next"]
            yaw += torch.remainder(sim.rpy[:, 2] - previous + math.pi, 2 * math.pi) - math.pi
            previous = sim.rpy[:, 2].clone()
            side = torch.tensor([w.side for w in sim.description.wheels])
            for q in (0, 1):
                speeds = sim.wheel_speed[:, side == q]
                spread = max(spread, float((speeds.max(1).values - speeds.min(1).values).max()))
        return float((yaw / (0.5 * 6.0)).median()), spread

    assert RoverConfig(robot="jackal").robot_spec.motor_per_side
    (coarse, spread), (fine, _) = turned(0.01, True), turned(0.0025, True)
    assert coarse == pytest.approx(fine, rel=0.02) and spread < 0.5
    explicit_coarse, explicit_fine = turned(0.01, False)[0], turned(0.0025, False)[0]
    assert abs(explicit_coarse - explicit_fine) > 0.05 * explicit_fine
