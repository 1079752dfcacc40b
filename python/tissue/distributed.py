"""Many scene variants on a Dask cluster: sweeps and calibration beyond one
Batch (docs/distributed.md).

    import tissue.distributed as td
    variants = [td.Variant("block.xml", {"E": E}) for E in (2000, 4000, 8000)]
    result = td.run(variants)                          # a LocalCluster on this machine
    result = td.run(variants, scheduler="tcp://host:8786")  # a running cluster
    result.force[2]                                    # (ticks, tools, 3) N

A variant is a scene, parameter overrides and optionally a tool path. Each
worker owns a tissue.Batch on its GPU (or its CPU cores) and runs the
variants in chunks that fill it; a chunk is one Dask task, so the tasks of a
worker that dies run again on another, and every variant is reported once.

Parameter names (ParameterError names a bad one):
  E, nu, rho, fibre_stiffness, prony<k>.g, prony<k>.tau   every material
  <material>.E, <material>.prony1.tau, ...                one material
"""
from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import time
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Mapping, Optional, Sequence

import numpy as np

import tissue

#: The material parameters a variant may set, with their physical ranges
#: (open intervals: the engine refuses the ends).
PARAMETER_RANGES = {
    "E": (0.0, math.inf),            # Pa
    "nu": (-1.0, 0.5),
    "rho": (0.0, math.inf),          # kg/m^3
    "fibre_stiffness": (0.0, math.inf),  # Pa (0 = isotropic: the closed end is allowed)
    "g": (0.0, 1.0),                 # a Prony term's relative modulus
    "tau": (0.0, math.inf),          # s
}

_PRONY = re.compile(r"prony([1-9][0-9]*)")


class ParameterError(ValueError):
    """A parameter name or value a variant cannot take, naming it and the rule."""


@dataclass(frozen=True)
class Parameter:
    """A parsed parameter name: which material ('' = every one), which quantity, which Prony term."""
    name: str
    material: str
    quantity: str       # E, nu, rho, fibre_stiffness, g or tau
    term: int = 0       # Prony term (1-based) for g and tau

    def check(self, value: float) -> None:
        lo, hi = PARAMETER_RANGES[self.quantity]
        closed_lo = self.quantity == "fibre_stiffness"
        ok = (value >= lo if closed_lo else value > lo) and value < hi
        if not (isinstance(value, (int, float, np.floating, np.integer)) and math.isfinite(value) and ok):
            raise ParameterError(f"parameter {self.name} = {value!r} is outside its physical range "
                                 f"{'[' if closed_lo else '('}{lo:g}, {hi:g})")


def parse_parameter(name: str) -> Parameter:
    """'E', 'nu', 'prony1.tau', 'liver.E', 'liver.prony2.g', ... as a Parameter."""
    parts = name.split(".")
    simple = ("E", "nu", "rho", "fibre_stiffness")

    def quantity(rest: List[str]) -> Optional[tuple]:
        if len(rest) == 1 and rest[0] in simple:
            return rest[0], 0
        if len(rest) == 2 and _PRONY.fullmatch(rest[0]) and rest[1] in ("g", "tau"):
            return rest[1], int(_PRONY.fullmatch(rest[0]).group(1))
        return None

    q = quantity(parts)
    if q is not None:
        return Parameter(name, "", q[0], q[1])
    if len(parts) >= 2 and parts[0]:
        q = quantity(parts[1:])
        if q is not None:
            return Parameter(name, parts[0], q[0], q[1])
    raise ParameterError(f"parameter '{name}' is not one a variant can set: give E, nu, rho, fibre_stiffness, "
                         f"prony<k>.g or prony<k>.tau, optionally after a material name (liver.E)")


def material_changes(params: Mapping[str, float]) -> List["tissue.MaterialChange"]:
    """The overrides as tissue.MaterialChange objects, one per material named; every value checked."""
    by_material: Dict[str, dict] = {}
    for name, value in params.items():
        p = parse_parameter(name)
        value = float(value) if isinstance(value, (int, float, np.floating, np.integer)) else value
        p.check(value)
        c = by_material.setdefault(p.material, {"prony": {}})
        if p.quantity in ("g", "tau"):
            g, tau = c["prony"].get(p.term, (None, None))
            c["prony"][p.term] = (value, tau) if p.quantity == "g" else (g, value)
        else:
            c[p.quantity] = value
    out = []
    for material, c in by_material.items():
        prony = c.pop("prony")
        out.append(tissue.MaterialChange(material, **c, prony=prony or None))
    return out


