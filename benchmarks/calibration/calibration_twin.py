"""Calibration across engines: our simulator fitted to bags recorded from the MuJoCo twin (issue 42 part 7).

    python -m benchmarks.calibration.calibration_twin [--rovers 4] [--seed 0] [--minutes 3] [--work DIR]
                                          [--figure docs/calibration_twin.png] [--contact friction_pair --out FILE]
                                          [--params friction,torque_scale,payload_mass,wheel_radius,friction_rise]

The twin (``atrv_warp.integrations.mujoco``) is the same rover, URDF and motor driver on MuJoCo's contact: soft
constraints with the tyre's compliance, an elliptic friction cone, its own solver. So a fit to its drive meets what
a real rover brings, a contact that is not ours, while its truth is still known.

1. Rovers: the nominal one, then the first ``--rovers`` that ``calibration_sweep.py`` draws from ``--seed``, with
   the sweep's drive seeds, so each is the sweep's rover on the other engine (same truth, same scripted drive).
2. For each: ``python -m atrv_warp.calibrate --record-example --engine mujoco --truth …`` (1 cm of reference-pose
   noise, the driver configured as the nominal rover), then the fit with the CLI's defaults in a fresh process.
3. Reports, per rover, the held-out position error before (the nominal rover) and after the fit, and the cut (target
   >= 2x where the nominal model misses by more than 5 cm), the fitted values against the twin's, the model check's
   ratios, and the same rover's figures on our own engine from the sweep's results file, where it has them.
4. And what tells the engines apart for that rover: the twin's rolling radius (its tyre sinks, and pushes on the
   ground inside its geometric radius), and an in-place turn at 1 rad/s through the nominal driver in both (ours
   with the twin's values and with the fitted ones).

``--contact friction_pair`` records the twin with its wheels' friction on pairs of their own, which keeps them on
flat ground in brisk turns: what is left of the gap once the twin's turns follow Coulomb's law as ours do.
``--params`` fits other parameters than the CLI's default (``atrv-calibrate --params``): with ``friction_rise``, our
wheels' sliding friction rising with slip speed, which the twin's hopping wheels resist brisk turns with. Each
``--params`` fits into a folder of its own beside the bag, so runs with and without share the recordings.

Each rover's bag, report and console output stay in ``--work``; an interrupted run resumes. Writes
``benchmarks/results/calibration_twin.json`` and, with ``--figure``, fitted against true values per parameter.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, write_results
from benchmarks.calibration.calibration_sweep import (
    RANGES,
    RESULTS,
    ROOT,
    draw_truths,
    fit_bag,
    judge,
    plot,
    record_bag,
    truth_toml,
)

VERSION = 2
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

CUT_TARGET = 2.0
"""Issue 42 part 7: the held-out error cut at least this much."""
MISSES = 0.05
"""[m]: a rover the nominal model misses by more than this on the held-out segments is held to the cut."""


HIGH_MU = 0.5
"""Rovers above this µ are summarised apart for the in-place turn (the twin's wheels lift in brisk turns there)."""


def span(values: list[float]) -> list[float]:
    """[smallest, largest] of ``values`` (NaNs where there are none)."""
    return [min(values), max(values)] if values else [math.nan, math.nan]


def nominal_truth() -> dict[str, float]:
    """The nominal rover's values of the swept parameters (the realistic variant, the default contact)."""
    from atrv_warp.sim.config import ContactConfig, RoverConfig

    rover, contact = RoverConfig(), ContactConfig()
    return {p: float(getattr(contact if table == "contact" else rover, key)) for p, (_, _, table, key) in RANGES.items()}


def configs(values: dict[str, float]):
    """The :class:`~atrv_warp.sim.config.RoverConfig` and :class:`~atrv_warp.sim.config.ContactConfig` of fit
    parameters' ``values`` (a truth, or a truth with fitted values over it), the others nominal."""
    from atrv_warp.sim.config import ContactConfig, RoverConfig
    from atrv_warp.sim.sysid.config import sim_config_tables

    tables = sim_config_tables(values)
    return RoverConfig(**tables["rover"]), ContactConfig(**tables["contact"])


CONTACTS = {"tyre": None, "friction_pair": {"solreffriction": (0.87, 1.0), "impratio": 10.0}}
"""The twin's contact settings a run can take: MuJoCo's contact with the tyre's compliance (the twin's default, what
``atrv-calibrate --record-example --engine mujoco`` records), or that with the wheels' friction on pairs of their own
(``mujoco_turning_study.py``'s ``tyre_friction_pair``: no wheel leaves flat ground in a brisk turn)."""


def twin_contact(name: str):
    """The :class:`~atrv_warp.integrations.mujoco.MujocoContact` of :data:`CONTACTS`' ``name``."""
    import dataclasses

    from atrv_warp.integrations.mujoco import MujocoContact

    return dataclasses.replace(MujocoContact(), **(CONTACTS[name] or {}))


def record_with_contact(folder: Path, truth: dict[str, float], drive_seed: int, minutes: float, noise: float,
                        contact: str) -> None:
    """``folder/drive.mcap`` recorded in the twin with the ``contact`` settings of :data:`CONTACTS` other than the
    default, through the library the CLI calls (``record_twin_bag``), as the CLI would record it."""
    from atrv_warp.integrations.mujoco.record import record_twin_bag

    rover, _ = configs(truth)
    record_twin_bag(folder / "drive.mcap", minutes, seed=drive_seed, rover=rover, friction=truth["friction"],
                    truth_noise=noise, truth_yaw_noise=noise / 0.5, contact=twin_contact(contact))


def run_rover(label: str, truth: dict[str, float], drive_seed: int, *, minutes: float, noise: float, work: Path,
              env: dict, contact: str = "tyre", params: tuple[str, ...] | None = None) -> dict:
    """Record rover ``label`` in the twin and fit ``params`` to it (default: the CLI's, ``DEFAULT_FIT``; or read what an
    earlier run left in ``work``): its row."""
    from atrv_warp.sim.sysid.config import DEFAULT_FIT

    params = params or DEFAULT_FIT
    folder = work / label
    into = folder if params == DEFAULT_FIT else folder / ("fit_" + "_".join(params))
    done = into / "row.json"
    if done.is_file():
        row = json.loads(done.read_text())
        if row["truth"] == truth and row["seed"] == drive_seed and row.get("fit_params") == list(params):
            return row
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "truth.toml").write_text(truth_toml(truth))
    if not (folder / "drive.mcap").is_file() and contact != "tyre":
        record_with_contact(folder, truth, drive_seed, minutes, noise, contact)
    if not (folder / "drive.mcap").is_file():
        record_bag(folder, label, ["--engine", "mujoco", "--minutes", str(minutes), "--noise", str(noise),
                                   "--seed", str(drive_seed)], env)
    into.mkdir(exist_ok=True)
    report, wall, code = fit_bag(folder, label, env, () if params == DEFAULT_FIT else ("--params", ",".join(params)),
                                 into=into)
    row = judge(truth, report)
    before, after = row["held_out"]["before_m"], row["held_out"]["after_m"]
    cut = before / max(after, 1e-9)
    row["held_out"].update(cut=cut, passes=bool(cut >= CUT_TARGET) if before > MISSES else None,
                           rule=f"cut >= {CUT_TARGET:g}x" if before > MISSES else f"nominal misses by <= {100 * MISSES:g} cm")
    row.update(rover=label, seed=drive_seed, exit_code=code, process_wall_s=wall, latency=report.get("latency"),
               misfit=report.get("misfit"), correlation=report.get("correlation"), confounded=report.get("confounded"),
               train=report["error_summary"]["train"], fit_params=list(params),
               fitted={p: report["values"][p] for p in params})
    done.write_text(json.dumps(row, indent=1) + "\n")
    return row


