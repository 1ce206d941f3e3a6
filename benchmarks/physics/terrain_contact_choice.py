"""Terrain contact: Newton's HFIELD collision pipeline vs an analytic per-world Warp kernel (CPU).

Run: ``python -m benchmarks.physics.terrain_contact_choice [--quick] [--cold]``

Why atrv_warp samples its own heightfield under each wheel instead of running Newton's collision
pipeline (docs/tasks.md, "Navigation"): per-call time at N = 256 and 1024 worlds of four wheel
cylinders on a 61 x 61 heightfield, first-call (compile) time, and smoothness of depth and normal
as one wheel is swept over a crest. Figures are printed and written to
``benchmarks/results/terrain_contact_choice.json`` (sweeps beside it as ``.npz``).

API used (read from newton 1.8 sources, examples/basic/example_basic_heightfield.py and
tests/test_heightfield.py):
  hf = newton.Heightfield(data, nrow, ncol, hx, hy, min_z, max_z)   # cols along x, rows along y
  builder.add_shape_heightfield(heightfield=hf)                     # static, body=-1, world -1 (global)
  world.add_body(...); world.add_shape_cylinder(body, radius, half_height, xform)  # axis = local z
  builder.add_world(world) x N;  model = builder.finalize(device="cpu")
  pipe = newton.CollisionPipeline(model); contacts = pipe.contacts(); pipe.collide(state, contacts)
  newton.eval_rigid_contact_kinematics(model, state, contacts, out_distance=...)  # signed distance
(model.collide() is deprecated since 1.5 in favour of CollisionPipeline.collide.)
"""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
import time
import warnings

import newton
import numpy as np
import warp as wp

from benchmarks._common import RESULTS, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

OUT = str(RESULTS)
QUICK = "--quick" in sys.argv

# ---------------------------------------------------------------- terrain
NROW = NCOL = 61
HX = HY = 15.0  # 30 m x 30 m
AMP = 0.1
WAVELEN = 4.0
K = 2.0 * math.pi / WAVELEN
R = 0.125
HL = 0.0375
DX = 2.0 * HX / (NCOL - 1)
DY = 2.0 * HY / (NROW - 1)


def terrain_fn(x, y):
    return AMP * np.sin(K * x) * np.cos(K * y)


xs = np.linspace(-HX, HX, NCOL)
ys = np.linspace(-HY, HY, NROW)
XX, YY = np.meshgrid(xs, ys)  # XX[r, c] = xs[c]; rows along y
ELEV = terrain_fn(XX, YY).astype(np.float32)

# cylinder axis (local z) -> world y : rotate +90 deg about x maps z -> -y (axis sign irrelevant)
Q_AXLE_Y = wp.quat_from_axis_angle(wp.vec3(1.0, 0.0, 0.0), 0.5 * math.pi)
WHEEL_OFFS = [(-0.3, -0.3), (0.3, -0.3), (-0.3, 0.3), (0.3, 0.3)]


def build_newton(centres_per_world: list[list[tuple[float, float, float]]]):
    """One global heightfield + one world per entry, each with free bodies carrying one cylinder."""
    b = newton.ModelBuilder()
    hf = newton.Heightfield(data=ELEV, nrow=NROW, ncol=NCOL, hx=HX, hy=HY)
    b.add_shape_heightfield(heightfield=hf)
    for centres in centres_per_world:
        w = newton.ModelBuilder()
        ids = []
        for c in centres:
            body = w.add_body(xform=wp.transform(wp.vec3(*c), Q_AXLE_Y))
            ids.append(w.add_shape_cylinder(body, radius=R, half_height=HL))
        # wheels never touch each other on the rover: filter cylinder-cylinder pairs so the
        # explicit broad phase only carries cylinder-heightfield pairs
        for i in range(len(ids)):
            for j in range(i + 1, len(ids)):
                w.shape_collision_filter_pairs.append((ids[i], ids[j]))
        b.add_world(w)
    return b.finalize(device="cpu")


