"""Cost of one TorchRL SAC gradient step on this CPU, by network width, batch size and threads.

Run: ``python -m benchmarks.perf.sac_update_cost [--skip-compile]``

The training defaults (width 128, batch 256, 1 trainer thread, collection in a second process)
were chosen with these figures: a step has a fixed cost of about 5 ms of per-call overhead, so
halving the batch from 512 saves only about a quarter, and a second thread buys little while it
would take the core the collector needs.

Then the candidates for a cheaper update (issue #16), at the default preset's width and batch on
one thread, each built by the trainer's own :class:`~atrv_warp.rl.learner.Learner`: the three
losses ``loss=`` switches between (TorchRL's SAC, CrossQ, REDQ), SAC with TorchRL's vmap over the
critics replaced by a loop, and SAC with the loss and its backward under ``torch.compile`` (its
compile time reported apart). Written to ``benchmarks/results/sac_update_cost.json``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"


def _fixed_batch(batch: int):
    import torch
    from tensordict import TensorDict

    return TensorDict({"observation": torch.randn(batch, 10), "action": torch.rand(batch, 2) * 2 - 1,
                       ("next", "observation"): torch.randn(batch, 10), ("next", "reward"): torch.randn(batch, 1),
                       ("next", "done"): torch.zeros(batch, 1, dtype=torch.bool),
                       ("next", "terminated"): torch.zeros(batch, 1, dtype=torch.bool)}, [batch])


def _time_updates(step, batch, warmup: int = 20, n: int = 200) -> tuple[float, float]:
    """(ms per update, seconds of the warm-up calls: compilation, if any)."""
    t0 = time.perf_counter()
    for _ in range(warmup):
        step(batch.clone())
    warm = time.perf_counter() - t0
    t0 = time.perf_counter()
    for _ in range(n):
        step(batch.clone())
    return (time.perf_counter() - t0) / n * 1e3, warm


def variants(skip_compile: bool) -> list[dict]:
    """Update cost of each candidate at the default preset's width and batch, one thread."""
    import torch

    from atrv_warp.policy import Normalize, make_actor
    from atrv_warp.rl.command_line import load_train_config
    from atrv_warp.rl.learner import Learner

    torch.set_num_threads(1)
    rows = []

    def learner(**overrides):
        cfg = load_train_config("default", overrides)
        torch.manual_seed(0)
        return cfg, Learner(cfg, make_actor(cfg.network.width, cfg.network.depth, normalize=Normalize()), Normalize())

    def record(name, step, batch, note=""):
        ms, warm = _time_updates(step, batch)
        rows.append({"variant": name, "batch": batch.shape[0], "ms_per_update": ms, "warmup_s": warm, "note": note})
        print(f"{name:28s} batch={batch.shape[0]:4d}: {ms:6.2f} ms per update  (first 20 calls {warm:5.1f} s)",
              flush=True)

    for loss in ("sac", "crossq", "redq"):
        for batch in (256, 512):
            _, lrn = learner(loss=loss)
            record(f"loss={loss}", lrn.update, _fixed_batch(batch))
    cfg = load_train_config("default", {})
    from torchrl.objectives import SACLoss, SoftUpdate

    from atrv_warp.rl.learner import make_qvalue

    loop = SACLoss(make_actor(cfg.network.width, cfg.network.depth), make_qvalue(cfg.network.width, cfg.network.depth),
                   num_qvalue_nets=2, target_entropy=-2.0, deactivate_vmap=True)
    loop.make_value_estimator(gamma=cfg.optim.gamma)
    loop_opt, loop_target = torch.optim.Adam(loop.parameters(), cfg.optim.lr), SoftUpdate(loop, tau=cfg.optim.tau)

    def loop_step(batch):
        out = loop(batch)
        loop_opt.zero_grad(set_to_none=True)
        (out["loss_actor"] + out["loss_qvalue"] + out["loss_alpha"]).backward()
        loop_opt.step()
        loop_target.step()

    record("sac, critics in a loop", loop_step, _fixed_batch(cfg.optim.batch_size), "deactivate_vmap=True")
    if not skip_compile:
        cfg, lrn = learner()

        def loss_and_backward(batch):
            out = lrn.loss(batch)
            (out["loss_actor"] + out["loss_qvalue"] + out["loss_alpha"]).backward()
            return out.detach()

        compiled = torch.compile(loss_and_backward)

        def step(batch):
            for opt in lrn.opts.values():
                opt.zero_grad(set_to_none=True)
            compiled(batch)
            for opt in lrn.opts.values():
                opt.step()
            lrn.target_update.step()

        record("sac, torch.compile", step, _fixed_batch(cfg.optim.batch_size), "loss + backward compiled (inductor)")
    return rows


