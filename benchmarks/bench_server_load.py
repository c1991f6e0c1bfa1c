"""The app's server under load: many concurrent requests, and memory over many uploads.

Starts ``shadeform app``'s server (:func:`shadeform.app.server.create_app` under uvicorn) in its
own process on a free loopback port, then

1. sends ``--requests`` requests, ``--concurrency`` at a time, cycling through the app's kinds
   of request: the options, an upload of a small PNG (each one different), and the photo and a
   reconstruction of the first image uploaded (the uploads push older images out of the
   server's bounded store; a client that keeps using an image keeps it); counts the statuses
   (every one must be a success: the requests are valid) and the latency;
2. uploads ``--uploads`` distinct 512x512 PNGs one after the other and reads the server
   process's resident memory (``VmRSS`` in ``/proc``) after each: it must stay flat once the
   server's bounded image store is full (``AppLimits.max_images``).

Writes ``benchmarks/results/server_load.md``. Linux only (``/proc``).

Run: ``python benchmarks/bench_server_load.py [--requests 1000] [--concurrency 50] [--uploads 200]``.
"""

from __future__ import annotations

import argparse
import asyncio
import io
import os
import platform
import socket
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: The server, without the warm-up: with a cold compile cache, compiling the kernels in the
#: background grows its memory for a minute or two, while it is being measured.
SERVE = (
    "import sys, uvicorn\n"
    "from shadeform.app.server import create_app\n"
    "uvicorn.run(create_app(), host='127.0.0.1', port=int(sys.argv[1]), log_level='error')\n"
)


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def png_bytes(seed: int, size: int) -> bytes:
    """A distinct shaded disc with a little noise, as an 8-bit PNG."""
    from PIL import Image

    rng = np.random.default_rng(seed)
    y, x = np.mgrid[:size, :size] / (size - 1) * 2 - 1
    r2 = x * x + y * y
    nz = np.sqrt(np.clip(1 - r2 / 0.8, 0, 1))
    light = rng.normal(size=3) * [0.3, 0.3, 0] + [0, 0, 1]
    light /= np.linalg.norm(light)
    shade = np.where(r2 < 0.8, np.clip(x * light[0] / 0.9 + -y * light[1] / 0.9 + nz * light[2], 0, 1), 0)
    image = np.clip(shade * 230 + rng.normal(0, 2, shade.shape), 0, 255).astype(np.uint8)
    out = io.BytesIO()
    Image.fromarray(image).save(out, format="PNG")
    return out.getvalue()


def rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS")


class Server:
    """The app's server in its own process."""

    def __init__(self) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.process = subprocess.Popen(
            [sys.executable, "-c", SERVE, str(self.port)], cwd=ROOT, stderr=subprocess.PIPE
        )

    def wait(self, client_get) -> None:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"the server ended: {self.process.stderr.read().decode()}")
            try:
                if client_get(f"{self.url}/api/options").status_code == 200:
                    return
            except Exception:  # not listening yet (httpx's ConnectError is no OSError)
                pass
            time.sleep(0.2)
        raise RuntimeError("the server did not answer within 120 s")

    def stop(self) -> None:
        self.process.terminate()
        self.process.wait(timeout=30)


async def hammer(url: str, requests: int, concurrency: int) -> dict:
    """``requests`` valid requests, ``concurrency`` in flight; statuses, latencies, errors."""
    import httpx

    statuses: Counter = Counter()
    failures: Counter = Counter()
    latencies: list[float] = []
    images: list[str] = []  # the first is used by every other request, so it stays in the store
    counter = iter(range(requests))
    limits = httpx.Limits(max_connections=concurrency, max_keepalive_connections=concurrency)
    async with httpx.AsyncClient(base_url=url, timeout=300, limits=limits) as client:
        # one image to start from, so every kind of request has something to act on
        first = await client.post("/api/images", files={"file": ("seed.png", png_bytes(0, 64), "image/png")})
        images.append(first.json()["image_id"])

        async def one(k: int) -> None:
            kind = k % 4
            start = time.perf_counter()
            try:
                if kind == 0:
                    response = await client.get("/api/options")
                elif kind == 1:
                    data = png_bytes(k + 1, 64)
                    response = await client.post(
                        "/api/images", files={"file": (f"p{k}.png", data, "image/png")}
                    )
                    if response.status_code == 201:
                        images.append(response.json()["image_id"])
                elif kind == 2:
                    response = await client.get(f"/api/images/{images[0]}/photo.png")
                else:
                    body = {"image_id": images[0], "params": {"step": 4}}
                    response = await client.post("/api/reconstruct", json=body)
                statuses[response.status_code] += 1
                if response.status_code >= 400:
                    failures[f"{response.status_code} {response.text[:120]}"] += 1
            except Exception as err:  # a refused or dropped connection is what is counted here
                statuses["no response"] += 1
                failures[f"{type(err).__name__}: {err}"[:160]] += 1
            latencies.append(time.perf_counter() - start)

        async def worker() -> None:
            for k in counter:
                await one(k)

        start = time.perf_counter()
        await asyncio.gather(*(worker() for _ in range(concurrency)))
        wall = time.perf_counter() - start
    return {"statuses": statuses, "failures": failures, "latencies": np.array(latencies), "wall": wall}


