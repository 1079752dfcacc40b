"""tissue.Batch (docs/batch.md): many scenes stepped together from NumPy.

Checks that can fail: forces come back as (N, tools, 3) and fields as
(N, nodes, 3) arrays equal, bit for bit on the cpu, to the same scenes run
alone in Simulations; tool poses for the whole batch come from one array;
material changes act on one scene; a scene that fails stops alone; two
Python threads sharing one batch take turns; misuse raises ValueError
naming the value.
"""
import threading

import numpy as np
import pytest

import tissue


def kidney_press(batch, sims, ticks):
    """Every scene's probe on the kidney's own scripted press."""
    for _ in range(ticks):
        batch.step()
        for s in sims:
            s.step()


def test_kidneys_in_a_batch_equal_kidneys_alone():
    batch = tissue.Batch("@kidney", 3, backend="cpu", precision="float", depth="all")
    assert len(batch) == 3 and batch.max_tools == 1 and batch.distinct_models == 1
    # scene 2 is stiffer: its own model
    batch.set_material(2, E=6000.0)
    assert batch.distinct_models == 2
    alone = [tissue.Simulation.load("@kidney", backend="cpu", precision="float", depth="all") for _ in range(2)]
    kidney_press(batch, alone, 130)  # the scripted probe reaches the surface after 100 ticks
    f = batch.forces()
    assert f.shape == (3, 1, 3) and f.dtype == np.float64
    assert np.array_equal(f[0, 0], alone[0].force(0))
    assert np.array_equal(f[1, 0], alone[1].force(0))
    assert np.linalg.norm(f[0, 0]) > 0, "the probe presses"
    assert np.linalg.norm(f[2, 0]) > 1.5 * np.linalg.norm(f[0, 0]), "twice as stiff presses back harder"
    u = batch.displacement()
    assert u.shape == (3, alone[0].n_nodes, 3)
    assert np.array_equal(u[0], alone[0].displacement())
    assert np.array_equal(batch.displacement(1), alone[1].displacement())
    assert batch.positions().shape == u.shape
    assert batch.jacobian().shape == (3, alone[0].n_elements)


def block_scene(tmp_path, name="block.xml", E=3000.0):
    """A 20 x 20 x 10 mm block of 6 x 6 x 3 cells written as a scene file, its base fixed, one tool."""
    nodes, tets = tissue.box_mesh(6, 6, 3, (0.02, 0.02, 0.01))
    lines = ['<tissue-scene version="1">', '  <mesh>', '    <nodes>']
    lines += ["      {:.9g} {:.9g} {:.9g}".format(*p) for p in nodes]
    lines += ['    </nodes>', '    <elements>']
    lines += ["      {} {} {} {}".format(*t) for t in tets]
    lines += ['    </elements>', '  </mesh>',
              f'  <material name="tissue" E="{E}" nu="0.4" rho="1000"/>',
              '  <element-set material="tissue" elements="all"/>',
              '  <fixed box-min="-1 -1 -1" box-max="1 1 0.0001"/>',
              '  <tool name="probe" radius="0.004" device="scripted">',
              '    <waypoint t="0" x="0.01" y="0.01" z="0.03"/>',
              '  </tool>',
              '</tissue-scene>']
    path = tmp_path / name
    path.write_text("\n".join(lines))
    return str(path)


def test_tool_poses_from_one_array_and_a_failing_scene_stops_alone(tmp_path):
    scene = block_scene(tmp_path)
    batch = tissue.Batch(scene, 4, backend="cpu", precision="double", depth="all")
    top = tissue.box_node(6, 6, 3, 3, 3)
    batch.set_loads(3, [top], [[0.0, 0.0, -1e9]])  # scene 3 blows up
    tips = np.zeros((4, 1, 3))
    for k in range(1, 41):
        s = min(1.0, k / 30)
        for i in range(4):
            tips[i, 0] = [0.01, 0.01, 0.014 - s * 0.0005 * (i + 1)]
        batch.set_tool_poses(tips)
        batch.step()
    assert batch.failed_scenes == [3]
    assert batch.failed(3) and not batch.failed(0)
    assert "element" in batch.failure(3) or "non-finite" in batch.failure(3)
    fz = batch.forces()[:3, 0, 2]
    assert (fz > 0).all() and fz[0] < fz[1] < fz[2], "deeper presses push back harder"
    batch.set_loads(3, np.zeros(0, dtype=np.int32), np.zeros((0, 3)))
    batch.reset(3)
    assert not batch.failed(3) and batch.ticks(3) == 0
    assert batch.step() == 4


def test_two_threads_share_one_batch(tmp_path):
    batch = tissue.Batch(block_scene(tmp_path), 2, backend="cpu", precision="double", depth="all")
    ref = tissue.Batch(block_scene(tmp_path, "b.xml"), 2, backend="cpu", precision="double", depth="all")
    for b in (batch, ref):
        b.set_tool_poses(np.array([[[0.01, 0.01, 0.0135]], [[0.01, 0.01, 0.0132]]]))

    def run():
        for _ in range(20):
            batch.step()

    threads = [threading.Thread(target=run) for _ in range(2)]
    reads = []
    for t in threads:
        t.start()
    while any(t.is_alive() for t in threads):
        reads.append(batch.displacement().sum())
    for t in threads:
        t.join()
    ref.step(40)
    assert batch.ticks(0) == 40
    assert np.array_equal(batch.displacement(), ref.displacement()), "reads beside steps change nothing"


