"""Why the MuJoCo twin turned so much worse than ours, and what MuJoCo's contact settings do to it (issue #41).

    pip install -e ".[mujoco]"; python -m benchmarks.transfer.mujoco_turning_study

For each of MuJoCo's contact settings in :func:`settings` (a ``MujocoContact``: solref/solimp, cone, impratio,
noslip, integrator, the wheel's shape, MuJoCo steps per 0.01 s driver substep):

- **a drop test**: the twin let down onto flat ground from where its wheels just touch; its static **sink** and
  how far it still **bounces** after 0.5, 1, 2 and 3 s; and where the ground touches each wheel at rest (contacts
  per wheel, their offset along the axle and depth below the wheel's centre: the wheels stand on their treads);
- per turn (in place (0, 0.5) and on the arc (0.5 m/s, 0.5 rad/s), as ``mujoco_agreement.py`` turns, and the
  nav task's fastest: in place at 2 rad/s and on an arc at 2 m/s and 2 rad/s) at µ 0.3 and 0.8:
  **chi** as ``mujoco_agreement.py`` measures it (its ``twin_turn``: the driver with a differential drive's wheel
  targets for 8 s, the means over the last 3 s sampled after each 0.05 s control step); **chi sampled every
  substep** (the same turn stepped one 0.01 s substep per step: where the wheels hop in a cycle of five substeps,
  the control step samples one phase of it and the two differ); **airborne**, the fraction of substeps after
  which a wheel was off the ground; the largest driver **torque** sampled [N·m] (its limit is 20); the
  **friction ratio**, the contacts' friction over their normal force (µ where the wheels slide as Coulomb's law
  has it, less where MuJoCo's friction is still in its viscous range); and the chassis' **lift** in the turn
  over its rest height [m];
- **on the hills terrain** at the nominal µ, the driver as deployed: the yaw rate over the command in place
  (1 rad/s) and on an arc (1 m/s, 1 rad/s) from one pose.

Our simulator's sink, bounce and chi once, for comparison. Then the mechanism on its own: one wheel slid along
the ground (:func:`sliding_wheel`) with MuJoCo's defaults, the tyre's sink, and the tyre damped as lightly as
ours, how far it rides above its rest height and how often it is on the ground. About three minutes on one core.
Prints the table and writes ``benchmarks/results/mujoco_turning_study.json`` (docs/physics.md reads it).
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

from benchmarks._common import load_results, markdown_table, pin_to_one_core, write_results
from benchmarks.transfer.mujoco_agreement import TURN_FRICTIONS, TURNS, ours_turn, steps, twin_turn

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
STUDY_TURNS = {**TURNS, "fast in place": (0.0, 2.0), "fast arc": (2.0, 2.0)}
"""The agreement's turns (linear [m/s], angular [rad/s]) and the fastest the nav task commands (2 m/s, 2 rad/s)."""
DROP_WINDOWS = (0.5, 1.0, 2.0, 3.0)  # [s] starts of the 0.5 s windows of the drop test's bounce amplitude


