"""Cost of one TorchRL SAC gradient step on this CPU, by network width, batch size and threads.

Run: ``python benchmarks/sac_update_cost.py``

The training defaults (width 128, batch 512, 1 trainer thread, collection in a second process)
were chosen from these figures: the update is dominated by per-call overhead, not FLOPs, so a
wider net or a larger batch costs little extra, and a second thread buys little while it would
take the core the collector needs. Written to ``benchmarks/results/sac_update_cost.json``.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


def main() -> int:
    import torch
    from tensordict import TensorDict
    from torchrl.objectives import SACLoss, SoftUpdate

    from atrv_warp.rl.agents import make_actor, make_qvalue

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
    out = RESULTS / "sac_update_cost.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"benchmark": "sac_update_cost", "rows": rows,
                               "time": time.strftime("%Y-%m-%d %H:%M:%S")}, indent=2) + "\n")
    print("\n| threads | width | batch | ms/update |\n|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['threads']} | {r['width']} | {r['batch']} | {r['ms_per_update']:.1f} |")
    print(f"\nwritten to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