def uploads(url: str, pid: int, count: int, size: int) -> list[float]:
    """Resident MiB of the server after each of ``count`` distinct uploads."""
    import httpx

    memory = []
    with httpx.Client(base_url=url, timeout=300) as client:
        for k in range(count):
            response = client.post(
                "/api/images", files={"file": (f"u{k}.png", png_bytes(10_000 + k, size), "image/png")}
            )
            if response.status_code != 201:
                raise RuntimeError(f"upload {k} refused: {response.status_code} {response.text}")
            memory.append(rss_mib(pid))
    return memory


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--requests", type=int, default=1000)
    parser.add_argument("--concurrency", type=int, default=50)
    parser.add_argument("--uploads", type=int, default=200)
    parser.add_argument("--size", type=int, default=512, help="side of the uploaded images")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "server_load.md")
    args = parser.parse_args()
    import httpx

    from shadeform.app.guard import AppLimits
    from shadeform.io.atomic import atomic_write

    server = Server()
    try:
        server.wait(httpx.get)
        result = asyncio.run(hammer(server.url, args.requests, args.concurrency))
        memory = uploads(server.url, server.process.pid, args.uploads, args.size)
    finally:
        server.stop()

    statuses, latencies = result["statuses"], result["latencies"] * 1000
    kept = AppLimits().max_images
    settled = memory[2 * kept - 1] if len(memory) >= 2 * kept else memory[-1]
    lines = [
        "# The app's server under load",
        "",
        f"`benchmarks/bench_server_load.py`: the server in its own process on loopback, {platform.machine()}, "
        f"{os.cpu_count()} CPUs shared with the client and other work; Python {platform.python_version()}.",
        "",
        f"## {args.requests:,} requests, {args.concurrency} at a time",
        "",
        "Cycling through: the options, an upload of a distinct 64x64 PNG, the first image's photo, a "
        "reconstruction of it (step 4).",
        "",
        "| requests | concurrent | statuses | errors | wall s | median ms | p99 ms | worst ms |",
        "|---:|---:|---|---:|---:|---:|---:|---:|",
        f"| {args.requests:,} | {args.concurrency} | "
        + ", ".join(f"{code}: {n}" for code, n in sorted(statuses.items(), key=str))
        + f" | {sum(result['failures'].values())} | {result['wall']:.1f} | {np.median(latencies):.0f} | "
        f"{np.percentile(latencies, 99):.0f} | {latencies.max():.0f} |",
        "",
    ]
    for failure, n in result["failures"].most_common(10):
        lines.append(f"- {n} x {failure}")
    lines += [
        "",
        f"## Memory over {args.uploads} distinct uploads ({args.size}x{args.size} PNG, one at a time)",
        "",
        f"Resident memory of the server process (MiB) after the given upload; the store keeps the "
        f"{kept} most recent images.",
        "",
        "| after upload | " + " | ".join(str(k) for k in _marks(len(memory))) + " |",
        "|---|" + "---:|" * len(_marks(len(memory))),
        "| MiB | " + " | ".join(f"{memory[k - 1]:.0f}" for k in _marks(len(memory))) + " |",
        "",
        f"Growth from upload {min(2 * kept, len(memory))} to {len(memory)}: "
        f"{memory[-1] - settled:+.0f} MiB ({(memory[-1] / settled - 1) * 100:+.1f} %).",
        "",
    ]
    text = "\n".join(lines)
    print(text)
    with atomic_write(args.out, mode="w") as f:
        f.write(text)


def _marks(count: int) -> list[int]:
    marks = [1, 8, 16, 32, 50, 100, 150, 200, 300, 400, 500]
    return [k for k in marks if k <= count] + ([count] if count not in marks else [])


if __name__ == "__main__":
    main()