# ---------------------------------------------------------------- analytic kernel
@wp.func
def bilinear(grid: wp.array3d(dtype=float), w: int, x: float, y: float):
    """Height and gradient of the bilinear interpolant at (x, y); clamps to the grid."""
    u = (x + HX) / DX
    v = (y + HY) / DY
    c0 = wp.clamp(int(wp.floor(u)), 0, NCOL - 2)
    r0 = wp.clamp(int(wp.floor(v)), 0, NROW - 2)
    fu = wp.clamp(u - float(c0), 0.0, 1.0)
    fv = wp.clamp(v - float(r0), 0.0, 1.0)
    h00 = grid[w, r0, c0]
    h01 = grid[w, r0, c0 + 1]
    h10 = grid[w, r0 + 1, c0]
    h11 = grid[w, r0 + 1, c0 + 1]
    h = (1.0 - fv) * ((1.0 - fu) * h00 + fu * h01) + fv * ((1.0 - fu) * h10 + fu * h11)
    gx = ((1.0 - fv) * (h01 - h00) + fv * (h11 - h10)) / DX
    gy = ((1.0 - fu) * (h10 - h00) + fu * (h11 - h01)) / DY
    return h, gx, gy


EDGE_TILT = wp.constant(0.02)  # same smoothing as atrv_warp cylinder_deepest_point


@wp.func
def cylinder_deepest_point(xf: wp.transform, radius: float, half_length: float, normal: wp.vec3) -> wp.vec3:
    c = wp.transform_get_translation(xf)
    a = wp.transform_vector(xf, wp.vec3(0.0, 0.0, 1.0))
    na = wp.dot(normal, a)
    radial = normal - na * a
    rl = wp.length(radial)
    p = c
    if rl > 1.0e-6:
        p = p - radial * (radius / rl)
    return p - a * (half_length * wp.clamp(na / EDGE_TILT, -1.0, 1.0))


@wp.kernel
def analytic_terrain_contact(
    shapes_per_world: int,
    grid: wp.array3d(dtype=float),
    body_q: wp.array(dtype=wp.transform),
    radius: float,
    half_length: float,
    out_depth: wp.array(dtype=float),
    out_normal: wp.array(dtype=wp.vec3),
    out_point: wp.array(dtype=wp.vec3),
):
    w = wp.tid()
    for s in range(shapes_per_world):
        i = w * shapes_per_world + s
        xf = body_q[i]
        c = wp.transform_get_translation(xf)
        _h, gx, gy = bilinear(grid, w, c[0], c[1])
        n = wp.normalize(wp.vec3(-gx, -gy, 1.0))
        p = cylinder_deepest_point(xf, radius, half_length, n)
        hp, _gx2, _gy2 = bilinear(grid, w, p[0], p[1])
        depth = n[2] * (hp - p[2])  # distance below the tangent plane through (p.x, p.y, hp)
        out_depth[i] = depth
        out_normal[i] = n
        out_point[i] = p


# ---------------------------------------------------------------- helpers
def world_centres(n_worlds: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n_worlds):
        ox, oy = rng.uniform(-12.0, 12.0, 2)
        cs = []
        for dx, dy in WHEEL_OFFS:
            x, y = ox + dx, oy + dy
            cs.append((x, y, float(terrain_fn(x, y)) + R - 0.005))  # ~5 mm penetration
        out.append(cs)
    return out


def timeit(fn, reps):
    wp.synchronize()
    t = time.perf_counter()
    for _ in range(reps):
        fn()
    wp.synchronize()
    return (time.perf_counter() - t) / reps


