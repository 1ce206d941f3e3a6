"""Differentiable rollouts: gradient agreement with finite differences, and forward/backward cost.

Run: ``python -m benchmarks.physics.diff_gradients [--horizons 1 2 5 10 20 40 100] [--sizes 1 64 1024]
[--without-wrench-fix] [--twist]``

Agreement: for each driving scenario and horizon T (env steps of 0.05 s), the tape gradient of
``L = x_T + y_T + 2 qz_T`` (final position and heading) with respect to all actions is compared
with central finite differences along random unit directions of two kinds: common mode (both
wheels together, random weights over time) and differential (left against right: what turns
the rover); and dL/dmu and dL/d(chassis mass) (the latter per unit relative change, m dL/dm,
against differences at 0.2 % and 0.66 % of the mass). Reported: the worst relative error |g.d - fd| / max(|fd|, 1e-3) of each
kind, against central differences at eps = 3e-3 (actions) and 1e-3 (mu). The same difference
is also taken at a step 3.3x larger; where the two disagree by more than 5 % the function is
not smooth at that scale (stick-slip, contact switching), the finite difference is no reference,
and the entry is marked (``"fd_rough": true`` in the JSON, a dagger in the tables).
Scenarios: ``straight`` (+2 N·m, rolling), ``slip`` (+20 N·m, wheels spinning),
``curve`` (left 4, right 8 N·m), ``spin`` (left -6, right +6 N·m, skidding in place).

``--twist``: the actions are ``/cmd_vel`` commands through the base's motor driver
(``DiffRollout(twist=True)``: the wheel-speed PI every substep on the tape), the directions vary the
forward speed (``linear``) and the yaw rate (``angular``), in scenarios ``straight`` (0.5 m/s),
``arc`` (0.5 m/s, 0.5 rad/s), ``spin`` (0.5 rad/s in place) and ``fast_arc`` (1 m/s, 0.2 rad/s); written
to ``diff_gradients_twist.json``.

Cost: wall time of the taped forward pass and of the backward pass per world-step at N worlds
(T = 20), on one core, median of ``--repeats``; graph replay and tile GEMM are off on this path.
Figures are printed and written to ``benchmarks/results/diff_gradients.json``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, pin_to_one_core, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
SCENARIOS = {"straight": (0.1, 0.1), "slip": (1.0, 1.0), "curve": (0.2, 0.4), "spin": (-0.3, 0.3)}
"""Torque actions (left, right) in [-1, 1] x 20 N·m."""
KINDS = {"common": (1.0, 1.0), "differential": (1.0, -1.0)}
"""Directions of the torque actions: both wheels together, left against right."""
TWIST_SCENARIOS = {"straight": (0.5, 0.0), "arc": (0.5, 0.5), "spin": (0.0, 0.5), "fast_arc": (1.0, 0.2)}
"""``--twist``: (linear [m/s], angular [rad/s]) commands."""
TWIST_KINDS = {"linear": (1.0, 0.0), "angular": (0.0, 1.0)}
LABELS = {"common": "both wheels together", "differential": "left vs right", "linear": "forward speed command",
          "angular": "yaw rate command", "friction": "friction mu", "mass": "chassis mass"}


def objective(poses):
    """Final x + y + 2 qz (qz ~ yaw / 2) of world 0."""
    return poses[-1, 0, 0] + poses[-1, 0, 1] + 2.0 * poses[-1, 0, 5]


def central(roll, state, a, mu, d_actions, d_mu, eps, d_mass=0.0):
    """Central difference of the objective along (d_actions, d_mu, d_mass [kg]) with step eps."""
    m = roll.nominal_chassis_mass
    plus = objective(roll(a + eps * d_actions, state, mu + eps * d_mu, m + eps * d_mass))
    minus = objective(roll(a - eps * d_actions, state, mu - eps * d_mu, m - eps * d_mass))
    return ((plus - minus) / (2 * eps)).item()


def magnitudes(row, key):
    """|tape| and |fd| values of one kind in a result row."""
    values = []
    for v in (row[key + "_tape"], row[key + "_fd"]):
        values.extend(v if isinstance(v, list) else [v])
    return [abs(v) for v in values]


def cell(row, key):
    """Table entry: the worst relative error, '~0' where the derivative vanishes, † where FD is rough."""
    if row[key + "_negligible"]:
        return "~0"
    return f"{100 * row[key + '_rel_err']:.1f} %" + ("†" if row[key + "_fd_rough"] else "")


def build_parser() -> argparse.ArgumentParser:
    """The command line's options."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--horizons", type=int, nargs="+", default=[1, 2, 5, 10, 20, 40, 100])
    parser.add_argument("--sizes", type=int, nargs="*", default=[1, 64, 1024])
    parser.add_argument("--directions", type=int, default=3, help="random directions per kind")
    parser.add_argument("--repeats", type=int, default=3, help="timed forward/backward passes per size (median)")
    parser.add_argument("--without-wrench-fix", action="store_true",
                        help="diagnostic: leave out atrv_warp.sim.diff's fix for Newton's in-place wrench "
                             "conversion, to measure what it changes (default output: diff_gradients_raw_wrench.json)")
    parser.add_argument("--twist", action="store_true",
                        help="the actions are /cmd_vel through the motor driver (default output: diff_gradients_twist.json)")
    parser.add_argument("--out", default=None)
    parser.add_argument("--report", metavar="JSON", help="print the tables of an existing results file and exit")
    return parser


