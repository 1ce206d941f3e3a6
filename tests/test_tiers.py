"""The quick tier trains nothing and starts no node or cluster, and a command run in this process behaves as the
interpreter would run it (``tests/conftest.py``)."""

from __future__ import annotations

import os
import sys

import pytest
import torch
from conftest import HEAVY_FIXTURES, heavy_without_slow, run_in_process


class _Item:
    """What the collection check reads of a collected test: its id, its fixtures and its marks."""

    def __init__(self, nodeid: str, fixtures: tuple[str, ...], slow: bool):
        self.nodeid, self.fixturenames, self._slow = nodeid, fixtures, slow

    def get_closest_marker(self, name: str):
        return object() if name == "slow" and self._slow else None


def test_a_heavy_fixture_outside_the_slow_tier_is_named():
    items = [_Item("t.py::quick_trains", ("tmp_path", "smoke_run"), slow=False),
             _Item("t.py::slow_trains", ("smoke_run",), slow=True),
             _Item("t.py::quick_ros", ("ros_env",), slow=False), _Item("t.py::plain", ("tmp_path",), slow=False)]
    assert heavy_without_slow(items) == [
        "t.py::quick_trains uses the fixture 'smoke_run' (trains) but is not marked slow",
        "t.py::quick_ros uses the fixture 'ros_env' (starts ROS 2 nodes) but is not marked slow"]
    assert set(HEAVY_FIXTURES) == {"smoke_run", "ros_env", "no_ray_before"}
    assert heavy_without_slow([_Item("t.py::quick_ray", ("no_ray_before",), slow=False)]) == [
        "t.py::quick_ray uses the fixture 'no_ray_before' (guards a test that starts a Ray cluster) but is not marked slow"]


def test_the_training_loop_refuses_in_the_quick_tier(tmp_path):
    """A quick test that reaches the training loop fails there, before the first batch, naming itself."""
    from atrv_warp.rl.command_line import load_train_config
    from atrv_warp.rl.loop import train

    with pytest.raises(AssertionError, match=r"test_tiers\.py::test_the_training_loop_refuses_in_the_quick_tier "
                                             r"trains but is not marked slow"):
        train(load_train_config("smoke", {"out_dir": str(tmp_path)}))
    assert not (tmp_path / "smoke" / "checkpoint.pt").exists()


def test_a_command_in_this_process_exits_and_prints_as_it_would_alone(tmp_path):
    before = (dict(os.environ), os.getcwd(), list(sys.argv), torch.get_num_threads())
    os.chdir(tmp_path)
    try:
        bad = run_in_process("atrv_warp.evaluate", "--episodes", "many")  # argparse: exit 2, one line on stderr
        assert bad.returncode == 2 and "--episodes: invalid int value: 'many'" in bad.stderr, bad.stderr
        assert bad.args[1:] == ["-m", "atrv_warp.evaluate", "--episodes", "many"] and bad.stdout == ""
        helped = run_in_process("atrv_warp.model", "--help")
        assert helped.returncode == 0 and helped.stdout.startswith("usage: ") and helped.stderr == ""
        raised = run_in_process("atrv_warp.no_such_module")  # the interpreter's answer: a traceback, exit 1
        assert raised.returncode == 1 and "No module named atrv_warp.no_such_module" in raised.stderr
        assert os.getcwd() == str(tmp_path)  # it ran in the repository root, and came back
    finally:
        os.chdir(before[1])
    assert (dict(os.environ), os.getcwd(), list(sys.argv), torch.get_num_threads()) == before
