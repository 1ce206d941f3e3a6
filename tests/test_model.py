"""URDF loading, validation, model building and inspection."""

import dataclasses
import subprocess
import sys
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


def test_model_cli():
    out = subprocess.run([sys.executable, "-m", "atrv_warp.model", "--variant", "reference"],
                         capture_output=True, text=True, check=True).stdout
    assert "10 bodies, 10 degrees of freedom; mass 54.00 kg" in out
    assert "left_front_wheel_link" in out


def test_config_errors():
    with pytest.raises(ValueError, match="unknown rover variant 'fast'"):
        get_variant("fast")
    with pytest.raises(ValueError, match=r"unknown RoverConfig key\(s\) \['wheel_radus'\]"):
        replace_checked(RoverConfig(), wheel_radus=0.1)
