"""Train the shape prior: ``python -m shadeform.prior.train`` (needs ``shadeform[train]``).

One seeded command makes the data (:mod:`shadeform.prior.dataset`: a bank of generated objects,
photographed anew for every example), trains :mod:`shadeform.prior.network` with Adam on the
Laplace likelihood of its normals, and writes the ONNX file the package ships. The shipped
``prior.onnx`` was made by the command in ``docs/prior.md``; ``--tiny`` runs one step on tiny data
(what CI does).

Data are made in worker processes while JAX trains, each example drawn from ``(seed, index)``, so
the run is the same whatever the number of workers. A checkpoint (weights, optimiser state, step)
is written every ``--every`` steps beside a log of the loss and the validation error (mean angle on
generated photos of a held-out seed), and ``--resume`` continues from it.
"""

from __future__ import annotations

import argparse
import collections
import json
import multiprocessing
import os
import pickle
import sys
import time
from pathlib import Path

import numpy as np

from shadeform.prior import dataset, network
from shadeform.prior.shapes import Shape

_BANK = None


class _Bank:
    """The bank's objects in memory-mapped arrays (shared by the worker processes)."""

    def __init__(self, folder: Path):
        self.arrays = {
            key: np.load(folder / f"{key}.npy", mmap_mode="r") for key in ("depth", "normals", "part")
        }
        self.kinds = (folder / "kinds.txt").read_text().split()

    def __len__(self):
        return len(self.kinds)

    def __getitem__(self, i):
        part = np.asarray(self.arrays["part"][i], dtype=np.int16)
        return Shape(
            np.asarray(self.arrays["depth"][i], dtype=np.float64),
            np.asarray(self.arrays["normals"][i], dtype=np.float64),
            part >= 0,
            part,
            self.kinds[i],
        )


def _chunk(job):
    seed, indices, size = job
    return dataset.shapes(seed, indices, size=size)


def _make_bank(folder: Path, seed: int, count: int, size: int, workers: int, context) -> Path:
    """Generate the bank once (in ``workers`` processes) into ``folder/bank-...``; reuse it after."""
    where = folder / f"bank-seed{seed}-count{count}-size{size}"
    if (where / "kinds.txt").exists():
        return where
    chunks = [(seed, range(start, min(start + 50, count)), size) for start in range(0, count, 50)]
    with context.Pool(max(workers, os.cpu_count() or 1)) as pool:
        bank = [shape for part in pool.imap(_chunk, chunks) for shape in part]
    where.mkdir(parents=True, exist_ok=True)
    np.save(where / "depth.npy", np.stack([s.depth for s in bank]).astype(np.float32))
    np.save(where / "normals.npy", np.stack([s.normals for s in bank]).astype(np.float32))
    np.save(where / "part.npy", np.stack([s.part for s in bank]).astype(np.int8))
    (where / "kinds.txt").write_text("\n".join(s.kind for s in bank) + "\n")
    return where


def _start_worker(where):
    global _BANK
    _BANK = _Bank(Path(where))


def _batch(job):
    """Examples ``start .. start + batch`` of the data seed, stacked."""
    seed, start, batch, size = job
    examples = [dataset.example(_BANK, seed, start + i, size=size) for i in range(batch)]
    x = np.stack([e.x for e in examples]).transpose(0, 2, 3, 1)  # NHWC for JAX
    return x, np.stack([e.target for e in examples]), np.stack([e.weight for e in examples])


def _angle(params, apply, x, target, weight):
    y = np.asarray(apply(params, x))
    n = y[..., :3] / np.linalg.norm(y[..., :3], axis=-1, keepdims=True)
    cos = np.clip(np.sum(n * target, axis=-1), -1, 1)
    return float(np.degrees(np.sum(np.arccos(cos) * weight) / np.sum(weight)))


def _save(path: Path, state) -> None:
    part = path.with_name(path.name + ".part")
    part.write_bytes(pickle.dumps(state))
    os.replace(part, path)


