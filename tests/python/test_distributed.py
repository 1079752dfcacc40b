"""tissue.distributed, tissue.fitting and `tissue sweep` / `tissue fit`
(docs/distributed.md).

Checks that can fail: a sweep on a Dask cluster (embedded, or joined by its
address) gives bit for bit what the same variants give in one local batch;
a worker killed in the middle of a sweep loses nothing and duplicates
nothing; a worker without a GPU falls back to the CPU and says so; the
command line writes NPZ, CSV and plots and keeps what finished when
interrupted; the fit recovers known parameters from a noisy synthetic
measurement (E within 2 %, a Prony g and tau within 5 %) and, on a GPU,
Young's modulus from Hertz's closed form within 3 %; bad input names the
row, option or parameter and the rule.
"""
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

import tissue
import tissue.distributed as td
import tissue.fitting as tf

HERE = os.path.dirname(os.path.abspath(__file__))


def write_block(path, E=3000.0, nu=0.4, prony=None, cells=(6, 6, 3), size=(0.02, 0.02, 0.01), press=0.003,
                press_time=0.2, hold=0.2, radius=0.004, start_gap=0.0005, precision="double", nodes_tets=None,
                fibre=None):
    """A block scene (base fixed) with a sphere pressed into the middle of its top, then held."""
    nodes, tets = nodes_tets if nodes_tets is not None else tissue.box_mesh(*cells, size)
    top = float(nodes[:, 2].max())
    cx, cy = 0.5 * (nodes[:, 0].min() + nodes[:, 0].max()), 0.5 * (nodes[:, 1].min() + nodes[:, 1].max())
    z0 = top + radius + start_gap
    lines = ['<tissue-scene version="1">', '  <mesh>', '    <nodes>']
    lines += ["      {:.12g} {:.12g} {:.12g}".format(*p) for p in nodes]
    lines += ['    </nodes>', '    <elements>']
    lines += ["      {} {} {} {}".format(*t) for t in tets]
    lines += ['    </elements>', '  </mesh>', f'  <material name="tissue" E="{E}" nu="{nu}" rho="1000">']
    if fibre is not None:
        lines.append(f'    <fibre stiffness="{fibre}" direction="1 0 0"/>')
    for g, tau in prony or []:
        lines.append(f'    <prony g="{g}" tau="{tau}"/>')
    zb = float(nodes[:, 2].min())
    lines += ['  </material>', '  <element-set material="tissue" elements="all"/>',
              f'  <fixed box-min="-1 -1 -1" box-max="1 1 {zb + 1e-7}"/>',
              f'  <tool name="probe" radius="{radius}" device="scripted">',
              f'    <waypoint t="0" x="{cx}" y="{cy}" z="{z0}"/>',
              f'    <waypoint t="{press_time}" x="{cx}" y="{cy}" z="{z0 - start_gap - press}"/>',
              *([f'    <waypoint t="{press_time + hold}" x="{cx}" y="{cy}" z="{z0 - start_gap - press}"/>'] if hold > 0 else []),
              '  </tool>', f'  <solver backend="cpu" precision="{precision}" depth="all"/>', '</tissue-scene>']
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
    return str(path)


@pytest.fixture(scope="module")
def block(tmp_path_factory):
    return write_block(tmp_path_factory.mktemp("scenes") / "block.xml")


@pytest.fixture(scope="module")
def visco(tmp_path_factory):
    # pressed 2 mm in 20 ms, then held for five relaxation times: the force relaxes with the Prony term
    return write_block(tmp_path_factory.mktemp("visco") / "visco.xml", prony=[(0.3, 0.08)], press=0.002,
                       press_time=0.02, hold=0.4, start_gap=0.0)


