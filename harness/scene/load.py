"""Read a TOML scene file (``docs/scene-format.md``) into a validated :class:`Scene`.

Every problem with the file raises :class:`HarnessError` whose ``where`` is ``"<file>: <key path>"`` (for example
``"scenes/x.toml: shapes[2].translate"``) and whose message says what was expected and what was found.
"""

from __future__ import annotations

import math
import os
import re
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from reference_impl.camera import Camera, Film
from reference_impl.errors import SettingsError

from harness.core.errors import ALLOW_OUTSIDE_ENV, HarnessError, read_user_bytes
from harness.core.limits import MAX_FILM_SIDE, envmap_problem, estimate_text, film_problem
from harness.core.options import env_switch
from harness.core.text import hint as suggestion  # `hint` is a local name here
from harness.core.text import short
from harness.files.imageio import exr_size, read_exr
from harness.scene.kinds.cameras import read_camera
from harness.scene.kinds.emitters import read_emitters
from harness.scene.kinds.media import read_media
from harness.scene.kinds.materials import CU_ETA, CU_K, MATERIAL_KEYS, read_material  # noqa: F401 (CU_*: hints)
from harness.scene.kinds.composites import is_composite, read_composites
from harness.scene.kinds.perturbations import PERTURBATIONS, read_perturbed
from harness.scene.triangulate import emitter_shades_flat
from harness.scene.kinds.shapes import MAX_SUBDIVISIONS, ONE_TYPE_KEYS, SHAPES  # noqa: F401 (MAX_*: the tests)
from harness.scene.kinds.textures import read_texture, texture_reference
from harness.scene.model import Emitter, Material, Medium, Scene, Shape, Texture
from harness.scene.mesh_files import (
    MAX_MESH_BYTES,
    ConfinedResolver,
    confined_path,
    read_mesh,
)
from harness.scene.typed_reader import TOML_PHRASING, TypedReader, show_value
from harness.scene.triangulate import (  # noqa: F401 (frame_to_world: a spot's frame, read by the tests)
    frame_to_world,
    is_similarity,
    object_to_world,
    rotate_matrix,
    scale_matrix,
    shape_triangles,
    translate_matrix,
    triangle_areas,
)

TOP_LEVEL_KEYS = ("name", "description", "closed_form", "camera", "film", "integrator", "textures", "materials",
                  "media", "shapes", "emitters", "regions")
# harness.renderers.groundtruth.CLOSED_FORMS
CLOSED_FORMS = ("furnace", "white-furnace", "leaning-plate", "sunlit-floor", "focused-plane")
FILM_KEYS = ("width", "height", "filter")
INTEGRATOR_KEYS = ("max_depth",)
SHAPE_KEYS = (
    "name", "type", "material", "to_world", "translate", "rotate", "scale", "emission", "flip_normals",
    "file", "flip_tex_coords", "face_normals", "center", "radius", "subdivisions", "interior", "exterior",
)  # fmt: skip
ROTATE_KEYS = ("axis", "angle")
MESH_SUFFIXES = (".ply", ".obj")
# An environment map is held in memory as float32 RGB (12 B per pixel) and handed to Mitsuba (another copy and its
# sampling tables): 8192 x 4096 (an "8K" lat-long map, 384 MiB as float32) at most.
MAX_ENVMAP_PIXELS = 2**25

DEFAULT_MAX_DEPTH = -1  # Mitsuba's path integrator: unbounded
# Radiance per channel: a path's sample is emission times weights that reach 1e6 and more near small lights, and
# the variance squares it; both must stay far inside float32 (3.4e38), the type of every image and EXR.
MAX_EMISSION = 1e12
INT32_MAX = 2**31 - 1

_OBJ_INDEX = re.compile(rb"[-+]?[0-9]+")
_TOML_POSITION = re.compile(r"\s*\(at line (\d+), column (\d+)\)\s*$")
_TOML_END = "(at end of document)"