def agreement_row(roll, state, T: int, name: str, left: float, right: float, kinds: dict, directions: int,
                  gen) -> dict:
    """Scenario ``name`` at horizon ``T``: the tape gradient of each kind, mu and mass against finite differences."""
    import torch

    a = torch.empty(T, 1, 2)
    a[..., 0], a[..., 1] = left, right
    mu = torch.tensor(0.3)
    aa = a.clone().requires_grad_(True)
    mm = mu.clone().requires_grad_(True)
    mass = torch.tensor(roll.nominal_chassis_mass, requires_grad=True)
    poses = roll(aa, state, mm, mass)
    objective(poses).backward()

    # where the rover ends up (the arena's walls are 15 m from the start)
    row = {"scenario": name, "horizon_steps": T, "horizon_s": 0.05 * T,
           "final_xy": poses[-1, 0, :2].tolist(), "path_max_x": poses[:, 0, 0].max().item()}
    for kind, (c0, c1) in kinds.items():
        worst, rough, tapes, fds = 0.0, False, [], []
        for _ in range(directions):
            w = torch.rand(T, 1, 1, generator=gen)  # random weights over time
            d = torch.cat([c0 * w, c1 * w], dim=-1)
            d /= d.norm()
            fd = central(roll, state, a, mu, d, 0.0, 3e-3)
            fd_coarse = central(roll, state, a, mu, d, 0.0, 1e-2)
            tape = (aa.grad * d).sum().item()
            err = abs(tape - fd) / max(abs(fd), 1e-3)
            if err >= worst:
                worst, rough = err, abs(fd_coarse - fd) > 0.05 * max(abs(fd), 1e-3)
            tapes.append(tape)
            fds.append(fd)
        row[f"{kind}_rel_err"], row[f"{kind}_fd_rough"] = worst, rough
        row[f"{kind}_tape"], row[f"{kind}_fd"] = tapes, fds
    fd_mu = central(roll, state, a, mu, 0.0, 1.0, 1e-3)
    fd_mu_coarse = central(roll, state, a, mu, 0.0, 1.0, 3.3e-3)
    row["friction_rel_err"] = abs(mm.grad.item() - fd_mu) / max(abs(fd_mu), 1e-3)
    row["friction_fd_rough"] = abs(fd_mu_coarse - fd_mu) > 0.05 * max(abs(fd_mu), 1e-3)
    row["friction_tape"], row["friction_fd"] = mm.grad.item(), fd_mu
    # chassis mass: steps of 0.2 % and 0.66 % of it; derivative reported per unit relative change
    m0 = roll.nominal_chassis_mass
    fd_m = m0 * central(roll, state, a, mu, 0.0, 0.0, 0.002 * m0, d_mass=1.0)
    fd_m_coarse = m0 * central(roll, state, a, mu, 0.0, 0.0, 0.0066 * m0, d_mass=1.0)
    tape_m = m0 * mass.grad.item()
    row["mass_rel_err"] = abs(tape_m - fd_m) / max(abs(fd_m), 1e-3)
    row["mass_fd_rough"] = abs(fd_m_coarse - fd_m) > 0.05 * max(abs(fd_m), 1e-3)
    row["mass_tape"], row["mass_fd"] = tape_m, fd_m
    return row