def grid(block, n=6):
    return [td.Variant(block, {"E": E, "nu": nu}) for E in np.linspace(2000, 6000, n // 2) for nu in (0.3, 0.45)]


def same(a, b):
    assert len(a.results) == len(b.results)
    for x, y in zip(a.results, b.results):
        assert x.index == y.index
        assert np.array_equal(x.force, y.force) and np.array_equal(x.tip, y.tip) and np.array_equal(x.time, y.time)


# ------------------------------------------------------------ parameters

def test_parameter_names_and_ranges_are_checked():
    assert td.parse_parameter("E") == td.Parameter("E", "", "E")
    assert td.parse_parameter("liver.prony2.tau") == td.Parameter("liver.prony2.tau", "liver", "tau", 2)
    with pytest.raises(td.ParameterError, match="parameter 'Young' is not one a variant can set"):
        td.parse_parameter("Young")
    with pytest.raises(td.ParameterError, match=r"parameter nu = 0.6 is outside its physical range \(-1, 0.5\)"):
        td.material_changes({"nu": 0.6})
    with pytest.raises(td.ParameterError, match=r"parameter prony1.g = 1.5 is outside"):
        td.material_changes({"prony1.g": 1.5})
    c = td.material_changes({"E": 5000, "tissue.prony1.tau": 0.2, "tissue.prony1.g": 0.1})
    assert [x.material for x in c] == ["", "tissue"]
    assert c[0].E == 5000 and c[1].prony == {1: (0.1, 0.2)}


def test_a_variant_sets_what_it_names(block):
    r = td.run([td.Variant(block), td.Variant(block, {"E": 6000.0})], local=True)
    f0, f1 = (np.linalg.norm(x.force[:, 0], axis=1).max() for x in r.results)
    assert 1.9 < f1 / f0 < 2.1, "twice E presses back about twice as hard"
    assert r.results[0].time[-1] == pytest.approx(0.4) and r.scene_steps > 0
    # a tool path of the variant's own: pressed half as deep
    path = np.array([[0, 0.01, 0.01, 0.0145], [0.2, 0.01, 0.01, 0.013], [0.4, 0.01, 0.01, 0.013]])
    shallow = td.run([td.Variant(block, {}, path)], local=True).results[0]
    assert np.allclose(shallow.tip[-1, 0], [0.01, 0.01, 0.013])
    assert np.linalg.norm(shallow.force[-1, 0]) < 0.6 * np.linalg.norm(r.results[0].force[-1, 0])
    with pytest.raises(ValueError, match="variant 0: .*duration = -1"):
        td.run([td.Variant(block, duration=-1.0)], local=True)
    with pytest.raises(ValueError, match="'pressure2' is not a field"):
        td.run([td.Variant(block)], local=True, fields=["pressure2"])


def test_a_worker_without_a_gpu_runs_on_the_cpu_and_says_so(block):
    if "cuda" in tissue.available_backends():
        pytest.skip("this machine has a GPU")
    r = td.run([td.Variant(block)], local=True, backend="cuda").results[0]
    assert r.backend == "cpu" and "has no usable GPU: it ran on the cpu" in r.note


# ------------------------------------------------------------ Dask

def test_a_local_cluster_gives_what_one_batch_gives(block):
    variants = grid(block)
    local = td.run(variants, local=True, fields=["displacement"])
    seen = []
    dask = td.run(variants, workers=2, chunk=2, fields=["displacement"], progress=lambda r, d, t: seen.append(r.index))
    same(local, dask)
    assert sorted(seen) == list(range(len(variants))), "each variant reported once"
    assert dask.workers == 2 and {r.worker for r in dask.results} != {"local"}
    assert np.array_equal(dask.results[3].fields["displacement"], local.results[3].fields["displacement"])


def test_a_worker_killed_mid_sweep_loses_and_repeats_nothing(block):
    from distributed import Client, LocalCluster
    variants = grid(block, 8)
    local = td.run(variants, local=True)
    seen, killed = [], []
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=40) as cluster, Client(cluster) as client:
        pids = client.run(os.getpid)

        def kill_one(r, done, total):
            seen.append(r.index)
            if killed:
                return
            busy = [w for w, tasks in client.processing().items() if tasks]
            if busy:  # a worker in the middle of a chunk dies at once
                killed.append(busy[0])
                os.kill(pids[busy[0]], signal.SIGKILL)

        dask = td.run(variants, client=client, chunk=1, progress=kill_one)
    assert killed, "a worker was killed while it ran a chunk"
    assert sorted(seen) == list(range(len(variants))), "every variant reported exactly once"
    same(local, dask)


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_running_cluster_is_joined_by_its_address(block):
    scheduler, worker = shutil.which("dask-scheduler"), shutil.which("dask-worker")
    if scheduler is None or worker is None:
        pytest.skip("Debian's dask-scheduler / dask-worker are not installed")
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = dict(os.environ)
    procs = [subprocess.Popen([scheduler, "--host", "127.0.0.1", "--port", str(port), "--dashboard-address", ":0"],
                              env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        time.sleep(1.0)
        procs.append(subprocess.Popen([worker, address, "--nthreads", "1", "--no-dashboard"], env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        from distributed import Client
        with Client(address, timeout="30s") as c:
            c.wait_for_workers(1, timeout=60)
        variants = grid(block, 4)
        same(td.run(variants, local=True), td.run(variants, scheduler=address))
    finally:
        for p in reversed(procs):
            p.terminate()
            p.wait(timeout=30)


# ------------------------------------------------------------ the command line

def cli(*args, **kw):
    return subprocess.run([sys.executable, "-m", "tissue.cli", *args], capture_output=True, text=True, **kw)


def test_the_tissue_program_hands_sweep_and_fit_to_python(block, tmp_path):
    program = os.path.join(os.path.dirname(tissue.__file__), "..", "..", "apps", "tissue")
    if not os.path.exists(program):
        pytest.skip("no tissue program beside the package (an installed package)")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}  # it finds the package itself
    h = subprocess.run([program, "sweep", "--help"], capture_output=True, text=True, env=env)
    assert h.returncode == 0 and "usage: tissue sweep" in h.stdout
    p = subprocess.run([program, "sweep", block, "--param", "E=2000,4000", "--out", str(tmp_path / "s"), "--local",
                        "--no-plots"], capture_output=True, text=True, env=env)
    assert p.returncode == 0 and "2 of 2 variants finished" in p.stdout, p.stderr
    f = subprocess.run([program, "fit", block, "--measured", str(tmp_path / "none.csv"), "--param", "E=1"],
                       capture_output=True, text=True, env=env)
    assert f.returncode == 2 and "none.csv" in f.stderr


def test_sweep_writes_npz_csv_and_plots(block, tmp_path):
    out = tmp_path / "sweep"
    p = cli("sweep", block, "--param", "E=2000:6000:3", "--param", "nu=0.3,0.45", "--out", str(out), "--local")
    assert p.returncode == 0, p.stderr
    assert "6 of 6 variants finished" in p.stdout
    z = np.load(out / "results.npz")
    assert list(z["param_names"]) == ["E", "nu"] and z["params"].shape == (6, 2) and z["finished"].all()
    local = td.run([td.Variant(block, {"E": E, "nu": nu}) for E, nu in z["params"]], local=True)
    for i, r in enumerate(local.results):
        assert np.array_equal(z["force"][i], r.force)
    rows = (out / "variants.csv").read_text().splitlines()
    assert rows[0].startswith("variant,E,nu,status") and len(rows) == 7 and ",finished," in rows[1]
    assert (out / "forces.csv").read_text().count("\n") == 1 + 6 * 400
    for png in ("force_time.png", "force_E.png", "force_nu.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    again = cli("sweep", block, "--param", "E=2000", "--out", str(out), "--local")
    assert again.returncode == 2 and "holds a previous result (results.npz)" in again.stderr


def test_sweep_refuses_bad_options_naming_them(block, tmp_path):
    cases = [(["--param", "E=-5"], "--param E=-5: parameter E = -5.0 is outside its physical range (0, inf)"),
             (["--param", "E=1000:2000:1"], "--param E: the count 1 must be >= 2"),
             (["--param", "Young=5"], "parameter 'Young' is not one a variant can set"),
             (["--param", "E=abc"], "--param E: 'abc' is not a number"),
             (["--param", "E=1,2", "--param", "E=3"], "--param E is given twice"),
             (["--param", "E=1:1e9:400", "--param", "nu=0:0.49:400"], "the grid has 160000 variants"),
             (["--fields", "stress"], "--fields: 'stress' is not a field"),
             (["--depth", "-2"], "--depth -2: give all, auto, scene or a number of rings >= 1")]
    for k, (args, want) in enumerate(cases):
        p = cli("sweep", block, *args, "--out", str(tmp_path / f"o{k}"), "--local")
        assert p.returncode == 2 and want in p.stderr, (args, p.stderr)


def test_an_interrupted_sweep_keeps_what_finished(block, tmp_path):
    out = tmp_path / "cut"
    proc = subprocess.Popen([sys.executable, "-m", "tissue.cli", "sweep", block, "--param", "E=2000:6000:40",
                             "--out", str(out), "--local", "--chunk", "1", "--no-plots"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    got = []
    reader = threading.Thread(target=lambda: got.extend(iter(lambda: os.read(proc.stderr.fileno(), 4096), b"")))
    reader.start()
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and b"3/40" not in b"".join(got):
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=120)
    reader.join(timeout=30)
    err = b"".join(got).decode(errors="replace")
    assert proc.returncode == 130, err
    assert "interrupted by SIGINT: the finished variants are written" in err
    z = np.load(out / "results.npz")
    done = int(z["finished"].sum())
    assert 3 <= done < 40
    rows = (out / "variants.csv").read_text().splitlines()[1:]
    assert sum(",finished," in r for r in rows) == done and sum(",not run," in r for r in rows) == 40 - done


# ------------------------------------------------------------ fitting

def noisy(r, every, noise, seed=7):
    F = np.linalg.norm(r.force[:, 0], axis=1)
    rng = np.random.default_rng(seed)
    sel = slice(every - 1, None, every)
    return r.time[sel], F[sel] * (1 + noise * rng.standard_normal(len(F[sel])))


def test_fit_recovers_young_s_modulus_from_a_noisy_measurement(block):
    truth = td.run([td.Variant(block, {"E": 5000.0})], local=True).results[0]
    t, F = noisy(truth, 10, 0.02)
    fit = tf.fit(block, tf.Measurement("time", t, F), {"E": 3000.0})
    assert fit.params["E"] == pytest.approx(5000, rel=0.02)
    lo, hi = fit.interval["E"]
    assert lo < fit.params["E"] < hi and 0 < (hi - lo) / 5000 < 0.05, "a 95 % interval of the noise's size"
    assert fit.variants == 2 * fit.iterations, "each evaluation: the point and one step, as one batch"
    # against depth: the same truth, the curve read along the press
    d, Fd = tf.simulated_curve(truth, "depth")
    keep = slice(5, None, 5)
    fit_d = tf.fit(block, tf.Measurement("depth", d[keep], Fd[keep]), {"E": 3000.0})
    assert fit_d.params["E"] == pytest.approx(5000, rel=0.02)


def test_fit_recovers_a_prony_term_from_a_held_press(visco):
    truth = td.run([td.Variant(visco)], local=True).results[0]
    t, F = noisy(truth, 2, 0.01)  # 210 rows, 1 % noise
    fit = tf.fit(visco, tf.Measurement("time", t, F), {"prony1.g": 0.15, "prony1.tau": 0.2})
    assert fit.params["prony1.g"] == pytest.approx(0.3, rel=0.05)
    assert fit.params["prony1.tau"] == pytest.approx(0.08, rel=0.05)


def test_fit_recovers_a_fibre_stiffness(tmp_path):
    # fibres along x in a block pressed from above: stretched around the tool, they stiffen the press
    scene = write_block(tmp_path / "fibre.xml", fibre=20000.0)
    truth = td.run([td.Variant(scene)], local=True).results[0]
    softer = td.run([td.Variant(scene, {"fibre_stiffness": 0.0})], local=True).results[0]
    F, F0 = (np.linalg.norm(r.force[-1, 0]) for r in (truth, softer))
    assert F > 1.05 * F0, "the fibres carry part of the press"
    t, Fm = noisy(truth, 10, 0.0)
    fit = tf.fit(scene, tf.Measurement("time", t, Fm), {"fibre_stiffness": 5000.0})
    assert fit.params["fibre_stiffness"] == pytest.approx(20000, rel=0.02)
    with pytest.raises(ValueError, match="has no <fibre>"):
        td.run([td.Variant(write_block(tmp_path / "plain.xml"), {"fibre_stiffness": 1000.0})], local=True)


def test_fit_names_the_row_and_the_rule(block, tmp_path):
    def csv(name, text):
        p = tmp_path / name
        p.write_text(text)
        return str(p)

    with pytest.raises(tf.MeasurementError, match=r"unsorted.csv:3: time 0.1 does not follow 0.2"):
        tf.read_measurement(csv("unsorted.csv", "t,force\n0.2,1\n0.1,2\n0.3,3\n"))
    with pytest.raises(tf.MeasurementError, match=r"words.csv:3: '0.2, lots' is not a row of numbers"):
        tf.read_measurement(csv("words.csv", "depth,force\n0.1,1\n0.2, lots\n"))
    with pytest.raises(tf.MeasurementError, match="every force is 0: the measured curve never touches"):
        tf.read_measurement(csv("zero.csv", "0.1,0\n0.2,0\n0.3,0\n"))
    with pytest.raises(tf.MeasurementError, match="header 'force' names neither time"):
        tf.read_measurement(csv("header.csv", "force,t\n0.1,0\n"))
    binary = tmp_path / "binary.csv"
    binary.write_bytes(b"t,force\n0.1,\x001\n")
    with pytest.raises(ValueError, match=r"binary.csv:2: the file is binary, not text"):
        tf.read_measurement(str(binary))
    with pytest.raises(ValueError, match=r"path.csv:3: t = 0.1 s does not follow t = 0.2 s"):
        td.read_path(csv("path.csv", "t,x,y,z\n0.2,0,0,0\n0.1,0,0,0\n"))
    m = tf.read_measurement(csv("ok.csv", "depth (m),force (N)\n0.0005,0.01\n0.001,0.03\n0.0015,0.05\n"))
    assert m.kind == "depth" and list(m.rows) == [2, 3, 4]
    high = np.array([[0, 0.01, 0.01, 0.02], [0.2, 0.01, 0.01, 0.019], [0.4, 0.01, 0.01, 0.019]])
    with pytest.raises(tf.MeasurementError, match="the simulated tool never touches the tissue"):
        tf.fit(block, m, {"E": 3000.0}, path=high)
    with pytest.raises(tf.MeasurementError, match=r"ok.csv:3: depth 0.001 lies beyond the simulated path.s reach"):
        shallow = np.array([[0, 0.01, 0.01, 0.0145], [0.4, 0.01, 0.01, 0.01305]])
        tf.fit(block, m, {"E": 3000.0}, path=shallow)
    with pytest.raises(td.ParameterError, match=r"parameter nu = 0.6 is outside its physical range"):
        tf.fit(block, m, {"nu": 0.6})


def test_fit_on_the_command_line(block, tmp_path):
    truth = td.run([td.Variant(block, {"E": 4000.0})], local=True).results[0]
    t, F = noisy(truth, 20, 0.0)
    meas = tmp_path / "m.csv"
    meas.write_text("t,force\n" + "".join(f"{a},{b}\n" for a, b in zip(t, F)))
    p = cli("fit", block, "--measured", str(meas), "--param", "E=2500", "--out", str(tmp_path / "fit"))
    assert p.returncode == 0, p.stderr
    import json
    doc = json.loads((tmp_path / "fit" / "fit.json").read_text())
    assert doc["params"]["E"] == pytest.approx(4000, rel=1e-3)
    assert (tmp_path / "fit" / "fit.png").read_bytes()[:4] == b"\x89PNG"
    bad = cli("fit", block, "--measured", str(meas), "--param", "nu=0.7")
    assert bad.returncode == 2 and "nu = 0.7 is outside its physical range" in bad.stderr


# ------------------------------------------------------------ Hertz (GPU)

def graded_block(a_max, per_radius=6):
    """A block of 40 contact radii, refined under its top's centre: cells of a_max / per_radius within 1.5 a_max,
    growing by 1.35 a cell beyond (tensor-product grading of box_mesh)."""
    L, core, h = 40 * a_max, 1.5 * a_max, a_max / per_radius

    def axis(n_core, centre):
        inner = np.linspace(0, core, n_core + 1)
        grow, x = 1.35, [core]
        step = h
        while x[-1] < L / 2 if centre else x[-1] < L:
            step *= grow
            x.append(x[-1] + step)
        outer = np.array(x[1:])
        return inner, outer

    inner, outer = axis(int(round(core / h)), True)
    half = np.concatenate([inner, outer])
    xs = np.concatenate([-half[::-1], half[1:]])
    inner_z, outer_z = axis(int(round(core / h)), False)
    zs = -np.concatenate([inner_z, outer_z])[::-1]
    nodes, tets = tissue.box_mesh(len(xs) - 1, len(xs) - 1, len(zs) - 1, (1.0, 1.0, 1.0))
    ix = np.rint(nodes[:, 0] * (len(xs) - 1)).astype(int)
    iy = np.rint(nodes[:, 1] * (len(xs) - 1)).astype(int)
    iz = np.rint(nodes[:, 2] * (len(zs) - 1)).astype(int)
    return np.stack([xs[ix], xs[iy], zs[iz]], axis=1), tets


def hertz_fit(tmp_path, per_radius, backend, press_time):
    """E fitted to Hertz's force against depth, F = 4/3 E / (1 - nu^2) sqrt(R) d^1.5, for a 5 mm sphere pressed
    0.5 mm (d / R = 0.1) into a graded block of 40 contact radii, starting from E = 2000 Pa."""
    E, nu, R, d_max = 3000.0, 0.45, 0.005, 0.0005
    a_max = np.sqrt(R * d_max)
    scene = write_block(tmp_path / "hertz.xml", E=2000.0, nu=nu, press=d_max * 1.02, press_time=press_time, hold=0.0,
                        radius=R, start_gap=1e-5, nodes_tets=graded_block(a_max, per_radius))
    depth = np.linspace(0.1, 1.0, 10) * d_max
    force = 4 / 3 * E / (1 - nu ** 2) * np.sqrt(R) * depth ** 1.5
    fit = tf.fit(scene, tf.Measurement("depth", depth, force), {"E": 2000.0}, backend=backend)
    print(fit.table())
    print("depth (mm), Hertz (N), fitted (N):\n" + "\n".join(f"{1e3 * d:.3f} {f:.6g} {g:.6g}"
                                                         for d, f, g in zip(depth, force, fit.fitted)))
    return fit.params["E"] / E - 1


def test_fit_recovers_young_s_modulus_from_hertz_s_closed_form(tmp_path):
    # a coarse grading (cells of a_max / 2 under the tool, 40,656 tets) in 0.5 s of press: the CI's size
    assert abs(hertz_fit(tmp_path, 2, "cpu", 0.5)) < 0.03


@pytest.mark.skipif("cuda" not in tissue.available_backends(), reason="needs the cuda backend and a GPU")
def test_fit_recovers_young_s_modulus_from_hertz_s_closed_form_on_a_fine_mesh(tmp_path):
    # cells of a_max / 6 under the tool (243,432 tets), pressed over 2 s
    assert abs(hertz_fit(tmp_path, 6, "cuda", 2.0)) < 0.03