def rolling_radius(truth: dict[str, float], speed: float = 0.5, seconds: float = 4.0, contact: str = "tyre") -> float:
    """The twin's rolling radius [m] for rover ``truth``: forward speed over the wheels' mean speed, driving
    straight at ``speed`` [m/s], averaged over the last second (its wheel sinks, and pushes on the ground at its
    contact point, inside the geometric radius)."""
    import numpy as np

    from atrv_warp.integrations.mujoco import MujocoTwin
    from atrv_warp.integrations.mujoco.record import twin_driver

    rover, _ = configs(truth)
    twin = MujocoTwin(rover=rover, friction=truth["friction"], driver=twin_driver(), contact=twin_contact(contact))
    ratios = []
    for k in range(round(seconds / twin.sim_cfg.step_dt)):
        twin.command(speed, 0.0)
        twin.step()
        if k >= round((seconds - 1.0) / twin.sim_cfg.step_dt):
            forward = float(twin.chassis_rotation[:, 0] @ twin.linear_velocity)
            ratios.append(forward / float(np.mean(twin.wheel_speed)))
    return float(np.mean(ratios))


def in_place_turn(truth: dict[str, float], rate: float = 1.0, seconds: float = 3.0,
                  contact: str = "tyre", fitted: dict[str, float] | None = None) -> dict[str, float]:
    """Rover ``truth`` turning in place at ``rate`` [rad/s] through the nominal driver, in ours and in the twin: each
    one's yaw rate over the command, averaged over the last second, and the share of the twin's steps in which a
    wheel left the ground for a substep (MuJoCo's soft contact lifts a sliding wheel; physics page); with
    ``fitted`` (a fit's values), also ours with them (``ours_fitted``)."""
    import numpy as np
    import torch

    from atrv_warp.integrations.mujoco import MujocoTwin
    from atrv_warp.integrations.mujoco.record import twin_driver
    from atrv_warp.sim import RoverSim

    rover, truth_contact = configs(truth)
    sims = [RoverSim(1, rover=rover, contact=truth_contact, driver=twin_driver())]
    if fitted:
        rover_fitted, contact_fitted = configs({**truth, **fitted})
        sims.append(RoverSim(1, rover=rover_fitted, contact=contact_fitted, driver=twin_driver()))
    twin = MujocoTwin(rover=rover, friction=truth["friction"], driver=twin_driver(), contact=twin_contact(contact))
    steps, last = round(seconds / twin.sim_cfg.step_dt), round(1.0 / twin.sim_cfg.step_dt)
    ours, theirs, airborne = [[] for _ in sims], [], 0
    for k in range(steps):
        for sim, rates in zip(sims, ours):
            sim.set_twist(torch.tensor([[0.0, rate]]))
            sim.step()
            if k >= steps - last:
                rates.append(float(sim.ang_vel[0, 2]) / rate)
        twin.command(0.0, rate)
        twin.step()
        if k >= steps - last:
            theirs.append(float(twin.angular_velocity[2]) / rate)
            airborne += int(twin.wheel_ground_substeps.min() < twin.substeps)
    out = {"rate": rate, "ours": float(np.mean(ours[0])), "twin": float(np.mean(theirs)), "twin_airborne": airborne / last}
    if fitted:
        out["ours_fitted"] = float(np.mean(ours[1]))
    return out


