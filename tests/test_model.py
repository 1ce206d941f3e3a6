"""URDF loading, validation, model building and inspection."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from atrv_warp.sim.config import RoverConfig, default_urdf_path, get_variant, replace_checked
from atrv_warp.sim.model import build_model, format_table, format_tree
from atrv_warp.sim.urdf import URDFError, load_rover

SPEC_LINKS = ["center_link", "left_front_wheel_link", "left_rear_wheel_link", "right_front_wheel_link",
              "right_rear_wheel_link", "cbimu_frame", "mpuimu_frame", "arm_base_frame", "lrf_frame", "novatel"]


def test_packaged_urdf_has_spec_links_and_geometry_inertias():
    desc = load_rover()
    assert [t[0] for t in desc.tree] == SPEC_LINKS
    # chassis: solid box 0.64 x 0.39 x 0.22 m, 48 kg
    m, (a, b, c) = 48.0, (0.64, 0.39, 0.22)
    expected = np.diag([m * (b * b + c * c) / 12, m * (a * a + c * c) / 12, m * (a * a + b * b) / 12])
    np.testing.assert_allclose(desc.chassis_inertial.inertia, expected, rtol=1e-9)
    assert desc.chassis_inertial.mass == 48.0
    for w in desc.wheels:  # solid cylinder r 0.125 m, length 0.075 m, 2.5 kg, axis = link z
        m, r, length = 2.5, 0.125, 0.075
        np.testing.assert_allclose(np.diag(w.inertial.inertia),
                                   [m * (3 * r * r + length * length) / 12] * 2 + [m * r * r / 2], rtol=1e-9)
    assert desc.total_mass == pytest.approx(58.0)  # the chassis and four 2.5 kg wheels: the realistic rover
    x = sorted({round(abs(w.origin[0, 3]), 6) for w in desc.wheels})
    assert x == [0.19]  # wheelbase 0.38 m
    track = 2 * (abs(desc.wheels[0].origin[1, 3]) + 0.03)
    assert track == pytest.approx(0.50)


def test_wheel_axes_follow_spec_convention():
    desc = load_rover()
    for w in desc.wheels:
        z_lateral = w.origin[:3, :3] @ np.array([0.0, 0.0, 1.0])
        side = 1.0 if w.side == 0 else -1.0
        np.testing.assert_allclose(z_lateral, [0.0, side, 0.0], atol=1e-9)  # link z points outward
        np.testing.assert_allclose(w.axis, [0.0, 0.0, side])  # +z left, -z right
        assert w.drive_sign == 1.0  # so positive torque drives every wheel forward
        np.testing.assert_allclose(w.outward, [0.0, 0.0, 1.0])


def test_reference_variant_masses():
    desc = load_rover(get_variant("reference"))
    assert desc.chassis_inertial.mass == 50.0
    for w in desc.wheels:
        assert w.inertial.mass == 1.0
        np.testing.assert_allclose(w.inertial.inertia, np.eye(3))


def test_missing_file_is_named(tmp_path):
    path = tmp_path / "nope.urdf"
    with pytest.raises(URDFError, match="not found.*nope.urdf"):
        load_rover(RoverConfig(urdf=str(path)))


def test_malformed_xml_is_named(tmp_path):
    path = tmp_path / "broken.urdf"
    path.write_text('<robot name="x"><link name="a"></robot>')
    with pytest.raises(URDFError, match="broken.urdf: malformed URDF"):
        load_rover(RoverConfig(urdf=str(path)))


def test_missing_required_link_is_named(tmp_path):
    text = Path(default_urdf_path()).read_text()
    path = tmp_path / "nolrf.urdf"
    path.write_text(text.replace('<link name="lrf_frame"/>', "").replace(
        '<joint name="lrf_frame_joint" type="fixed">\n    <parent link="center_link"/>\n'
        '    <child link="lrf_frame"/>\n    <origin xyz="0.3 0.0 0.19" rpy="0 0 0"/>\n  </joint>', ""))
    with pytest.raises(URDFError, match="required sensor frame link 'lrf_frame' not found"):
        load_rover(RoverConfig(urdf=str(path)))


def test_other_urdf_with_same_roles(tmp_path):
    """A different rover (renamed wheels, wider track, fixed-joint wheel rejected) builds from its roles."""
    text = Path(default_urdf_path()).read_text().replace("left_front_wheel", "lf_wheel")
    text = text.replace('<origin xyz="0.19 -0.22 0"', '<origin xyz="0.25 -0.30 0"')
    path = tmp_path / "other.urdf"
    path.write_text(text)
    rover = RoverConfig(urdf=str(path), left_wheels=("lf_wheel_link", "left_rear_wheel_link"))
    built = build_model(2, rover=rover)
    assert built.model.body_count == 10 and built.model.joint_dof_count == 20
    bad = tmp_path / "fixedwheel.urdf"
    bad.write_text(text.replace('name="lf_wheel_joint" type="continuous"', 'name="lf_wheel_joint" type="fixed"'))
    with pytest.raises(URDFError, match="lf_wheel_link.*revolute/continuous"):
        load_rover(dataclasses.replace(rover, urdf=str(bad)))


def test_built_model_layout():
    built = build_model(3)
    m = built.model
    assert m.body_count == 15  # chassis + 4 wheels per world; sensor frames are named frames
    assert m.joint_dof_count == 30 and m.joint_coord_count == 33  # 6 + 4 DOF per world
    assert m.articulation_count == 3
    assert m.world_count == 3
    assert [m.body_label[i].split("/")[-1] for i in range(5)] == SPEC_LINKS[:5]


def test_tree_and_table():
    desc = load_rover()
    tree = format_tree(desc)
    assert tree.splitlines()[0] == "center_link  <- world  (free)"
    assert "  novatel  <- center_link  (fixed)" in tree
    table = format_table(desc)
    assert "10 bodies, 10 degrees of freedom" in table


def test_model_cli(run_module):
    out = run_module("atrv_warp.model", "--variant", "reference").stdout
    assert "10 bodies, 10 degrees of freedom; mass 54.00 kg" in out
    assert "left_front_wheel_link" in out


def test_config_errors():
    with pytest.raises(ValueError, match="unknown rover variant 'fast'"):
        get_variant("fast")
    with pytest.raises(ValueError, match=r"unknown RoverConfig key\(s\) \['wheel_radus'\]"):
        replace_checked(RoverConfig(), wheel_radus=0.1)


ROS_URDF = """<?xml version="1.0"?>
<robot name="ros_rover">
  <link name="base_footprint"/>
  <joint name="base_footprint_joint" type="fixed">
    <parent link="base_footprint"/><child link="base_link"/><origin xyz="0 0 0.0635"/>
  </joint>
  <link name="base_link"/>
  <joint name="chassis_joint" type="fixed">
    <parent link="base_link"/><child link="chassis_link"/>
  </joint>
  <link name="chassis_link">
    <inertial><origin xyz="0.01 0 0.07"/><mass value="16.5"/>
      <inertia ixx="0.31" iyy="0.39" izz="0.45" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0 0 0.092"/><geometry><box size="0.42 0.31 0.184"/></geometry></collision>
  </link>
  <link name="payload_link">
    <inertial><mass value="2.0"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <joint name="payload_joint" type="fixed">
    <parent link="chassis_link"/><child link="payload_link"/><origin xyz="0 0 0.2"/>
  </joint>
  <link name="laser"/>
  <joint name="laser_joint" type="fixed">
    <parent link="base_link"/><child link="laser"/><origin xyz="0.12 0 0.3"/>
  </joint>
  WHEELS
