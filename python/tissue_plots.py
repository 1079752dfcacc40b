"""Plots of the verification commands' JSON, drawn with matplotlib.

    tissue tradeoff @kidney --json t.json  ->  scripts/plot tradeoff t.json -o t.png
    tissue hertz --json h.json             ->  scripts/plot hertz h.json -o h.png
    tissue converge --json c.json          ->  scripts/plot converge c.json -o c.png
    tissue palpate --json p.json           ->  scripts/plot palpate p.json -o p.png

Each function takes the parsed JSON and returns a matplotlib Figure (the
tests read its axes); bad input raises PlotError naming what is missing.
"""
import json

import matplotlib

matplotlib.use("Agg")  # headless: files only
import matplotlib.pyplot as plt  # noqa: E402

KINDS = ("tradeoff", "hertz", "converge", "palpate")

# one colour per tradeoff group (the sweep's dimensions)
GROUP_COLOURS = {
    "baseline": "black", "depth": "tab:blue", "auto": "tab:red", "precision": "tab:purple", "safety": "tab:green",
    "mesh": "tab:orange", "tolerance": "tab:brown", "anchor": "tab:cyan", "compare": "tab:pink", "mass": "tab:olive",
}
ERROR_FLOOR = 1e-9  # tradeoff errors below are drawn at the floor (exact within float)


class PlotError(ValueError):
    """The JSON is not what the plot needs."""


def _need(obj, key, where):
    if not isinstance(obj, dict) or key not in obj:
        raise PlotError(f"{where}: no '{key}'")
    return obj[key]


def detect(data):
    """The kind of a command's JSON, from its shape."""
    if isinstance(data, list) and data and isinstance(data[0], dict) and "levels" in data[0]:
        return "hertz"
    if isinstance(data, dict):
        if "references" in data and "rows" in data:
            return "tradeoff"
        if "limit" in data and "rows" in data:
            return "converge"
        if "points" in data and "tumour_radius" in data:
            return "palpate"
    raise PlotError("not the JSON of tissue tradeoff, hertz, converge or palpate")


def pareto_front(points):
    """Indices of the points (cost, error) no other point beats in both, by ascending cost."""
    front = []
    for i, (c, e) in enumerate(points):
        dominated = any((c2 <= c and e2 <= e) and (c2 < c or e2 < e) for j, (c2, e2) in enumerate(points) if j != i)
        if not dominated:
            front.append(i)
    return sorted(front, key=lambda i: points[i][0])


def tradeoff(data, title=None):
    rows = [r for r in _need(data, "rows", "tradeoff") if not r.get("failed")]
    if not rows:
        raise PlotError("tradeoff: no successful rows to draw")
    cost = [1e3 * _need(r, "wall_per_tick_s", "tradeoff row") for r in rows]
    error = [max(_need(r, "disp_err", "tradeoff row"), ERROR_FLOOR) for r in rows]
    fig, ax = plt.subplots(figsize=(11, 6.5), layout="constrained")
    for group in sorted({r["group"] for r in rows}):
        idx = [i for i, r in enumerate(rows) if r["group"] == group]
        ax.scatter([cost[i] for i in idx], [error[i] for i in idx], s=30, zorder=3,
                   color=GROUP_COLOURS.get(group, "grey"), label=group)
    front = [i for i, r in enumerate(rows) if r.get("pareto")]
    front.sort(key=lambda i: cost[i])
    ax.plot([cost[i] for i in front], [error[i] for i in front], "-", color="0.45", lw=1.5, zorder=2)
    ax.scatter([cost[i] for i in front], [error[i] for i in front], s=160, facecolors="none", edgecolors="black",
               lw=1.5, zorder=4, label="Pareto front")
    for i, r in enumerate(rows):
        ax.annotate(r.get("label", "").split(":")[0], (cost[i], error[i]), xytext=(6, 4), textcoords="offset points",
                    fontsize=7, color=GROUP_COLOURS.get(r["group"], "grey"))
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time per 1 ms haptic tick (ms)")
    ax.set_ylabel("max nodal displacement error / max displacement\n(against the same mesh's reference)")
    ax.set_title(title or f"speed-accuracy tradeoff: {data.get('scene', '?')} ({data.get('device', '?')})")
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1), title=f"errors < {ERROR_FLOOR:g} drawn at {ERROR_FLOOR:g}",
              title_fontsize=8)
    return fig


