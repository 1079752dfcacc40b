"""`tissue sweep` and `tissue fit` (docs/distributed.md): the command line
of tissue.distributed and tissue.fitting. The `tissue` program hands these
two commands to `python3 -m tissue.cli`."""
from __future__ import annotations

import argparse
import csv
import itertools
import json
import math
import os
import signal
import sys
import time
from typing import Dict, List, Sequence

import numpy as np

from . import distributed as td
from . import fitting as tf

#: Variants a sweep runs without --force.
MAX_VARIANTS = 100000


class UsageError(ValueError):
    """A bad option, naming it and the rule."""


def parse_values(option: str, text: str) -> List[float]:
    """`a:b:n` (n values from a to b), `a:b:n:log` (geometric), `v1,v2,...` or `v`."""
    def number(t: str) -> float:
        try:
            v = float(t)
        except ValueError:
            raise UsageError(f"{option}: '{t}' is not a number") from None
        if not math.isfinite(v):
            raise UsageError(f"{option}: {t} is not a finite number")
        return v

    if ":" in text:
        parts = text.split(":")
        if len(parts) not in (3, 4) or (len(parts) == 4 and parts[3] != "log"):
            raise UsageError(f"{option}: '{text}' must be a:b:n or a:b:n:log (n values from a to b)")
        a, b = number(parts[0]), number(parts[1])
        try:
            n = int(parts[2])
        except ValueError:
            raise UsageError(f"{option}: the count '{parts[2]}' is not a whole number") from None
        if n < 2:
            raise UsageError(f"{option}: the count {n} must be >= 2 (give one value as NAME=v)")
        if len(parts) == 4:
            if not (a > 0 and b > 0):
                raise UsageError(f"{option}: a log range needs a > 0 and b > 0")
            return list(np.geomspace(a, b, n))
        return list(np.linspace(a, b, n))
    return [number(t) for t in text.split(",")]


def parse_param(text: str, need_value: bool = True):
    """NAME=VALUES as (name, values), the name checked."""
    if "=" not in text:
        raise UsageError(f"--param {text}: give NAME=VALUES (E=1000:20000:8, nu=0.45,0.49)")
    name, values = text.split("=", 1)
    name = name.strip()
    try:
        p = td.parse_parameter(name)
    except td.ParameterError as e:
        raise UsageError(f"--param {text}: {e}") from None
    vals = parse_values(f"--param {name}", values)
    for v in vals:
        try:
            p.check(v)
        except td.ParameterError as e:
            raise UsageError(f"--param {text}: {e}") from None
    return name, vals


def check_depth(text: str) -> None:
    """--depth: all, auto, scene or a whole number of rings >= 1."""
    if text in ("all", "auto", "scene") or (text.isdigit() and int(text) >= 1):
        return
    raise UsageError(f"--depth {text}: give all, auto, scene or a number of rings >= 1")


def prepare_out(path: str, overwrite: bool, mine: Sequence[str]) -> None:
    """The output folder: created; one holding a previous result is refused unless --overwrite."""
    if os.path.exists(path) and not os.path.isdir(path):
        raise UsageError(f"--out {path}: is a file, not a folder")
    os.makedirs(path, exist_ok=True)
    old = [f for f in mine if os.path.exists(os.path.join(path, f))]
    if old and not overwrite:
        raise UsageError(f"--out {path}: holds a previous result ({old[0]}); give another folder or --overwrite")


def write_atomic(path: str, write) -> None:
    part = path + ".part"
    write(part)
    os.replace(part, path)


class _Lines:
    """A progress line a second on stderr where tqdm is missing."""

    def __init__(self, total: int):
        self.total, self.n, self.postfix, self.last = total, 0, "", 0.0

    def update(self, k: int) -> None:
        self.n += k
        if time.monotonic() - self.last > 1 or self.n == self.total:
            self.last = time.monotonic()
            print(f"  {self.n}/{self.total} variants  {self.postfix}", file=sys.stderr)

    def set_postfix_str(self, s: str) -> None:
        self.postfix = s

    def close(self) -> None:
        pass


def progress_bar(total: int):
    """tqdm's bar (variants done, rate, time left), or a line a second without it."""
    try:
        from tqdm import tqdm
    except ImportError:
        return _Lines(total)
    return tqdm(total=total, unit="variant", file=sys.stderr, dynamic_ncols=True)