def bench(n_worlds: int, reps: int):
    res = {"N": n_worlds}
    cents = world_centres(n_worlds)
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as wlist:
        warnings.simplefilter("always")
        model = build_newton(cents)
        state = model.state()
        res["newton_build_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        # default auto estimate is 5 contacts per cylinder-heightfield pair and overflows
        # ("Contact buffer overflowed 5189 > 5120"), so size it explicitly
        pipe = newton.CollisionPipeline(model, rigid_contact_max=16 * 4 * n_worlds)
        contacts = pipe.contacts()
        res["newton_pipeline_init_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        pipe.collide(state, contacts)
        wp.synchronize()
        res["newton_first_collide_new_model_s"] = time.perf_counter() - t0
    res["newton_warnings"] = sorted({str(w.message)[:160] for w in wlist})
    res["newton_rigid_contact_max"] = int(contacts.rigid_contact_max)
    res["newton_contact_count"] = int(contacts.rigid_contact_count.numpy()[0])
    res["newton_explicit_pairs"] = int(model.shape_contact_pair_count) if hasattr(model, "shape_contact_pair_count") else None
    res["newton_collide_ms"] = 1e3 * timeit(lambda: pipe.collide(state, contacts), reps)
    # variant: no per-pair contact reduction
    pipe2 = newton.CollisionPipeline(model, rigid_contact_max=64 * 4 * n_worlds, reduce_contacts=False)
    c2 = pipe2.contacts()
    t0 = time.perf_counter()
    pipe2.collide(state, c2)
    wp.synchronize()
    res["newton_noreduce_first_collide_s"] = time.perf_counter() - t0
    res["newton_noreduce_contact_count"] = int(c2.rigid_contact_count.numpy()[0])
    res["newton_noreduce_collide_ms"] = 1e3 * timeit(lambda: pipe2.collide(state, c2), reps)

    # analytic kernel on the same poses
    grid = wp.array(np.broadcast_to(ELEV, (n_worlds, NROW, NCOL)).copy(), dtype=float, device="cpu")
    nshape = 4 * n_worlds
    depth = wp.zeros(nshape, dtype=float, device="cpu")
    normal = wp.zeros(nshape, dtype=wp.vec3, device="cpu")
    point = wp.zeros(nshape, dtype=wp.vec3, device="cpu")

    def launch():
        wp.launch(analytic_terrain_contact, dim=n_worlds,
                  inputs=[4, grid, state.body_q, R, HL], outputs=[depth, normal, point], device="cpu")

    t0 = time.perf_counter()
    launch()
    wp.synchronize()
    res["analytic_first_launch_s"] = time.perf_counter() - t0
    res["analytic_ms"] = 1e3 * timeit(launch, reps * 10)
    d = depth.numpy()
    res["analytic_depth_mean_mm"] = float(1e3 * d.mean())
    res["analytic_depth_minmax_mm"] = [float(1e3 * d.min()), float(1e3 * d.max())]
    return res


def smooth_sweep(n_samples: int = 200, y0: float = 0.0):
    """Cylinder centre at y = y0, z fixed, x swept over the crest at x = 1 (a grid node column)."""
    xs_s = np.linspace(0.0, 2.0, n_samples)
    z0 = AMP + R - 0.025  # 25 mm penetration at the crest of the true sinusoid
    cents = [[(float(x), y0, z0)] for x in xs_s]
    model = build_newton(cents)
    state = model.state()
    pipe = newton.CollisionPipeline(model, rigid_contact_max=16 * n_samples)
    contacts = pipe.contacts()
    t0 = time.perf_counter()
    pipe.collide(state, contacts)  # first collide of the process: includes JIT compile / cache load
    wp.synchronize()
    t_first_newton = time.perf_counter() - t0
    cnt = int(contacts.rigid_contact_count.numpy()[0])
    dist = wp.zeros(contacts.rigid_contact_max, dtype=float, device="cpu")
    newton.eval_rigid_contact_kinematics(model, state, contacts, out_distance=dist)
    dist = dist.numpy()[:cnt]
    nrm = contacts.rigid_contact_normal.numpy()[:cnt]
    s0 = contacts.rigid_contact_shape0.numpy()[:cnt]
    s1 = contacts.rigid_contact_shape1.numpy()[:cnt]
    shape_world = model.shape_world.numpy()
    hf_shape = int(np.flatnonzero(model.shape_type.numpy() == int(newton.GeoType.HFIELD))[0])

    nt_count = np.zeros(n_samples, int)
    nt_pen_count = np.zeros(n_samples, int)
    nt_depth = np.zeros(n_samples)  # deepest penetration (>0), 0 if none
    nt_normal = np.tile([0.0, 0.0, 1.0], (n_samples, 1))
    nt_sumdepth = np.zeros(n_samples)  # sum of penetrations (what a per-contact penalty law integrates)
    for k in range(cnt):
        other = s1[k] if s0[k] == hf_shape else s0[k]
        wi = int(shape_world[other])
        pen = -float(dist[k])
        # normal points from shape0 to shape1; make it point from terrain to the cylinder
        n = nrm[k] if s0[k] == hf_shape else -nrm[k]
        nt_count[wi] += 1
        if pen > 0:
            nt_pen_count[wi] += 1
            nt_sumdepth[wi] += pen
        if pen > nt_depth[wi]:
            nt_depth[wi] = pen
            nt_normal[wi] = n

    # analytic
    grid = wp.array(np.broadcast_to(ELEV, (n_samples, NROW, NCOL)).copy(), dtype=float, device="cpu")
    depth = wp.zeros(n_samples, dtype=float, device="cpu")
    normal = wp.zeros(n_samples, dtype=wp.vec3, device="cpu")
    point = wp.zeros(n_samples, dtype=wp.vec3, device="cpu")
    t0 = time.perf_counter()
    wp.launch(analytic_terrain_contact, dim=n_samples, inputs=[1, grid, state.body_q, R, HL],
              outputs=[depth, normal, point], device="cpu")
    wp.synchronize()
    t_first_an = time.perf_counter() - t0
    an_depth = np.maximum(depth.numpy(), 0.0)
    an_normal = normal.numpy()

    # reference: true sinusoid, brute-force max over rim points (cylinder axis along y)
    th = np.linspace(-math.pi, math.pi, 2001)
    yy = np.linspace(-HL, HL, 9)[:, None]
    ref = np.array([np.max(terrain_fn(x + R * np.sin(th)[None, :], y0 + yy) - (z0 - R * np.cos(th))[None, :])
                    for x in xs_s])
    ref = np.maximum(ref, 0.0)

    def ang_jump(nv):
        nv = nv / np.linalg.norm(nv, axis=1, keepdims=True)
        c = np.clip(np.sum(nv[1:] * nv[:-1], axis=1), -1, 1)
        return float(np.degrees(np.arccos(c)).max())

    out = {
        "newton_first_collide_incl_compile_s": t_first_newton,
        "analytic_first_launch_incl_compile_s": t_first_an,
        "y0": y0,
        "x_step_mm": float(1e3 * (xs_s[1] - xs_s[0])),
        "z_centre": z0,
        "ref_true_sinusoid_max_depth_mm": float(1e3 * ref.max()),
        "ref_max_jump_mm": float(1e3 * np.abs(np.diff(ref)).max()),
        "newton": {
            "contacts_per_sample_min_max": [int(nt_count.min()), int(nt_count.max())],
            "penetrating_contacts_per_sample_min_max": [int(nt_pen_count.min()), int(nt_pen_count.max())],
            "count_changes": int(np.count_nonzero(np.diff(nt_count))),
            "count_histogram": {int(k): int(v) for k, v in zip(*np.unique(nt_count, return_counts=True))},
            "max_depth_mm": float(1e3 * nt_depth.max()),
            "max_jump_deepest_depth_mm": float(1e3 * np.abs(np.diff(nt_depth)).max()),
            "max_jump_sum_depth_mm": float(1e3 * np.abs(np.diff(nt_sumdepth)).max()),
            "max_jump_deepest_normal_deg": ang_jump(nt_normal),
            "max_abs_err_vs_true_mm": float(1e3 * np.abs(nt_depth - ref).max()),
        },
        "analytic": {
            "max_depth_mm": float(1e3 * an_depth.max()),
            "max_jump_depth_mm": float(1e3 * np.abs(np.diff(an_depth)).max()),
            "max_jump_normal_deg": ang_jump(an_normal),
            "max_abs_err_vs_true_mm": float(1e3 * np.abs(an_depth - ref).max()),
        },
    }
    np.savez(os.path.join(OUT, f"terrain_contact_sweep_y{y0:g}.npz"), x=xs_s, ref=ref, nt_depth=nt_depth, nt_normal=nt_normal,
             nt_count=nt_count, nt_sumdepth=nt_sumdepth, an_depth=an_depth, an_normal=an_normal)
    return out


def main():
    if "--cold" in sys.argv:  # fresh kernel cache -> first-call times include real compilation
        import shutil
        d = os.path.join(tempfile.gettempdir(), "atrv_terrain_choice_kcache")
        shutil.rmtree(d, ignore_errors=True)
        wp.config.kernel_cache_dir = d
    wp.init()
    results = {"newton": newton.__version__, "warp": wp.__version__, "device": "cpu",
               "terrain": f"{NROW}x{NCOL} over {2*HX}x{2*HY} m, amp {AMP} m, wavelength {WAVELEN} m"}
    # y0 = 0: crest line lies exactly on a grid row (worst case for one-sided bilinear gradients)
    # y0 = 0.25: mid-cell
    results["smoothness"] = smooth_sweep(200, 0.0)
    results["smoothness_midcell"] = smooth_sweep(200, 0.25)
    results["bench"] = []
    for n in ([256] if QUICK else [256, 1024]):
        r = bench(n, reps=3 if QUICK else 10)
        results["bench"].append(r)
        print(json.dumps(r), flush=True)

    print(f"\n{'N':>6} {'newton ms':>14} {'analytic ms':>14} {'nt 1st(new N) s':>12} {'an 1st s':>12} {'contacts':>10}")
    for r in results["bench"]:
        print(f"{r['N']:6d} {r['newton_collide_ms']:14.3f} {r['analytic_ms']:14.4f} "
              f"{r['newton_first_collide_new_model_s']:12.2f} {r['analytic_first_launch_s']:12.2f} "
              f"{r['newton_contact_count']:10d}")
    for key in ("smoothness", "smoothness_midcell"):
        sm = results[key]
        print(f"sweep y0={sm['y0']}: ref max depth {sm['ref_true_sinusoid_max_depth_mm']:.2f} mm")
        nt, an = sm["newton"], sm["analytic"]
        print(f"  newton  : contacts/sample {nt['contacts_per_sample_min_max']} (changes {nt['count_changes']}),"
              f" max depth {nt['max_depth_mm']:.2f} mm, max jump deepest {nt['max_jump_deepest_depth_mm']:.2f} mm,"
              f" sum-depth {nt['max_jump_sum_depth_mm']:.2f} mm, normal {nt['max_jump_deepest_normal_deg']:.2f} deg,"
              f" err vs true {nt['max_abs_err_vs_true_mm']:.2f} mm")
        print(f"  analytic: max depth {an['max_depth_mm']:.2f} mm, max jump {an['max_jump_depth_mm']:.2f} mm,"
              f" normal {an['max_jump_normal_deg']:.2f} deg, err vs true {an['max_abs_err_vs_true_mm']:.2f} mm")
    # Newton's heightfield against our kernel on a synthetic terrain: neither the rover's dynamics nor a task
    write_results(os.path.join(OUT, "terrain_contact_choice.json"), results, version=VERSION, dynamics=False)


if __name__ == "__main__":
    main()