def load_scene(path: str | Path, *, allow_outside_paths: bool | None = None) -> Scene:
    """Read and validate the scene file at ``path``; raise :class:`HarnessError` for anything wrong with it.

    Mesh and environment-map files are read here too (relative to the scene file's folder), so a returned
    :class:`Scene` always triangulates and holds its maps' pixels. A file a scene names (a mesh, an envmap) must
    resolve, after symlinks, inside the scene file's folder unless ``allow_outside_paths``; None (the default) takes
    it from the environment variable ``HARNESS_ALLOW_OUTSIDE_PATHS`` (``1``: allowed; :func:`outside_paths_allowed`),
    which the CLI's ``--allow-outside-paths`` sets, so that worker processes follow the command's choice.
    """
    path = Path(path)
    if allow_outside_paths is None:
        allow_outside_paths = outside_paths_allowed()
    reader = _SceneReader(str(path), path.parent, allow_outside_paths)
    return reader.scene(_read_toml(reader.opened(path)), path)


#: This checkout's canonical scenes (``scenes/NAME.toml``), where a bare scene NAME is looked for last.
CANONICAL_SCENES = Path(__file__).resolve().parents[2] / "scenes"


def find_scene(value: str, where: str, folder: str | Path = ".") -> Path:
    """The scene file that a suite's ``scene`` key or a command's SCENE argument names: ``value`` relative to
    ``folder`` (the suite's folder; the current one on the command line) or, for a bare NAME (no ``/``, no
    ``.toml``), the first file of ``scenes/NAME.toml`` beside ``folder``, in the current folder and among this
    checkout's canonical scenes (``scenes = "furnace"`` and ``harness render furnace`` alike). None found is a
    HarnessError at ``where`` saying where it looked, with the closest scene name there."""
    folder = Path(folder)
    candidates = [folder / value]
    searched = []
    if "/" not in value and not value.endswith(".toml"):
        searched = list(dict.fromkeys([folder.parent / "scenes", Path("scenes"), CANONICAL_SCENES]))
        candidates += [scenes / f"{value}.toml" for scenes in searched]
        candidates = list(dict.fromkeys(candidates))
    for candidate in candidates:
        try:
            if candidate.is_file():
                return candidate
        except OSError as err:  # a name too long for the file system, a loop of symbolic links, ...
            raise HarnessError(where, f"cannot look for the scene file {short(str(candidate))}: "
                               f"{err.strerror or err}") from None
    names = sorted({p.stem for scenes in searched if scenes.is_dir() for p in scenes.glob("*.toml")})
    raise HarnessError(where, f"no scene {short(value)} (looked for {', '.join(short(str(c)) for c in candidates)})"
                       f"{suggestion(value, names)}")


def scene_argument(text: str, where: str = "scene") -> Path:
    """A command's SCENE: a path as given (:func:`load_scene` says what is wrong with it), or a bare NAME resolved
    as a suite's ``scene`` is (:func:`find_scene`: a near miss gets a did-you-mean, at ``where``)."""
    path = Path(text)
    if path.suffix or "/" in text or os.sep in text or path.exists():
        return path
    return find_scene(text, where)


def outside_paths_allowed() -> bool:
    """The process-wide default of ``load_scene(allow_outside_paths=...)``: ``$HARNESS_ALLOW_OUTSIDE_PATHS``, read
    by :func:`harness.core.options.env_switch` (``1``, ``on``, ``yes``, ``true`` allow; ``0``, ``off``, ``no``,
    ``false``, empty or unset refuse; anything else is a HarnessError naming the variable)."""
    return env_switch(ALLOW_OUTSIDE_ENV)