def csv_rows(path: str):
    """(line number, text, cells) of each row of a small CSV that holds something, # comments and blanks
    skipped; a file that is not text is refused naming it."""
    try:
        with open(path, "rb") as f:
            data = f.read()
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b"\n") + 1
        raise ValueError(f"{path}:{line}: the file is not UTF-8 text (byte 0x{data[e.start]:02x})") from None
    for line_no, line in enumerate(text.splitlines(), 1):
        if "\0" in line:
            raise ValueError(f"{path}:{line_no}: the file is binary, not text (a NUL byte)")
        body = line.split("#", 1)[0].strip()
        if body:
            yield line_no, body, [c.strip() for c in body.split(",")]


def read_path(path: str) -> np.ndarray:
    """A tool path CSV (t, x, y, z[, grasp[, ax, ay, az]] per row, an optional header, # comments) as rows."""
    rows = []
    width = None
    header = False
    for line_no, text, cells in csv_rows(path):
        try:
            values = [float(c) for c in cells]
        except ValueError:
            if not rows and not header:
                header = True  # a header row, before any numbers
                continue
            raise ValueError(f"{path}:{line_no}: '{text}' is not a row of numbers (t, x, y, z[, grasp[, ax, ay, az]])")
        if len(values) not in (4, 5, 8):
            raise ValueError(f"{path}:{line_no}: {len(values)} values; a path row has 4, 5 or 8 "
                             f"(t, x, y, z[, grasp[, ax, ay, az]])")
        if width is not None and len(values) != width:
            raise ValueError(f"{path}:{line_no}: {len(values)} values where the rows above have {width}")
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"{path}:{line_no}: a value is not finite")
        if rows and not values[0] > rows[-1][0]:
            raise ValueError(f"{path}:{line_no}: t = {values[0]:g} s does not follow t = {rows[-1][0]:g} s: "
                             f"times must increase")
        width = len(values)
        rows.append(values)
    if len(rows) < 2:
        raise ValueError(f"{path}: {len(rows)} path row(s); a path needs at least 2")
    return np.array(rows)


@dataclass
class Variant:
    """One simulation to run: a scene (a file or '@kidney'), parameter
    overrides (names above), optionally a path for a tool (rows t x y z
    [grasp [ax ay az]]), and how long to run (s; default: when the paths end)."""
    scene: str
    params: Mapping[str, float] = field(default_factory=dict)
    path: Optional[np.ndarray] = None
    tool: int = 0
    duration: Optional[float] = None

    def check(self) -> None:
        material_changes(self.params)  # names and ranges
        if self.path is not None:
            p = np.asarray(self.path, dtype=float)
            if p.ndim != 2 or p.shape[1] not in (4, 5, 8) or len(p) < 2:
                raise ValueError(f"variant path: shape {p.shape}; rows t x y z [grasp [ax ay az]], at least 2")
        if self.duration is not None and not (math.isfinite(self.duration) and self.duration > 0):
            raise ValueError(f"variant duration = {self.duration!r} s must be > 0")


@dataclass
class VariantResult:
    """What one variant gave: the tools' force and tip after each tick, the
    final fields asked for, and where it ran. failure is None for a run
    that finished, else why it stopped (its rows up to then are kept)."""
    index: int
    time: np.ndarray                  # (ticks,) s
    force: np.ndarray                 # (ticks, tools, 3) N
    tip: np.ndarray                   # (ticks, tools, 3) m
    fields: Dict[str, np.ndarray]     # name -> final field
    failure: Optional[str]
    backend: str
    worker: str
    note: str = ""                    # e.g. the fallback to the CPU
    steps: int = 0                    # TLED steps run


@dataclass
class Result:
    """Every variant's result, in the variants' order."""
    variants: List[Variant]
    results: List[VariantResult]
    wall: float = 0.0                 # s, the whole run
    workers: int = 0
    scene_steps: int = 0              # TLED steps over all variants

    @property
    def force(self) -> List[np.ndarray]:
        return [r.force for r in self.results]

    @property
    def failed(self) -> List[int]:
        return [r.index for r in self.results if r.failure is not None]

    def notes(self) -> List[str]:
        return sorted({r.note for r in self.results if r.note})


# --------------------------------------------------------------- one worker

def _ticks(batch, scene: int, v: Variant) -> int:
    end = v.duration
    if end is None:
        end = float(v.path[-1, 0]) if v.path is not None else batch.path_end(scene)
    if not end > 0:
        raise ValueError(f"variant of {v.scene}: no duration given and the scene has no scripted path to end it")
    return max(1, int(round(end / batch.tick_seconds(scene))))