def train(args) -> dict:
    """Run the training that ``args`` describe; returns the last log line."""
    import jax
    import jax.numpy as jnp
    import optax

    size, widths = args.size, tuple(args.widths)
    folder = Path(args.checkpoint)
    folder.mkdir(parents=True, exist_ok=True)
    state_file = folder / "state.pkl"
    schedule = optax.warmup_cosine_decay_schedule(
        0.0, args.lr, min(200, args.steps // 10 + 1), max(args.steps, 2), args.lr / 30
    )
    optimiser = optax.chain(optax.clip_by_global_norm(1.0), optax.adam(schedule))
    if args.resume and state_file.exists():
        state = pickle.loads(state_file.read_bytes())
        params = {k: jnp.asarray(v) for k, v in state["params"].items()}
        opt_state = jax.tree_util.tree_map(jnp.asarray, state["opt"])
        step0 = state["step"]
    else:
        params = {k: jnp.asarray(v) for k, v in network.init(args.seed, widths=widths).items()}
        opt_state = optimiser.init(params)
        step0 = 0

    @jax.jit
    def update(params, opt_state, x, target, weight):
        value, grads = jax.value_and_grad(network.loss)(params, x, target, weight)
        updates, opt_state = optimiser.update(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, value

    apply = jax.jit(network.apply)
    context = multiprocessing.get_context("spawn")
    # validation: another seed's objects and photos, never trained on
    _start_worker(_make_bank(folder, args.seed + 1000, args.validation, size, args.workers, context))
    val = _batch((args.seed + 1000, 0, args.validation, size))
    bank = _make_bank(folder, args.seed, args.bank, size, args.workers, context)
    log = folder / "log.jsonl"
    started = time.time()
    last = {}
    with context.Pool(args.workers, _start_worker, (str(bank),)) as pool:
        losses = []
        # a few batches made ahead, no more: the workers wait rather than fill the memory
        ahead = collections.deque()
        for step in range(step0 + 1, args.steps + 1):
            while len(ahead) < 2 * args.workers and step + len(ahead) <= args.steps:
                ahead.append(
                    pool.apply_async(
                        _batch, ((args.seed, (step - 1 + len(ahead)) * args.batch, args.batch, size),)
                    )
                )
            x, target, weight = ahead.popleft().get()
            params, opt_state, value = update(params, opt_state, x, target, weight)
            losses.append(float(value))
            if step % args.every == 0 or step == args.steps:
                last = {
                    "step": step,
                    "loss": float(np.mean(losses)),
                    "validation_degrees": _angle(params, apply, *val),
                    "minutes": (time.time() - started) / 60,
                }
                losses = []
                with log.open("a") as file:
                    file.write(json.dumps(last) + "\n")
                print(json.dumps(last), flush=True)
                numpy_params = {k: np.asarray(v) for k, v in params.items()}
                state = {
                    "params": numpy_params,
                    "opt": jax.tree_util.tree_map(np.asarray, opt_state),
                    "step": step,
                }
                _save(state_file, state)
                _write_model(numpy_params, args.out, size)
    return last


def _write_model(params, out, size) -> None:
    import onnx

    out = Path(out)
    part = out.with_name(out.name + ".part")
    onnx.save_model(network.to_onnx(params, size=size), str(part))
    os.replace(part, out)


def parse(argv=None):
    parser = argparse.ArgumentParser(
        prog="python -m shadeform.prior.train", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--steps", type=int, default=4000, help="training steps (default 4000)")
    parser.add_argument("--batch", type=int, default=16, help="examples per step (default 16)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the data and the weights (default 0)")
    parser.add_argument(
        "--bank", type=int, default=2000, help="generated objects to photograph (default 2000)"
    )
    parser.add_argument(
        "--size", type=int, default=network.SIZE, help="network side in pixels, a multiple of 16"
    )
    parser.add_argument(
        "--widths", type=lambda text: [int(v) for v in text.split(",")], default=list(network.WIDTHS)
    )
    parser.add_argument("--lr", type=float, default=2e-3, help="peak learning rate (default 2e-3)")
    parser.add_argument("--workers", type=int, default=1, help="processes making the data (default 1)")
    parser.add_argument("--validation", type=int, default=64, help="held-out examples (default 64)")
    parser.add_argument("--every", type=int, default=100, help="steps between checkpoints (default 100)")
    parser.add_argument("--checkpoint", default="out/prior-train", help="folder of the checkpoint and log")
    parser.add_argument("--out", default="out/prior-train/prior.onnx", help="the ONNX file to write")
    parser.add_argument("--resume", action="store_true", help="continue from the checkpoint")
    parser.add_argument(
        "--tiny", action="store_true", help="one step on tiny data and a tiny network (a smoke test)"
    )
    args = parser.parse_args(argv)
    if args.tiny:
        args.steps, args.batch, args.bank, args.size, args.validation, args.every = 1, 2, 2, 32, 2, 1
        args.widths = [4, 4, 4, 4, 4]
    if args.size % 16:
        parser.error(f"--size must be a multiple of 16, got {args.size}")
    return args


def main(argv=None) -> int:
    train(parse(argv))
    return 0


if __name__ == "__main__":
    sys.exit(main())