def _read_toml(path: Path) -> dict[str, Any]:
    """The parsed TOML document; file-system, encoding and syntax problems become :class:`HarnessError`."""
    label = str(path)
    data = read_user_bytes(path, missing="no such scene file", directory="expected a scene file, got a directory")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise HarnessError(label, f"expected UTF-8 text, got an undecodable byte at offset {err.start}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        message = str(err)
        position = _TOML_POSITION.search(message)
        if position:
            where = f"{label}: line {position[1]}, column {position[2]}"
            message = message[: position.start()]
        elif message.endswith(_TOML_END):
            where = f"{label}: end of document"
            message = message[: -len(_TOML_END)].rstrip()
        else:
            where = label
        raise HarnessError(where, f"malformed TOML: {message}") from None
    except (ValueError, RecursionError) as err:  # e.g. integers beyond Python's digit limit, absurd nesting
        raise HarnessError(label, f"malformed TOML: {err}") from None


# --------------------------------------------------------------------------------------------------------------------
# The reader.


class _SceneReader(TypedReader):
    """Turns a parsed TOML document into a :class:`Scene`, raising :class:`HarnessError` on the first problem.

    ``label`` is the file path shown in messages; ``folder`` is where mesh file names are relative to and, unless
    ``allow_outside``, the folder they must stay in. ``files`` lists every file read for the scene, in the order
    read (:meth:`opened`; :attr:`Scene.files`). The typed readers and their messages are
    :class:`~harness.scene.typed_reader.TypedReader`'s, phrased as TOML writes values and keys.
    """

    max_emission = MAX_EMISSION  # radiance per channel, at most (shapes' emission, emitters, envmaps)

    def __init__(self, label: str, folder: Path, allow_outside: bool = False):
        super().__init__(label, TOML_PHRASING)
        self.folder = folder
        self.allow_outside = allow_outside
        self.files: list[Path] = []
        self.scene_textures: dict[str, Texture] = {}  # [textures], once read (materials and lights name them)
        # a mesh file's parse, by its resolved path, for every later shape that names it (a forest's thousands of
        # trees naming a few files: each file read and parsed once; harness.generators.forest)
        self.parsed_meshes: dict[Path, tuple] = {}
        self.scene_media: dict[str, Medium] = {}  # [media], once read (shapes and the camera name them)

    def opened(self, path: Path) -> Path:
        """``path``, recorded among the files the scene is read from: every file the loader reads passes through
        here (the scene file, :meth:`file_path`, the resolver of the files a mesh names)."""
        self.files.append(path)
        return path

    def settings(self, build):
        """Call ``build()`` (a core constructor); turn its SettingsError into a HarnessError at the same key."""
        try:
            with np.errstate(all="ignore"):
                return build()
        except SettingsError as err:
            raise self.error(err.key, err.message) from None

    # ---- the document --------------------------------------------------------------------------------------------

    def scene(self, document: dict, path: Path) -> Scene:
        self.check_keys(document, TOP_LEVEL_KEYS, "")
        name = self.string(document.get("name", path.stem), "name")
        description = self.string(document.get("description", ""), "description")
        camera = self.camera(document)
        film = self.film(document)
        max_depth = self.max_depth(document)
        textures = self.textures(document)
        materials = self.materials(document)
        self.scene_media = read_media(self, document)
        camera_medium = self.camera_medium(document)
        shapes = self.shapes(document, materials)
        self.check_textured_shapes(shapes, materials)
        emitters = self.emitters(document)
        closed_form = None
        if "closed_form" in document:
            closed_form = self.choice(document["closed_form"], "closed_form", CLOSED_FORMS)
        regions = self.regions(document, shapes)
        return Scene(name, description, camera, film, max_depth, materials, shapes, path, closed_form,
                     emitters=emitters, regions=regions, files=tuple(dict.fromkeys(self.files)), textures=textures,
                     media=self.scene_media, camera_medium=camera_medium)

    def regions(self, document: dict, shapes: list[Shape]) -> tuple[str, ...]:
        """``regions``: names of shapes whose pixels the strategy table measures apart (docs/scene-format.md)."""
        raw = document.get("regions", [])
        if not isinstance(raw, list) or not all(isinstance(r, str) for r in raw):
            raise self.expected("regions", "a list of shape names", raw)
        names = {shape.name for shape in shapes}
        for i, region in enumerate(raw):
            if region not in names:
                raise self.error(f"regions[{i}]", f"expected the name of a [[shapes]] entry, got {region!r}")
        if len(set(raw)) != len(raw):
            raise self.error("regions", "expected each shape once")
        return tuple(raw)

    def camera(self, document: dict) -> Camera:
        return read_camera(self, document)

    def camera_medium(self, document: dict) -> str | None:
        """``[camera] medium``: the medium the camera sits in (a name of ``[media]``), or None."""
        table = document["camera"]
        return self.medium_name(table["medium"], "camera.medium") if "medium" in table else None

    def medium_name(self, value: Any, key: str) -> str:
        """A name of ``[media]`` (read before the shapes and the camera's medium), with the closest one
        suggested."""
        name = self.string(value, key)
        media: dict[str, Medium] = self.scene_media
        if name not in media:
            defined = ", ".join(repr(m) for m in media) or "none"
            raise self.error(key, f"unknown medium {name!r}{suggestion(name, media)} (defined in [media]: "
                                  f"{defined})")
        return name

    def film(self, document: dict) -> Film:
        table = self.required_table(document, "film")
        self.check_keys(table, FILM_KEYS, "film")
        size = {}
        for key in ("width", "height"):
            value = self.integer(self.require(table, key, "film", "pixels"), f"film.{key}", "a positive integer")
            if value < 1:
                raise self.expected(f"film.{key}", f"a positive integer of at most {MAX_FILM_SIDE} pixels", value)
            size[key] = value
        width, height = size["width"], size["height"]
        for key, value in size.items():
            if value > MAX_FILM_SIDE:
                raise self.error(f"film.{key}", (
                    f"expected a positive integer of at most {MAX_FILM_SIDE} pixels, got {show_value(value)} "
                    f"({show_value(width)} x {show_value(height)} pixels need {estimate_text(width, height)}); "
                    f"lower film.{key}"))
        problem = film_problem(width, height)
        if problem:
            raise self.error("film", f"{problem}; lower film.width / film.height")
        filter_name = self.string(table.get("filter", "box"), "film.filter")
        return self.settings(lambda: Film(size["width"], size["height"], filter_name))

    def max_depth(self, document: dict) -> int:
        table = self.table(document.get("integrator", {}), "integrator")
        self.check_keys(table, INTEGRATOR_KEYS, "integrator")
        what = "-1 (unbounded) or an integer from 1 to 2**31 - 1"
        depth = self.integer(table.get("max_depth", DEFAULT_MAX_DEPTH), "integrator.max_depth", what)
        if depth == 0 or depth < -1 or depth > INT32_MAX:
            raise self.expected("integrator.max_depth", what, depth)
        return depth

    def textures(self, document: dict) -> dict[str, Texture]:
        table = self.table(document.get("textures", {}), "textures")
        self.scene_textures = {name: read_texture(self, name, entry) for name, entry in table.items()}
        return self.scene_textures

    def materials(self, document: dict) -> dict[str, Material]:
        """The ``[materials]`` in file order: the plain ones first read, then the normal and bump maps around them
        (:mod:`harness.scene.kinds.perturbations`)."""
        table = self.table(document.get("materials", {}), "materials")
        perturbing = {name: entry for name, entry in table.items()
                      if isinstance(entry, dict) and isinstance(entry.get("type"), str) and entry["type"] in PERTURBATIONS}
        composite = {name: entry for name, entry in table.items() if is_composite(entry)}
        self.perturbing_names = set(perturbing)
        plain = {name: read_material(self, name, entry) for name, entry in table.items()
                 if name not in perturbing and name not in composite}
        read = dict(plain)
        for name, entry in perturbing.items():
            read[name] = read_perturbed(self, name, entry, self.join("materials", name), plain)
        read.update(read_composites(self, composite, read))
        return {name: read[name] for name in table}

    def check_textured_shapes(self, shapes: list[Shape], materials: dict[str, Material]) -> None:
        """Refuse a textured material on a shape without texture coordinates (a mesh file without them) and an
        emitting mesh whose vertex normals lean off its triangles."""
        for shape in shapes:
            material = materials[shape.material]
            if shape.is_emitter and not emitter_shades_flat(shape):
                raise self.error(f"shapes[{shape.index}].face_normals",
                                 f"shape {shape.name!r} emits light and its vertex normals lean off its triangles' "
                                 "normals; Mitsuba 3.9.1 turns and samples an area light by them (docs/mitsuba.md, "
                                 "\"Shading normals\"): expected face_normals = true on it")
            if shape.is_emitter and material.type == "mask":
                raise self.error(f"shapes[{shape.index}].material",
                                 f"shape {shape.name!r} emits light and its material {shape.material!r} is a mask: "
                                 "expected an emitter without holes (a light's emission does not pass a mask)")
            textured = material.looks_up_textures
            if not (textured or shape.emission_texture is not None):
                continue
            key = f"shapes[{shape.index}].{'material' if textured else 'emission'}"
            if shape.type == "mesh" and shape.mesh_uv is None:
                raise self.error(key, f"shape {shape.name!r} is textured, but mesh {shape.file.name!r} has no "
                                      "texture coordinates (PLY u, v / s, t / texture_u, texture_v; OBJ vt)")

    # ---- shapes --------------------------------------------------------------------------------------------------

    def shapes(self, document: dict, materials: dict[str, Material]) -> list[Shape]:
        entries = self.array(document.get("shapes", []), "shapes", "an array of tables ([[shapes]])")
        shapes: list[Shape] = []
        seen: dict[str, int] = {}  # each name's first index: a dict, not a scan (thousands of shapes)
        for index, entry in enumerate(entries):
            shape = self.shape(index, entry, materials)
            if shape.name in seen:
                message = f"duplicate shape name {shape.name!r} (also shapes[{seen[shape.name]}])"
                raise self.error(f"shapes[{index}].name", message)
            seen[shape.name] = shape.index
            shapes.append(shape)
        return shapes

    def shape(self, index: int, entry: Any, materials: dict[str, Material]) -> Shape:
        key = f"shapes[{index}]"
        table = self.table(entry, key)
        self.check_keys(table, SHAPE_KEYS, key)
        shape_type = self.choice(self.require(table, "type", key, "a shape type"), f"{key}.type", tuple(SHAPES))
        kind = SHAPES[shape_type]
        for name in ONE_TYPE_KEYS:
            if name in table and name not in kind.keys:
                owners = " or ".join(repr(t) for t, other in SHAPES.items() if name in other.keys)
                message = f"key {name!r} applies only to shapes of type {owners}, not {shape_type!r}"
                raise self.error(f"{key}.{name}", message)
        fields: dict[str, Any] = {
            "index": index,
            "name": self.string(table.get("name", f"shape{index}"), f"{key}.name"),
            "type": shape_type,
            "material": self.material_name(table, key, materials),
            "flip_normals": self.boolean(table.get("flip_normals", False), f"{key}.flip_normals"),
        }
        for side in ("interior", "exterior"):  # Mitsuba's medium transition: the media on its two sides
            if side in table:
                fields[side] = self.medium_name(table[side], f"{key}.{side}")
        fields["to_world"], placement_key = self.placement(table, key)
        if "emission" in table:
            fields.update(self.emission_fields(table["emission"], f"{key}.emission"))
        fields.update(kind.read(self, table, key))
        shape = Shape(**fields)
        self.check_placed_shape(shape, key, placement_key)
        return shape

    def material_name(self, table: dict, key: str, materials: dict[str, Material]) -> str:
        name = self.string(self.require(table, "material", key, "the name of a [materials] table"), f"{key}.material")
        if name not in materials:
            defined = ", ".join(repr(m) for m in materials) or "none"
            hint = suggestion(name, materials)
            raise self.error(f"{key}.material", f"unknown material {name!r}{hint} (defined in [materials]: {defined})")
        return name

    def emission_fields(self, value: Any, key: str) -> dict[str, Any]:
        """A shape's ``emission``: a radiance, or ``{ texture = "NAME" }`` (its values >= 0, not all 0, at most
        MAX_EMISSION), whose mean stands in for its power."""
        texture = texture_reference(self, value, key, self.scene_textures)
        if texture is None:
            return {"emission": self.emission(value, key)}
        top, mean = texture.max_value, texture.mean_value
        if texture.type == "checkerboard" and max(top) > 1:
            raise self.error(key, f"checkerboard {texture.name!r} has colours up to {max(top):.6g}: Mitsuba 3.9.1's "
                                  "checkerboard takes colours in [0, 1] only (a reflectance's), also as a radiance; "
                                  "use a bitmap (an OpenEXR file) for a brighter textured emission")
        if max(top) > MAX_EMISSION or max(mean) <= 0:
            raise self.error(key, f"texture {texture.name!r} has values up to {max(top):.6g} and a mean of "
                                  f"{max(mean):.6g}: expected an emitted radiance at most {MAX_EMISSION:g}, not all 0")
        return {"emission": mean, "emission_texture": texture}

    def emission(self, value: Any, key: str) -> tuple[float, float, float]:
        what = f"a list of 3 finite numbers >= 0, not all 0, each at most {MAX_EMISSION:g}".replace("e+", "e")
        radiance = self.vector3(value, key, what)
        if min(radiance) < 0 or max(radiance) == 0 or max(radiance) > MAX_EMISSION:
            raise self.expected(key, what, value)
        return radiance

    def placement(self, table: dict, key: str) -> tuple[np.ndarray, str]:
        """The shape's to_world matrix and the key path to blame if it is singular."""
        composed = [name for name in ("translate", "rotate", "scale") if name in table]
        if "to_world" in table:
            if composed:
                raise self.error(
                    f"{key}.to_world",
                    f"expected either to_world or translate / rotate / scale, not both (found {', '.join(composed)})",
                )
            return self.matrix4(table["to_world"], f"{key}.to_world"), f"{key}.to_world"
        translation = self.vector3(table.get("translate", [0.0, 0.0, 0.0]), f"{key}.translate")
        rotation = self.rotation(table.get("rotate", []), f"{key}.rotate")
        scale = self.scale(table.get("scale", 1.0), f"{key}.scale")
        with np.errstate(all="ignore"):
            matrix = translate_matrix(translation) @ rotation @ scale_matrix(scale)
        return matrix, f"{key}.scale" if "scale" in table else key

    def rotation(self, value: Any, key: str) -> np.ndarray:
        """R_1 @ R_2 @ ... for an array of rotations (the last listed acts first on points), or one rotation."""
        if isinstance(value, dict):
            return self.one_rotation(value, key)
        if not isinstance(value, list):
            raise self.expected(key, "a table {axis = [x, y, z], angle = degrees} or an array of such tables", value)
        matrix = np.eye(4)
        for index, item in enumerate(value):
            matrix = matrix @ self.one_rotation(item, f"{key}[{index}]")
        return matrix

    def one_rotation(self, value: Any, key: str) -> np.ndarray:
        table = self.table(value, key)
        self.check_keys(table, ROTATE_KEYS, key)
        what = "a list of 3 finite numbers, not all 0"
        axis = self.vector3(self.require(table, "axis", key, what), f"{key}.axis", what)
        with np.errstate(all="ignore"):
            length = float(np.linalg.norm(axis))
        if not (0.0 < length < math.inf):
            raise self.expected(f"{key}.axis", what, table["axis"])
        angle = self.number(self.require(table, "angle", key, "degrees"), f"{key}.angle", "a finite angle in degrees")
        return rotate_matrix(axis, angle)

    def scale(self, value: Any, key: str) -> tuple[float, float, float]:
        what = "a finite number or a list of 3 finite numbers"
        if isinstance(value, list):
            return self.vector3(value, key, what)
        factor = self.number(value, key, what)
        return (factor, factor, factor)

    def mesh(self, table: dict, key: str) -> dict[str, Any]:
        """The mesh file's absolute path and its triangles, read by :func:`harness.scene.mesh_files.read_mesh`
        (trimesh) from the bytes read here (its materials and textures skipped: it opens no file the mesh names)."""
        file_key = f"{key}.file"
        name = self.string(self.require(table, "file", key, "a PLY or OBJ file name"), file_key)
        if not name.lower().endswith(MESH_SUFFIXES):
            raise self.expected(file_key, "a .ply or .obj file name", name)
        path = self.file_path(name, file_key, "mesh")
        if path not in self.parsed_meshes:
            self.parsed_meshes[path] = self.parse_mesh(path, name, file_key)
        vertices, triangles, uv, normals, file_type, normals_usable = self.parsed_meshes[path]
        flip = self.boolean(table.get("flip_tex_coords", file_type == "obj"), f"{key}.flip_tex_coords")
        face_normals = self.boolean(table.get("face_normals", False), f"{key}.face_normals")
        if normals is not None and not face_normals and not normals_usable:
            raise self.error(file_key, f"mesh {name!r} has a vertex normal that is zero or not finite "
                                       "(or set face_normals = true to shade it flat)")
        if uv is not None and flip:
            uv = uv.copy()
            uv[:, 1] = 1.0 - uv[:, 1]
            uv.setflags(write=False)
        return {"file": path, "mesh_vertices": vertices, "mesh_triangles": triangles, "mesh_uv": uv,
                "flip_tex_coords": flip, "face_normals": face_normals,
                "mesh_normals": None if face_normals else normals}

    def parse_mesh(self, path: Path, name: str, file_key: str) -> tuple:
        """A mesh file's vertices, triangles, texture coordinates (as in the file, or None), vertex normals (or
        None), type (``ply`` or ``obj``) and whether its normals are all finite and non-zero (checked once per file,
        for the shapes that shade with them), checked; the arrays read-only, since every shape naming the file
        shares them."""
        size = path.stat().st_size
        if size > MAX_MESH_BYTES:
            raise self.error(file_key, f"mesh file {name!r} is {size / 2**20:.0f} MiB; expected at most "
                                       f"{MAX_MESH_BYTES / 2**30:g} GiB")
        where = self.where(file_key)
        data = read_user_bytes(path, missing="no such mesh file", where=where, limit=MAX_MESH_BYTES)
        file_type = name.lower().rsplit(".", 1)[-1]  # the name's suffix: a symlink's target may have another
        if file_type == "obj":
            problem = obj_face_problem(data)
            if problem:
                raise self.error(file_key, f"mesh {name!r}: {problem}")
        resolver = ConfinedResolver(self.folder, path.parent, where, allow_outside=self.allow_outside,
                                    opened=self.opened)
        try:
            vertices, triangles, normals, uv, _ = read_mesh(data, file_type, resolver)
        except ValueError as err:
            raise self.error(file_key, f"cannot read the mesh file {name!r}: {err}") from None
        if len(triangles) == 0:
            raise self.error(file_key, f"expected a mesh with at least one triangle, got none in {name!r}")
        if triangles.min() < 0 or triangles.max() >= len(vertices):
            raise self.error(file_key, f"mesh {name!r} has a triangle with a vertex index out of range")
        if not np.all(np.isfinite(vertices)):
            raise self.error(file_key, f"mesh {name!r} has non-finite vertex coordinates")
        if uv is not None and not np.all(np.isfinite(uv)):
            raise self.error(file_key, f"mesh {name!r} has non-finite texture coordinates")
        for array in (vertices, triangles, uv, normals):
            if array is not None:
                array.setflags(write=False)
        usable = normals is None or bool(np.all(np.isfinite(normals)) and np.all(np.linalg.norm(normals, axis=1) > 0))
        return vertices, triangles, uv, normals, file_type, usable

    def file_path(self, name: str, key: str, what: str) -> Path:
        """The absolute, symlink-resolved path of a file the scene names (relative to its folder), which must exist,
        be a regular file and, unless ``allow_outside``, lie inside the scene file's folder. Every file a scene names
        goes through here (and is recorded, :meth:`opened`), and every file such a file names through the same
        :func:`harness.scene.mesh_files.confined_path`."""
        return self.opened(confined_path(self.folder, name, what, self.where(key),
                                         allow_outside=self.allow_outside))

    def check_placed_shape(self, shape: Shape, key: str, placement_key: str) -> None:
        """Refuse singular or overflowing placements, non-uniformly scaled spheres and zero-area lights."""
        with np.errstate(all="ignore"):
            linear = object_to_world(shape)[:3, :3]
            determinant = float(np.linalg.det(linear)) if np.all(np.isfinite(linear)) else math.nan
        if not math.isfinite(determinant):
            raise self.error(placement_key, "the placement overflows (non-finite matrix entries)")
        if determinant == 0:
            light = "; a light needs positive area" if shape.is_emitter else ""
            message = f"expected an invertible placement, got a singular matrix (a zero scale){light}"
            raise self.error(placement_key, message)
        if SHAPES[shape.type].similarity_only and not is_similarity(shape.to_world[:3, :3]):
            raise self.error(
                placement_key,
                "expected a placement without non-uniform scale or shear for a sphere (Mitsuba's sphere allows "
                "only rotation, uniform scale and translation)",
            )
        vertices, triangles = shape_triangles(shape)
        if not np.all(np.isfinite(vertices)):
            raise self.error(placement_key, "the placed shape overflows (non-finite world coordinates)")
        if shape.is_emitter:
            area = float(np.sum(triangle_areas(vertices, triangles)))
            if area == math.inf or math.isnan(area):
                raise self.error(placement_key, f"the area of light {shape.name!r} overflows")
            if area <= 0:
                raise self.error(key, f"zero-area light {shape.name!r}: all of its triangles are degenerate")


    # ---- emitters that are not shapes ----------------------------------------------------------------------------

    def emitters(self, document: dict) -> tuple[Emitter, ...]:
        return read_emitters(self, document)

    def envmap_image(self, name: str, key: str) -> tuple[Path, np.ndarray]:
        """The path and pixels of the environment map ``name`` (at ``key``), after its header's size and cost
        (:func:`harness.core.limits.envmap_problem`, :data:`MAX_ENVMAP_PIXELS`)."""
        path = self.file_path(name, key, "envmap")
        try:
            problem = envmap_problem(*exr_size(path, max_pixels=MAX_ENVMAP_PIXELS))  # on the header alone
            image = None if problem else read_exr(path, max_pixels=MAX_ENVMAP_PIXELS).image
        except HarnessError as err:
            raise self.error(key, f"envmap file {name!r}: {err.message}") from None
        if problem:
            raise self.error(key, f"envmap file {name!r}: {problem}")
        return path, image


def obj_face_problem(data: bytes) -> str | None:
    """Why the faces of an OBJ file's text are wrong, or None. OBJ indices are 1-based (negative: relative to the
    last one so far); trimesh turns an index 0 (``f 0 1 2``, ``f 1/0 2 3``) into some other vertex and goes on, so
    every index is checked here: an integer, not 0, naming a vertex (texture coordinate, normal) that exists."""
    kinds = (b"v", b"vt", b"vn")
    lines = data.splitlines()
    totals = dict.fromkeys(kinds, 0)
    for line in lines:
        head = line.split(None, 1)[:1]
        if head and head[0] in totals:
            totals[head[0]] += 1
    so_far = dict.fromkeys(kinds, 0)
    for number, line in enumerate(lines, 1):
        fields = line.split()
        if not fields:
            continue
        if fields[0] in so_far:
            so_far[fields[0]] += 1
        if fields[0] != b"f":
            continue
        for token in fields[1:]:
            if token.startswith(b"#"):
                break
            problem = _obj_index_problem(token, totals, so_far)
            if problem:
                return f"line {number}: {problem}"
    return None


def _obj_index_problem(token: bytes, totals: dict, so_far: dict) -> str | None:
    """Why one face vertex (``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn``) of an OBJ file is wrong, or None."""
    shown = show_value(token.decode("utf-8", "replace"))
    parts = token.split(b"/")
    if len(parts) > 3 or not parts[0]:
        return f"expected a face vertex v, v/vt, v//vn or v/vt/vn, got {shown}"
    for kind, part in zip((b"v", b"vt", b"vn"), parts):
        if not part:
            continue
        if not _OBJ_INDEX.fullmatch(part):
            return f"expected integer indices in a face, got {shown}"
        index = int(part)
        if index == 0:
            return f"index 0 in the face vertex {shown}; OBJ indices start at 1"
        total = totals[kind] if index > 0 else so_far[kind]
        if abs(index) > total:
            where = " before it" if index < 0 else ""
            return (f"the face vertex {shown} names {kind.decode()} {index}, but the file has {total} "
                    f"{kind.decode()} lines{where}")
    return None