# ------------------------------------------------------------------ sweep

SWEEP_FILES = ("results.npz", "variants.csv", "forces.csv")


def write_sweep(out: str, names: List[str], grid: List[Dict[str, float]], results: List, tool_count: int) -> int:
    """The finished variants' results: NPZ (every array), variants.csv (one row per variant: its parameters,
    peak and final force, status) and forces.csv (every tick of every tool). Returns how many are written."""
    done = [r for r in results if r is not None]
    ticks = max((len(r.time) for r in done), default=0)
    n = len(grid)
    force = np.full((n, ticks, tool_count, 3), np.nan)
    tip = np.full((n, ticks, tool_count, 3), np.nan)
    time_s = np.full((n, ticks), np.nan)
    finished = np.zeros(n, bool)
    failed = np.zeros(n, bool)
    for r in done:
        k = len(r.time)
        force[r.index, :k] = r.force
        tip[r.index, :k] = r.tip
        time_s[r.index, :k] = r.time
        finished[r.index] = True
        failed[r.index] = r.failure is not None
    params = np.array([[g[p] for p in names] for g in grid]) if names else np.zeros((n, 0))
    extra = {}
    for r in done:
        for f, a in r.fields.items():
            extra.setdefault(f, [None] * n)[r.index] = a
    arrays = {k: np.stack([a if a is not None else np.full_like(next(x for x in v if x is not None), np.nan)
                           for a in v]) for k, v in extra.items()}

    def npz(p):
        with open(p, "wb") as f:
            np.savez_compressed(f, param_names=np.array(names), params=params, time=time_s, force=force, tip=tip,
                                finished=finished, failed=failed, **arrays)

    write_atomic(os.path.join(out, "results.npz"), npz)

    def variants_csv(p):
        with open(p, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["variant"] + names + ["status", "ticks", "peak_force_N", "final_force_N", "failure"])
            for i, g in enumerate(grid):
                r = results[i]
                if r is None:
                    w.writerow([i] + [f"{g[p]:.9g}" for p in names] + ["not run", 0, "", "", ""])
                    continue
                mag = np.linalg.norm(r.force[:, 0], axis=1) if len(r.time) else np.zeros(1)
                w.writerow([i] + [f"{g[p]:.9g}" for p in names] +
                           ["failed" if r.failure else "finished", len(r.time), f"{mag.max():.9g}",
                            f"{mag[-1]:.9g}", r.failure or ""])

    write_atomic(os.path.join(out, "variants.csv"), variants_csv)

    def forces_csv(p):
        with open(p, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["variant", "tick", "t_s", "tool", "fx_N", "fy_N", "fz_N"])
            for r in done:
                for k in range(len(r.time)):
                    for t in range(tool_count):
                        fx, fy, fz = r.force[k, t]
                        w.writerow([r.index, k + 1, f"{r.time[k]:.9g}", t, f"{fx:.9g}", f"{fy:.9g}", f"{fz:.9g}"])

    write_atomic(os.path.join(out, "forces.csv"), forces_csv)
    return len(done)


