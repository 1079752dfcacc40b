"""scripts/plot and python/tissue_plots.py: the verification commands' JSON
drawn with matplotlib. Each plot is checked against its data (what is on
the axes), the Pareto front against its definition, and bad input against
a clear message and exit code 2."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

SOURCE = os.environ.get("TISSUE_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
sys.path.append(os.path.join(SOURCE, "python"))  # after the build's tissue package
import tissue_plots  # noqa: E402

DATA = os.path.join(os.path.dirname(__file__), "data")
DOCS = os.path.join(SOURCE, "docs", "accuracy")


def load(path):
    with open(path, encoding="utf-8") as f:
        return json.load(f)


def run_plot(*args):
    return subprocess.run([os.path.join(SOURCE, "scripts", "plot"), *args], capture_output=True, text=True, timeout=120)


def test_tradeoff_plot_shows_every_row_and_the_front():
    data = load(os.path.join(DOCS, "tradeoff-kidney-cpu.json"))
    fig = tissue_plots.tradeoff(data)
    ax = fig.axes[0]
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    rows = [r for r in data["rows"] if not r["failed"]]
    drawn = np.concatenate([c.get_offsets() for c in ax.collections[:-1]])  # the groups' points
    assert len(drawn) == len(rows)
    expected = sorted((1e3 * r["wall_per_tick_s"], max(r["disp_err"], 1e-9)) for r in rows)
    np.testing.assert_allclose(sorted(map(tuple, drawn)), expected, rtol=1e-12)
    # the front the C++ sweep marked is the set no other row beats in both cost and error
    marked = sorted((1e3 * r["wall_per_tick_s"], r["disp_err"]) for r in rows if r["pareto"])
    computed = [(1e3 * rows[i]["wall_per_tick_s"], rows[i]["disp_err"])
                for i in tissue_plots.pareto_front([(r["wall_per_tick_s"], r["disp_err"]) for r in rows])]
    assert marked == sorted(computed)
    line = ax.lines[0].get_xydata()
    np.testing.assert_allclose(line[:, 0], [c for c, _ in marked])


def test_pareto_front_definition():
    pts = [(1, 5), (2, 3), (3, 4), (4, 1), (2, 3.5), (5, 1)]
    assert tissue_plots.pareto_front(pts) == [0, 1, 3]


def test_hertz_plot_draws_the_closed_form():
    data = load(os.path.join(DATA, "hertz.json"))
    fig = tissue_plots.hertz(data)
    assert len(fig.axes) == 2 * len(data)
    for k, study in enumerate(data):
        left = fig.axes[2 * k]
        closed = left.lines[-1].get_xydata()
        E, nu, R = study["E"], study["nu"], study["R"]
        d = closed[:, 0] * 1e-3
        np.testing.assert_allclose(closed[:, 1], 4 / 3 * E / (1 - nu**2) * np.sqrt(R) * d**1.5, rtol=1e-6)
        right = fig.axes[2 * k + 1]
        assert right.get_xscale() == "log"
        np.testing.assert_allclose(right.lines[0].get_ydata(), [lv["max_error"] for lv in study["levels"]])


def test_palpation_plot_marks_the_increase():
    data = load(os.path.join(DOCS, "palpation.json"))
    fig = tissue_plots.palpate(data)
    ax = fig.axes[0]
    tumour, base = ax.lines[0].get_ydata(), ax.lines[1].get_ydata()
    np.testing.assert_allclose(tumour, [p["force_tumour"] for p in data["points"]])
    np.testing.assert_allclose(base, [p["force_baseline"] for p in data["points"]])
    label = ax.texts[0].get_text()
    assert label == "+24.8 %"  # docs/meshing.md's figure


def test_converge_plot_has_the_limit():
    path = os.path.join(DATA, "converge.json")
    data = load(path)
    fig = tissue_plots.converge(data)
    ax = fig.axes[0]
    assert any(np.allclose(l.get_ydata(), data["limit"]) for l in ax.lines)  # the Richardson limit line
    refined = ax.lines[0].get_ydata()
    np.testing.assert_allclose(refined, [r["force_norm"] for r in data["rows"] if r["in_limit"] and not r["failed"]])


@pytest.mark.parametrize("kind,path", [("auto", os.path.join(DOCS, "tradeoff-kidney-cpu.json")),
                                       ("palpate", os.path.join(DOCS, "palpation.json")),
                                       ("auto", os.path.join(DATA, "hertz.json")),
                                       ("auto", os.path.join(DATA, "converge.json"))])
def test_the_script_writes_pictures(kind, path, tmp_path):
    for ext, magic in ((".png", b"\x89PNG"), (".svg", b"<?xml")):
        out = tmp_path / ("plot" + ext)
        r = run_plot(kind, path, "-o", str(out))
        assert r.returncode == 0, r.stderr
        assert out.read_bytes()[:len(magic)] == magic and out.stat().st_size > 5000


def test_bad_input_is_a_clear_error(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"rows": [')
    r = run_plot("tradeoff", str(bad), "-o", str(tmp_path / "x.png"))
    assert r.returncode == 2 and "bad.json" in r.stderr and "not JSON" in r.stderr and "Traceback" not in r.stderr
    r = run_plot("auto", str(tmp_path / "missing.json"), "-o", str(tmp_path / "x.png"))
    assert r.returncode == 2 and "missing.json" in r.stderr and "Traceback" not in r.stderr
    r = run_plot("hertz", os.path.join(DOCS, "palpation.json"), "-o", str(tmp_path / "x.png"))
    assert r.returncode == 2 and "expected a list of studies" in r.stderr
    other = tmp_path / "other.json"
    other.write_text('{"a": 1}')
    r = run_plot("auto", str(other), "-o", str(tmp_path / "x.png"))
    assert r.returncode == 2 and "not the JSON of tissue" in r.stderr
    broken = tmp_path / "broken.json"
    broken.write_text('{"references": [], "rows": [{"group": "x", "failed": ""}]}')
    r = run_plot("tradeoff", str(broken), "-o", str(tmp_path / "x.png"))
    assert r.returncode == 2 and "broken.json" in r.stderr and "wall_per_tick_s" in r.stderr