def ours(sweep: dict | None, k: int) -> dict | None:
    """Rover ``k`` of the sweep on our own engine (its held-out errors and fitted values), if the sweep ran it."""
    for r in (sweep or {}).get("rovers", []):
        if r["rover"] == k:
            return {"held_out": r["held_out"], "fitted": {p: v["fitted"] for p, v in r["params"].items()},
                    "all_within": r["all_within"], "misfit_flagged": bool((r.get("misfit") or {}).get("flagged"))}
    return None


def draw(rows: list[dict], path: Path, params: tuple[str, ...], default: tuple[str, ...], results: Path) -> None:
    """Fitted against true values per parameter (the sweep's :func:`plot`), with the twin's rolling radius, into
    ``path``; ``params``: the parameters fitted, named in the title where they are more than ``default``."""
    also = "" if tuple(params) == tuple(default) else " (also " + ", ".join(sorted(set(params) - set(default))) + ")"
    plot(rows, path, title=(f"our simulator fitted to {len(rows)} rovers recorded in the MuJoCo twin{also}"
                            ": blue within tolerance, red outside"),
         extra={"wheel_radius": ("the twin's rolling radius", [r["truth"]["wheel_radius"] for r in rows],
                                 [r["twin_rolling_radius"] for r in rows])},
         results=(results,), version=VERSION)