def cost_row(n: int, args: argparse.Namespace, gen) -> dict:
    """Forward and backward wall time per world-step of the taped rollout at ``n`` worlds (T = 20)."""
    import torch

    from atrv_warp.sim.diff import DiffRollout

    T = 20
    roll = DiffRollout(n, steps=T, wrench_fix=not args.without_wrench_fix, twist=args.twist)
    state = roll.initial_state()
    a = (torch.rand(T, n, 2, generator=gen) * 2 - 1).requires_grad_(True)  # torques, or m/s and rad/s
    roll(a, state)  # warm-up
    t_fwd, t_bwd = [], []
    for _ in range(args.repeats):  # median of repeats: one short run on a shared core is noisy
        t0 = time.perf_counter()
        poses = roll(a, state)
        t_fwd.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        poses[-1, :, :2].sum().backward()
        t_bwd.append(time.perf_counter() - t0)
    t_fwd, t_bwd = statistics.median(t_fwd), statistics.median(t_bwd)
    return {"num_worlds": n, "steps": T, "forward_us_per_world_step": 1e6 * t_fwd / (n * T),
            "backward_us_per_world_step": 1e6 * t_bwd / (n * T), "backward_over_forward": t_bwd / t_fwd}


def main() -> int:
    args = build_parser().parse_args()
    if args.report:
        report(json.loads(Path(args.report).read_text()))
        return 0
    pin_to_one_core()
    import torch
    torch.set_num_threads(1)
    from atrv_warp.sim.diff import DiffRollout

    fix = not args.without_wrench_fix
    default_name = ("diff_gradients_raw_wrench.json" if args.without_wrench_fix else
                    "diff_gradients_twist.json" if args.twist else "diff_gradients.json")
    scenarios, kinds = (TWIST_SCENARIOS, TWIST_KINDS) if args.twist else (SCENARIOS, KINDS)
    args.out = args.out or str(RESULTS / default_name)

    agreement = []
    gen = torch.Generator().manual_seed(0)
    for T in args.horizons:
        roll = DiffRollout(1, steps=T, wrench_fix=fix, twist=args.twist)
        state = roll.initial_state()
        for name, (left, right) in scenarios.items():
            row = agreement_row(roll, state, T, name, left, right, kinds, args.directions, gen)
            agreement.append(row)
            k0, k1 = kinds
            print(f"T={T:3d} ({0.05 * T:4.2f} s) {name:8s} {k0} {100 * row[k0 + '_rel_err']:7.2f}%"
                  f"{'†' if row[k0 + '_fd_rough'] else ' '} {k1} {100 * row[k1 + '_rel_err']:7.2f}%"
                  f"{'†' if row[k1 + '_fd_rough'] else ' '} friction {100 * row['friction_rel_err']:7.2f}%"
                  f"{'†' if row['friction_fd_rough'] else ' '} (tape {row['friction_tape']:+.4f}, "
                  f"fd {row['friction_fd']:+.4f}) "
                  f"chassis mass {100 * row['mass_rel_err']:7.2f}%{'†' if row['mass_fd_rough'] else ' '}; "
                  f"max x {row['path_max_x']:.2f} m",
                  flush=True)

    cost = []
    for n in args.sizes:
        row = cost_row(n, args, gen)
        cost.append(row)
        print(f"N={n:5d}: forward {row['forward_us_per_world_step']:9.1f} us, backward "
              f"{row['backward_us_per_world_step']:9.1f} us per world-step; backward/forward "
              f"{row['backward_over_forward']:.2f}", flush=True)

    results = {"benchmark": "diff_gradients", "wrench_fix": not args.without_wrench_fix, "twist": args.twist,
               "scenarios": list(scenarios), "kinds": list(kinds), "agreement": agreement,
               "cost": cost, "time": time.strftime("%Y-%m-%d %H:%M:%S")}
    report(results)
    out = write_results(args.out, results, version=VERSION, driver=args.twist)
    print(f"\nwritten to {out}")
    return 0