def hertz(data, title=None):
    if not isinstance(data, list) or not data:
        raise PlotError("hertz: expected a list of studies")
    fig, axes = plt.subplots(len(data), 2, figsize=(11, 4.2 * len(data)), squeeze=False, layout="constrained")
    for (left, right), study in zip(axes, data):
        levels = _need(study, "levels", "hertz study")
        nu, E, R = study.get("nu", "?"), study.get("E", "?"), study.get("R", 0)
        closed = None
        for lv in levels:
            pts = _need(lv, "points", "hertz level")
            d = [1e3 * _need(p, "delta", "hertz point") for p in pts]
            left.plot(d, [_need(p, "force", "hertz point") for p in pts], "o-", ms=4,
                      label=f"{lv.get('tets', '?')} tets (h = {1e3 * lv.get('h_contact', 0):.2f} mm)")
            if closed is None or len(pts) > len(closed[0]):
                closed = (d, [_need(p, "hertz", "hertz point") for p in pts])
        upper = study.get("upper")
        if upper:  # two elastic spheres: the effective modulus and radius
            left.plot(*closed, "k--", lw=1.5, label="Hertz: 4/3 E* sqrt(R*) d^1.5")
            left.set_ylabel("force between the spheres (N)")
            left.set_title(f"E = {upper.get('E', '?')} Pa on E = {E} Pa, nu = {nu}, "
                           f"R = {1e3 * upper.get('R', 0):g} on {1e3 * R:g} mm")
        else:
            left.plot(*closed, "k--", lw=1.5, label="Hertz: 4/3 E/(1-nu^2) sqrt(R) d^1.5")
            left.set_ylabel("force on the sphere (N)")
            left.set_title(f"E = {E} Pa, nu = {nu}, R = {1e3 * R:g} mm")
        left.set_xlabel("indentation d (mm)")
        left.legend(fontsize=8)
        left.grid(alpha=0.3)
        h = [1e3 * lv["h_contact"] for lv in levels]
        right.loglog(h, [_need(lv, "max_error", "hertz level") for lv in levels], "s-", color="tab:red")
        right.set_xlabel("edge under the contact h (mm)")
        right.set_ylabel("largest |F / F_Hertz - 1|")
        right.set_title("error against mesh size")
        right.grid(True, which="both", alpha=0.3)
    if title:
        fig.suptitle(title)
    return fig


def converge(data, title=None):
    rows = [r for r in _need(data, "rows", "converge") if not r.get("failed")]
    limit = _need(data, "limit", "converge")
    if not rows:
        raise PlotError("converge: no successful rows to draw")
    fig, ax = plt.subplots(figsize=(7.5, 4.8), layout="constrained")
    for in_limit, style, name in ((True, "o-", "refined under the tool"), (False, "D", "uniform re-mesh")):
        sel = [r for r in rows if bool(r.get("in_limit", True)) == in_limit]
        if sel:
            ax.plot([1e3 * _need(r, "edge_under_tool", "converge row") for r in sel],
                    [_need(r, "force_norm", "converge row") for r in sel], style, label=name)
            for r in sel:
                ax.annotate(f"{r.get('tets', '?')} tets", (1e3 * r["edge_under_tool"], r["force_norm"]),
                            xytext=(5, 5), textcoords="offset points", fontsize=7)
    ax.axhline(limit, color="black", ls="--", lw=1, label=f"Richardson limit {limit:.5f} N (order {data.get('order', 0):.2f})")
    ax.set_xscale("log")
    ax.set_xlabel("edge under the tool (mm)")
    ax.set_ylabel("|force on the tool| at the held press (N)")
    ax.set_title(title or f"mesh convergence of the tool force ({data.get('backend', '?')})")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def palpate(data, title=None):
    pts = _need(data, "points", "palpate")
    if not pts:
        raise PlotError("palpate: no points")
    x = [1e3 * _need(p, "x", "palpate point") for p in pts]
    ft = [_need(p, "force_tumour", "palpate point") for p in pts]
    fb = [_need(p, "force_baseline", "palpate point") for p in pts]
    a = 1e3 * _need(data, "tumour_radius", "palpate")
    fig, ax = plt.subplots(figsize=(7.5, 4.5), layout="constrained")
    ax.axvspan(-a, a, color="tab:red", alpha=0.08, label=f"tumour (radius {a:g} mm)")
    ax.plot(x, ft, "o-", color="tab:red", label=f"with the tumour ({data.get('stiffness_ratio', '?')} x stiffer)")
    ax.plot(x, fb, "s--", color="tab:blue", label="without (same mesh, tissue material)")
    k = max(range(len(pts)), key=lambda i: ft[i] / fb[i] if fb[i] else 0)
    ax.annotate(f"{100 * (ft[k] / fb[k] - 1):+.1f} %", (x[k], ft[k]), xytext=(8, -4), textcoords="offset points")
    ax.set_xlabel("probe position along the scan (mm)")
    ax.set_ylabel(f"force at {1e3 * data.get('press', 0):g} mm press (N)")
    ax.set_title(title or f"palpation: {1e3 * data.get('tool_radius', 0):g} mm probe, {data.get('tets', '?')} tets")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def load(path):
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except OSError as e:
        raise PlotError(f"{path}: cannot read: {e.strerror}") from None
    except json.JSONDecodeError as e:
        raise PlotError(f"{path}: not JSON (line {e.lineno}, column {e.colno}: {e.msg})") from None


def plot_file(kind, path, output, title=None):
    """Draws `path` (JSON) as `kind` (or "auto") into `output` (.png, .svg, .pdf); returns the kind."""
    data = load(path)
    if kind == "auto":
        kind = detect(data)
    if kind not in KINDS:
        raise PlotError(f"unknown plot kind '{kind}' (one of {', '.join(KINDS)}, auto)")
    try:
        fig = globals()[kind](data, title)
    except PlotError as e:
        raise PlotError(f"{path}: {e}") from None
    except (KeyError, TypeError, IndexError) as e:
        raise PlotError(f"{path}: not {kind} JSON ({type(e).__name__}: {e})") from None
    fig.savefig(output, dpi=110)
    plt.close(fig)
    return kind