def settings() -> list[tuple[str, str, object]]:
    """(name, what it is, ``MujocoContact``) for every setting studied: MuJoCo's defaults (the twin before this
    study) and each knob the issue asked about, then the tyre's static sink (the twin's contact now) and knobs on
    it, and the tyre damped as lightly as ours."""
    from atrv_warp.integrations.mujoco.mjcf import MUJOCO_DEFAULT_CONTACT as d
    from atrv_warp.integrations.mujoco.mjcf import MujocoContact

    t = MujocoContact()
    r = dataclasses.replace
    return [
        ("mujoco_default", "MuJoCo's defaults (the twin before)", d),
        ("default_steps5", "defaults, 5 MuJoCo steps per substep", r(d, steps_per_substep=5)),
        ("default_steps10", "defaults, 10 MuJoCo steps per substep", r(d, steps_per_substep=10)),
        ("default_noslip", "defaults, noslip solver (10 iterations)", r(d, noslip_iterations=10)),
        ("default_pyramidal", "defaults, pyramidal cone", r(d, cone="pyramidal")),
        ("default_impratio10", "defaults, impratio 10", r(d, impratio=10.0)),
        ("default_implicitfast", "defaults, implicitfast integrator", r(d, integrator="implicitfast")),
        ("default_stiffer", "stiffer: solref 0.004 s, 5 MuJoCo steps per substep",
         r(d, solref=(0.004, 1.0), steps_per_substep=5)),
        ("default_sphere", "defaults, sphere wheels (one contact each)", r(d, wheel="sphere")),
        ("default_impedance_tyre_sink", "the tyre's sink at MuJoCo's default impedance (solref 0.267 s)",
         r(d, solref=(0.267, 1.0))),
        ("tyre", "the tyre's sink: solref 0.087 s, impedance 0.5 (the twin now)", t),
        ("tyre_impedance0.3", "the tyre's sink at impedance 0.3 (solref 0.0731 s)",
         r(t, solref=(0.0731, 1.0), solimp=(0.3, 0.3, 0.001))),
        ("tyre_impedance0.7", "the tyre's sink at impedance 0.7 (solref 0.1117 s)",
         r(t, solref=(0.1117, 1.0), solimp=(0.7, 0.7, 0.001))),
        ("tyre_steps5", "tyre, 5 MuJoCo steps per substep", r(t, steps_per_substep=5)),
        ("tyre_noslip", "tyre, noslip solver (10 iterations)", r(t, noslip_iterations=10)),
        ("tyre_pyramidal", "tyre, pyramidal cone", r(t, cone="pyramidal")),
        ("tyre_sphere", "tyre, sphere wheels (one contact each, twice the sink)", r(t, wheel="sphere")),
        ("tyre_light_damping", "the tyre's sink, damped as lightly as ours (damping ratio 0.06, solref 1.45 s)",
         r(t, solref=(1.45, 0.06))),
        ("tyre_friction_pair", "tyre, wheels' friction: solreffriction 0.87 s, impratio 10",
         r(t, solreffriction=(0.87, 1.0), impratio=10.0)),
    ]


def at_rest(contact, seconds: float = 6.0) -> dict:
    """The drop test: the twin let down onto flat ground from where its wheels just touch (its reset), brakes off,
    stepped one 0.01 s substep per step for ``seconds``. Its wheel ``sink`` [m] at the end (how far the chassis sits
    below where rigid wheels would hold it: the mean of the last second), the chassis origin's ``height`` [m] then,
    its ``bounce`` on the way (:func:`bounce`), and where the ground touches each wheel at the end: the contacts per
    wheel, their largest offset along the wheel's axle from its centre (``along_axle`` [m]; the cylinder's rim edges
    are half its width out) and their mean depth below its centre (``below_centre`` [m], about the radius): the
    wheels stand on their treads, axles level."""
    import mujoco

    from atrv_warp.integrations.mujoco import MujocoTwin
    from atrv_warp.sim.config import SimConfig

    twin = MujocoTwin(contact=contact, sim=SimConfig(step_dt=SimConfig().sim_dt))
    dt, heights = twin.sim_cfg.step_dt, []
    for _ in range(steps(seconds, dt)):
        twin.step(torques=(0.0, 0.0))
        heights.append(float(twin.root_pose[2]))
    m, d = twin.model, twin.data
    axle_z = float(np.mean([w.origin[2, 3] for w in twin.description.wheels]))
    height = float(np.mean(heights[-steps(1.0, dt):]))
    links = [w.link for w in twin.description.wheels]
    along, below, count = [], [], np.zeros(len(links))
    for i in range(d.ncon):
        for g in d.contact.geom[i]:
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, m.geom_bodyid[g])
            if name not in links:
                continue
            wheel = links.index(name)
            count[wheel] += 1
            offset = d.contact.pos[i] - d.geom_xpos[g]
            axle = d.xmat[m.geom_bodyid[g]].reshape(3, 3) @ np.asarray(twin.description.wheels[wheel].axis, dtype=float)
            along.append(abs(float(offset @ axle)))
            below.append(-float(offset[2]))
    return {"sink": twin.arena_cfg.ground_top + twin.rover_cfg.wheel_radius - axle_z - height, "height": height,
            "bounce": bounce(heights, dt), "contacts_per_wheel": count.tolist(), "along_axle": max(along),
            "below_centre": float(np.mean(below))}


SLIPS = (0.1, 0.2, 0.4)  # [m/s] a lone wheel's sliding speeds