def report(results) -> None:
    """Mark negligible entries and print the Markdown tables (also used by ``--report``)."""
    agreement = results["agreement"]
    horizons = sorted({r["horizon_steps"] for r in agreement})
    kinds = results.get("kinds", list(KINDS))
    scenarios = results.get("scenarios", list(SCENARIOS))
    # Full slip saturates friction: the actions then barely move the rover, and the relative error
    # of a ~0 derivative says nothing. Entries whose derivatives are all under 1 % of the median
    # scenario's at that horizon are marked negligible (shown as "~0").
    for T in horizons:
        rows = [r for r in agreement if r["horizon_steps"] == T]
        for key in (*kinds, "friction", "mass"):
            scale = statistics.median(max(magnitudes(r, key)) for r in rows)
            for r in rows:
                r[key + "_negligible"] = max(magnitudes(r, key)) < 0.01 * scale
    print(f"\ngradient agreement ({'with' if results['wrench_fix'] else 'WITHOUT'} the wrench-adjoint fix)")
    for key in (*kinds, "friction", "mass"):
        label = LABELS[key]
        print(f"\nworst relative error, {label} († = finite differences not smooth at this scale; "
              "~0 = derivative under 1 % of the median scenario's):")
        print("| scenario | " + " | ".join(f"{0.05 * T:.2f} s" for T in horizons) + " |")
        print("|---|" + "---:|" * len(horizons))
        for name in scenarios:
            rows = sorted((r for r in agreement if r["scenario"] == name), key=lambda r: r["horizon_steps"])
            print(f"| {name} | " + " | ".join(cell(r, key) for r in rows) + " |")
    if results["cost"]:
        print("\n| N | forward us/world-step | backward us/world-step | backward/forward |\n|---:|---:|---:|---:|")
        for r in results["cost"]:
            print(f"| {r['num_worlds']} | {r['forward_us_per_world_step']:.1f} | {r['backward_us_per_world_step']:.1f} | "
                  f"{r['backward_over_forward']:.2f} |")
        sim_results = RESULTS / "sim_throughput.json"
        taped = {r["num_worlds"]: r["forward_us_per_world_step"] for r in results["cost"]}
        if sim_results.exists() and 1024 in taped:  # against the graph-replayed training simulator
            plain = {r["num_worlds"]: 1e6 / r["env_steps_per_s"] for r in json.loads(sim_results.read_text())["rows"]}
            if 1024 in plain:
                print(f"\ntaped forward at N = 1024: {taped[1024] / plain[1024]:.1f}x the training simulator's "
                      f"{plain[1024]:.1f} us per world-step (sim_throughput.json)")


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def _diff_gradients(kind: str, name: str = "diff_gradients.json") -> str:
    d = load_results(name)
    rows = d["agreement"]
    horizons = sorted({r["horizon_s"] for r in rows})
    scenarios = list(dict.fromkeys(r["scenario"] for r in rows))
    cell = {(r["scenario"], r["horizon_s"]): r for r in rows}

    def fmt(r: dict) -> str:
        if r[f"{kind}_negligible"]:
            return "~0"
        return f"{100 * r[f'{kind}_rel_err']:.1f} %" + ("†" if r[f"{kind}_fd_rough"] else "")

    return markdown_table(["scenario", *(f"{h:.2f} s" for h in horizons)], ["---"] + ["---:"] * len(horizons),
                          [[sc, *(fmt(cell[(sc, h)]) for h in horizons)] for sc in scenarios])


def diff_gradients_common() -> str:
    """``diff_gradients.json``: both wheels together, tape against central differences."""
    return _diff_gradients("common")


def diff_gradients_differential() -> str:
    """``diff_gradients.json``: left against right (steering)."""
    return _diff_gradients("differential")


def diff_gradients_friction() -> str:
    """``diff_gradients.json``: the friction coefficient."""
    return _diff_gradients("friction")


def diff_gradients_mass() -> str:
    """``diff_gradients.json``: the chassis mass."""
    return _diff_gradients("mass")


def diff_gradients_twist_linear() -> str:
    """``diff_gradients_twist.json``: the forward-speed command through the motor driver."""
    return _diff_gradients("linear", "diff_gradients_twist.json")


def diff_gradients_twist_angular() -> str:
    """``diff_gradients_twist.json``: the yaw-rate command through the motor driver."""
    return _diff_gradients("angular", "diff_gradients_twist.json")


def diff_cost() -> str:
    """``diff_gradients.json``: forward and backward cost of the taped rollout per world-step."""
    return markdown_table(["worlds", "forward [µs / world-step]", "backward [µs / world-step]", "backward / forward"],
                          ["---:"] * 4,
                          [[str(r["num_worlds"]), f"{r['forward_us_per_world_step']:.0f}", f"{r['backward_us_per_world_step']:.0f}",
                    f"{r['backward_over_forward']:.2f}"] for r in load_results("diff_gradients.json")["cost"]])


TABLES = {
    "diff_gradients_common": diff_gradients_common,
    "diff_gradients_differential": diff_gradients_differential,
    "diff_gradients_friction": diff_gradients_friction,
    "diff_gradients_mass": diff_gradients_mass,
    "diff_gradients_twist_linear": diff_gradients_twist_linear,
    "diff_gradients_twist_angular": diff_gradients_twist_angular,
    "diff_cost": diff_cost,
}


if __name__ == "__main__":
    sys.exit(main())
