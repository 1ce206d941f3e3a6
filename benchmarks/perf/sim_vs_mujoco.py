"""Our simulator against MuJoCo's C rollout of the MJCF twin, in one run, on one core (issue #17).

Run: ``pip install -e .[bench]`` once, then
``python -m benchmarks.perf.sim_vs_mujoco [--sizes 64 1024 4096] [--rounds 3] [--work 65536]``

Both simulators do the same work: N rovers (N = 64, 1,024, 4,096), random wheel torques
uniform in ±20 N·m, drawn once per 0.05 s env step (left and right side, the same numbers for
both), 0.01 s solver steps (5 per env step). Ours: ``atrv_warp.sim.RoverSim(N)``, commands written
into ``sim.commands`` then ``sim.step()``. MuJoCo: ``mujoco.rollout.rollout`` of N copies of
``benchmarks/perf/mujoco_twin/atrvjr.xml`` with one ``MjData`` (nthread=1: the calling thread, no pool)
and the controls of the same simulated time. An env-step is 0.05 s of one rover; MuJoCo's count is
N x (simulated time / 0.05 s). Each measurement runs ``--work`` env-steps (N x T); the two are
interleaved (ours, MuJoCo, ours, MuJoCo, ...) for ``--rounds`` rounds and the median is reported.
The process is pinned to one core, torch and MuJoCo use one thread.

Before timing, both workloads are validated: one rover dropped 2 cm settles at a plausible height
and drives forward under +4 N·m on every wheel (compared with the no-slip rolling acceleration),
and every timed run ends finite. Our kernel compile + first step and each N's build are timed on
their own. The table (ratio ours/MuJoCo per N) is printed and written to
``benchmarks/results/sim_vs_mujoco.json``.
"""

from __future__ import annotations

import argparse
import importlib.util
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks._common import load_results, markdown_table, pin_to_one_core, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

HERE = Path(__file__).resolve().parent
TWIN_DIR = HERE / "mujoco_twin"
RESULTS = HERE.parent / "results"
STEP_DT = 0.05  # one env step [s]
TORQUE = 20.0  # random torque bound [N·m]
DRIVE = 4.0  # forward-check torque on every wheel [N·m] (DriveMode.FORWARD)