def plot_sweep(out: str, names: List[str], grid: List[Dict[str, float]], results: List) -> List[str]:
    """force_time.png (|F| of tool 0 against time, one line per variant) and force_<param>.png (peak |F|
    against each swept parameter)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    made = []
    done = [r for r in results if r is not None and len(r.time)]
    if not done:
        return made
    fig, ax = plt.subplots(figsize=(7, 4.5))
    cmap = plt.get_cmap("viridis")
    for j, r in enumerate(done):
        ax.plot(r.time, np.linalg.norm(r.force[:, 0], axis=1), color=cmap(j / max(1, len(done) - 1)), lw=1)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("|F| on tool 0 (N)")
    ax.set_title(f"{len(done)} variants")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path = os.path.join(out, "force_time.png")
    write_atomic(path, lambda p: fig.savefig(p, dpi=110, format="png"))
    plt.close(fig)
    made.append(path)
    for name in names:
        fig, ax = plt.subplots(figsize=(6, 4))
        others = [p for p in names if p != name]
        keyed: Dict[tuple, list] = {}
        for r in done:
            g = grid[r.index]
            keyed.setdefault(tuple(g[p] for p in others), []).append((g[name], np.linalg.norm(r.force[:, 0], axis=1).max()))
        for key, pts in sorted(keyed.items()):
            pts.sort()
            label = ", ".join(f"{p} = {v:.4g}" for p, v in zip(others, key)) or None
            ax.plot([a for a, _ in pts], [b for _, b in pts], "o-", label=label)
        ax.set_xlabel(name)
        ax.set_ylabel("peak |F| on tool 0 (N)")
        if others and len(keyed) <= 12:
            ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        path = os.path.join(out, f"force_{name}.png")
        write_atomic(path, lambda p: fig.savefig(p, dpi=110, format="png"))
        plt.close(fig)
        made.append(path)
    return made


def sweep_main(argv: Sequence[str]) -> int:
    ap = argparse.ArgumentParser(prog="tissue sweep", description="Run a scene over a grid of parameters, on this "
                                 "machine or a Dask cluster (docs/distributed.md)")
    ap.add_argument("scene", help="scene file or @kidney")
    ap.add_argument("--param", action="append", default=[], metavar="NAME=VALUES",
                    help="E=1000:20000:8 (8 values), E=1e3:1e5:5:log, nu=0.45,0.49; the grid is every combination")
    ap.add_argument("--path", help="tool path CSV (t, x, y, z[, grasp[, ax, ay, az]]) for --tool, instead of the "
                    "scene's")
    ap.add_argument("--tool", type=int, default=0, help="the tool --path drives (default 0)")
    ap.add_argument("--duration", type=float, help="seconds to run (default: when the path ends)")
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--overwrite", action="store_true", help="replace a previous result in --out")
    ap.add_argument("--scheduler", help="a running Dask scheduler, tcp://host:8786 (default: a cluster on this "
                    "machine)")
    ap.add_argument("--workers", type=int, help="CPU workers of the local cluster (default: one per GPU, else 1)")
    ap.add_argument("--local", action="store_true", help="run in this process, without Dask")
    ap.add_argument("--backend", choices=("auto", "cpu", "cuda"), default="auto")
    ap.add_argument("--precision", choices=("float", "double"))
    ap.add_argument("--depth", default="all", help="deformation region: all (default: the whole mesh), auto, a ring "
                    "count, or scene (each scene's own)")
    ap.add_argument("--fields", default="", help="final fields to keep: displacement,pressure,...")
    ap.add_argument("--chunk", type=int, help="variants per task (default: what fills a worker)")
    ap.add_argument("--no-plots", action="store_true")
    ap.add_argument("--force", action="store_true", help=f"run more than {MAX_VARIANTS} variants")
    a = ap.parse_args(argv)
    try:
        params = [parse_param(p) for p in a.param]
        names = [n for n, _ in params]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise UsageError(f"--param {sorted(dup)[0]} is given twice")
        grid = [dict(zip(names, combo)) for combo in itertools.product(*[v for _, v in params])] or [{}]
        if len(grid) > MAX_VARIANTS and not a.force:
            raise UsageError(f"--param: the grid has {len(grid)} variants, more than {MAX_VARIANTS}; narrow it or give "
                             f"--force")
        path = td.read_path(a.path) if a.path else None
        if a.duration is not None and not (math.isfinite(a.duration) and a.duration > 0):
            raise UsageError(f"--duration {a.duration}: must be > 0 s")
        if a.workers is not None and a.workers < 1:
            raise UsageError(f"--workers {a.workers}: must be >= 1")
        if a.chunk is not None and a.chunk < 1:
            raise UsageError(f"--chunk {a.chunk}: must be >= 1")
        check_depth(a.depth)
        fields = [f for f in a.fields.split(",") if f]
        bad = [f for f in fields if f not in td.FIELDS]
        if bad:
            raise UsageError(f"--fields: '{bad[0]}' is not a field; choose from {', '.join(td.FIELDS)}")
        prepare_out(a.out, a.overwrite, SWEEP_FILES)
    except (UsageError, ValueError, OSError) as e:
        print(f"tissue sweep: error: {e}", file=sys.stderr)
        return 2
    variants = [td.Variant(a.scene, g, path, a.tool, a.duration) for g in grid]
    where = a.scheduler or ("this process" if a.local else "a Dask cluster on this machine")
    print(f"sweep: {len(variants)} variants of {a.scene} ({', '.join(f'{n}: {len(v)}' for n, v in params) or 'as given'}) "
          f"on {where}", file=sys.stderr)
    results: List = [None] * len(variants)
    tools = [1]
    last_write = [time.monotonic()]
    bar = progress_bar(len(variants))
    t0 = time.monotonic()
    steps = [0]

    def progress(r, done, total):
        results[r.index] = r
        tools[0] = max(tools[0], r.force.shape[1] if r.force.ndim == 3 else 1)
        steps[0] += r.steps
        bar.update(1)
        bar.set_postfix_str(f"{steps[0] / max(1e-9, time.monotonic() - t0):,.0f} scene-steps/s")
        if time.monotonic() - last_write[0] > 30:  # a killed sweep keeps what finished half a minute ago
            write_sweep(a.out, names, grid, results, tools[0])
            last_write[0] = time.monotonic()

    interrupted = False
    try:
        res = td.run(variants, scheduler=a.scheduler, workers=a.workers, backend=a.backend, precision=a.precision,
                     fields=fields, chunk=a.chunk, progress=progress, local=a.local,
                     depth=None if a.depth == "scene" else a.depth)
    except KeyboardInterrupt:
        interrupted = True
        res = None
    except (ValueError, RuntimeError, OSError) as e:
        bar.close()
        print(f"tissue sweep: error: {e}", file=sys.stderr)
        n = write_sweep(a.out, names, grid, results, tools[0])
        print(f"wrote {n} finished variants to {a.out}", file=sys.stderr)
        return 1
    bar.close()
    n = write_sweep(a.out, names, grid, results, tools[0])
    plots = [] if a.no_plots else plot_sweep(a.out, names, grid, results)
    failed = [r.index for r in results if r is not None and r.failure]
    for note in sorted({r.note for r in results if r is not None and r.note}):
        print(f"note: {note}", file=sys.stderr)
    wall = time.monotonic() - t0
    print(f"sweep: {n} of {len(variants)} variants finished in {wall:.3g} s, {steps[0]:,} TLED steps "
          f"({steps[0] / max(wall, 1e-9):,.0f} scene-steps/s){'' if not failed else f'; {len(failed)} stopped (variants.csv says why)'}")
    print(f"wrote {', '.join(os.path.join(a.out, f) for f in SWEEP_FILES)}" + (f", {len(plots)} plots" if plots else ""))
    if interrupted:
        print("tissue sweep: interrupted by SIGINT: the finished variants are written", file=sys.stderr)
        return 130
    return 0


# ------------------------------------------------------------------ fit

def plot_fit(path: str, fit: tf.FitResult) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    m = fit.measurement
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    xs = m.x * (1e3 if m.kind == "depth" else 1)
    ax.plot(xs, m.force, "o", ms=3, label="measured")
    ax.plot(xs, fit.fitted, "-", label="fitted: " + ", ".join(f"{k} = {v:.4g}" for k, v in fit.params.items()))
    ax.set_xlabel("depth (mm)" if m.kind == "depth" else "time (s)")
    ax.set_ylabel("|F| (N)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    write_atomic(path, lambda p: fig.savefig(p, dpi=110, format="png"))
    plt.close(fig)


def fit_main(argv: Sequence[str]) -> int:
    ap = argparse.ArgumentParser(prog="tissue fit", description="Estimate material parameters from a measured force "
                                 "curve by least squares over simulations (docs/distributed.md)")
    ap.add_argument("scene", help="scene file or @kidney")
    ap.add_argument("--measured", required=True, help="CSV of rows x, force (N); x is time (s) or depth (m)")
    ap.add_argument("--x", choices=("time", "depth"), help="what x is when the CSV has no header (default time)")
    ap.add_argument("--param", action="append", default=[], metavar="NAME=START",
                    help="a parameter to fit and its start value: E=3000, nu=0.45, prony1.g=0.2, prony1.tau=0.5, "
                    "fibre_stiffness=1e4")
    ap.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE", help="an override held fixed")
    ap.add_argument("--path", help="tool path CSV for --tool, instead of the scene's")
    ap.add_argument("--tool", type=int, default=0)
    ap.add_argument("--out", help="folder for fit.json, fit.csv and fit.png")
    ap.add_argument("--overwrite", action="store_true")
    ap.add_argument("--scheduler", help="evaluate on a running Dask cluster, tcp://host:8786")
    ap.add_argument("--cluster", action="store_true", help="evaluate on a Dask cluster started on this machine")
    ap.add_argument("--backend", choices=("auto", "cpu", "cuda"), default="auto")
    ap.add_argument("--precision", choices=("float", "double"), default="double")
    ap.add_argument("--depth", default="all", help="deformation region: all (default), auto, a ring count, or scene")
    ap.add_argument("--max-evaluations", type=int, default=30)
    a = ap.parse_args(argv)
    try:
        start, fixed = {}, {}
        for text in a.param:
            n, v = parse_param(text)
            if len(v) != 1:
                raise UsageError(f"--param {text}: a fit takes one start value")
            start[n] = v[0]
        for text in a.fix:
            n, v = parse_param(text)
            if len(v) != 1:
                raise UsageError(f"--fix {text}: give one value")
            fixed[n] = v[0]
        if not start:
            raise UsageError("--param: give at least one parameter to fit (E=3000)")
        check_depth(a.depth)
        if a.max_evaluations < 1:
            raise UsageError(f"--max-evaluations {a.max_evaluations}: must be >= 1")
        m = tf.read_measurement(a.measured, a.x)
        path = td.read_path(a.path) if a.path else None
        if a.out:
            prepare_out(a.out, a.overwrite, ("fit.json",))
    except (UsageError, ValueError, OSError) as e:
        print(f"tissue fit: error: {e}", file=sys.stderr)
        return 2
    client = cluster = None
    try:
        if a.cluster and not a.scheduler:
            from distributed import Client
            cluster = td.local_cluster()
            client = Client(cluster)
        print(f"fit: {', '.join(start)} of {a.scene} to {len(m.x)} rows of {a.measured} ({m.kind}); each evaluation "
              f"{len(start) + 1} simulations on {a.scheduler or ('a Dask cluster on this machine' if client else 'this process')}",
              file=sys.stderr)
        fit = tf.fit(a.scene, m, start, path=path, fixed=fixed, tool=a.tool, precision=a.precision,
                     backend=a.backend, scheduler=a.scheduler, client=client, local=client is None and not a.scheduler,
                     max_evaluations=a.max_evaluations, log=lambda s: print(s, file=sys.stderr),
                     depth=None if a.depth == "scene" else a.depth)
    except KeyboardInterrupt:
        print("tissue fit: interrupted by SIGINT", file=sys.stderr)
        return 130
    except (ValueError, RuntimeError) as e:
        print(f"tissue fit: error: {e}", file=sys.stderr)
        return 1
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    print(fit.table())
    if a.out:
        doc = {"scene": a.scene, "measured": a.measured, "kind": m.kind, "params": fit.params,
               "interval_95": {k: list(v) for k, v in fit.interval.items()}, "start": fit.start, "fixed": fixed,
               "residual_rms_N": fit.residual_rms, "relative_rms": fit.relative_rms, "evaluations": fit.iterations,
               "simulations": fit.variants, "message": fit.message}
        write_atomic(os.path.join(a.out, "fit.json"), lambda p: open(p, "w").write(json.dumps(doc, indent=2) + "\n"))

        def rows(p):
            with open(p, "w", newline="") as f:
                w = csv.writer(f)
                w.writerow([m.kind, "measured_N", "fitted_N"])
                for x, y, z in zip(m.x, m.force, fit.fitted):
                    w.writerow([f"{x:.9g}", f"{y:.9g}", f"{z:.9g}"])

        write_atomic(os.path.join(a.out, "fit.csv"), rows)
        plot_fit(os.path.join(a.out, "fit.png"), fit)
        print(f"wrote {a.out}/fit.json, fit.csv, fit.png")
    return 0


def main(argv: Sequence[str] = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    commands = {"sweep": sweep_main, "fit": fit_main}
    if not argv or argv[0] not in commands:
        print("usage: python3 -m tissue.cli {sweep,fit} ...", file=sys.stderr)
        return 2
    return commands[argv[0]](argv[1:])


if __name__ == "__main__":
    sys.exit(main())
