"""Training and inference throughput (samples/s) of PointNet, VoxNet and 3DmFV-Net (not a test; prints a table).

Random clouds of the given size (the models' cost does not depend on the values), batch
size from each model's paper (:data:`zbuf_occlude.learn.training.OPTIMISER_DEFAULTS`),
one optimiser step per training batch (forward, loss incl. PointNet's regulariser,
backward, step), ``torch.no_grad`` eval-mode forward for inference.  Two configurations:
``quick`` (the widths and points of ``--scale quick``) and ``paper`` (full widths,
1,024 points).  Wall time and process CPU time of ``--iters`` batches after ``--warmup``
batches; on a shared machine the CPU-time rate is the steadier one (with one thread it is
what an idle core would give).

    python benchmarks/bench_learn.py                          # both configurations, CPU
    python benchmarks/bench_learn.py --configs quick --iters 5
    python benchmarks/bench_learn.py --device cuda            # on a GPU machine
"""

from __future__ import annotations

import argparse
import platform
import sys
import time

import torch
import torch.nn.functional as F

from zbuf_occlude.experiments.table3 import SCALES
from zbuf_occlude.learn.models import MODELS, build_model, count_parameters
from zbuf_occlude.learn.training import OPTIMISER_DEFAULTS, resolve_device

CONFIGS = {
    "quick": {"points": SCALES["quick"].points, "width": SCALES["quick"].width, "fv_grid": SCALES["quick"].fv_grid},
    "paper": {"points": 1024, "width": {m: 1.0 for m in MODELS}, "fv_grid": 8},
}


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize()


def bench(model_name: str, points: int, width: float, fv_grid: int, device: torch.device, iters: int, warmup: int,
          n_classes: int = 40) -> dict:  # fmt: skip
    torch.manual_seed(0)
    batch = OPTIMISER_DEFAULTS[model_name]["batch_size"]
    model = build_model(model_name, n_classes, width=width, fv_grid=fv_grid).to(device)
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    x = torch.rand(batch, points, 3, device=device) - 0.5
    y = torch.randint(0, n_classes, (batch,), device=device)
    model.train()
    for i in range(warmup + iters):
        if i == warmup:
            _sync(device)
            t0, c0 = time.perf_counter(), time.process_time()
        opt.zero_grad()
        logits = model(x)
        loss = F.cross_entropy(logits, y)
        reg = getattr(model, "regularizer", None)
        if isinstance(reg, torch.Tensor):
            loss = loss + reg
        loss.backward()
        opt.step()
    _sync(device)
    train_sps = batch * iters / (time.perf_counter() - t0)
    train_cpu = batch * iters / (time.process_time() - c0)
    model.eval()
    with torch.no_grad():
        for i in range(warmup + iters):
            if i == warmup:
                _sync(device)
                t0, c0 = time.perf_counter(), time.process_time()
            model(x)
    _sync(device)
    infer_sps = batch * iters / (time.perf_counter() - t0)
    infer_cpu = batch * iters / (time.process_time() - c0)
    return {"model": model_name, "points": points, "width": width, "batch": batch,
            "parameters": count_parameters(model), "train_sps": train_sps, "infer_sps": infer_sps,
            "train_cpu": train_cpu, "infer_cpu": infer_cpu}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--configs", default="quick,paper", help="comma-separated: quick, paper")
    ap.add_argument("--models", default=",".join(MODELS))
    ap.add_argument("--device", default="cpu", choices=("cpu", "cuda"))
    ap.add_argument("--threads", type=int, help="torch CPU threads (default: torch's)")
    ap.add_argument("--iters", type=int, default=5)
    ap.add_argument("--warmup", type=int, default=1)
    args = ap.parse_args(argv)
    device = resolve_device(args.device)
    if args.threads:
        torch.set_num_threads(args.threads)
    name = torch.cuda.get_device_name() if device.type == "cuda" else (platform.processor() or platform.machine())
    print(f"device: {device.type} ({name}), torch {torch.__version__}, {torch.get_num_threads()} CPU threads\n")
    print(
        "| config | model | points | width | batch | parameters | train samples/s (wall) | train samples/CPU-s "
        "| inference samples/s (wall) | inference samples/CPU-s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for cfg in args.configs.split(","):
        c = CONFIGS[cfg]
        for m in args.models.split(","):
            grid = c["fv_grid"] if m == "3dmfv" else None
            r = bench(m, c["points"], c["width"][m], grid or 8, device, args.iters, args.warmup)
            name = f"{m} ({grid}³ Gaussians)" if grid else m
            print(f"| {cfg} | {name} | {r['points']} | {r['width']} | {r['batch']} | {r['parameters']:,} | "
                  f"{r['train_sps']:.1f} | {r['train_cpu']:.1f} | {r['infer_sps']:.1f} | {r['infer_cpu']:.1f} |",
                  flush=True)  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
