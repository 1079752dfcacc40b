"""Sweep throughput and the Dask scheduler's overhead per variant
(docs/distributed.md, "Measurements"): JSON rows, one per setting.

    PYTHONPATH=build/python python3 bench/sweep_bench.py [--variants 32] [--workers 1,2] [--json out.json]
        [--backend cuda --scene @kidney --duration 0.5 --chunk 64]   # one worker per GPU

Each row runs the same variants (a 20 x 20 x 10 mm block of 648 tets pressed
and held for 0.4 s, E swept) in one process without Dask ("local"), or on a
LocalCluster of W workers. scene_steps_per_s counts TLED steps over the
wall time of the run (the cluster's start is startup_s);
overhead_ms_per_variant is (wall - local wall) / variants for a run of 32
one-tick variants, one per task: what Dask adds to each.
"""
import argparse
import json
import os
import platform
import sys
import tempfile
import time

import numpy as np

import tissue
import tissue.distributed as td

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests", "python"))
from test_distributed import write_block  # noqa: E402  (the tests' block scene)


def machine() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            name = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        name = platform.processor()
    return f"{name} ({os.cpu_count()} cores)"


def timed(variants, **kw):
    t0 = time.perf_counter()
    r = td.run(variants, **kw)
    return time.perf_counter() - t0, r


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--variants", type=int, default=32)
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--backend", default="cpu")
    ap.add_argument("--scene", help="a scene instead of the tests' block (e.g. @kidney)")
    ap.add_argument("--duration", type=float, help="seconds each variant runs (default: its path)")
    ap.add_argument("--chunk", type=int, default=1, help="variants per task")
    ap.add_argument("--json")
    a = ap.parse_args()
    scene = a.scene or write_block(os.path.join(tempfile.mkdtemp(), "block.xml"))
    variants = [td.Variant(scene, {"E": float(E)}, duration=a.duration) for E in np.linspace(2000, 8000, a.variants)]
    short = [td.Variant(scene, {"E": float(E)}, duration=0.001) for E in np.linspace(2000, 8000, min(32, a.variants))]
    rows = []
    base_wall, base = timed(variants, local=True, backend=a.backend, chunk=a.chunk)
    base_short, _ = timed(short, local=True, backend=a.backend, chunk=1)
    rows.append({"machine": machine(), "scene": a.scene or "block", "backend": base.results[0].backend,
                 "chunk": a.chunk, "setting": "local", "workers": 0, "variants": a.variants,
                 "wall_s": round(base_wall, 3), "scene_steps": base.scene_steps,
                 "scene_steps_per_s": round(base.scene_steps / base_wall), "overhead_ms_per_variant": 0.0})
    print(json.dumps(rows[-1]), flush=True)
    from distributed import Client
    for w in [int(x) for x in a.workers.split(",") if x]:
        t0 = time.perf_counter()
        gpus = td.gpu_count() if a.backend != "cpu" else 0
        cluster = td.local_cluster(None if gpus else w)  # on a GPU machine: one worker per GPU
        client = Client(cluster)
        client.wait_for_workers(gpus or w)
        startup = time.perf_counter() - t0
        try:
            wall, r = timed(variants, client=client, backend=a.backend, chunk=a.chunk)
            wall_short, _ = timed(short, client=client, backend=a.backend, chunk=1)
        finally:
            client.close()
            cluster.close()
        rows.append({"machine": machine(), "scene": a.scene or "block", "backend": r.results[0].backend,
                     "chunk": a.chunk, "setting": "LocalCluster", "workers": gpus or w, "variants": a.variants,
                     "startup_s": round(startup, 2), "wall_s": round(wall, 3), "scene_steps": r.scene_steps,
                     "scene_steps_per_s": round(r.scene_steps / wall),
                     "overhead_ms_per_variant": round(1e3 * (wall_short - base_short) / len(short), 1)})
        print(json.dumps(rows[-1]), flush=True)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)
            f.write("\n")


if __name__ == "__main__":
    main()