def sliding_wheel(contact, mu: float, slip: float, seconds: float = 2.0) -> dict:
    """The mechanism on its own: one wheel (the rover's cylinder, a quarter of its mass, axle level, on slide
    joints along x and z) slid along the ground at ``slip`` [m/s] (its x velocity reset every step, so friction
    stays at µ N against it) with MuJoCo's settings ``contact``. Returns how much higher [m] it rides than at rest
    over the last second (``lift``; its ``sink`` at rest for scale) and the fraction of those steps after which it
    touched the ground (``contact``)."""
    import mujoco

    from atrv_warp.integrations.mujoco.mjcf import number, vector
    from atrv_warp.sim.config import RoverConfig, SimConfig
    from atrv_warp.sim.urdf import load_rover

    rover, sim = RoverConfig(), SimConfig()
    mass = load_rover(rover).total_mass / 4
    shape = (f'type="cylinder" zaxis="0 1 0" size="{number(rover.wheel_radius)} {number(0.5 * rover.wheel_length)}"'
             if contact.wheel == "cylinder" else f'type="sphere" size="{number(rover.wheel_radius)}"')
    xml = f"""<mujoco>
  <option timestep="{number(sim.sim_dt / contact.steps_per_substep)}" gravity="0 0 {number(sim.gravity)}"
          integrator="{contact.integrator}" cone="{contact.cone}" impratio="{number(contact.impratio)}"
          noslip_iterations="{contact.noslip_iterations}"/>
  <default><geom condim="3" friction="{number(mu)} 0 0" solref="{vector(contact.solref)}"
                 solimp="{vector(contact.solimp)}"/></default>
  <worldbody>
    <geom type="plane" size="50 50 0.1"/>
    <body pos="0 0 {number(rover.wheel_radius)}">
      <joint type="slide" axis="1 0 0"/><joint type="slide" axis="0 0 1"/>
      <geom {shape} mass="{number(mass)}"/>
    </body>
  </worldbody>
</mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    for _ in range(steps(5.0, m.opt.timestep)):  # a lightly damped tyre bounces for seconds
        mujoco.mj_step(m, d)
    rest = float(d.qpos[1])
    total, kept = steps(seconds, m.opt.timestep), steps(1.0, m.opt.timestep)
    heights, touching = [], 0
    for k in range(total):
        d.qvel[0] = slip
        mujoco.mj_step(m, d)
        if k >= total - kept:
            heights.append(float(d.qpos[1]))
            touching += int(d.ncon > 0)
    return {"mu": mu, "slip": slip, "sink": -rest, "lift": float(np.mean(heights)) - rest, "contact": touching / kept}


TERRAIN_POSE = (0.0, 0.0, 0.0)  # x [m], y [m], yaw [rad] on the hills preset's first tile
TERRAIN_TURNS = {"in place": (0.0, 1.0), "arc": (1.0, 1.0)}  # /cmd_vel (linear [m/s], angular [rad/s])


def terrain_turns(contact=None, *, ours: bool = False, seconds: float = 3.0, average: float = 2.0) -> dict:
    """Turns on the ``hills`` terrain at the nominal µ, the driver as deployed (its effective track factor):
    from :data:`TERRAIN_POSE` on the preset's first tile, each of :data:`TERRAIN_TURNS` for ``seconds``, the mean
    yaw rate over the last ``average`` seconds over the command, in our simulator (``ours``) or the twin with
    ``contact``."""
    import torch

    from atrv_warp.integrations.mujoco import MujocoTwin
    from atrv_warp.sim import RoverSim

    out = {}
    for label, command in TERRAIN_TURNS.items():
        sim = RoverSim(1, terrain="hills")
        sim.terrain.tile.zero_()
        sim.reset(poses=[TERRAIN_POSE])
        pose = sim.root_pose[0].double().numpy()
        twin = None if ours else MujocoTwin(terrain=sim.terrain.grid, tile=0, contact=contact)
        if twin is not None:
            twin.reset(pose[:3], pose[3:])
        dt = sim.sim_cfg.step_dt
        rates = []
        for k in range(steps(seconds, dt)):
            if ours:
                sim.set_twist(torch.tensor([command]))
                sim.step()
                rate = float(sim.ang_vel[0, 2])
            else:
                twin.command(*command)
                twin.step()
                rate = float(twin.angular_velocity[2])
            if k >= steps(seconds - average, dt):
                rates.append(rate)
        out[label.replace(" ", "_")] = float(np.mean(rates)) / command[1]
    return out


def bounce(heights, dt: float) -> list[float]:
    """The drop test's bounce: the largest distance [m] of the chassis height from its final rest (the mean of the
    last second) in 0.5 s windows starting at :data:`DROP_WINDOWS`."""
    z = np.asarray(heights)
    rest = z[-steps(1.0, dt):].mean()
    return [float(np.abs(z[steps(a, dt):steps(a + 0.5, dt)] - rest).max()) for a in DROP_WINDOWS]


def ours_drop(seconds: float = 6.0) -> tuple[float, list[float]]:
    """Our rover's static sink [m] (the contact law's) and its :func:`bounce` let down as the twin's is."""
    from atrv_warp.sim import RoverSim
    from atrv_warp.sim.config import SimConfig

    rover = RoverSim(1, sim=SimConfig(step_dt=SimConfig().sim_dt))
    axle_z = float(np.mean([w.origin[2, 3] for w in rover.description.wheels]))
    touching = rover.arena_cfg.ground_top + rover.rover_cfg.wheel_radius - axle_z
    rover.reset(height=touching)
    heights = []
    for _ in range(steps(seconds, rover.sim_cfg.step_dt)):
        rover.step()
        heights.append(float(rover.root_pose[0, 2]))
    return touching - rover.rest_height, bounce(heights, rover.sim_cfg.step_dt)