def run_chunk(chunk: Sequence[Variant], indices: Sequence[int], backend: Optional[str] = None,
              precision: Optional[str] = None, fields: Sequence[str] = (), worker: str = "local",
              depth: Optional[str] = "all") -> List[VariantResult]:
    """Runs variants as one Batch here; the worker side of run()."""
    note = ""
    if backend in (None, "auto"):
        backend = "cuda" if "cuda" in tissue.available_backends() else "cpu"
    elif backend == "cuda" and "cuda" not in tissue.available_backends():
        backend, note = "cpu", f"worker {worker} has no usable GPU: it ran on the cpu"
    batch = tissue.Batch([(v.scene, material_changes(v.params)) for v in chunk], backend=backend,
                         precision=precision, depth=depth)
    ticks = []
    for i, v in enumerate(chunk):
        if v.path is not None:
            batch.set_tool_path(i, v.tool, np.asarray(v.path, dtype=float))
        ticks.append(_ticks(batch, i, v))
    n, tools, most = len(chunk), batch.max_tools, max(ticks)
    force = np.zeros((most, n, tools, 3))
    tip = np.zeros((most, n, tools, 3))
    stopped = [None] * n
    for k in range(most):
        running = batch.step()
        force[k] = batch.forces()
        tip[k] = batch.tips()
        for i in batch.failed_scenes:
            if stopped[i] is None:
                stopped[i] = (k, batch.failure(i))
        if running == 0:
            break
    out = []
    for i, v in enumerate(chunk):
        length = ticks[i] if stopped[i] is None else stopped[i][0]
        dt = batch.tick_seconds(i)
        got = {name: np.asarray(getattr(batch, name)(i)) for name in fields}
        out.append(VariantResult(indices[i], dt * np.arange(1, length + 1), force[:length, i].copy(),
                                 tip[:length, i].copy(), got, None if stopped[i] is None else stopped[i][1],
                                 backend, worker, note, length * batch.steps_per_tick(i)))
    return out


def _pin_to_cores() -> None:
    """A worker of the embedded cluster keeps to its share of the cores (TISSUE_CORES, set by local_cluster,
    with TISSUE_THREADS their count): the cpu backend's threads follow the calling thread's CPU affinity mask
    and TISSUE_THREADS, so workers side by side do not oversubscribe the cores."""
    cores = os.environ.get("TISSUE_CORES")
    if cores and hasattr(os, "sched_setaffinity"):
        want = {int(c) for c in cores.split(",")}
        if os.sched_getaffinity(0) != want:
            os.sched_setaffinity(0, want)


def _run_task(chunk, indices, backend, precision, fields, depth):
    """The Dask task: run_chunk on this worker, named by its address."""
    from distributed import get_worker
    _pin_to_cores()
    try:
        name = get_worker().address
    except ValueError:
        name = "local"
    return run_chunk(chunk, indices, backend, precision, fields, name, depth)


# --------------------------------------------------------------- the cluster

FIELDS = ("displacement", "positions", "pressure", "internal_force", "jacobian")


