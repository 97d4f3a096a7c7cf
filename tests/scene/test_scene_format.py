"""The TOML scene format: loading, validation messages, transforms, orientation, triangulation, canonical scenes."""

from __future__ import annotations

import contextlib
import copy
import math
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import MINIMAL_SCENE, fuzz_examples
from tomltext import to_toml
from harness.core.errors import HarnessError
from harness.scene import Scene, load_scene, triangulate
from harness.scene.triangulate import rotate_matrix, shape_triangles

REPO = Path(__file__).resolve().parents[2]
SCENES = REPO / "scenes"
CANONICAL = sorted(p.stem for p in SCENES.glob("*.toml"))  # every scene in scenes/

# A small valid scene that tests extend with extra shapes or override with replacements.
MINIMAL = MINIMAL_SCENE


def write_scene(folder: Path, text: str, name: str = "scene.toml") -> Path:
    path = folder / name
    path.write_text(text)
    return path


def load_text(tmp_path: Path, text: str) -> Scene:
    return load_scene(write_scene(tmp_path, text))


def shape_scene(tmp_path: Path, shape_toml: str) -> Scene:
    """MINIMAL plus one [[shapes]] entry given as its body."""
    return load_text(tmp_path, MINIMAL + "\n[[shapes]]\n" + shape_toml)


def doc_example() -> str:
    """The example scene of docs/scene-format.md (it uses every shape type; its mesh is meshes/bunny.ply)."""
    text = (REPO / "docs" / "scene-format.md").read_text()
    return re.search(r"## Example\s+```toml\n(.*?)```", text, re.S).group(1)


def doc_emitters_example() -> str:
    """The example of the "Emitters" section of docs/scene-format.md (its map is textures/sky.exr)."""
    text = (REPO / "docs" / "scene-format.md").read_text()
    return re.search(r"### Example with emitters\s+```toml\n(.*?)```", text, re.S).group(1)


def copy_sky(folder: Path) -> None:
    (folder / "textures").mkdir(parents=True, exist_ok=True)
    (folder / "textures" / "sky.exr").write_bytes((SCENES / "textures" / "sky.exr").read_bytes())