def main() -> int:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-compile", action="store_true", help="leave out the torch.compile variant")
    args = parser.parse_args()
    import torch
    from tensordict import TensorDict
    from torchrl.objectives import SACLoss, SoftUpdate

    from atrv_warp.policy import make_actor
    from atrv_warp.rl.learner import make_qvalue

    rows = []
    for threads in (1, 2):
        torch.set_num_threads(threads)
        for width, batch in ((64, 256), (128, 256), (128, 512), (256, 256), (256, 512), (128, 1024)):
            actor = make_actor(width)
            loss = SACLoss(actor, make_qvalue(width), num_qvalue_nets=2, target_entropy=-2.0)
            loss.make_value_estimator(gamma=0.99)
            opt = torch.optim.Adam(loss.parameters(), 3e-4)
            target = SoftUpdate(loss, tau=0.005)
            td = TensorDict({"observation": torch.randn(batch, 10), "action": torch.rand(batch, 2) * 2 - 1,
                             ("next", "observation"): torch.randn(batch, 10), ("next", "reward"): torch.randn(batch, 1),
                             ("next", "done"): torch.zeros(batch, 1, dtype=torch.bool),
                             ("next", "terminated"): torch.zeros(batch, 1, dtype=torch.bool)}, [batch])
            for i in range(70):
                if i == 10:
                    t0 = time.perf_counter()
                out = loss(td)
                opt.zero_grad()
                (out["loss_actor"] + out["loss_qvalue"] + out["loss_alpha"]).backward()
                opt.step()
                target.step()
            ms = (time.perf_counter() - t0) / 60 * 1e3
            rows.append({"threads": threads, "width": width, "batch": batch, "ms_per_update": ms})
            print(f"threads={threads} width={width:3d} batch={batch:4d}: {ms:6.2f} ms per update", flush=True)
    print("\ncandidates for a cheaper update (default width, one thread):")
    cands = variants(args.skip_compile)
    out = write_results(RESULTS / "sac_update_cost.json", {"benchmark": "sac_update_cost", "rows": rows,
                                                           "variants": cands,
                                                           "time": time.strftime("%Y-%m-%d %H:%M:%S")}, version=VERSION, dynamics=False)
    print("\n| threads | width | batch | ms/update |\n|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['threads']} | {r['width']} | {r['batch']} | {r['ms_per_update']:.1f} |")
    print("\n| variant | batch | ms/update | first 20 calls [s] |\n|---|---:|---:|---:|")
    for r in cands:
        print(f"| {r['variant']} | {r['batch']} | {r['ms_per_update']:.1f} | {r['warmup_s']:.1f} |")
    print(f"\nwritten to {out}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def sac_update_cost() -> str:
    """``sac_update_cost.json``: one gradient step of the trainer's ``Learner`` per loss and batch, one thread."""
    names = {"loss=sac": "SAC", "sac, critics in a loop": "SAC, critics in a Python loop instead of TorchRL's vmap",
             "sac, torch.compile": "SAC, loss and backward under `torch.compile`", "loss=crossq": "CrossQ",
             "loss=redq": "REDQ (10 critics)"}
    cells: dict[str, dict[int, str]] = {}
    for v in load_results("sac_update_cost.json")["variants"]:
        text = f"{v['ms_per_update']:.1f} ms"
        if v["warmup_s"] > 5:
            text += f", after {v['warmup_s']:.0f} s of compilation"
        cells.setdefault(names.get(v["variant"], v["variant"]), {})[v["batch"]] = text
    order = [n for n in names.values() if n in cells]
    return markdown_table(["variant", "batch 256", "batch 512"], ["---", "---:", "---:"],
                          [[n, cells[n].get(256, ""), cells[n].get(512, "")] for n in order])


TABLES = {
    "sac_update_cost": sac_update_cost,
}


if __name__ == "__main__":
    sys.exit(main())
