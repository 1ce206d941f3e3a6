"""Core placement: a run's worker processes pin to the run's other cores, not to the one the trainer took."""

import json
import os
import subprocess
import sys

import pytest

_SCRIPT = """
import json, multiprocessing, os
from atrv_warp.runtime import pin_to_core

def child(queue):
    pin_to_core(1)  # as the async collector's worker and the background validation do
    queue.put(sorted(os.sched_getaffinity(0)))

if __name__ == "__main__":
    cores = sorted(os.sched_getaffinity(0))
    pin_to_core(0)  # the trainer pins itself first, as train() does
    context = multiprocessing.get_context("spawn")
    queue = context.Queue()
    process = context.Process(target=child, args=(queue,))
    process.start()
    print(json.dumps({"cores": cores, "trainer": sorted(os.sched_getaffinity(0)), "worker": queue.get(timeout=60)}))
    process.join()
"""


def _session_cores() -> list[int]:
    """The cores this test session may use, even where a ``train()`` in this process has pinned it to one."""
    if not hasattr(os, "sched_setaffinity"):
        pytest.skip("needs an OS with affinity calls")
    from atrv_warp.runtime import run_cores

    cores = run_cores()
    if len(cores) < 2:
        pytest.skip("needs two cores")
    return cores


def test_a_worker_started_by_a_pinned_trainer_pins_to_the_other_core(tmp_path):
    cores = _session_cores()
    script = tmp_path / "pin.py"
    script.write_text(_SCRIPT)
    env = {k: v for k, v in os.environ.items() if k != "ATRV_WARP_CORES"}  # a fresh run, on all the cores
    out = json.loads(subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env,
                                    timeout=120, check=True,
                                    preexec_fn=lambda: os.sched_setaffinity(0, set(cores))).stdout)
    assert out["cores"] == cores, out
    assert out["trainer"] == [cores[0]] and out["worker"] == [cores[1]], out


def test_a_bad_cores_variable_is_one_line(monkeypatch):
    from atrv_warp.runtime import run_cores

    monkeypatch.setenv("ATRV_WARP_CORES", "0,one")
    with pytest.raises(ValueError, match=r"ATRV_WARP_CORES='0,one': expected core numbers separated by commas"):
        run_cores()


def test_a_started_process_is_pinned_by_its_parent():
    """The background validation is pinned from the trainer as it starts, before its imports run anywhere."""
    from atrv_warp.runtime import pin_to_core

    cores = _session_cores()
    mine = os.sched_getaffinity(0)
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        pin_to_core(1, pid=child.pid)
        assert os.sched_getaffinity(child.pid) == {cores[1]}
        assert os.sched_getaffinity(0) == mine  # this process left as it was
    finally:
        child.kill()
        child.wait()