</robot>
"""
WHEEL = """
  <link name="{name}_wheel_link">
    <inertial><mass value="0.477"/><inertia ixx="0.0013" iyy="0.0024" izz="0.0013" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin rpy="1.5708 0 0"/><geometry><cylinder radius="0.098" length="0.04"/></geometry></collision>
  </link>
  <joint name="{name}_wheel_joint" type="continuous">
    <parent link="chassis_link"/><child link="{name}_wheel_link"/>
    <origin xyz="{x} {y} 0.0345"/><axis xyz="0 1 0"/>
  </joint>"""


def _ros_urdf(tmp_path, sides=(("front_left", 0.131, 0.1878), ("front_right", 0.131, -0.1878),
                                ("rear_left", -0.131, 0.1878), ("rear_right", -0.131, -0.1878))) -> Path:
    path = tmp_path / "ros_rover.urdf"
    path.write_text(ROS_URDF.replace("WHEELS", "".join(WHEEL.format(name=n, x=x, y=y) for n, x, y in sides)))
    return path


def test_a_ros_urdf_loads_with_its_chassis_below_the_root_and_its_wheels_found(tmp_path):
    """A URDF written in the ROS conventions: base_footprint the root, a massless base_link, the mass on chassis_link
    below it with a payload fixed to it, a laser fixed to base_link, four wheels on continuous joints about +y. The
    chassis is one body with every link fixed to it (masses merged, each a frame in its frame), the wheels are found
    by the rule (left first, front first), each drives forward with a positive torque, and the rover settles."""
    rover = RoverConfig(urdf=str(_ros_urdf(tmp_path)), chassis_link="chassis_link", left_wheels=(), right_wheels=(),
                        sensor_frames=("laser",), wheel_radius=0.098, wheel_length=0.04, wheel_offset=0.0)
    desc = load_rover(rover)
    assert desc.chassis == "chassis_link" and desc.chassis_inertial.mass == pytest.approx(18.5)
    assert [w.link for w in desc.wheels] == ["front_left_wheel_link", "rear_left_wheel_link",
                                             "front_right_wheel_link", "rear_right_wheel_link"]
    assert [w.side for w in desc.wheels] == [0, 0, 1, 1] and all(w.drive_sign == 1.0 for w in desc.wheels)
    assert desc.wheel_radius == pytest.approx(0.098)
    frames = {f.name: f.transform for f in desc.frames}
    assert set(frames) == {"base_footprint", "base_link", "payload_link", "laser"}
    np.testing.assert_allclose(frames["base_footprint"][:3, 3], [0, 0, -0.0635])
    np.testing.assert_allclose(frames["laser"][:3, 3], [0.12, 0, 0.3])
    assert {row[0]: row[1:] for row in desc.tree}["base_link"] == ("chassis_link", "chassis_joint", "fixed")
    from atrv_warp import RoverSim

    sim = RoverSim(1, rover=rover)
    for _ in range(20):
        sim.step()
    z = float(sim.root_pose[0, 2])
    sim.commands[:] = 2.0
    for _ in range(20):
        sim.step()
    ground = sim.arena_cfg.ground_top
    assert z - ground == pytest.approx(0.0635, abs=0.01)  # on its wheels: their radius less their joints' height
    assert float(sim.root_pose[0, 0]) > 0.2  # and drives forward


def test_wheels_on_one_side_or_none_are_named(tmp_path):
    one_side = _ros_urdf(tmp_path, (("front_left", 0.1, 0.2), ("rear_left", -0.1, 0.2)))
    rover = RoverConfig(urdf=str(one_side), chassis_link="chassis_link", left_wheels=(), right_wheels=(),
                        sensor_frames=())
    with pytest.raises(URDFError, match="wheels on one side only"):
        load_rover(rover)
    none = tmp_path / "none.urdf"
    none.write_text(ROS_URDF.replace("WHEELS", ""))
    with pytest.raises(URDFError, match="found 0 wheel joint"):
        load_rover(dataclasses.replace(rover, urdf=str(none)))


def test_a_urdf_that_is_no_tree_or_no_regular_file_is_refused_before_anything_walks_it(tmp_path):
    """Issue 70: a joint loop (through the chassis' parent: it hung every reader), a second root, a link with two
    parents, a device, a pipe or an oversized file are each one URDFError naming the problem, at once."""
    import os
    import time

    ros = _ros_urdf(tmp_path).read_text()
    rover = RoverConfig(chassis_link="chassis_link", left_wheels=(), right_wheels=(), sensor_frames=())
    loop = ('<joint name="back_up" type="fixed"><parent link="chassis_link"/><child link="base_footprint"/>'
            "</joint></robot>")
    cases = {"loop": (loop, r"has one root link .* has 0: \[\] \(a loop of joints leaves none\)"),
             "orphan": ('<link name="orphan"/></robot>', r"has one root link .* has 2: \['base_footprint', 'orphan'\]"),
             "two_parents": (('<joint name="again" type="fixed"><parent link="laser"/><child link="chassis_link"/>'
                              "</joint></robot>"), r"link 'chassis_link' is the child of two joints")}
    for name, (tail, message) in cases.items():
        path = tmp_path / f"{name}.urdf"
        path.write_text(ros.replace("</robot>", tail))
        t0 = time.perf_counter()
        with pytest.raises(URDFError, match=message):
            load_rover(dataclasses.replace(rover, urdf=str(path)))
        assert time.perf_counter() - t0 < 5.0, name
    pipe = tmp_path / "pipe.urdf"
    os.mkfifo(pipe)
    big = tmp_path / "big.urdf"
    big.write_bytes(b" " * (11 << 20))
    for path, message in ((Path("/dev/zero"), "the URDF is not a regular file"), (pipe, "the URDF is not a regular file"),
                          (big, r"the URDF is 11.0 MiB, over the 10 MiB")):
        with pytest.raises(URDFError, match=message):
            load_rover(dataclasses.replace(rover, urdf=str(path)))
