"""The light tree (``light_selection = "tree"``): its choices follow its own pmf, the pmf a sample carries is the pmf
of its light, every light that can light a point has pdf(k | x) > 0, and its paths fit their 64-bit trails.

Scenes: 60 lights (quads of random size, orientation, power and colour in a 20-unit box), and the same with two
emitters that are not surfaces (``num_other = 2``). Shading points: 6 fixed points with their normals, some inside
the lights' box.

Chi-square: the choices of 10^6 uniforms at each shading point against ``pmf_many`` at that point
(:func:`harness.judges.chi2.chi2_test_discrete`), m = 12 tests (6 points x 2 scenes) at Sidak's
alpha = 1 - 0.99^(1/12) (a 1 % chance of a false alarm for the file; the seeds are fixed, so a tree passes or fails
reproducibly). ``test_rejects_a_wrong_pmf`` proves the machinery fails a pmf that is off.
"""

from __future__ import annotations

import numpy as np
import pytest

from harness.judges import chi2
from reference_impl.geometry import Geometry
from reference_impl.kernels import records
from reference_impl.kernels.config import M_TREE_NO_BOUND_ANGLE
from reference_impl.kernels.light_tree import pmf_many, select_many
from reference_impl.light_tree import MAX_DEPTH, LightTree
from reference_impl.lights import LightSampler

N_SAMPLES = 1_000_000
M_TESTS = 12
ALPHA = 1 - 0.99 ** (1 / M_TESTS)


def _quads(n: int, seed: int, spread: float = 20.0):
    """n quads (two triangles each), random centres in [-spread/2, spread/2]^3, sizes 0.2-2, random orientations,
    emission 0.1-50 in random colours; light k = quad k."""
    g = np.random.default_rng(seed)
    vertices, triangles, emission = [], [], []
    for k in range(n):
        c = (g.random(3) - 0.5) * spread
        a, b = np.linalg.qr(g.normal(size=(3, 3)))[0][:, :2].T * g.uniform(0.2, 2.0, size=(2, 1))
        base = len(vertices)
        vertices += [c - a - b, c + a - b, c + a + b, c - a + b]
        triangles += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
        le = g.uniform(0.1, 50.0) * g.uniform(0.2, 1.0, size=3)
        emission += [le, le]
    t = len(triangles)
    return Geometry(vertices=np.array(vertices), triangles=np.array(triangles), material=np.zeros(t, int),
                    reflectance=np.array([[0.5, 0.5, 0.5]]), two_sided=np.array([False]), emission=np.array(emission),
                    light_id=np.repeat(np.arange(n), 2))


def _tables(geometry: Geometry, extra: int = 0):
    sampler = LightSampler(geometry, "tree", np.ones(extra) if extra else None)
    return sampler, records.tree_tables(sampler)


POINTS = np.array([[0.0, 0.0, 0.0], [12.0, 3.0, -2.0], [-9.5, 9.5, 9.5], [3.0, -30.0, 1.0], [0.5, 0.2, 4.0],
                   [40.0, 40.0, 40.0]])
NORMALS = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.6, 0.0, 0.8], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0],
                    [-0.57735, -0.57735, -0.57735]])


def _choices(tables, num_area, num_lights, point, normal, seed, mutant=0):
    u = np.random.default_rng(seed).random(N_SAMPLES)
    x = np.repeat(point[None], N_SAMPLES, axis=0)
    n = np.repeat(normal[None], N_SAMPLES, axis=0)
    return select_many(tables, num_area, num_lights, u, x, n, mutant)


def _all_pmfs(tables, num_lights, point, normal):
    k = np.arange(num_lights)
    return pmf_many(tables, k, np.repeat(point[None], num_lights, axis=0), np.repeat(normal[None], num_lights, axis=0))


@pytest.mark.parametrize("extra", [0, 2])
@pytest.mark.parametrize("where", range(len(POINTS)))
def test_choices_follow_the_pmf(where, extra):
    sampler, tables = _tables(_quads(60, seed=3), extra)
    num_area, num_lights = sampler.num_area, sampler.num_lights
    light, pmf = _choices(tables, num_area, num_lights, POINTS[where], NORMALS[where], seed=100 + where)
    p = np.concatenate([_all_pmfs(tables, num_area, POINTS[where], NORMALS[where]), sampler.pmf[num_area:]])
    # what is not in the lights is "no light": a node whose children's bounds both exclude x, though its own did not
    assert p.sum() <= 1.0 + 1e-12
    # the weight test: each sample's pmf is its light's, to the bit
    area = (light >= 0) & (light < num_area)
    np.testing.assert_array_equal(pmf[area], p[light[area]])
    np.testing.assert_array_equal(pmf[light >= num_area], sampler.pmf[light[light >= num_area]])
    outcomes = np.where(light < 0, num_lights, light)
    p_none = max(0.0, 1.0 - p.sum())
    result = chi2.chi2_test_discrete(outcomes, np.append(p, p_none),
                                     name=f"tree choices at point {where}, {extra} other emitters")
    print(result.line())
    assert not result.failures(ALPHA), result.failures(ALPHA)