def test_misuse_raises_naming_the_value(tmp_path):
    batch = tissue.Batch(block_scene(tmp_path), 2, backend="cpu", depth="all")
    with pytest.raises(ValueError, match=r"shape \(2, 1, 3\)"):
        batch.set_tool_poses(np.zeros((3, 1, 3)))
    with pytest.raises(ValueError, match="scene 5 does not exist"):
        batch.set_tool_pose(5, 0, [0, 0, 0])
    with pytest.raises(ValueError, match="no material 'liver'"):
        batch.set_material(0, "liver", E=5000.0)
    with pytest.raises(ValueError, match="copies"):
        tissue.Batch(block_scene(tmp_path), 0)
    with pytest.raises(ValueError, match="must be >= 1"):
        batch.step(0)
    with pytest.raises(ValueError, match="outside 1"):
        batch.step(2**64)
    with pytest.raises(ValueError, match="force=True"):
        batch.step(10**12)
    with pytest.raises(ValueError, match="1.5"):
        batch.set_loads(0, [1.5], [[0.0, 0.0, -1.0]])
    with pytest.raises(ValueError, match="more than 1000 x its size"):
        batch.set_tool_pose(1, 0, [0.0, 0.0, 1e300])
    assert batch.ticks(0) == 0, "nothing refused ran"


def test_a_huge_copy_count_is_refused_at_once():
    with pytest.raises(ValueError, match="a batch of 100000000 scenes needs at least"):
        tissue.Batch("@kidney", 10**8, backend="cpu")


def test_device_arrays_on_the_cpu_raise_naming_the_host():
    batch = tissue.Batch("@kidney", 2, backend="cpu", depth="all")
    with pytest.raises(ValueError, match="keeps its fields on the host"):
        batch.device_displacement()


cuda = pytest.mark.skipif("cuda" not in tissue.available_backends(), reason="no usable CUDA backend here")


@cuda
@pytest.mark.parametrize("precision", ["float", "double"])
def test_device_arrays_are_the_fields_where_they_lie(precision):
    """PyTorch reads a group's displacement and internal force without a copy, and sets the tool poses from a
    device tensor: the same numbers as the NumPy copies and the host arrays."""
    torch = pytest.importorskip("torch")
    if not torch.cuda.is_available():
        pytest.skip("PyTorch sees no GPU")
    n = 6
    batch = tissue.Batch("@kidney", n, backend="cuda", precision=precision, depth="all")
    twin = tissue.Batch("@kidney", n, backend="cuda", precision=precision, depth="all")
    for _ in range(110):  # the scripted probe reaches the kidney
        batch.step()
        twin.step()
    tip = np.array(batch.last(0).tools[0].tip)
    centre = batch.positions(0).mean(axis=0)
    down = (centre - tip) / np.linalg.norm(centre - tip)  # on towards the kidney's centre
    tips = torch.zeros((n, batch.max_tools, 3), dtype=torch.float64, device="cuda")
    for k in range(1, 21):
        for i in range(n):  # each scene's probe presses on to its own depth
            tips[i, 0] = torch.as_tensor(tip + down * 2e-5 * (i + 1) * k)
        batch.set_tool_poses(tips)               # from the device
        twin.set_tool_poses(tips.cpu().numpy())  # from the host
        batch.step()
        twin.step()
    assert (batch.forces()[:, 0, :] != 0).any(axis=1).all(), "every probe presses"
    np.testing.assert_array_equal(batch.forces(), twin.forces())
    for name, host in (("device_displacement", batch.displacement()), ("device_internal_force", batch.internal_force())):
        a = getattr(batch, name)()
        assert a.shape == (n, host.shape[1], 3)
        seen = torch.as_tensor(a, device="cuda")               # __cuda_array_interface__
        same = torch.from_dlpack(a)                            # DLPack
        assert seen.data_ptr() == same.data_ptr() == a.__cuda_array_interface__["data"][0], "no copy"
        np.testing.assert_array_equal(seen.double().cpu().numpy(), host, err_msg=name)
        np.testing.assert_array_equal(same.double().cpu().numpy(), host, err_msg=name)
        one = torch.as_tensor(getattr(batch, name)(3), device="cuda")
        np.testing.assert_array_equal(one.double().cpu().numpy(), host[3], err_msg=name + " of scene 3")
    assert float(torch.as_tensor(batch.device_displacement(), device="cuda").abs().max()) > 1e-5, "the kidneys moved"
    with pytest.raises(ValueError, match="float64 or float32"):
        batch.set_tool_poses(torch.zeros((n, batch.max_tools, 3), dtype=torch.int32, device="cuda"))
    with pytest.raises(ValueError, match=r"shape \(6, 1, 3\)"):
        batch.set_tool_poses(torch.zeros((n + 1, batch.max_tools, 3), dtype=torch.float64, device="cuda"))


def test_a_batch_names_each_scenes_bodies(tmp_path):
    from test_simulation import two_blocks_scene

    two = two_blocks_scene(tmp_path / "two.xml")
    batch = tissue.Batch([two, block_scene(tmp_path)], backend="cpu", precision="double")
    left, right = batch.bodies(0)
    assert (left.name, right.name) == ("left", "right")
    assert right.nodes == slice(left.n_nodes, batch.n_nodes(0), 1)
    assert [b.name for b in batch.bodies(1)] == ["body"]
    with pytest.raises(ValueError, match="scene 2"):
        batch.bodies(2)


def test_a_batch_gives_each_scenes_body_contacts():
    batch = tissue.Batch(["@kidney-fat", "@kidney"], backend="cpu")
    sim = tissue.Simulation.load("@kidney-fat", backend="cpu")
    kidney_press(batch, [sim], 150)
    alone, together = sim.body_contacts(), batch.body_contacts(0)
    assert len(alone["node"]) > 0
    for k in alone:
        np.testing.assert_array_equal(together[k], alone[k])
    assert len(batch.body_contacts(1)["node"]) == 0
    with pytest.raises(ValueError, match="scene 2"):
        batch.body_contacts(2)
