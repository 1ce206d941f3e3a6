"""What a calibration writes: the simulator-config TOML (read back by ``--sim-config``), the JSON report and
a plot of recorded against simulated paths."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from atrv_warp.sim.sysid.config import FIT_PARAMETERS, sim_config_tables
from atrv_warp.sim.sysid.fit import CalibrationResult

__all__ = ["format_report", "plot_paths", "write_report", "write_sim_config"]


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else repr(round(v, 6))
    return repr(v)


def write_sim_config(path, result: CalibrationResult, source: str) -> None:
    """The fitted values as a simulator-config TOML file (``[rover]``, ``[contact]``), with a
    ``[calibration]`` record (the bag, the errors, each value's standard error and spread, the driver the commands
    were replayed through) that the loader does not read. The driver's configuration is the robot's software, not its
    physics: the simulator takes it from ``RoverSim(driver=...)`` and the ROS node's parameters, never from this file."""
    tables = sim_config_tables(result.values)
    summary = result.error_summary()
    lines = [f"# Simulator config fitted by atrv-calibrate to {source}.",
             "# Use it with --sim-config FILE (train), sim_config=FILE (RoverSim, RoverEnv), -p sim_config:=FILE (ROS).", ""]
    for table in ("rover", "contact"):
        if tables[table]:
            lines.append(f"[{table}]")
            lines += [f"{k} = {_toml_value(v)}" for k, v in tables[table].items()]
            lines.append("")
    lines += ["[calibration]  # a record for people; not read by the simulator",
              f"bag = {_toml_value(str(source))}",
              f"segments_train = {int((~result.segments.held_out).sum())}",
              f"segments_held_out = {int(result.segments.held_out.sum())}",
              f"command = {_toml_value(result.segments.command)}",
              *([f"command_latency_s = {_toml_value(result.latency['seconds'])}  # /cmd_vel reached the driver so late"]
                if result.latency else []),
              f"held_out_error_before_m = {_toml_value(summary['held_out']['before_m'])}",
              f"held_out_error_after_m = {_toml_value(summary['held_out']['after_m'])}",
              *([f"misfit = {_toml_value(result.misfit['flagged'])}  # the model check (the report's misfit)"]
                if result.misfit else []), "",
              "[calibration.standard_error]  # the recording's noise (sandwich) and the replay's fidelity, in quadrature"]
    lines += [f"{k} = {_toml_value(v)}" for k, v in result.standard_error.items()]
    lines += ["", "[calibration.spread]  # standard deviation over the converged starts (nan: one converged)"]
    lines += [f"{k} = {_toml_value(v)}" for k, v in result.spread.items()]
    if result.driver is not None:
        lines += ["", "[calibration.driver]  # the robot's driver the /cmd_vel were replayed through (its configuration)"]
        lines += [f"{k} = {_toml_value(v)}" for k, v in result.driver.items()]
    Path(path).write_text("\n".join(lines) + "\n")


def format_report(result: CalibrationResult) -> str:
    """The result as the console table: each parameter, then the errors before and after."""
    def number(v: float) -> str:
        return "—" if math.isnan(v) else f"{v:.2g}"

    def interval(value: float, error: float) -> str:
        return "—" if math.isnan(error) else f"{value - 1.96 * error:.4g} to {value + 1.96 * error:.4g}"

    rows = [f"{'parameter':<14}{'before':>10}{'fitted':>10}{'95 % interval':>22}{'spread':>9}  unit"]
    for name, value in result.values.items():
        rows.append(f"{name:<14}{result.nominal[name]:>10.4g}{value:>10.4g}"
                    f"{interval(value, result.standard_error[name]):>22}{number(result.spread[name]):>9}  "
                    f"{FIT_PARAMETERS[name].unit}")
    rows.append("95 % interval: 1.96 standard errors either side (the recording's noise and the replay's fidelity, in "
                "quadrature); spread: the standard deviation of the fit's starts' end points (how well they agree)")
    for a, b, r in result.confounded:
        rows.append(f"{a} and {b} are confounded (correlation {r:+.2f}): the drive fixes a combination of them, not "
                    "each; fit one with the other known (--params)")
    rows.append("")
    rows.append(f"{'position error (median per segment)':<38}{'before':>9}{'after':>9}{'cut':>7}  (cut: before / after)")
    for split, s in result.error_summary().items():
        n = len(result.errors[split]["before"])
        rows.append(f"{split.replace('_', '-') + f' ({n} segments)':<38}{s['before_m']:>8.3f}m{s['after_m']:>8.3f}m"
                    f"{s['reduction']:>6.1f}x")
    lat = result.latency
    if lat is not None:
        rows.append("")
        if not lat["fitted"]:
            rows.append(f"command latency {lat['seconds']:g} s (given)")
        else:
            losses = ", ".join(f"{k:g} s {v:.3g}" for k, v in lat["loss_by_latency"].items())
            rows.append(f"command latency {lat['seconds']:g} s (fitted; training loss by latency: {losses})")
    if result.misfit is not None:
        rows.append(result.misfit["line"])
    return "\n".join(rows)


def write_report(path, result: CalibrationResult, source: str) -> None:
    Path(path).write_text(json.dumps({"bag": str(source), **result.to_dict()}, indent=1) + "\n")


def plot_paths(path, result: CalibrationResult, source: str, count: int = 8) -> None:
    """Recorded, nominal and calibrated paths of up to ``count`` held-out segments, each from its start."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    p = result.paths
    n = min(count, len(p["recorded"]))
    order = np.argsort([-np.abs(r[-1, :2]).sum() for r in p["recorded"]])[:n]  # the longest moves
    cols = min(4, n)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.0 * rows + 0.6), squeeze=False)
    for ax, i in zip(axes.flat, sorted(order)):
        for key, style, label in (("recorded", "k-", "recorded (smoothed)"), ("nominal", "C3--", "nominal sim"),
                                  ("calibrated", "C0-", "calibrated sim")):
            xy = p[key][i]
            ax.plot(xy[:, 0], xy[:, 1], style, lw=1.6 if key == "recorded" else 1.3, label=label)
        ax.plot(0, 0, "ko", ms=3)
        ax.set_title(f"t = {p['t0'][i]:.1f} s", fontsize=9)
        ax.set_aspect("equal", adjustable="datalim")
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7, loc="best")
    s = result.error_summary()["held_out"]
    fig.suptitle(f"{Path(source).name}: held-out segments, x and y [m] from each start; median position error "
                 f"{s['before_m']:.3f} m nominal, {s['after_m']:.3f} m calibrated", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