def main() -> int:
    try:
        import mujoco  # noqa: F401
    except ImportError:
        print("MuJoCo is missing: pip install -e '.[mujoco]'", file=sys.stderr)
        return 2
    from atrv_warp.sim.config import SimConfig

    pin_to_one_core()
    every_substep = SimConfig(step_dt=SimConfig().sim_dt)
    sink, bounced = ours_drop()
    ours = {"sink": sink, "sink_mm": 1000 * sink, "bounce": bounced, "chi": [], "terrain": terrain_turns(ours=True)}
    for mu in TURN_FRICTIONS:
        for label, command in STUDY_TURNS.items():
            ours["chi"].append({"turn": label.replace(" ", "_"), "mu": mu, "chi": ours_turn(mu, command)})
    print(f"ours: sink {1000 * sink:.2f} mm, on the hills yaw rate / command {ours['terrain']}, bounce after "
          f"{DROP_WINDOWS} s "
          f"{np.round(1000 * np.asarray(bounced), 2)} mm; chi " +
          ", ".join(f"{c['turn']} µ {c['mu']:g} {c['chi']:.2f}" for c in ours["chi"]), flush=True)
    print("per setting, per µ (0.3, 0.8) and turn (" + ", ".join(STUDY_TURNS) + "): chi sampled per control step / "
          "per substep, the substeps with a wheel airborne, the largest driver torque [N·m], friction / normal force")
    table, rows = [], []
    for name, label, contact in settings():
        rest = at_rest(contact)
        table.append({"setting": name, "label": label, "contact": dataclasses.asdict(contact), **rest,
                      "sink_mm": 1000 * rest["sink"], "terrain": terrain_turns(contact)})
        cells = []
        for mu in TURN_FRICTIONS:
            for turn, command in STUDY_TURNS.items():
                step = twin_turn(mu, command, contact=contact)
                sub = twin_turn(mu, command, contact=contact, sim=every_substep)
                torque = max(step["torque_max"], sub["torque_max"])
                rows.append({"setting": name, "turn": turn.replace(" ", "_"), "mu": mu, "chi": step["chi"],
                             "chi_substeps": sub["chi"], "airborne": sub["airborne"], "torque_max": torque,
                             "yaw_rate": sub["yaw_rate"], "lift": sub["height"] - rest["height"],
                             "friction_ratio": sub["friction_ratio"]})
                ratio = "-" if sub["friction_ratio"] is None else f"{sub['friction_ratio']:.2f}"
                cells.append(f"{step['chi']:.2f}/{sub['chi']:.2f} {sub['airborne']:.0%} {torque:.0f} {ratio}")
        print(f"{label}: sink {1000 * rest['sink']:.2f} mm, {rest['contacts_per_wheel'][0]:.0f} contacts per wheel, "
              f"on the hills yaw rate / command {table[-1]['terrain']}, "
              f"bounce {np.round(1000 * np.asarray(table[-1]['bounce']), 2)} mm\n    " + " | ".join(cells), flush=True)
    wheel = []
    for name, label, contact in settings():
        if name not in ("mujoco_default", "tyre", "tyre_light_damping"):
            continue
        for mu in TURN_FRICTIONS:
            for slip in SLIPS:
                w = sliding_wheel(contact, mu, slip)
                wheel.append({"setting": name, **w, "lift_mm": 1000 * w["lift"], "sink_mm": 1000 * w["sink"]})
                w = wheel[-1]
                print(f"a lone wheel, {label}: µ {mu:g}, sliding at {slip:g} m/s: rides {1000 * w['lift']:+.2f} mm "
                      f"above rest (sink {1000 * w['sink']:.2f} mm), on the ground {w['contact']:.0%} of steps")
    result = {"turns": {t.replace(" ", "_"): c for t, c in STUDY_TURNS.items()}, "frictions": list(TURN_FRICTIONS),
              "terrain_pose": list(TERRAIN_POSE), "terrain_turns": {t.replace(" ", "_"): c for t, c in TERRAIN_TURNS.items()},
              "drop_windows": list(DROP_WINDOWS), "ours": ours, "settings": table, "rows": rows,
              "sliding_wheel": wheel}
    path = write_results(RESULTS / "mujoco_turning_study.json", result, version=VERSION, driver=True)
    print(f"written to {path}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def mujoco_turning_study() -> str:
    """``mujoco_turning_study.json``: per MuJoCo contact setting, the twin's sink at rest, chi in the agreement's
    turns and how often a wheel was airborne in them, the sliding wheels' friction over their load at µ 0.8, the
    fastest in-place turn at µ 0.8, and turns on the hills terrain; our simulator first."""
    data = load_results("mujoco_turning_study.json")
    rows = data["rows"]

    def cell(setting, turn, mu, field="chi_substeps"):
        return next(r for r in rows if r["setting"] == setting and r["turn"] == turn and r["mu"] == mu)[field]

    ours = {(c["turn"], c["mu"]): c["chi"] for c in data["ours"]["chi"]}
    out = [["**ours** (Coulomb, one contact per wheel)", f"{data['ours']['sink_mm']:.1f}",
            f"{ours['in_place', 0.3]:.2f} / {ours['arc', 0.3]:.2f}", f"{ours['in_place', 0.8]:.2f} / {ours['arc', 0.8]:.2f}",
            "-", "-", f"{ours['fast_in_place', 0.8]:.2f}", "-",
            f"{data['ours']['terrain']['in_place']:.2f} / {data['ours']['terrain']['arc']:.2f}"]]
    for s in data["settings"]:
        name = s["setting"]
        nominal = [(t, mu) for mu in (0.3, 0.8) for t in ("in_place", "arc")]
        airborne = max(cell(name, t, mu, "airborne") for t, mu in nominal)
        ratio = cell(name, "in_place", 0.8, "friction_ratio")
        label = f"**{s['label']}**" if name == "tyre" else s["label"]
        out.append([label, f"{s['sink_mm']:.2f}",
                    f"{cell(name, 'in_place', 0.3):.2f} / {cell(name, 'arc', 0.3):.2f}",
                    f"{cell(name, 'in_place', 0.8):.2f} / {cell(name, 'arc', 0.8):.2f}", f"{airborne:.0%}",
                    "-" if ratio is None else f"{ratio:.2f}", f"{cell(name, 'fast_in_place', 0.8):.2f}",
                    f"{cell(name, 'fast_in_place', 0.8, 'airborne'):.0%}",
                    f"{s['terrain']['in_place']:.2f} / {s['terrain']['arc']:.2f}"])
    return markdown_table(["MuJoCo setting", "sink [mm]", "chi µ 0.3: in place / arc", "chi µ 0.8: in place / arc",
                   "wheel airborne (worst of these turns)", "friction / load, µ 0.8 in place",
                   "chi at 2 rad/s in place, µ 0.8", "airborne then", "hills, µ 0.3: yaw rate / command, in place / arc"],
                          ["---", "---:", "---:", "---:", "---:", "---:", "---:", "---:", "---:"], out)


TABLES = {
    "mujoco_turning_study": mujoco_turning_study,
}


if __name__ == "__main__":
    sys.exit(main())
