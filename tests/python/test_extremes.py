"""Extreme presses end well: a nearly incompressible block (nu = 0.49)
pressed by a 4 mm sphere to half its radius and beyond its radius runs to
the end with a finite force; a path that starts half a radius inside the
block is brought in from outside and runs, never a far-field blow-up."""
import numpy as np

import tissue.distributed as td
from test_distributed import write_block

R = 0.004


def press(tmp_path, name, **kw):
    scene = write_block(tmp_path / f"{name}.xml", nu=0.49, cells=(12, 12, 6), radius=R, press_time=0.2, hold=0.3,
                        **kw)
    return td.run([td.Variant(scene)], local=True, depth=None).results[0]


def test_presses_to_half_and_beyond_the_radius_run_to_the_end(tmp_path):
    half = press(tmp_path, "half", press=0.5 * R)
    deep = press(tmp_path, "deep", press=1.1 * R)
    for r in (half, deep):
        assert r.failure is None, r.failure
        F = np.linalg.norm(r.force[:, 0], axis=1)
        assert len(F) == 500 and np.all(np.isfinite(F)) and F[-1] > 0
    assert np.linalg.norm(deep.force[-1, 0]) > 2 * np.linalg.norm(half.force[-1, 0])


def test_a_start_inside_the_block_is_brought_in_and_runs(tmp_path):
    # the Scheduler brings a tool whose first pose touches the tissue in from outside (core kEntrySpeed)
    r = press(tmp_path, "inside", press=1e-6, start_gap=-0.5 * R)
    assert r.failure is None, r.failure
    assert np.all(np.isfinite(r.force)) and np.linalg.norm(r.force[-1, 0]) > 0