def test_rejects_a_wrong_pmf():
    sampler, tables = _tables(_quads(60, seed=3))
    light, _pmf = _choices(tables, 60, 60, POINTS[0], NORMALS[0], seed=7)
    p = _all_pmfs(tables, 60, POINTS[0], NORMALS[0])
    wrong = p * (1 + 0.2 * (np.arange(60) % 2))
    result = chi2.chi2_test_discrete(light, wrong / wrong.sum())
    assert result.p_value < 1e-9


def _can_light(geometry: Geometry, k: int, point: np.ndarray, samples: int = 400) -> bool:
    """Whether a point of light k (of its two triangles, on a grid of barycentrics) has its front side toward x."""
    tris = np.flatnonzero(geometry.light_id == k)
    g = np.random.default_rng(k)
    for t in tris:
        b = g.random((samples, 2))
        b = np.where(b.sum(1, keepdims=True) > 1, 1 - b, b)
        c = geometry.corners[t]
        y = c[0] + b[:, :1] * (c[1] - c[0]) + b[:, 1:] * (c[2] - c[0])
        if np.any((point - y) @ geometry.normal[t] > 0):
            return True
    return False


@pytest.mark.parametrize("mutant, conservative", [(0, True), (M_TREE_NO_BOUND_ANGLE, False)])
def test_every_light_that_can_light_x_has_a_positive_pmf(mutant, conservative):
    """Importance is a bound: pdf(k | x) > 0 wherever light k can light x. The planted fault that drops the box's
    angle from the bound fails it (the test can fail)."""
    geometry = _quads(60, seed=3)
    sampler, tables = _tables(geometry)
    g = np.random.default_rng(9)
    points = np.concatenate([POINTS, (g.random((40, 3)) - 0.5) * 24])
    missed = 0
    for x in points:
        normal = np.zeros(3)
        pmf = pmf_many(tables, np.arange(60), np.repeat(x[None], 60, 0), np.repeat(normal[None], 60, 0), mutant)
        missed += sum(1 for k in range(60) if pmf[k] == 0 and _can_light(geometry, k, x))
    assert (missed == 0) == conservative, missed


def test_trails_reach_their_leaves_and_depth_stays_under_64():
    # 3000 lights along a line with powers growing geometrically: a cost-driven split would go deep; the tree keeps
    # each path within the 64 bits of its trail.
    n = 3000
    vertices = np.zeros((4 * n, 3))
    xs = np.arange(n, dtype=float) ** 2 * 1e-3
    for i, off in enumerate([(0, 0), (0.1, 0), (0.1, 0.1), (0, 0.1)]):
        vertices[i::4] = np.column_stack([xs + off[0], np.full(n, off[1]), np.zeros(n)])
    base = 4 * np.arange(n)
    triangles = np.concatenate([np.column_stack([base, base + 1, base + 2]), np.column_stack([base, base + 2, base + 3])])
    light_id = np.concatenate([np.arange(n), np.arange(n)])
    emission = np.repeat((1.01 ** np.arange(n))[:, None], 3, axis=1)[light_id]
    t = len(triangles)
    geometry = Geometry(vertices=vertices, triangles=triangles, material=np.zeros(t, int),
                        reflectance=np.array([[0.5, 0.5, 0.5]]), two_sided=np.array([False]), emission=emission,
                        light_id=light_id)
    tree = LightTree(geometry, np.full(n, 0.01), np.full(n, -1))
    assert len(tree) == 2 * n - 1
    depths = []
    for k in range(n):
        node, bits, depth = 0, int(tree.trail[k]), 0
        while not tree.leaf[node]:
            node = tree.child[node] if bits & 1 else node + 1
            bits >>= 1
            depth += 1
        assert tree.child[node] == k
        depths.append(depth)
    assert max(depths) <= MAX_DEPTH
    # and a pmf over all of them sums to 1 at a point above the line
    tree.p_tree = 1.0
    tables = records.tree_tables(type("Sampler", (), {"tree": tree})())
    x = np.repeat([[500.0, 1.0, 3.0]], n, axis=0)
    pmf = pmf_many(tables, np.arange(n), x, np.repeat([[0.0, 0.0, 1.0]], n, axis=0))
    assert pmf.sum() == pytest.approx(1.0, abs=1e-9)