def build_parser() -> argparse.ArgumentParser:
    """The command line's options."""
    from atrv_warp.sim.sysid.config import DEFAULT_FIT

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rovers", type=int, default=4, help="drawn rovers after the nominal one (%(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="the sweep's seed to draw them from (%(default)s)")
    parser.add_argument("--minutes", type=float, default=3.0, help="sim minutes of driving per rover (%(default)s)")
    parser.add_argument("--noise", type=float, default=0.01, help="reference position noise [m] (%(default)s)")
    parser.add_argument("--work", default=None, help="folder kept between runs (default: one in /tmp)")
    parser.add_argument("--figure", default=None, help="write the fitted-against-true figure here")
    parser.add_argument("--contact", default="tyre", choices=list(CONTACTS),
                        help="the twin's contact settings (%(default)s: its default; friction_pair: the wheels' "
                             "friction on pairs of their own, which keeps them on flat ground in brisk turns)")
    parser.add_argument("--params", default=",".join(DEFAULT_FIT),
                        help="the parameters to fit (atrv-calibrate --params; default %(default)s, the CLI's)")
    parser.add_argument("--out", default=str(RESULTS / "calibration_twin.json"), help="results file (%(default)s)")
    parser.add_argument("--figure-only", action="store_true",
                        help="record and fit nothing: draw --figure from the results file an earlier run wrote")
    return parser


def summarise(rows: list[dict]) -> dict:
    """The results file's summary of the rovers' ``rows``."""
    held = [r for r in rows if r["held_out"]["passes"] is not None]
    return {"rovers_run": len(rows), "held_to_the_cut": len(held),
            "cut_passes": sum(r["held_out"]["passes"] for r in held),
            "cut_min": min((r["held_out"]["cut"] for r in held), default=math.nan),
            "after_m_median": sorted(r["held_out"]["after_m"] for r in rows)[len(rows) // 2],
            "converged": sum(bool(r["converged"]) for r in rows),
            "misfit_flagged": sum(bool((r.get("misfit") or {}).get("flagged")) for r in rows),
            "within_by_parameter": {p: sum(r["params"][p]["within"] for r in rows) for p in RANGES},
            "interval_coverage": (sum(v["covered"] for r in rows for v in r["params"].values())
                                  / sum(len(r["params"]) for r in rows)),
            "wheel_radius_vs_geometric_mm": [1000 * r["params"]["wheel_radius"]["error"] for r in rows],
            "wheel_radius_vs_rolling_mm": [1000 * r["wheel_radius_vs_rolling"] for r in rows],
            # the ranges the docs cite: [smallest, largest]
            "after_cm_median": 100 * sorted(r["held_out"]["after_m"] for r in rows)[len(rows) // 2],
            "ours_after_cm": span([100 * r["ours"]["held_out"]["after_m"] for r in rows if r.get("ours")]),
            "under_geometric_mm": span([-1000 * r["params"]["wheel_radius"]["error"] for r in rows]),
            "off_rolling_mm": span([abs(1000 * r["wheel_radius_vs_rolling"]) for r in rows]),
            "turn_ours": span([r["in_place_turn"]["ours"] for r in rows]),
            "turn_ours_fitted_high_mu": span([r["in_place_turn"]["ours_fitted"] for r in rows
                                              if r["truth"]["friction"] > HIGH_MU]),
            "friction_rise": span([r["fitted"]["friction_rise"] for r in rows if "friction_rise" in r["fitted"]]),
            "friction_error_high_mu": span([r["params"]["friction"]["error"] for r in rows
                                            if r["truth"]["friction"] > HIGH_MU]),
            "turn_twin_low_mu": span([r["in_place_turn"]["twin"] for r in rows if r["truth"]["friction"] <= HIGH_MU]),
            "turn_twin_high_mu": span([r["in_place_turn"]["twin"] for r in rows if r["truth"]["friction"] > HIGH_MU]),
            "high_mu": span([r["truth"]["friction"] for r in rows if r["truth"]["friction"] > HIGH_MU]),
            "airborne_high_mu_percent": span([100 * r["in_place_turn"]["twin_airborne"] for r in rows
                                              if r["truth"]["friction"] > HIGH_MU]),
            "target": f"held-out error cut >= {CUT_TARGET:g}x where the nominal model misses by > {100 * MISSES:g} cm"}


def main() -> int:
    from atrv_warp.sim.sysid.config import DEFAULT_FIT, FIT_PARAMETERS

    parser = build_parser()
    args = parser.parse_args()
    if args.figure_only:
        if not args.figure:
            parser.error("--figure-only needs --figure PATH")
        earlier = json.loads(Path(args.out).read_text())
        draw(earlier["rovers"], ROOT / args.figure, tuple(earlier["fit_params"]), DEFAULT_FIT, Path(args.out).resolve())
        return 0
    if args.rovers < 0 or not (math.isfinite(args.minutes) and args.minutes > 0):
        parser.error("--rovers must be >= 0 and --minutes a finite number > 0")
    params = tuple(p.strip() for p in args.params.split(",") if p.strip())
    if not set(RANGES) <= set(params) or not set(params) <= set(FIT_PARAMETERS):
        parser.error(f"--params must hold {','.join(RANGES)} (the values judged against the twin's) and only "
                     f"parameters the fit knows ({','.join(FIT_PARAMETERS)}), got {args.params!r}")

    sweep_file = RESULTS / ("calibration_sweep.json" if args.seed == 0 else f"calibration_sweep_seed{args.seed}.json")
    sweep = json.loads(sweep_file.read_text()) if sweep_file.is_file() else None
    rovers = [("nominal", nominal_truth(), 1000 * args.seed)]
    rovers += [(f"rover_{k:02d}", t, 1000 * args.seed + k + 1) for k, t in enumerate(draw_truths(args.rovers, args.seed))]
    work = Path(args.work or Path(tempfile.gettempdir()) / f"atrv-calibration-twin-seed{args.seed}")
    work.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONUNBUFFERED="1", WARP_CACHE_PATH=os.environ.get("WARP_CACHE_PATH", str(work / "warp-cache")))
    print(f"{len(rovers)} rovers in the MuJoCo twin ({args.minutes:g} min of driving each); kept in {work}", flush=True)
    rows = []
    for k, (label, t, drive_seed) in enumerate(rovers):
        print(f"{label}: mu {t['friction']:.3f}, torque x{t['torque_scale']:.3f}, payload {t['payload_mass']:.1f} kg, "
              f"wheel {1000 * t['wheel_radius']:.1f} mm ...", flush=True)
        try:
            row = run_rover(label, t, drive_seed, minutes=args.minutes, noise=args.noise, work=work, env=env,
                            contact=args.contact, params=params)
        except RuntimeError as err:  # one rover's failure is reported; the others' rows are kept
            print(f"  {err}", file=sys.stderr, flush=True)
            continue
        row["ours"] = ours(sweep, k - 1) if k > 0 else None
        row["twin_rolling_radius"] = rolling_radius(t, contact=args.contact)
        row["wheel_radius_vs_rolling"] = row["params"]["wheel_radius"]["fitted"] - row["twin_rolling_radius"]
        row["in_place_turn"] = turn = in_place_turn(t, contact=args.contact, fitted=row["fitted"])
        rows.append(row)
        h, errors = row["held_out"], ", ".join(f"{p} {v['error']:+.3g}" for p, v in row["params"].items())
        verdict = "" if h["passes"] is None else (" passes" if h["passes"] else " FAILS")
        print(f"  held-out {100 * h['before_m']:.1f} -> {100 * h['after_m']:.1f} cm (cut {h['cut']:.1f}x{verdict}); "
              f"fitted - truth: {errors}; the twin's rolling radius {1000 * row['twin_rolling_radius']:.1f} mm "
              f"(fitted {1000 * row['wheel_radius_vs_rolling']:+.1f} mm from it); in place at {turn['rate']:g} rad/s ours "
              f"turns at {turn['ours']:.2f} of it ({turn['ours_fitted']:.2f} with the fitted values), the twin "
              f"{turn['twin']:.2f} (a wheel airborne in "
              f"{100 * turn['twin_airborne']:.0f} % of its steps); {row['reason']}; "
              f"{'MISFIT flagged' if (row.get('misfit') or {}).get('flagged') else 'model check passes'}", flush=True)
    if not rows:
        print("no rover finished: nothing to write", file=sys.stderr)
        return 1
    summary = summarise(rows)
    print(f"\ncut >= {CUT_TARGET:g}x on {summary['cut_passes']} of the {summary['held_to_the_cut']} rovers the nominal "
          f"model misses by > {100 * MISSES:g} cm (smallest cut {summary['cut_min']:.1f}x); median held-out error after "
          f"the fit {100 * summary['after_m_median']:.1f} cm; converged {summary['converged']} of {len(rows)}; "
          f"misfit flagged on {summary['misfit_flagged']}")
    result = {"benchmark": "calibration_twin", "contact": args.contact, "fit_params": list(params), "seed": args.seed,
              "minutes": args.minutes,
              "pose_noise_m": args.noise,
              "sweep_results": sweep_file.name if sweep else None, "summary": summary, "rovers": rows,
              "cores": os.cpu_count(), "time": time.strftime("%Y-%m-%d %H:%M:%S")}
    path = write_results(args.out, result, version=VERSION, driver=True)
    print(f"wrote {path}")
    if args.figure:
        draw(rows, ROOT / args.figure, params, DEFAULT_FIT, Path(path).resolve())
        print(f"figure: {args.figure}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def _twin_truth(t: dict) -> str:
    """A twin rover's true values, as the twin tables show them."""
    return f"{t['friction']:.2f}, {t['torque_scale']:.2f}, {t['payload_mass']:.1f}, {1000 * t['wheel_radius']:.1f}"


def calibration_twin(name: str = "calibration_twin.json") -> str:
    """``calibration_twin.json``: each rover recorded in the MuJoCo twin and fitted in ours, beside the same rover
    recorded in ours (the sweep's row, where it ran it)."""
    d = load_results(name)
    rise = "friction_rise" in d.get("fit_params", [])
    rows = []
    for r in d["rovers"]:
        p, t, h, m = r["params"], r["truth"], r["held_out"], r.get("misfit") or {}
        errors = [f"{100 * p['friction']['error'] / t['friction']:+.1f} %",
                  f"{100 * p['torque_scale']['error'] / t['torque_scale']:+.1f} %",
                  f"{p['payload_mass']['error']:+.1f} kg", f"{1000 * p['wheel_radius']['error']:+.1f} mm"]
        cut = f"{h['cut']:.1f}×" + ("" if h["passes"] is None else " ✓" if h["passes"] else " ✗")
        ratios = " / ".join(f"{m['ratio'][c]:.1f}" for c in ("position", "wheel_speed", "effort") if c in m.get("ratio", {}))
        o, turn = r.get("ours"), r["in_place_turn"]
        rows.append([r["rover"].replace("_", " "), _twin_truth(t), *errors,
                     *([f"{r['fitted']['friction_rise']:.2f}"] if rise else []),
                     f"{100 * h['before_m']:.1f} → {100 * h['after_m']:.1f} cm", cut, "yes" if r["converged"] else "no",
                     f"{turn['twin']:.2f} / {turn['ours']:.2f} / {turn['ours_fitted']:.2f}",
                     f"{ratios}{': **misfit**' if m.get('flagged') else ''}",
                     "-" if o is None else f"{100 * o['held_out']['before_m']:.1f} → {100 * o['held_out']['after_m']:.1f} cm"])
    return markdown_table(["rover", "truth: µ, torque, payload [kg], wheel [mm]", "µ error", "torque error", "payload error",
                   "wheel error", *(["friction rise [s/m]"] if rise else []), "held-out error", "cut", "converged",
                   "turn in place at 1 rad/s: twin / ours / ours fitted",
                   "model check (position / wheel speed / effort ÷ noise)", "the same rover in ours"],
                          ["---", "---"] + ["---:"] * (7 if rise else 6) + ["---", "---:", "---", "---:"], rows)


def calibration_twin_validation() -> str:
    """``calibration_twin_seed1.json`` and ``calibration_twin_friction_rise_seed1.json``: rovers drawn from another
    seed, fitted with the CLI's defaults and with the friction's rise, side by side, and a line counting the rovers
    the rise's fit leaves worse."""
    plain, rise = load_results("calibration_twin_seed1.json"), load_results("calibration_twin_friction_rise_seed1.json")
    rows, worse = [], 0
    for a, b in zip(plain["rovers"], rise["rovers"], strict=True):
        ha, hb = a["held_out"], b["held_out"]
        worse += hb["after_m"] > ha["after_m"]
        rows.append([a["rover"].replace("_", " "), _twin_truth(a["truth"]), f"{100 * ha['before_m']:.1f} cm",
                     f"{100 * ha['after_m']:.1f} cm ({ha['cut']:.1f}×)", f"{100 * hb['after_m']:.1f} cm ({hb['cut']:.1f}×)",
                     f"{b['fitted']['friction_rise']:.2f}"])
    table = markdown_table(["rover", "truth: µ, torque, payload [kg], wheel [mm]", "nominal model's held-out error",
                    "after the default fit (cut)", "after the fit with the rise (cut)", "friction rise [s/m]"],
                           ["---", "---", "---:", "---:", "---:", "---:"], rows)
    return (f"{table}\n\nThe fit with the rise leaves a larger held-out error than the default fit on {worse} of these "
            f"{len(rows)} rovers.")


def calibration_twin_friction_rise() -> str:
    """``calibration_twin_friction_rise.json``: :func:`calibration_twin` with the friction's rise fitted too."""
    return calibration_twin("calibration_twin_friction_rise.json")


TABLES = {
    "calibration_twin": calibration_twin,
    "calibration_twin_friction_rise": calibration_twin_friction_rise,
    "calibration_twin_validation": calibration_twin_validation,
}


if __name__ == "__main__":
    sys.exit(main())