def _load_make_twin():
    spec = importlib.util.spec_from_file_location("make_twin", TWIN_DIR / "make_twin.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _quat_yaw(yaw: np.ndarray) -> np.ndarray:
    """(w, x, y, z) quaternions of rotations by ``yaw`` [rad] about +z."""
    return np.stack([np.cos(yaw / 2), np.zeros_like(yaw), np.zeros_like(yaw), np.sin(yaw / 2)], axis=-1)


class MujocoTwin:
    """The twin's model, one MjData, and state packing for ``mujoco.rollout``."""

    def __init__(self, xml: str, sides: list[int]):
        import mujoco
        from mujoco import rollout

        self.mj = mujoco
        self.rollout = rollout
        t0 = time.perf_counter()
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.compile_s = time.perf_counter() - t0
        self.data = mujoco.MjData(self.model)
        self.spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        self.nstate = mujoco.mj_stateSize(self.model, self.spec)
        self.sides = np.asarray(sides)
        self.substeps = round(STEP_DT / self.model.opt.timestep)
        self.wheel_qvel = np.array([self.model.jnt_dofadr[self.model.actuator_trnid[k, 0]]
                                    for k in range(self.model.nu)])

    def initial_states(self, poses: np.ndarray, dz: float = 0.0) -> np.ndarray:
        """(N, nstate) states at rest: chassis at (x [m], y [m], yaw [rad]) per row, ``dz`` [m] above qpos0."""
        m, d = self.model, self.data
        out = np.empty((len(poses), self.nstate))
        for i, (x, y, yaw) in enumerate(poses):
            self.mj.mj_resetData(m, d)
            d.qpos[0:3] = (x, y, m.qpos0[2] + dz)
            d.qpos[3:7] = _quat_yaw(np.asarray(yaw))
            self.mj.mj_getState(m, d, out[i], self.spec)
        return out

    def controls(self, commands: np.ndarray) -> np.ndarray:
        """(T, N, 2) [left, right] torques per env step -> (N, T x substeps, nu) MuJoCo controls."""
        per_wheel = commands[:, :, self.sides]  # (T, N, nu)
        return np.ascontiguousarray(np.repeat(per_wheel.transpose(1, 0, 2), self.substeps, axis=1), dtype=np.float64)

    def run(self, state0: np.ndarray, control: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Roll out every row of ``state0`` under ``control`` on the calling thread; (N, steps, nstate)."""
        state, _ = self.rollout.rollout(self.model, self.data, state0, control, state=out)
        return state

    def resets(self, state0: np.ndarray, states: np.ndarray) -> list[tuple[int, int]]:
        """(world, step) of each rollout MuJoCo reset after a diverging step (Nan, Inf or huge qacc):
        mj_step then restarts that world at qpos0, time 0, so its clock no longer runs on from ``state0``."""
        expected = state0[:, :1] + self.model.opt.timestep * np.arange(1, states.shape[1] + 1)
        off = np.abs(states[:, :, 0] - expected) > 1e-6
        return [(int(w), int(np.argmax(off[w]))) for w in np.flatnonzero(off.any(1))]

    def unpack(self, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """qpos (.., nq), qvel (.., nv) of FULLPHYSICS states (time first)."""
        nq, nv = self.model.nq, self.model.nv
        return state[..., 1:1 + nq], state[..., 1 + nq:1 + nq + nv]


def validate(twin: MujocoTwin) -> dict:
    """Drop 2 cm, settle 1 s, drive 3 s at +4 N·m per wheel: both simulators, one rover each."""
    import torch

    from atrv_warp.sim import DriveMode, RoverSim
    from atrv_warp.sim.protocols import rolling_acceleration

    settle, drive = 20, 60  # env steps
    sim = RoverSim(1)
    sim.reset(height=sim.rest_height + 0.02)
    for _ in range(settle):
        sim.step()
    ours_z = sim.root_pose[0, 2].item()
    x0 = sim.root_pose[0, :2].clone()
    sim.set_mode(DriveMode.FORWARD)
    for _ in range(drive):
        sim.step()
    ours_dx, ours_dy = (sim.root_pose[0, :2] - x0).tolist()
    ours_ok = bool(torch.isfinite(sim.root_pose).all() and not sim.nonfinite.any())

    s0 = twin.initial_states(np.zeros((1, 3)), dz=0.02)
    k = twin.substeps
    ctrl = np.concatenate([np.zeros((1, settle * k, twin.model.nu)), np.full((1, drive * k, twin.model.nu), DRIVE)], 1)
    states = twin.run(s0, ctrl)
    qpos, _ = twin.unpack(states[0])
    mj_z = float(qpos[settle * k - 1, 2])
    mj_dx, mj_dy = (qpos[-1, :2] - qpos[settle * k - 1, :2]).tolist()
    mj_ok = bool(np.isfinite(states).all())

    # no slip, from rest: x = a t^2 / 2 with a = 4 tau / r / (M + sum I / r^2)
    ideal = 0.5 * rolling_acceleration(sim, DRIVE) * (drive * STEP_DT) ** 2
    # chassis-origin height [m] with the wheels just touching the ground
    touch = (sim.arena_cfg.ground_top + sim.rover_cfg.wheel_radius
             - float(np.mean([w.origin[2, 3] for w in sim.description.wheels])))

    def plausible(z: float, dx: float, dy: float, finite: bool) -> bool:
        # resting 0 … 3 cm deep into the ground, forward at 50 … 105 % of no-slip rolling, straight
        return (finite and touch - 0.03 <= z <= touch + 0.005
                and 0.5 * ideal <= dx <= 1.05 * ideal and abs(dy) < 0.05 * dx)

    return {"settle_s": settle * STEP_DT, "drive_s": drive * STEP_DT, "drive_torque_Nm": DRIVE,
            "no_slip_dx_m": ideal,
            "ours": {"rest_z_m": ours_z, "dx_m": ours_dx, "dy_m": ours_dy, "finite": ours_ok,
                     "ok": plausible(ours_z, ours_dx, ours_dy, ours_ok)},
            "mujoco": {"rest_z_m": mj_z, "dx_m": mj_dx, "dy_m": mj_dy, "finite": mj_ok,
                       "ok": plausible(mj_z, mj_dx, mj_dy, mj_ok)}}


def build_parser() -> argparse.ArgumentParser:
    """The command line's options."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 1024, 4096])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--work", type=int, default=65536, help="env-steps (N x T) per measurement")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=str(RESULTS / "sim_vs_mujoco.json"))
    return parser


def measure(n: int, twin: MujocoTwin, rng: np.random.Generator, args: argparse.Namespace) -> dict | None:
    """One row: ``n`` rovers in ours and in MuJoCo, interleaved for ``args.rounds``; None if a state is not finite."""
    import torch
    import warp as wp

    from atrv_warp.sim import RoverSim

    steps = max(8, args.work // n)  # env steps per measurement
    poses = np.column_stack([rng.uniform(-12, 12, n), rng.uniform(-12, 12, n), rng.uniform(-np.pi, np.pi, n)])
    commands = rng.uniform(-TORQUE, TORQUE, (steps, n, 2)).astype(np.float32)

    t0 = time.perf_counter()
    sim = RoverSim(n)
    sim.reset(poses=torch.as_tensor(poses, dtype=torch.float32))
    sim.step()  # records the graph
    wp.synchronize()
    build_s = time.perf_counter() - t0
    for _ in range(19):  # settle 1 s
        sim.step()
    cmd_t = torch.as_tensor(commands)

    # MuJoCo: settle 1 s at zero torque (untimed), then time from the settled states
    control = twin.controls(commands)
    state = twin.run(twin.initial_states(poses), np.zeros((n, 20 * twin.substeps, twin.model.nu)))
    mj_state0 = np.ascontiguousarray(state[:, -1])
    out = np.empty((n, steps * twin.substeps, twin.nstate))

    ours_rates, mj_rates = [], []
    mj_reset: dict[int, list[float]] = {}  # world -> chassis x, y, z [m] before MuJoCo reset it
    for _ in range(args.rounds):
        t0 = time.perf_counter()
        for t in range(steps):
            sim.commands.copy_(cmd_t[t])
            sim.step()
        wp.synchronize()
        ours_rates.append(n * steps / (time.perf_counter() - t0))

        t0 = time.perf_counter()
        twin.run(mj_state0, control, out)
        mj_rates.append(n * steps / (time.perf_counter() - t0))
        for w, k in twin.resets(mj_state0, out):
            mj_reset.setdefault(w, twin.unpack(out[w, k - 1] if k else mj_state0[w])[0][:3].tolist())
        mj_state0 = np.ascontiguousarray(out[:, -1])

    ours_finite = bool(torch.isfinite(sim.root_pose).all() and not sim.nonfinite.any())
    mj_finite = bool(np.isfinite(out).all())
    if not (ours_finite and mj_finite):
        print(f"N={n}: non-finite state (ours finite {ours_finite}, MuJoCo finite {mj_finite})", file=sys.stderr)
        return None
    qpos, qvel = twin.unpack(mj_state0)
    row = {
        "num_worlds": n, "env_steps_per_measurement": steps, "sim_time_per_measurement_s": steps * STEP_DT,
        "ours_env_steps_per_s": statistics.median(ours_rates), "mujoco_env_steps_per_s": statistics.median(mj_rates),
        "ours_rounds": ours_rates, "mujoco_rounds": mj_rates, "ours_build_s": build_s,
        # after the timed runs: how hard the rovers were driven (our motor tapers to 0 at 50 rad/s)
        "ours_mean_abs_wheel_speed_rad_s": sim.wheel_speed.abs().mean().item(),
        "mujoco_mean_abs_wheel_speed_rad_s": float(np.abs(qvel[:, twin.wheel_qvel]).mean()),
        # worlds MuJoCo found diverging and restarted at its origin (timed runs; their state before)
        "mujoco_reset_worlds": len(mj_reset), "mujoco_reset_chassis_xyz_m": mj_reset,
        "ours_mean_chassis_z_m": sim.root_pose[:, 2].mean().item(),
        "mujoco_mean_chassis_z_m": float(qpos[:, 2].mean()),
    }
    row["ratio_ours_over_mujoco"] = row["ours_env_steps_per_s"] / row["mujoco_env_steps_per_s"]
    print(f"N={n:5d} ({steps} env steps, build {build_s:.1f} s): ours {row['ours_env_steps_per_s']:10,.0f}  "
          f"MuJoCo {row['mujoco_env_steps_per_s']:10,.0f} env-steps/s  ratio {row['ratio_ours_over_mujoco']:.2f}  "
          f"(MuJoCo reset {len(mj_reset)} diverging world(s))",
          flush=True)
    return row


def print_table(rows: list[dict]) -> None:
    """Print the rows as a Markdown table."""
    print("\n| worlds | ours env-steps/s | MuJoCo env-steps/s | ours / MuJoCo |\n|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['num_worlds']} | {r['ours_env_steps_per_s']:,.0f} | {r['mujoco_env_steps_per_s']:,.0f} | "
              f"{r['ratio_ours_over_mujoco']:.2f} |")


def main() -> int:
    args = build_parser().parse_args()

    pin_to_one_core()
    try:
        import mujoco
    except ImportError:
        print("MuJoCo is missing: pip install -e .[bench]", file=sys.stderr)
        return 1
    import torch
    import warp as wp

    torch.set_num_threads(1)
    make_twin = _load_make_twin()
    xml_path = TWIN_DIR / "atrvjr.xml"
    xml = make_twin.twin_xml()
    if xml_path.read_text() != xml:
        print(f"{xml_path} is stale: run python benchmarks/perf/mujoco_twin/make_twin.py", file=sys.stderr)
        return 1
    twin = MujocoTwin(xml, make_twin.wheel_sides())

    from atrv_warp.sim import RoverSim

    # -- our compile + first step, on its own (Warp's kernel cache as the user has it)
    t0 = time.perf_counter()
    RoverSim(1).step()
    wp.synchronize()
    compile_s = time.perf_counter() - t0
    print(f"MuJoCo {mujoco.__version__}; ours: kernel load/compile + first step {compile_s:.2f} s; "
          f"MuJoCo XML compile {1e3 * twin.compile_s:.1f} ms")

    # -- the workload, validated before any timing
    check = validate(twin)
    for who in ("ours", "mujoco"):
        c = check[who]
        print(f"check {who:6s}: rest z {c['rest_z_m']:.4f} m, x after {check['drive_s']:g} s at {DRIVE:g} N·m "
              f"{c['dx_m']:.3f} m (no slip {check['no_slip_dx_m']:.3f} m), y {c['dy_m']:+.4f} m -> "
              f"{'ok' if c['ok'] else 'FAILED'}")
    if not (check["ours"]["ok"] and check["mujoco"]["ok"]):
        print("workload check failed; no timing", file=sys.stderr)
        return 1

    rng = np.random.default_rng(args.seed)
    rows = []
    for n in args.sizes:
        row = measure(n, twin, rng, args)
        if row is None:
            return 1
        rows.append(row)

    result = {
        "benchmark": "sim_vs_mujoco",
        "mujoco_version": mujoco.__version__,
        "twin": "benchmarks/perf/mujoco_twin/atrvjr.xml",
        "machine": f"{platform.machine()} {platform.processor() or ''}".strip(),
        "cores_used": 1,
        "rounds": args.rounds,
        "statistic": "median",
        "torque_bound_Nm": TORQUE,
        "ours_compile_and_first_step_s": compile_s,
        "mujoco_xml_compile_s": twin.compile_s,
        "validation": check,
        "rows": rows,
        "time": time.strftime("%Y-%m-%d %H:%M:%S"),
    }
    out_path = write_results(args.out, result, version=VERSION)
    print_table(rows)
    print(f"\nwritten to {out_path}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def sim_vs_mujoco() -> str:
    """``sim_vs_mujoco.json``: our env-steps/s against MuJoCo's rollout of the twin."""
    rows = load_results("sim_vs_mujoco.json")["rows"]
    return markdown_table(["N", "ours env-steps/s", "MuJoCo env-steps/s", "ours / MuJoCo"], ["---:"] * 4,
                          [[str(r["num_worlds"]), f"{r['ours_env_steps_per_s']:,.0f}", f"{r['mujoco_env_steps_per_s']:,.0f}",
                    f"{r['ratio_ours_over_mujoco']:.2f}"] for r in rows])


TABLES = {
    "sim_vs_mujoco": sim_vs_mujoco,
}


if __name__ == "__main__":
    sys.exit(main())