def test_a_node_holds_its_lights():
    geometry = _quads(60, seed=5)
    sampler, _tables_ = _tables(geometry)
    tree = sampler.tree
    for node in range(len(tree)):
        if tree.leaf[node]:
            continue
        # the lights under the node: the leaves reached from it
        stack, lights = [node], []
        while stack:
            m = stack.pop()
            if tree.leaf[m]:
                lights.append(tree.child[m])
            else:
                stack += [m + 1, tree.child[m]]
        tris = np.flatnonzero(np.isin(geometry.light_id, lights))
        corners = geometry.corners[tris].reshape(-1, 3)
        assert np.all(corners >= tree.lo[node] - 1e-12) and np.all(corners <= tree.hi[node] + 1e-12)
        assert tree.phi[node] == pytest.approx(sum(tree.phi[np.flatnonzero(tree.leaf & np.isin(tree.child, lights))]))
        cos = geometry.normal[tris] @ tree.w[node]
        assert np.all(cos >= tree.cos_o[node] - 1e-9)


# ----------------------------------------------------------------------------------------------- in the renders


def _render(scene, **settings):
    import reference_impl
    from harness.scene import triangulate

    values = {"spp": 4, "seed": 11, "max_depth": scene.max_depth, **settings}
    return reference_impl.render(triangulate(scene), scene.camera, scene.film, reference_impl.Settings(**values))


def test_tree_renders_give_the_same_bits_whatever_the_batch_and_threads():
    from conftest import load_small

    scene = load_small("lamp-grid", 16)
    for sampler in ("sobol", "independent"):
        a = _render(scene, light_selection="tree", batch_size=37, sampler=sampler)
        b = _render(scene, light_selection="tree", batch_size=1000, threads=1, sampler=sampler)
        assert a.image.tobytes() == b.image.tobytes()
        assert a.stats["light_selections"] > 0


def test_the_tree_takes_a_lambertian_render_to_the_path_loop_and_refuses_branching():
    from conftest import load_small

    from reference_impl.errors import SettingsError

    scene = load_small("multi-light", 8)
    a = _render(scene, light_selection="tree", engine="wavefront")
    b = _render(scene, light_selection="tree", engine="path")
    assert a.image.tobytes() == b.image.tobytes()  # the path loop both times
    with pytest.raises(SettingsError, match="indirect_rays"):
        _render(scene, light_selection="tree", indirect_rays=2)


@pytest.mark.parametrize("direct", ["area", "mis"])
def test_tree_and_power_agree_in_expectation(direct):
    """The same image in expectation: per-pixel means of tree and power renders of lamp-grid (64 lamps, a polished
    floor) within the engines' agreement bound (tests/reference_impl/engine_agreement.py)."""
    from conftest import load_small

    try:
        from engine_agreement import Z_MAX, mean_z
    except ImportError:  # tests/ imported as a package
        from tests.reference_impl.engine_agreement import Z_MAX, mean_z

    scene = load_small("lamp-grid", 24)
    a = _render(scene, spp=256, direct=direct, light_selection="power")
    b = _render(scene, spp=256, seed=12, direct=direct, light_selection="tree")
    assert mean_z(a, b).max() <= Z_MAX
    if direct == "area":  # the comparison can fail: the planted fault that loses lights (light samples alone)
        a = _render(scene, spp=1024, direct=direct, light_selection="power")
        c = _render(scene, spp=1024, seed=13, direct=direct, light_selection="tree",
                    mutant="light-tree-no-bound-angle")
        assert mean_z(a, c).max() > Z_MAX


@pytest.mark.parametrize("name", ["point-spot", "sun-sky"])
def test_the_tree_on_a_scene_without_area_lights(name):
    """No area light: the tree is empty and every emitter is chosen uniformly, 1 / n_other (pbrt-v4's infinite
    lights); the image agrees with power's in expectation."""
    from conftest import load_small

    try:
        from engine_agreement import Z_MAX, mean_z
    except ImportError:  # tests/ imported as a package
        from tests.reference_impl.engine_agreement import Z_MAX, mean_z

    scene = load_small(name, 16)
    a = _render(scene, spp=256, light_selection="power")
    b = _render(scene, spp=256, seed=12, light_selection="tree")
    assert mean_z(a, b).max() <= Z_MAX
