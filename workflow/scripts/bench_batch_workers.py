"""Issue 17: stacked training (five seeds, robust recipe) with each seed's batches built in the training process
(threads) against built in worker processes (palpation.model.batch_workers): wall seconds and identity.

    python workflow/scripts/bench_batch_workers.py DEVICE SLIDES STEPS EPOCHS W [W ...]

W: 0 = in the training process, 1 = worker processes, run in the order given on one synthetic Sim set of SLIDES
slides (palpation.graph.synthetic); STEPS training batches an epoch, 4 val batches, no early stopping. Each run
prints its wall time and its largest loss and weight difference from the first run. Per-step time: run it with two
STEPS values and divide the difference of the walls by the difference of the steps. docs/recipe.md gives the figures.
"""
import sys, tempfile, time
from dataclasses import replace
from pathlib import Path
import numpy as np, torch
from palpation.model.benchmark import compose_job
from palpation.graph.synthetic import write_sim
from palpation.graph.layout import rest_layout
from palpation.model.job import load_job_data
from palpation.model.stacked import fit_seeds
dev, n_slides, batches, epochs = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
job = compose_job("A-to-A", dev, "x", ["recipe=robust", f"train.train_batches={batches}", f"train.epochs={epochs}",
                                       "train.val_batches=4", "recipe.patience=null"])
tmp = Path(tempfile.mkdtemp())
sim = write_sim(tmp / "sim", rest_layout(job.rest), n_slides, 398)
job = replace(job, data={**job.data, "sim": str(sim)})
d = load_job_data(job)
ref = None
for w in sys.argv[5:]:
    torch.cuda.synchronize() if dev.startswith("cuda") else None
    t0 = time.perf_counter()
    out = fit_seeds(d.train, d.val, d.rest, d.topo, job.model, job.train, [0, 1, 2, 3, 4], batch_workers=w == "1")
    torch.cuda.synchronize() if dev.startswith("cuda") else None
    dt = time.perf_counter() - t0
    losses = np.array([[m["train/loss"] for m, _ in r.steps if "train/loss" in m and len(m) == 1] for r in out])
    wts = torch.cat([p.detach().flatten().cpu() for r in out for p in r.model.parameters()]).numpy()
    hist = [[h["val/fg_iou"] for h in r.history] for r in out]
    if ref is None:
        ref = (losses, wts, hist)
    print(f"workers={w}: {dt:.2f} s for {losses.shape[1]} steps ({losses.shape[1] / dt:.2f} steps/s); vs first: "
          f"max|loss diff| {np.abs(losses - ref[0]).max():.3g}, max|w diff| {np.abs(wts - ref[1]).max():.3g}, "
          f"val fg_iou equal {hist == ref[2]}", flush=True)