def front_normals(scene: Scene, index: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (front side) and centroids of the world triangles of one shape."""
    vertices, triangles = shape_triangles(scene.shapes[index])
    corners = vertices[triangles]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return normal / np.linalg.norm(normal, axis=1, keepdims=True), corners.mean(axis=1)


@contextlib.contextmanager
def assert_error(path: Path, key: str, *fragments: str):
    """Expect a HarnessError that names the file and the key path and whose message contains the fragments."""
    with pytest.raises(HarnessError) as info:
        yield info
    err = info.value
    assert err.where == f"{path}: {key}", str(err)
    assert str(err).startswith(f"{path}: {key}: ")
    for fragment in fragments:
        assert fragment in err.message, str(err)


# --------------------------------------------------------------------------------------------------------------------
# Canonical scenes


@pytest.mark.parametrize("name", CANONICAL)
def test_canonical_scene_loads_and_triangulates(name):
    scene = load_scene(SCENES / f"{name}.toml")
    geometry = triangulate(scene)
    assert scene.name == name
    assert scene.description.strip()
    assert scene.film.filter == "box"
    assert len(geometry.triangles) > 0
    assert np.all(geometry.area > 0), "canonical scenes have no degenerate triangles"
    assert geometry.num_lights == len(scene.lights) and len(scene.lights) + len(scene.emitters) >= 1
    for shape in scene.shapes:
        assert scene.materials[shape.material].two_sided is False  # everything one-sided, as in Mitsuba's diffuse


def test_cornell_box_numbers():
    scene = load_scene(SCENES / "cornell-box.toml")
    geometry = triangulate(scene)
    assert len(geometry.triangles) == 2 * 6 + 12 * 2 == 36
    assert geometry.num_lights == 1
    assert scene.max_depth == 8
    assert (scene.film.width, scene.film.height, scene.film.filter) == (256, 256, "box")
    assert scene.camera.fov == pytest.approx(39.3077) and scene.camera.fov_axis == "smaller"
    assert list(scene.materials) == ["white", "green", "red"]
    np.testing.assert_allclose(geometry.reflectance[1], [0.105421, 0.37798, 0.076425])
    np.testing.assert_allclose(geometry.reflectance[2], [0.570068, 0.0430135, 0.0443706])
    light = geometry.light_id == 0
    assert light.sum() == 2
    assert geometry.area[light].sum() == pytest.approx(4 * 0.23 * 0.19)
    np.testing.assert_allclose(geometry.emission[light], [[18.387, 13.9873, 6.75357]] * 2)
    np.testing.assert_allclose(geometry.normal[light], [[0, -1, 0]] * 2, atol=1e-12)
    assert np.all(geometry.material[light] == 0)  # the light rectangle uses the white BSDF
    # Walls face into the box: every wall's normal points towards the origin.
    by_name = {shape.name: shape for shape in scene.shapes}
    expected = {"floor": [0, 1, 0], "ceiling": [0, -1, 0], "back": [0, 0, 1], "green-wall": [-1, 0, 0],
                "red-wall": [1, 0, 0]}  # fmt: skip
    for name, direction in expected.items():
        index = by_name[name].index
        normals, _ = front_normals(scene, index)
        np.testing.assert_allclose(normals, [direction] * 2, atol=1e-12)
    for name in ("small-box", "large-box"):
        normals, centroids = front_normals(scene, by_name[name].index)
        centre = by_name[name].to_world[:3, 3]
        assert np.all(np.sum(normals * (centroids - centre), axis=1) > 0), "box faces point outward"


def test_cornell_box_matches_mitsuba_transforms():
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    reference = mi.cornell_box()
    scene = load_scene(SCENES / "cornell-box.toml")
    for shape in scene.shapes:
        expected = np.array(reference[shape.name]["to_world"].matrix, dtype=np.float64)
        np.testing.assert_allclose(shape.to_world, expected, atol=1e-6, err_msg=shape.name)
        assert shape.type == reference[shape.name]["type"]
    light = scene.shapes[0]
    np.testing.assert_allclose(light.emission, reference["light"]["emitter"]["radiance"]["value"])
    sensor = reference["sensor"]
    assert scene.camera.fov == sensor["fov"] and scene.camera.fov_axis == sensor["fov_axis"]
    assert (scene.film.width, scene.film.height) == (sensor["film"]["width"], sensor["film"]["height"])
    assert scene.max_depth == reference["integrator"]["max_depth"]
    for name, material in scene.materials.items():
        np.testing.assert_allclose(material.reflectance, reference[name]["reflectance"]["value"])


def test_furnace_faces_inward_and_emits():
    scene = load_scene(SCENES / "furnace.toml")
    geometry = triangulate(scene)
    assert len(geometry.triangles) == 5120 and geometry.num_lights == 1
    assert scene.max_depth == -1
    centroids = geometry.corners.mean(axis=1)
    assert np.all(np.sum(geometry.normal * (np.asarray(scene.camera.origin) - centroids), axis=1) > 0)
    np.testing.assert_allclose(geometry.emission, 1.0)
    np.testing.assert_allclose(geometry.reflectance, [[0.3, 0.5, 0.7]])
    assert "Le / (1 - rho)" in scene.description


def test_soft_shadows_orientation():
    scene = load_scene(SCENES / "soft-shadows.toml")
    by_name = {shape.name: shape.index for shape in scene.shapes}
    assert scene.max_depth == 2 and (scene.film.width, scene.film.height) == (128, 128)
    light_normals, light_centres = front_normals(scene, by_name["light"])
    floor_normals, _ = front_normals(scene, by_name["floor"])
    np.testing.assert_allclose(light_normals, [[0, -1, 0]] * 2, atol=1e-12)
    np.testing.assert_allclose(light_centres[:, 1], 2.0)
    np.testing.assert_allclose(floor_normals, [[0, 1, 0]] * 2, atol=1e-12)
    geometry = triangulate(scene)
    assert geometry.area[geometry.light_id == 0].sum() == pytest.approx(1.0)


def test_multi_light_ids_follow_shape_order():
    scene = load_scene(SCENES / "multi-light.toml")
    geometry = triangulate(scene)
    assert geometry.num_lights == 3 and scene.max_depth == 3
    lights = scene.lights
    areas = [geometry.area[geometry.light_id == k].sum() for k in range(3)]
    powers = [math.pi * area * np.asarray(light.emission) for area, light in zip(areas, lights)]
    assert len(set(np.round(areas, 6))) == 3, "three different sizes"
    assert len({tuple(np.round(p, 3)) for p in powers}) == 3, "three different powers"
    heights = set()
    for k, light in enumerate(lights):
        mask = geometry.light_id == k
        np.testing.assert_allclose(geometry.emission[mask], [light.emission] * mask.sum())
        np.testing.assert_allclose(geometry.normal[mask], [[0, -1, 0]] * mask.sum(), atol=1e-12)
        heights.add(round(float(geometry.corners[mask][..., 1].mean()), 6))
    assert len(heights) == 3, "slightly different heights"
    assert np.all(geometry.light_id[geometry.emission.sum(axis=1) == 0] == -1)


# --------------------------------------------------------------------------------------------------------------------
# Transforms


def test_translate_rotate_scale_order(tmp_path):
    scene = shape_scene(
        tmp_path,
        'type = "cube"\nmaterial = "white"\ntranslate = [1, 2, 3]\n'
        "rotate = { axis = [0, 0, 1], angle = 90 }\nscale = [2, 1, 1]\n",
    )
    matrix = scene.shapes[0].to_world
    # Scale first: (1, 0, 0) -> (2, 0, 0); then rotate 90 deg about z -> (0, 2, 0); then translate -> (1, 4, 3).
    np.testing.assert_allclose(matrix @ [1, 0, 0, 1], [1, 4, 3, 1], atol=1e-12)
    np.testing.assert_allclose(matrix[3], [0, 0, 0, 1])


def test_rotation_array_last_listed_acts_first(tmp_path):
    scene = shape_scene(
        tmp_path,
        'type = "cube"\nmaterial = "white"\n'
        "rotate = [{ axis = [1, 0, 0], angle = 90 }, { axis = [0, 0, 1], angle = 90 }]\n",
    )
    matrix = scene.shapes[0].to_world
    # R = Rx(90) @ Rz(90): z acts first, (1, 0, 0) -> (0, 1, 0), then x: (0, 1, 0) -> (0, 0, 1).
    np.testing.assert_allclose(matrix[:3, :3] @ [1, 0, 0], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(matrix, rotate_matrix([1, 0, 0], 90) @ rotate_matrix([0, 0, 1], 90), atol=1e-12)


def test_rotation_is_right_handed_and_normalises_axis():
    np.testing.assert_allclose(rotate_matrix([0, 0, 5], 90)[:3, :3] @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(rotate_matrix([2, 0, 0], 90)[:3, :3] @ [0, 1, 0], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(rotate_matrix([0, 3, 0], 90)[:3, :3] @ [0, 0, 1], [1, 0, 0], atol=1e-12)


def test_rotation_matches_mitsuba():
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    axis = np.array([1.0, 2.0, 3.0])
    for angle in (-17.0, 37.0, 123.0):
        expected = np.array(mi.ScalarTransform4f().rotate(axis / np.linalg.norm(axis), angle).matrix)
        np.testing.assert_allclose(rotate_matrix(axis, angle), expected, atol=1e-6)


def test_to_world_is_row_major(tmp_path):
    scene = shape_scene(
        tmp_path,
        'type = "rectangle"\nmaterial = "white"\n'
        "to_world = [[2, 0, 0, 5], [0, 3, 0, 6], [0, 0, 1, 7], [0, 0, 0, 1]]\n",
    )
    vertices, _ = shape_triangles(scene.shapes[0])
    np.testing.assert_allclose(vertices.min(axis=0), [3, 3, 7])
    np.testing.assert_allclose(vertices.max(axis=0), [7, 9, 7])


def test_sphere_center_radius_then_placement(tmp_path):
    scene = shape_scene(
        tmp_path,
        'type = "sphere"\nmaterial = "white"\ncenter = [1, 0, 0]\nradius = 0.5\nsubdivisions = 2\n'
        "translate = [0, 0, 2]\nrotate = { axis = [0, 0, 1], angle = 90 }\n",
    )
    vertices, triangles = shape_triangles(scene.shapes[0])
    assert len(triangles) == 20 * 4**2
    # Centre (1, 0, 0) rotated about z to (0, 1, 0), then moved to (0, 1, 2); vertices at distance 0.5.
    np.testing.assert_allclose(np.linalg.norm(vertices - [0, 1, 2], axis=1), 0.5)


# --------------------------------------------------------------------------------------------------------------------
# Orientation


def test_rectangle_faces_plus_z_and_flip_normals_swaps(tmp_path):
    plain = shape_scene(tmp_path, 'type = "rectangle"\nmaterial = "white"\n')
    flipped = shape_scene(tmp_path, 'type = "rectangle"\nmaterial = "white"\nflip_normals = true\n')
    np.testing.assert_allclose(front_normals(plain)[0], [[0, 0, 1]] * 2)
    np.testing.assert_allclose(front_normals(flipped)[0], [[0, 0, -1]] * 2)
    assert triangulate(plain).area.sum() == pytest.approx(4.0)


@pytest.mark.parametrize("shape_type", ["cube", "sphere"])
def test_closed_shapes_face_outward_unless_flipped(tmp_path, shape_type):
    base = f'type = "{shape_type}"\nmaterial = "white"\ntranslate = [1, 2, 3]\n'
    for flip, sign in ((False, 1.0), (True, -1.0)):
        scene = shape_scene(tmp_path, base + f"flip_normals = {str(flip).lower()}\n")
        normals, centroids = front_normals(scene)
        outward = np.sum(normals * (centroids - [1, 2, 3]), axis=1)
        assert np.all(sign * outward > 0)
    cube = shape_scene(tmp_path, base)
    if shape_type == "cube":
        assert len(triangulate(cube).triangles) == 12 and len(triangulate(cube).vertices) == 24


@pytest.mark.parametrize(("shape_type", "keeps_front"), [("rectangle", True), ("cube", True), ("sphere", False)])
def test_mirroring_follows_mitsuba(tmp_path, shape_type, keeps_front):
    # Mitsuba 3 keeps the front of rectangles and cubes under a negative-determinant placement, swaps spheres'.
    plain = shape_scene(tmp_path, f'type = "{shape_type}"\nmaterial = "white"\n')
    mirrored = shape_scene(tmp_path, f'type = "{shape_type}"\nmaterial = "white"\nscale = [-1, 1, 1]\n')
    normals, centroids = front_normals(mirrored)
    plain_normals, plain_centroids = front_normals(plain)
    if shape_type == "rectangle":
        outward, plain_outward = normals[:, 2], plain_normals[:, 2]
    else:
        outward = np.sum(normals * centroids, axis=1)
        plain_outward = np.sum(plain_normals * plain_centroids, axis=1)
    assert np.all(plain_outward > 0)
    assert np.all((outward > 0) == keeps_front)


@pytest.mark.parametrize("shape_type", ["rectangle", "cube", "sphere"])
def test_orientation_agrees_with_mitsuba_rendering(tmp_path, shape_type):
    """Mitsuba sees an emitter only from its front: compare with our winding for mirrored and flipped shapes."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    transform = mi.ScalarTransform4f
    for mirror in (False, True):
        for flip in (False, True):
            scale = "[-1, 1, 1]" if mirror else "1"
            body = f'type = "{shape_type}"\nmaterial = "white"\nscale = {scale}\nflip_normals = {str(flip).lower()}\n'
            normals, centroids = front_normals(shape_scene(tmp_path, body + "emission = [1, 1, 1]\n"))
            nearest = np.argmax(centroids[:, 2])  # the triangle the camera at +z looks at
            we_see_front = normals[nearest, 2] > 0
            sensor = {
                "type": "perspective", "fov": 10,
                "to_world": transform().look_at(origin=[0.05, 0.03, 5], target=[0.05, 0.03, 0], up=[0, 1, 0]),
                "film": {"type": "hdrfilm", "width": 4, "height": 4, "rfilter": {"type": "box"}},
                "sampler": {"type": "independent", "sample_count": 4},
            }  # fmt: skip
            shape = {
                "type": shape_type, "flip_normals": flip,
                "to_world": transform().scale([-1, 1, 1] if mirror else [1, 1, 1]),
                "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 1.0}},
            }  # fmt: skip
            scene = {"type": "scene", "integrator": {"type": "path"}, "sensor": sensor, "shape": shape}
            image = np.array(mi.render(mi.load_dict(scene)))
            mitsuba_sees_front = image.mean() > 0.5
            assert we_see_front == mitsuba_sees_front, (shape_type, mirror, flip)


# --------------------------------------------------------------------------------------------------------------------
# Mesh files


def write_tetrahedron(path: Path) -> trimesh.Trimesh:
    """A tetrahedron with outward faces, written with trimesh (PLY or OBJ from the suffix)."""
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh.export(path)
    return mesh


@pytest.mark.parametrize("suffix", [".obj", ".ply"])
def test_mesh_file_relative_to_scene_file(tmp_path, monkeypatch, suffix):
    folder = tmp_path / "scenes"
    mesh = write_tetrahedron(folder / "meshes" / f"tet{suffix}")
    path = write_scene(
        folder,
        MINIMAL + f'\n[[shapes]]\ntype = "mesh"\nmaterial = "white"\nfile = "meshes/tet{suffix}"\n'
        "translate = [0, 0, 1]\nemission = [1, 1, 1]\nface_normals = true\n",
    )
    monkeypatch.chdir(tmp_path)  # the mesh is found relative to the scene file, not the working directory
    scene = load_scene(Path("scenes") / "scene.toml")
    shape = scene.shapes[0]
    assert shape.file.is_absolute() and shape.file == (folder / "meshes" / f"tet{suffix}").resolve()
    geometry = triangulate(scene)
    assert len(geometry.triangles) == 4 and geometry.num_lights == 1
    assert geometry.area.sum() == pytest.approx(mesh.area)
    centroids = geometry.corners.mean(axis=1)
    inside = np.array([0.25, 0.25, 1.25])
    assert np.all(np.sum(geometry.normal * (centroids - inside), axis=1) > 0), "winding kept as in the file"
    assert path.exists()


def test_doc_example_loads(tmp_path):
    write_tetrahedron(tmp_path / "meshes" / "bunny.ply")
    scene = load_text(tmp_path, doc_example())
    assert [shape.type for shape in scene.shapes] == ["rectangle", "rectangle", "cube", "sphere", "mesh"]
    assert triangulate(scene).num_lights == 1


def test_doc_emitters_example_loads(tmp_path):
    copy_sky(tmp_path)
    scene = load_text(tmp_path, doc_emitters_example())
    assert [e.type for e in scene.emitters] == ["point", "spot", "directional", "envmap"]
    assert scene.emitters[0].name == "bulb" and scene.emitters[1].beam_width == 18.75
    assert scene.emitters[3].image.shape == (64, 128, 3) and scene.lights == []


def test_doc_shading_example_loads(tmp_path):
    """The example of the "Shading normals" section (its map and mesh are the canonical scenes')."""
    text = (REPO / "docs" / "scene-format.md").read_text()
    example = re.search(r"## Shading normals.*?```toml\n(.*?)```", text, re.S).group(1)
    for name in ("textures/bumps-normal.png", "meshes/blob.ply"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes((SCENES / name).read_bytes())
    scene = load_text(tmp_path, MINIMAL + example)
    bumpy = scene.materials["bumpy"]
    assert bumpy.type == "diffuse" and bumpy.perturbation.type == "normalmap" and bumpy.perturbation.bsdf == "grey"
    assert [shape.type for shape in scene.shapes] == ["rectangle", "mesh"]
    assert triangulate(scene).has_shading_normals


# --------------------------------------------------------------------------------------------------------------------
# Errors: each names the file and the key path


def test_missing_file(tmp_path):
    path = tmp_path / "nope.toml"
    with pytest.raises(HarnessError) as info:
        load_scene(path)
    assert str(path) in str(info.value) and "no such scene file" in str(info.value)


def test_malformed_toml_gives_line_and_column(tmp_path):
    path = write_scene(tmp_path, MINIMAL + "\n[film\nwidth = 3\n")
    with pytest.raises(HarnessError) as info:
        load_scene(path)
    line = MINIMAL.count("\n") + 2
    assert info.value.where == f"{path}: line {line}, column 6"
    assert "malformed TOML" in info.value.message


def test_unknown_key_suggests_closest(tmp_path):
    path = write_scene(tmp_path, MINIMAL.replace("reflectance", "reflectence"))
    with assert_error(path, "materials.white.reflectence", "unknown key 'reflectence'; did you mean 'reflectance'?"):
        load_scene(path)


def test_unknown_shape_key_suggests_closest(tmp_path):
    path = write_scene(tmp_path, MINIMAL + '[[shapes]]\ntype = "cube"\nmaterial = "white"\ntranslat = [0, 0, 0]\n')
    with assert_error(path, "shapes[0].translat", "did you mean 'translate'?"):
        load_scene(path)


def test_wrong_type(tmp_path):
    path = write_scene(tmp_path, MINIMAL + '[[shapes]]\ntype = "cube"\nmaterial = "white"\ntranslate = "abc"\n')
    with assert_error(path, "shapes[0].translate", 'expected a list of 3 finite numbers, got "abc"'):
        load_scene(path)


def test_wrong_integer_type(tmp_path):
    path = write_scene(tmp_path, MINIMAL.replace("width = 16", "width = 16.0"))
    with assert_error(path, "film.width", "expected a positive integer, got 16.0"):
        load_scene(path)


def test_missing_material_reference(tmp_path):
    path = write_scene(tmp_path, MINIMAL + '[[shapes]]\ntype = "cube"\nmaterial = "whte"\n')
    with assert_error(path, "shapes[0].material", "unknown material 'whte'", "did you mean 'white'?"):
        load_scene(path)


def test_missing_mesh_file(tmp_path):
    path = write_scene(tmp_path, MINIMAL + '[[shapes]]\ntype = "mesh"\nmaterial = "white"\nfile = "gone.ply"\n')
    with assert_error(path, "shapes[0].file", "no such mesh file", "gone.ply"):
        load_scene(path)


def test_mesh_without_triangles(tmp_path):
    (tmp_path / "empty.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    path = write_scene(tmp_path, MINIMAL + '[[shapes]]\ntype = "mesh"\nmaterial = "white"\nfile = "empty.obj"\n')
    with assert_error(path, "shapes[0].file", "at least one triangle"):
        load_scene(path)


def test_bad_fov_axis(tmp_path):
    path = write_scene(tmp_path, MINIMAL.replace("fov = 40", 'fov = 40\nfov_axis = "diagonal"'))
    with assert_error(path, "camera.fov_axis", "expected one of x, y, smaller, larger", "'diagonal'"):
        load_scene(path)


def test_bad_filter(tmp_path):
    path = write_scene(tmp_path, MINIMAL.replace("height = 16", 'height = 16\nfilter = "mitchell"'))
    with assert_error(path, "film.filter", "expected one of box, tent, gaussian", "'mitchell'"):
        load_scene(path)


def test_up_parallel_to_view(tmp_path):
    path = write_scene(tmp_path, MINIMAL.replace("up = [0, 1, 0]", "up = [0, 0, 2]"))
    with assert_error(path, "camera.up", "not parallel"):
        load_scene(path)


def test_film_too_large(tmp_path):
    path = write_scene(tmp_path, MINIMAL.replace("width = 16", "width = 16385"))
    with assert_error(path, "film.width", "at most 16384"):
        load_scene(path)
    path = write_scene(tmp_path, MINIMAL.replace("width = 16", "width = 16384").replace("height = 16", "height = 8192"))
    with assert_error(path, "film", "at most 67108864 pixels"):
        load_scene(path)


@pytest.mark.parametrize("depth", [0, -2])
def test_bad_max_depth(tmp_path, depth):
    path = write_scene(tmp_path, MINIMAL + f"[integrator]\nmax_depth = {depth}\n")
    with assert_error(path, "integrator.max_depth", "-1 (unbounded)"):
        load_scene(path)


def test_default_max_depth_is_unbounded(tmp_path):
    assert load_text(tmp_path, MINIMAL).max_depth == -1


def test_reflectance_out_of_range(tmp_path):
    path = write_scene(tmp_path, MINIMAL.replace("[0.8, 0.8, 0.8]", "[0.8, 1.2, 0.8]"))
    with assert_error(path, "materials.white.reflectance", "in [0, 1]", "[0.8, 1.2, 0.8]"):
        load_scene(path)


@pytest.mark.parametrize("emission", ["[0, 0, 0]", "[1, -1, 1]", "[1, nan, 1]"])
def test_bad_emission(tmp_path, emission):
    path = write_scene(tmp_path, MINIMAL + f'[[shapes]]\ntype = "cube"\nmaterial = "white"\nemission = {emission}\n')
    with assert_error(path, "shapes[0].emission", ">= 0, not all 0"):
        load_scene(path)


def test_zero_scale_light(tmp_path):
    path = write_scene(
        tmp_path, MINIMAL + '[[shapes]]\ntype = "rectangle"\nmaterial = "white"\nscale = 0\nemission = [1, 1, 1]\n'
    )
    with assert_error(path, "shapes[0].scale", "singular", "light"):
        load_scene(path)


def test_degenerate_mesh_light(tmp_path):
    (tmp_path / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    path = write_scene(
        tmp_path,
        MINIMAL + '[[shapes]]\ntype = "mesh"\nmaterial = "white"\nfile = "flat.obj"\nemission = [1, 1, 1]\n',
    )
    with assert_error(path, "shapes[0]", "zero-area light", "shape0"):
        load_scene(path)


def test_unknown_shape_type(tmp_path):
    path = write_scene(tmp_path, MINIMAL + '[[shapes]]\ntype = "cub"\nmaterial = "white"\n')
    with assert_error(path, "shapes[0].type", "expected one of rectangle, cube, sphere, mesh", "did you mean 'cube'?"):
        load_scene(path)


def test_to_world_and_translate_together(tmp_path):
    path = write_scene(
        tmp_path,
        MINIMAL + '[[shapes]]\ntype = "cube"\nmaterial = "white"\ntranslate = [1, 0, 0]\n'
        "to_world = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n",
    )
    with assert_error(path, "shapes[0].to_world", "not both"):
        load_scene(path)


def test_rotate_entry_errors_name_the_entry(tmp_path):
    path = write_scene(
        tmp_path,
        MINIMAL + '[[shapes]]\ntype = "cube"\nmaterial = "white"\n'
        "rotate = [{ axis = [1, 0, 0], angle = 10 }, { axis = [0, 0, 0], angle = 10 }]\n",
    )
    with assert_error(path, "shapes[0].rotate[1].axis", "not all 0"):
        load_scene(path)


def test_non_uniform_sphere(tmp_path):
    path = write_scene(tmp_path, MINIMAL + '[[shapes]]\ntype = "sphere"\nmaterial = "white"\nscale = [1, 2, 1]\n')
    with assert_error(path, "shapes[0].scale", "sphere"):
        load_scene(path)


def test_key_of_another_shape_type(tmp_path):
    path = write_scene(tmp_path, MINIMAL + '[[shapes]]\ntype = "cube"\nmaterial = "white"\nradius = 2\n')
    with assert_error(path, "shapes[0].radius", "only to shapes of type 'sphere'"):
        load_scene(path)


def test_missing_camera_table(tmp_path):
    path = write_scene(tmp_path, MINIMAL.replace("[camera]", "[kamera]"))
    with assert_error(path, "kamera", "did you mean 'camera'?"):
        load_scene(path)


# --------------------------------------------------------------------------------------------------------------------
# Fuzzing: load_scene returns a Scene or raises HarnessError, never anything else


KEY_NAMES = ["name", "type", "material", "to_world", "translate", "rotate", "scale", "emission", "flip_normals",
             "file", "center", "radius", "subdivisions", "axis", "angle", "reflectance", "two_sided", "width",
             "height", "filter", "max_depth", "origin", "target", "up", "fov", "fov_axis", "emitters", "position",
             "intensity", "cutoff_angle", "beam_width", "direction", "irradiance", "radiance"]  # fmt: skip
WORDS = ["box", "tent", "gaussian", "x", "y", "smaller", "larger", "white", "red", "rectangle", "cube", "sphere",
         "mesh", "m.obj", "m.ply", "", "point", "spot", "directional", "constant", "envmap", "textures/sky.exr",
         "m.exr"]  # fmt: skip

short_text = st.text(st.characters(exclude_categories=["Cs"]), max_size=6)  # no lone surrogates: TOML refuses them
scalars = st.one_of(
    st.booleans(),
    st.integers(-3, 20000),
    st.integers(),
    st.floats(),
    st.sampled_from([0.0, -0.0, 1e-320, 1e308, -1e308, 0.5, 90.0, 180.0]),
    short_text,
    st.sampled_from(WORDS),
)
values = st.recursive(
    scalars,
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.sampled_from(KEY_NAMES), inner, max_size=3),
    max_leaves=10,
)


def entries(node) -> list[tuple]:
    """Every (container, key) pair inside a parsed document, depth first."""
    pairs = []
    for key, child in node.items() if isinstance(node, dict) else enumerate(node):
        pairs.append((node, key))
        if isinstance(child, (dict, list)):
            pairs += entries(child)
    return pairs


numbers = st.one_of(
    st.integers(-2, 3),
    st.floats(-3, 3),
    st.sampled_from([0, 0.0, -1, 1e-200, 1e200, 2**40, math.inf, math.nan, 16384, 16385]),
)


def mutate(document: dict, data) -> None:
    """One random edit anywhere in the document: replace a value (with anything, or with a number of similar kind),
    delete an entry, or add one to a table or array. Every entry is equally likely to be picked."""
    rng = data.draw(st.randoms(use_true_random=False))
    pairs = entries(document)
    action = data.draw(st.sampled_from(["replace", "tweak", "tweak", "delete", "add"]))
    if action != "add" and pairs:
        container, key = rng.choice(pairs)
        old = container[key]
        if action == "replace":
            container[key] = data.draw(values)
        elif action == "delete":
            del container[key]
        elif isinstance(old, list) and old:
            old[rng.randrange(len(old))] = data.draw(numbers)
        else:
            container[key] = data.draw(numbers)
        return
    containers = [document] + [c[k] for c, k in pairs if isinstance(c[k], (dict, list))]
    container = rng.choice(containers)
    if isinstance(container, dict):
        container[data.draw(st.sampled_from(KEY_NAMES) | short_text)] = data.draw(values)
    else:
        container.append(data.draw(values))


def load_or_harness_error(path: Path) -> None:
    """A Scene, or a HarnessError whose text is one line naming this file."""
    try:
        assert isinstance(load_scene(path), Scene)
    except HarnessError as err:
        text = str(err)
        assert len(text.splitlines()) == 1 and text.startswith(f"{path}: "), text


FUZZ_SEEDS = {name: (SCENES / f"{name}.toml").read_text() for name in CANONICAL} | {"doc-example": doc_example(),
                                                                                    "doc-emitters": doc_emitters_example()}


@pytest.fixture(scope="module")
def fuzz_folder(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("fuzz")
    write_tetrahedron(folder / "meshes" / "bunny.ply")
    copy_sky(folder)
    return folder


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
@settings(max_examples=fuzz_examples(300), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data(), seed=st.sampled_from(sorted(FUZZ_SEEDS)))
def test_fuzz_mutated_documents(fuzz_folder, data, seed):
    document = copy.deepcopy(tomllib.loads(FUZZ_SEEDS[seed]))
    for _ in range(data.draw(st.integers(1, 3))):
        mutate(document, data)
    load_or_harness_error(write_scene(fuzz_folder, to_toml(document), "mutated.toml"))


@settings(max_examples=fuzz_examples(50), deadline=None)
@given(data=st.data(), seed=st.sampled_from(sorted(FUZZ_SEEDS)))
def test_fuzz_edited_text(fuzz_folder, data, seed):
    text = FUZZ_SEEDS[seed]
    for _ in range(data.draw(st.integers(1, 3))):
        start = data.draw(st.integers(0, len(text)))
        end = data.draw(st.integers(start, min(len(text), start + 20)))
        text = text[:start] + data.draw(st.text(alphabet='[]{}=",.#-+0123456789 \nabcxyz', max_size=10)) + text[end:]
    load_or_harness_error(write_scene(fuzz_folder, text, "edited.toml"))