def gpu_count() -> int:
    """GPUs this machine's workers may use (CUDA_VISIBLE_DEVICES, else nvidia-smi); 0 without the cuda backend."""
    if "cuda" not in tissue.available_backends():
        return 0
    visible = os.environ.get("CUDA_VISIBLE_DEVICES")
    if visible is not None:
        return len([d for d in visible.split(",") if d.strip() and d.strip() != "-1"])
    smi = shutil.which("nvidia-smi")
    if smi is None:
        return 1
    try:
        out = subprocess.run([smi, "-L"], capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        return 1
    return max(1, sum(1 for line in out.splitlines() if line.startswith("GPU ")))


def _dask():
    """The distributed module, or an error saying how to get it."""
    try:
        import distributed
    except ImportError:
        raise RuntimeError("tissue.distributed needs Dask's distributed scheduler: apt-get install python3-distributed "
                           "(or pip install distributed); run(..., local=True) runs in this process without it") from None
    return distributed


def local_cluster(workers: Optional[int] = None):
    """The embedded cluster: one worker per GPU (each sees only its GPU), or
    `workers` CPU workers (default one, with every core: the batch uses TBB;
    several share the cores out, each keeping to its own)."""
    _dask()
    from distributed import LocalCluster, Nanny, SpecCluster, Scheduler
    gpus = gpu_count()
    if gpus > 0 and workers is None:
        spec = {f"gpu{i}": {"cls": Nanny, "options": {"nthreads": 1, "env": {"CUDA_VISIBLE_DEVICES": str(i)}}}
                for i in range(gpus)}
        return SpecCluster(workers=spec, scheduler={"cls": Scheduler, "options": {"dashboard_address": None}},
                           silence_logs=40)
    n = workers or 1
    if n == 1 or not hasattr(os, "sched_getaffinity"):
        return LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                            silence_logs=40)
    # several CPU workers share the cores out: worker i keeps to its own (_pin_to_cores)
    cores = sorted(os.sched_getaffinity(0))
    share = [cores[i * len(cores) // n:(i + 1) * len(cores) // n] or [cores[i % len(cores)]] for i in range(n)]
    spec = {i: {"cls": Nanny, "options": {"nthreads": 1, "env": {"TISSUE_CORES": ",".join(map(str, share[i])),
                                                                   "TISSUE_THREADS": str(len(share[i]))}}}
            for i in range(n)}
    return SpecCluster(workers=spec, scheduler={"cls": Scheduler, "options": {"dashboard_address": None}},
                       silence_logs=40)


def default_chunk(n_variants: int, workers: int, backend: Optional[str]) -> int:
    """Variants per task: enough to fill a worker's batch (256 scenes on a GPU, two per core on a CPU), and
    at least two tasks per worker where there are variants for them, so that a lost worker loses little."""
    gpu = backend in (None, "auto", "cuda") and gpu_count() > 0
    fill = 256 if gpu else 2 * (os.cpu_count() or 1)
    return max(1, min(fill, math.ceil(n_variants / max(1, 2 * workers))))


def run(variants: Sequence[Variant], *, scheduler: Optional[str] = None, workers: Optional[int] = None,
        backend: Optional[str] = None, precision: Optional[str] = None, fields: Sequence[str] = (),
        chunk: Optional[int] = None, progress: Optional[Callable[[VariantResult, int, int], None]] = None,
        client=None, local: bool = False, depth: Optional[str] = "all") -> Result:
    """Runs every variant and returns their results in order.

    scheduler: a running cluster's address ('tcp://host:8786'); None starts a
    LocalCluster on this machine (local_cluster), or, with local=True, runs
    the chunks in this process without Dask. client: an existing
    distributed.Client to use instead. progress(result, done, total) is
    called as each variant's result arrives. depth: the deformation region
    ("all", the default: the whole mesh, the accurate choice and the one a
    GPU steps many scenes of in one launch; "auto" or a ring count: the
    haptic loop's shortcut; None: each scene's own). Every variant is checked
    before any runs (ParameterError, ValueError naming it)."""
    variants = list(variants)
    if not variants:
        raise ValueError("run: no variants")
    for i, v in enumerate(variants):
        try:
            v.check()
        except ValueError as e:
            raise type(e)(f"variant {i}: {e}") from None
    bad = [f for f in fields if f not in FIELDS]
    if bad:
        raise ValueError(f"fields: {bad[0]!r} is not a field; choose from {', '.join(FIELDS)}")
    if chunk is not None and chunk < 1:
        raise ValueError(f"chunk = {chunk} must be >= 1")
    t0 = time.perf_counter()
    results: List[Optional[VariantResult]] = [None] * len(variants)
    done = 0

    def take(chunk_results: List[VariantResult], total: int):
        nonlocal done
        for r in chunk_results:
            if results[r.index] is None:  # a chunk that ran twice is reported once
                results[r.index] = r
                done += 1
                if progress is not None:
                    progress(r, done, total)

    if local and scheduler is None and client is None:
        size = chunk or default_chunk(len(variants), 1, backend)
        for start in range(0, len(variants), size):
            idx = list(range(start, min(start + size, len(variants))))
            take(run_chunk([variants[i] for i in idx], idx, backend, precision, fields, "local", depth), len(variants))
        return _result(variants, results, t0, 1)

    _dask()
    from distributed import Client, as_completed
    own_cluster = own_client = None
    if client is None:
        if scheduler is not None:
            own_client = client = Client(scheduler, timeout="30s")
        else:
            own_cluster = local_cluster(workers)
            own_client = client = Client(own_cluster)
    try:
        n_workers = max(1, len(client.scheduler_info().get("workers", {})))
        size = chunk or default_chunk(len(variants), n_workers, backend)
        futures = []
        for start in range(0, len(variants), size):
            idx = list(range(start, min(start + size, len(variants))))
            futures.append(client.submit(_run_task, [variants[i] for i in idx], idx, backend, precision,
                                         tuple(fields), depth, pure=False))
        for fut in as_completed(futures):
            take(fut.result(), len(variants))
        return _result(variants, results, t0, n_workers)
    finally:
        if own_client is not None:
            own_client.close()
        if own_cluster is not None:
            own_cluster.close()


def _result(variants, results, t0, workers) -> Result:
    steps = sum(r.steps for r in results if r is not None)
    return Result(variants, results, time.perf_counter() - t0, workers, steps)
