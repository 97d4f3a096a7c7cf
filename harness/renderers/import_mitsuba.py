"""A Mitsuba 3 XML scene read into this project's scene format (``harness import FILE --out DIR``; docs/import.md).

Mitsuba's own parser reads the file (pinned Mitsuba 3.9.1, ``mi.parser.parse_file`` in ``scalar_rgb``): it follows
``include`` elements, resolves ``default`` parameters and references, and gives every plugin with its properties
(floats as float64) and its place in its file. Each plugin this project can express becomes its table of the TOML
scene format (docs/scene-format.md), whose keys are Mitsuba's names with Mitsuba's meanings, so a value is copied,
never converted: floats are written with ``repr`` and read back as the same float64.

What maps to what:

* ``path`` integrator -> ``[integrator] max_depth`` (``rr_depth`` only changes the noise);
* ``perspective`` / ``thinlens`` / ``orthographic`` sensor -> ``[camera]`` (its ``<lookat>`` read from the XML
  element itself, as written; an orthographic ``<scale>`` before it -> ``scale``), its ``hdrfilm`` and ``rfilter``
  -> ``[film]``;
* a BSDF -> ``[materials.NAME]`` (NAME: its ``id``, or its parent's name and key for a nested one that is no copy
  of a named one); ``twosided`` around one BSDF that takes ``two_sided`` -> that BSDF with ``two_sided = true``;
* a ``bitmap`` / ``checkerboard`` texture -> ``[textures.NAME]``, a bitmap's file copied into ``textures/``;
* ``rectangle`` / ``cube`` / ``sphere`` -> the same shape with its ``to_world``; ``ply`` -> a ``mesh`` naming a
  copy of the file; ``obj`` / ``serialized`` -> a ``mesh`` naming a binary PLY of the mesh Mitsuba reads (object
  space, its ``to_world`` kept); a ``shapegroup``'s shapes placed by each ``instance`` -> shapes of their own (the
  instance's ``to_world`` times the shape's); an ``area`` emitter -> the shape's ``emission``;
* ``point`` / ``spot`` / ``directional`` / ``constant`` / ``envmap`` -> ``[[emitters]]`` (an envmap's file copied);
* ``volpath`` integrator -> ``[integrator] max_depth`` as ``path`` (the scene format picks volpath by its media);
* a ``homogeneous`` medium (its ``isotropic`` / ``hg`` phase) -> ``[media.NAME]`` (NAME: its ``id``, or its
  parent's name and key), a shape's ``interior`` / ``exterior`` and the sensor's ``medium`` -> the same keys naming
  it; the ``null`` BSDF -> a ``null`` material; ``heterogeneous`` is refused (not supported yet).

Anything else (another plugin type, a property the scene format does not have, a spectrum where RGB is expected, a
film crop, an include outside the scene's folder, ...) raises one :class:`HarnessError` naming the element and its
place, ``FILE:LINE:COL`` (Mitsuba's byte offset as a line and a column); with ``lenient`` it is dropped instead and
listed (:attr:`ImportedScene.dropped`, and the scene's description).
"""

from __future__ import annotations

import contextlib
import json
import math
import re
import xml.parsers.expat
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness.core.errors import HarnessError, not_regular
from harness.renderers.imports import ImportedScene, toml_key, toml_value
from harness.renderers.meshfiles import MESH_DIR, TEXTURE_DIR, ply_bytes, safe_name
from harness.scene.kinds.composites import COMPOSITES
from harness.scene.kinds.materials import MATERIALS, ONE_NUMBER_RANGES
from harness.scene.kinds.perturbations import PERTURBATIONS
from harness.scene.mesh_files import confined_path

MITSUBA_VERSION = "3.9.1"
VARIANT = "scalar_rgb"

#: sensor plugin -> its properties kept (besides to_world, the sampler and the film)
SENSOR_KEYS = {"perspective": ("fov", "fov_axis"), "thinlens": ("fov", "fov_axis", "aperture_radius", "focus_distance"),
               "orthographic": ()}
#: properties read and not kept: the harness picks its clip planes from the scene's extent (docs/import.md); a
#: ``focus_distance`` is kept only on a thin lens (without a lens it changes nothing)
SENSOR_IGNORED = ("near_clip", "far_clip")
FILM_IGNORED = ("pixel_format", "component_format", "file_format", "sample_border")
FILTERS = {"box": {}, "tent": {"radius": 1.0}, "gaussian": {"stddev": 0.5}}
#: emitter plugin (not area) -> its properties, each the scene key of the same name
EMITTER_KEYS = {
    "point": ("position", "intensity", "to_world"),
    "spot": ("to_world", "intensity", "cutoff_angle", "beam_width"),
    "directional": ("direction", "irradiance", "to_world"),
    "constant": ("radiance",),
    "envmap": ("filename", "scale", "to_world"),
}
ANALYTIC = ("rectangle", "cube", "sphere")
SHAPE_COMMON = ("to_world", "flip_normals")
SHAPE_KEYS = {"rectangle": SHAPE_COMMON, "cube": SHAPE_COMMON, "sphere": SHAPE_COMMON + ("center", "radius"),
              "ply": SHAPE_COMMON + ("filename", "face_normals", "flip_tex_coords"),
              "obj": SHAPE_COMMON + ("filename", "face_normals", "flip_tex_coords"),
              "serialized": SHAPE_COMMON + ("filename", "face_normals", "shape_index")}
TEXTURE_KEYS = {"bitmap": ("filename", "filter_type", "wrap_mode", "raw", "to_uv"),
                "checkerboard": ("color0", "color1", "to_uv")}
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".exr")
#: scene keys that take a colour only (a Mitsuba float there is the grey of that value)
COLOUR_ONLY = ("reflectance", "intensity", "irradiance", "radiance")
BSDF_REFS = ("bsdf", "bsdf_0", "bsdf_1")
#: the integrators whose ``max_depth`` the scene format keeps (``volpath``: a scene with media or a null material)
INTEGRATORS = ("path", "volpath")
#: a ``homogeneous`` medium's properties the scene format has (``sample_emitters`` changes the noise only)
MEDIUM_KEYS = ("albedo", "sigma_t", "scale")
MEDIUM_IGNORED = ("sample_emitters",)
#: phase plugin -> its properties
PHASE_KEYS = {"isotropic": (), "hg": ("g",)}
#: Mitsuba 3.9.1's defaults of the properties the scene format requires, written out where the XML leaves them
MITSUBA_DEFAULTS = {
    "diffuse": {"reflectance": [0.5, 0.5, 0.5]},
    "point": {"intensity": [1.0, 1.0, 1.0], "position": [0.0, 0.0, 0.0]},
    "spot": {"intensity": [1.0, 1.0, 1.0], "to_world": np.eye(4).tolist()},
    "directional": {"irradiance": [1.0, 1.0, 1.0], "direction": [0.0, 0.0, 1.0]},
    "constant": {"radiance": [1.0, 1.0, 1.0]},
}


class _Dropped(Exception):
    """An element left out by ``lenient``: its enclosing top-level element goes too."""


class _SkipProperty(_Dropped):
    """A property left out by ``lenient``: its element stays (caught where the element reads its properties)."""



@dataclass
class _XmlFacts:
    """What Mitsuba's parser does not keep, read from the XML itself: each sensor's ``<lookat>`` (and a
    ``<scale>`` before it) by the sensor's byte offset, and every ``include`` with its offset."""

    lookats: dict[int, tuple[dict, dict | None]] = field(default_factory=dict)
    includes: list[tuple[str, int]] = field(default_factory=list)


def import_mitsuba(path: Path, *, lenient: bool = False) -> ImportedScene:
    """Read the Mitsuba 3 XML file ``path`` into the scene format.

    Parameters
    ----------
    path : Path
        The scene's XML file; files it names (meshes, images, includes) must lie in its folder.
    lenient : bool
        Drop what cannot be expressed (listed in ``dropped``) instead of refusing the file.

    Returns
    -------
    ImportedScene
        The TOML text and the files it names.
    """
    return _Importer(Path(path), lenient).run()


def line_column(data: bytes, offset: int) -> tuple[int, int]:
    """The 1-based line and column of byte ``offset`` of ``data`` (Mitsuba's ``file_location``)."""
    before = data[:offset]
    return before.count(b"\n") + 1, offset - (before.rfind(b"\n") + 1) + 1


def _read_xml_facts(data: bytes) -> _XmlFacts:
    """The lookats inside each ``sensor`` and the ``include`` elements, by byte offset (Mitsuba's offsets point at a
    tag's name, one byte after its ``<``)."""
    facts = _XmlFacts()
    parser = xml.parsers.expat.ParserCreate()
    stack: list[tuple[str, int, dict]] = []
    pending: dict[int, list] = {}

    def start(tag, attrs):
        offset = parser.CurrentByteIndex + 1
        stack.append((tag, offset, attrs))
        if tag == "include":
            facts.includes.append((attrs.get("filename", ""), offset))
        if tag == "sensor":
            pending[offset] = []
        if len(stack) >= 3 and stack[-2][0] == "transform" and stack[-3][0] == "sensor" \
                and stack[-2][2].get("name") == "to_world":
            pending[stack[-3][1]].append((tag, attrs))

    def end(tag):
        _, offset, _ = stack.pop()
        if tag == "sensor":
            ops = pending.pop(offset)
            names = [op[0] for op in ops]
            if names == ["lookat"]:
                facts.lookats[offset] = (ops[0][1], None)
            elif names == ["scale", "lookat"]:
                facts.lookats[offset] = (ops[1][1], ops[0][1])

    parser.StartElementHandler, parser.EndElementHandler = start, end
    try:
        parser.Parse(data, True)
    except xml.parsers.expat.ExpatError:
        pass  # Mitsuba's parser has accepted the file; what expat cannot read has no lookat to keep
    return facts


def _numbers_text(text: str) -> list[float]:
    """``"1, 2, 3"`` or ``"1 2 3"`` as floats (Mitsuba's way of writing a vector attribute)."""
    return [float(x) for x in text.replace(",", " ").split()]


class _Importer:
    """One file's import: the parser's state, the tables built so far, the files to write and what was dropped."""

    def __init__(self, path: Path, lenient: bool):
        self.path, self.lenient = path, lenient
        self.folder = path.resolve().parent
        self.dropped: list[str] = []
        self.files: dict[str, bytes] = {}
        self.materials: dict[str, dict] = {}   # name -> table, in order
        self.nested_names: set[str] = set()          # materials made for a nested plugin (deduplicated at the end)
        self.material_of_node: dict[int, str] = {}
        self.failed: set[int] = set()
        self.textures: dict[str, dict] = {}
        self.texture_of_content: dict[str, str] = {}
        self.shapes: list[dict] = []
        self.emitters: list[dict] = []
        self.camera: dict | None = None
        self.film: dict | None = None
        self.media: dict[str, dict] = {}  # name -> [media.NAME] table, in order
        self.medium_of_node: dict[int, str] = {}
        self.max_depth: int | None = None
        self.raw: dict[int, bytes] = {}
        self.facts: dict[int, _XmlFacts] = {}

    # ---- places and refusals ---------------------------------------------------------------------------------------

    def where(self, node) -> str:
        """``FILE:LINE:COL`` of a node."""
        data = self.raw[node.file_index]
        line, col = line_column(data, node.offset)
        return f"{self.state.files[node.file_index]}:{line}:{col}"

    def refuse(self, where: str, element: str, expected: str) -> None:
        """Refuse (a HarnessError) or, lenient, note the element as dropped and raise :class:`_Dropped`."""
        if not self.lenient:
            raise HarnessError(f"{where}: {element}", expected)
        self.dropped.append(f"{where}: {element}: {expected}")
        raise _Dropped()

    def note(self, where: str, element: str, expected: str) -> None:
        """Refuse, or (lenient) list what is left as it is and go on: a difference that keeps the element."""
        if not self.lenient:
            raise HarnessError(f"{where}: {element}", expected)
        self.dropped.append(f"{where}: {element}: {expected}")

    def element(self, node) -> str:
        props = node.props
        label = f" id={props.id()!r}" if props.id() else ""
        return f"<{self.tag(node)} type={props.plugin_name()!r}{label}>"

    @staticmethod
    def tag(node) -> str:
        name = node.type.name
        return {"Integrator": "integrator", "Sensor": "sensor", "Film": "film", "Sampler": "sampler",
                "ReconstructionFilter": "rfilter", "BSDF": "bsdf", "Emitter": "emitter", "Shape": "shape",
                "Texture": "texture", "Scene": "scene", "Medium": "medium",
                "PhaseFunction": "phase"}.get(name, name.lower())

    def refuse_node(self, node, expected: str) -> None:
        self.refuse(self.where(node), self.element(node), expected)

    def refuse_property(self, node, key: str, expected: str) -> None:
        """Refuse a property; lenient, list it and leave it out (:class:`_SkipProperty`)."""
        where, element = self.where(node), f"{self.element(node)} property {key!r}"
        if not self.lenient:
            raise HarnessError(f"{where}: {element}", expected)
        self.dropped.append(f"{where}: {element}: {expected}")
        raise _SkipProperty()

    # ---- the parse -------------------------------------------------------------------------------------------------

    def run(self) -> ImportedScene:
        import mitsuba as mi  # optional: Mitsuba takes seconds to import and only an import of its XML needs it
        self.mi = mi
        if mi.__version__ != MITSUBA_VERSION:
            raise HarnessError("mitsuba", f"expected Mitsuba {MITSUBA_VERSION} (the version this importer is pinned "
                                          f"to), found {mi.__version__}")
        irregular = not_regular(self.path)  # a named pipe would block Mitsuba's parser
        if irregular is not None:
            raise irregular
        if not self.path.is_file():
            raise HarnessError(str(self.path), "expected a Mitsuba 3 XML file: no such file")
        self.check_includes(self.path, set())
        previous = mi.variant()
        mi.set_variant(VARIANT)
        try:
            return self.read(mi)
        finally:
            if previous is not None and previous != VARIANT:  # the process's Mitsuba renders keep their variant
                mi.set_variant(previous)

    def read(self, mi) -> ImportedScene:
        """Parse, check the files read, walk the plugins; the scene's text."""
        try:
            self.state = mi.parser.parse_file(mi.parser.ParserConfig(VARIANT), str(self.path))
        except Exception as err:  # Mitsuba's own one-line reason (a syntax error, an unknown reference, ...)
            raise HarnessError(str(self.path), _first_line(str(err))) from None
        for index, name in enumerate(self.state.files):  # however Mitsuba found them
            path = confined_path(self.folder, str(Path(str(name)).resolve()), "include",  # as Mitsuba named it
                                 f"{self.path}: <include filename={str(name)!r}>",
                                 outside_hint="an include outside it is not followed")
            self.raw[index] = path.read_bytes()
            self.facts[index] = _read_xml_facts(self.raw[index])
        self.walk_scene()
        return ImportedScene(self.toml(), self.files, list(self.dropped), self.path)

    def check_includes(self, path: Path, seen: set) -> None:
        """Every ``include`` (followed through the files it names) must name a file inside the scene's folder.

        A name is relative to the scene's folder, in an included file too: Mitsuba resolves an include through its
        file resolver, whose first folder is the scene's (the including file's folder is not searched; mitsuba-data's
        participating_media/include/test-scene-base.xml includes ``include/preamble.xml`` so)."""
        if path in seen:
            return
        seen.add(path)
        data = path.read_bytes()
        for name, offset in _read_xml_facts(data).includes:
            line, col = line_column(data, offset)
            # before Mitsuba's parser opens it: outside the folder, missing, or a named pipe (which would block it)
            target = confined_path(self.folder, name, "include", f"{path}:{line}:{col}: <include filename={name!r}>",
                                   outside_hint="an include outside it is not followed")
            self.check_includes(target, seen)

    def child(self, props, key):
        return self.state.nodes[props[key].index()]

    def walk_scene(self) -> None:
        root = self.state.nodes[0]
        for key in root.props.keys():
            node = self.child(root.props, key)
            try:
                self.top_level(node)
            except _Dropped:
                pass

    def top_level(self, node) -> None:
        kind = self.tag(node)
        name = node.props.plugin_name()
        if kind in ("integrator", "sensor") and getattr(self, f"seen_{kind}", False):
            self.refuse_node(node, f"expected one {kind} (the scene format has one {kind}), got a second")
        if kind == "integrator":
            self.seen_integrator = True
            self.integrator(node)
        elif kind == "sensor":
            self.seen_sensor = True
            self.sensor(node)
        elif kind == "bsdf":
            name = self.material(node, node.props.id() or f"bsdf{len(self.materials)}", top=True)
            self.nested_names.discard(name)  # a shape before it may have named it first
        elif kind == "texture":
            pass  # read where a material names it
        elif kind == "medium":
            self.medium(node, node.props.id() or f"medium{len(self.media)}")
        elif kind == "sampler":
            pass  # a sampler by id (a sensor's <ref>): the sample count and seed are a render's, not the scene's
        elif kind == "shape" and name == "shapegroup":
            pass  # placed by its instances
        elif kind == "shape" and name == "instance":
            self.instance(node)
        elif kind == "shape":
            self.shapes.append(self.shape(node, None))
        elif kind == "emitter" and name == "area" and self.named_by_a_shape(node):
            pass  # an area emitter by id, read where a shape's <ref> names it (mitsuba-data's cbox)
        elif kind == "emitter":
            self.emitters.append(self.emitter(node))
        else:
            self.refuse_node(node, "expected an integrator, a sensor, a sampler, a bsdf, a texture, a medium, a "
                                   "shape or an emitter")

    def named_by_a_shape(self, node) -> bool:
        """Whether some shape of the file names ``node`` (a top-level plugin with an id) through a ``<ref>``."""
        ident = node.props.id()
        for other in self.state.nodes:
            if ident and self.tag(other) == "shape":
                for key in other.props.keys():
                    if self.is_nested(other, key) and self.nested(other, key) is node:
                        return True
        return False

    # ---- values ----------------------------------------------------------------------------------------------------

    def value(self, node, key: str, colour: bool = False):
        """A plain property's value in the scene format: bool, int, float (repr round trip), string, a colour or a
        vector as a list, a transform as a 4x4 list of rows."""
        props, types = node.props, self.mi.Properties.Type
        kind = props.type(key)
        if kind == types.Bool:
            return bool(props[key])
        if kind == types.Integer:
            return int(props[key])
        if kind == types.Float:
            number = float(props[key])
            if not math.isfinite(number):
                self.refuse_property(node, key, f"expected a finite number, got {number!r}")
            return [number] * 3 if colour else number
        if kind == types.String:
            return str(props[key])
        if kind in (types.Color, types.Vector):
            return [float(x) for x in props[key]]
        if kind == types.Transform:
            return np.array(props[key].matrix, dtype=np.float64).tolist()
        self.refuse_property(node, key, "expected a number, an rgb colour, a vector, a boolean or a string "
                                        "(a spectrum is not taken: the scene format is RGB)")

    def plain_keys(self, node, allowed, what: str) -> dict:
        """``{key: value}`` of the node's plain properties, each of ``allowed``; nested plugins are left out."""
        out = {}
        for key in node.props.keys():
            with contextlib.suppress(_SkipProperty):  # lenient: this property left out
                if self.is_nested(node, key):
                    continue
                if key not in allowed:
                    self.refuse_property(node, key, f"expected one of the {what} properties the scene format has: "
                                                    f"{', '.join(allowed) or 'none'}")
                out[key] = self.value(node, key, colour=key in COLOUR_ONLY)
        return out

    def is_nested(self, node, key: str) -> bool:
        types = self.mi.Properties.Type
        return node.props.type(key) in (types.ResolvedReference, types.Reference)

    def nested(self, node, key: str):
        """The node a nested plugin or a ``<ref>`` names."""
        props, types = node.props, self.mi.Properties.Type
        if props.type(key) == types.Reference:
            ident = props[key].id()
            return self.state.nodes[self.state.id_to_index[ident]]
        return self.child(props, key)

    # ---- integrator, sensor, film ----------------------------------------------------------------------------------

    def integrator(self, node) -> None:
        if node.props.plugin_name() not in INTEGRATORS:
            self.refuse_node(node, "expected Mitsuba's path integrator, or volpath (the ones the reference is judged "
                                   "against)")
        values = self.plain_keys(node, ("max_depth", "rr_depth", "hide_emitters"),
                                 f"{node.props.plugin_name()} integrator")
        if values.get("hide_emitters"):
            self.refuse_property(node, "hide_emitters", "expected false: the scene format has no hidden emitters")
        self.max_depth = values.get("max_depth", -1)

    def sensor(self, node) -> None:
        name = node.props.plugin_name()
        if name not in SENSOR_KEYS:
            self.refuse_node(node, f"expected a sensor of type {', '.join(SENSOR_KEYS)}")
        camera: dict = {"type": name}
        for key in node.props.keys():
            with contextlib.suppress(_SkipProperty):  # lenient: this property left out
                if self.is_nested(node, key) and self.tag(self.nested(node, key)) == "medium":
                    camera["medium"] = self.medium(self.nested(node, key), f"{name}-{key}")
                elif self.is_nested(node, key):
                    self.sensor_part(self.nested(node, key))
                elif key == "to_world":
                    camera.update(self.look_at(node))
                elif key in SENSOR_KEYS[name]:
                    camera[key] = self.value(node, key)
                elif key not in SENSOR_IGNORED and not (key == "focus_distance" and name != "thinlens"):
                    self.refuse_property(node, key, f"expected one of the {name} properties the scene format has: "
                                                    f"{', '.join(SENSOR_KEYS[name] + ('to_world',) + SENSOR_IGNORED)}")
        if name != "orthographic" and "fov" not in camera:
            self.refuse_node(node, "expected fov (without it Mitsuba takes a 50 mm focal_length along the image's "
                                   "diagonal, an axis the scene format has not)")
        if "origin" not in camera:
            self.refuse_node(node, "expected a to_world transform with a <lookat> (the scene's camera is a look-at)")
        if name == "thinlens" and "aperture_radius" not in camera:
            self.refuse_node(node, "expected aperture_radius (Mitsuba's default 0 is no lens: use perspective)")
        self.camera = camera

    def look_at(self, node) -> dict:
        """origin, target, up (and an orthographic ``scale``) of the sensor's ``<lookat>``, as written in the XML,
        checked against the matrix Mitsuba made of them; another transform is refused."""
        found = self.facts[node.file_index].lookats.get(node.offset)
        if found is None:
            self.refuse_placement(node, "expected a <lookat> (after a <scale> for an orthographic "
                                      "sensor) and nothing else: the scene's camera is a look-at")
        look, scale = found
        try:
            out = {key: _numbers_text(look[key]) for key in ("origin", "target", "up")}
            if scale is not None:
                values = (_numbers_text(scale["value"]) if "value" in scale
                          else [float(scale.get(axis, 1.0)) for axis in "xyz"])
                out["scale"] = values * 3 if len(values) == 1 else values
        except (KeyError, ValueError):
            out = {}
        if scale is not None and node.props.plugin_name() != "orthographic":
            self.refuse_placement(node, "expected a <lookat> alone: only an orthographic sensor takes "
                                      "a <scale>")
        if not out or not self.same_look_at(node, out):
            self.refuse_placement(node, "expected a <lookat> with origin, target and up written as "
                                      "numbers (as the scene's camera takes them)")
        return out

    def refuse_placement(self, node, expected: str) -> None:
        """A sensor's ``to_world`` refused, even with ``lenient``: the scene needs its camera, and leaving the
        placement out left none, so the line said "expected a sensor with a film" instead of why (mitsuba-data's
        veach_mis.xml: ``<scale x="-1"/>`` twice before its ``<lookat>``)."""
        raise HarnessError(f"{self.where(node)}: {self.element(node)} property 'to_world'", expected)

    def same_look_at(self, node, camera: dict) -> bool:
        """Whether Mitsuba's matrix of the sensor is the look-at (times the scale) read from the XML, exactly."""
        mi = self.mi
        if any(len(camera[key]) != 3 for key in ("origin", "target", "up")) or len(camera.get("scale", [1] * 3)) != 3:
            return False
        transform = mi.ScalarTransform4d.look_at(origin=camera["origin"], target=camera["target"], up=camera["up"])
        if "scale" in camera:
            transform = transform @ mi.ScalarTransform4d.scale(camera["scale"])
        return np.array_equal(np.array(transform.matrix), np.array(node.props["to_world"].matrix))

    def sensor_part(self, node) -> None:
        kind = self.tag(node)
        if kind == "sampler":
            return  # the sample count and seed are a render's, not the scene's
        if kind != "film" or node.props.plugin_name() != "hdrfilm":
            self.refuse_node(node, "expected an hdrfilm film and a sampler in the sensor")
        film: dict = {"filter": "gaussian"}  # Mitsuba's default filter
        for key in node.props.keys():
            with contextlib.suppress(_SkipProperty):  # lenient: this property left out
                if self.is_nested(node, key):
                    film["filter"] = self.rfilter(self.nested(node, key))
                elif key in ("width", "height"):
                    film[key] = self.value(node, key)
                elif key not in FILM_IGNORED:
                    self.refuse_property(node, key, "expected width, height, an rfilter (and the output's "
                                                    f"{', '.join(FILM_IGNORED)}): the scene's film has no crop")
        film.setdefault("width", 768)
        film.setdefault("height", 576)  # Mitsuba's defaults
        border = bool(node.props["sample_border"]) if "sample_border" in node.props.keys() else False
        if border != (film["filter"] != "box"):  # lenient: the film kept, its border pixels the reference's
            self.note(self.where(node), f"{self.element(node)} property 'sample_border'",
                      f"expected {str(not border).lower()} with the {film['filter']} filter: the reference's border "
                      f"pixels take samples from outside the image exactly when the filter reaches beyond its pixel")
        self.film = film

    def rfilter(self, node) -> str:
        name = node.props.plugin_name()
        if name not in FILTERS:
            self.refuse_node(node, f"expected an rfilter of type {', '.join(FILTERS)}")
        for key in node.props.keys():
            with contextlib.suppress(_SkipProperty):  # lenient: this property left out
                if key not in FILTERS[name] or self.value(node, key) != FILTERS[name][key]:
                    self.refuse_property(node, key, f"expected Mitsuba's default {name} filter "
                                                    f"{FILTERS[name] or ''} (the scene format's)")
        return name

    # ---- materials -------------------------------------------------------------------------------------------------

    def material(self, node, name: str, top: bool = False) -> str:
        """The material of a BSDF node: its table under ``name`` (a node read before keeps its name)."""
        index = self.node_index(node)
        if index in self.material_of_node:
            return self.material_of_node[index]
        if index in self.failed:
            raise _Dropped()  # listed once, where it was dropped
        try:
            return self._material(node, name, index, top)
        except _Dropped:
            self.failed.add(index)
            raise

    def _material(self, node, name: str, index: int, top: bool) -> str:
        kind = node.props.plugin_name()
        if self.tag(node) != "bsdf":
            self.refuse_node(node, "expected a bsdf")
        if kind in MATERIALS:
            table = self.leaf(node, kind)
        elif kind == "twosided":
            table = self.twosided(node, name)
        elif kind in COMPOSITES:
            table = self.composite(node, kind, name)
        elif kind in PERTURBATIONS:
            table = self.perturbation(node, kind, name)
        else:
            self.refuse_node(node, "expected a bsdf of type "
                                   f"{', '.join(list(MATERIALS) + list(COMPOSITES) + list(PERTURBATIONS))}")
        name = self.unique(name, self.materials)
        self.materials[name] = table
        if not top:
            self.nested_names.add(name)
        self.material_of_node[index] = name
        return name

    def node_index(self, node) -> int:
        """The node's index in the parser's list (nodes compare by identity of place: file and offset)."""
        key = (node.file_index, node.offset)
        if not hasattr(self, "_index_of"):
            self._index_of = {(n.file_index, n.offset): i for i, n in enumerate(self.state.nodes)}
        return self._index_of[key]

    @staticmethod
    def unique(name: str, taken: dict) -> str:
        name = name or "unnamed"
        if name not in taken:
            return name
        n = 2
        while f"{name}-{n}" in taken:
            n += 1
        return f"{name}-{n}"

    def leaf(self, node, kind: str) -> dict:
        allowed = [k for k in MATERIALS[kind].keys if k not in ("type", "two_sided")]
        table: dict = {"type": kind}
        for key in node.props.keys():
            with contextlib.suppress(_SkipProperty):  # lenient: this property left out
                if key not in allowed:
                    self.refuse_property(node, key, f"expected one of the {kind} properties the scene format has: "
                                                    f"{', '.join(allowed)}")
                if self.is_nested(node, key):
                    if key not in MATERIALS[kind].textured:
                        self.refuse_property(node, key, f"expected a value: {kind}'s textured properties are "
                                                        f"{', '.join(MATERIALS[kind].textured) or 'none'}")
                    texture = self.nested(node, key)
                    if key in ONE_NUMBER_RANGES and texture.props.plugin_name() != "bitmap":
                        # the format's loader refuses it (Mitsuba's checkerboard as one number swaps its colours);
                        # the import wrote it and failed even leniently (bsdf_roughconductor_textured_carbon.xml)
                        self.refuse_property(node, key, f"a {texture.props.plugin_name()} texture: {key} takes a "
                                                        "bitmap (Mitsuba 3.9.1's checkerboard as one number swaps "
                                                        "its two colours)")
                    table[key] = {"texture": self.texture(texture)}
                else:
                    value = self.value(node, key, colour=key in COLOUR_ONLY)
                    if isinstance(value, str) and (key in ("int_ior", "ext_ior") or
                                                   (key == "material" and value != "none")):
                        # mitsuba-data's docs scenes ("bk7", "Au"): the import wrote the name, which the format's
                        # loader then refused, so lenient could not leave it out
                        self.refuse_property(node, key, f"a named {'conductor' if key == 'material' else 'index'} "
                                                        f"{value!r}: Mitsuba's tables are not imported; the scene "
                                                        "format takes numbers (eta and k, int_ior, ext_ior)")
                    table[key] = value
        return {**table, **{k: v for k, v in MITSUBA_DEFAULTS.get(kind, {}).items() if k not in table}}

    def nested_bsdfs(self, node) -> list[tuple[str, object]]:
        return [(key, self.nested(node, key)) for key in node.props.keys()
                if self.is_nested(node, key) and self.tag(self.nested(node, key)) == "bsdf"]

    def twosided(self, node, name: str) -> dict:
        """``twosided`` around one unnamed BSDF that takes ``two_sided`` (a leaf, not perturbed) -> that BSDF with
        ``two_sided = true``; else the ``twosided`` type naming one or two materials."""
        inner = self.nested_bsdfs(node)
        others = [k for k in node.props.keys() if k not in dict(inner)]
        if others:
            self.refuse_property(node, others[0], "expected one or two nested bsdfs and nothing else")
        if not 1 <= len(inner) <= 2:
            self.refuse_node(node, f"expected one or two nested bsdfs, got {len(inner)}")
        if len(inner) == 1 and inner[0][0] not in BSDF_REFS[1:]:
            kind = inner[0][1].props.plugin_name()
            if kind in MATERIALS and MATERIALS[kind].two_sided and not self.is_reference(node, inner[0][0]):
                return {**self.leaf(inner[0][1], kind), "two_sided": True}
        names = [self.material(child, f"{name}-{key}") for key, child in inner]
        return {"type": "twosided", "bsdf": names[0] if len(names) == 1 else names}

    def is_reference(self, node, key: str) -> bool:
        return node.props.type(key) == self.mi.Properties.Type.Reference

    def composite(self, node, kind: str, name: str) -> dict:
        """``blendbsdf`` (``weight``, two bsdfs) or ``mask`` (``opacity``, one bsdf)."""
        item = "weight" if kind == "blendbsdf" else "opacity"
        inner = self.nested_bsdfs(node)
        table: dict = {"type": kind}
        for key in node.props.keys():
            with contextlib.suppress(_SkipProperty):  # lenient: this property left out
                if key in dict(inner):
                    continue
                if key != item:
                    self.refuse_property(node, key, f"expected {item} and the nested bsdfs")
                table[item] = ({"texture": self.texture(self.nested(node, key))} if self.is_nested(node, key)
                               else self.value(node, key))
        names = [self.material(child, f"{name}-{key}") for key, child in inner]
        want = 2 if kind == "blendbsdf" else 1
        if len(names) != want:
            self.refuse_node(node, f"expected {want} nested bsdf{'s' if want > 1 else ''}, got {len(names)}")
        table["bsdf"] = names if kind == "blendbsdf" else names[0]
        return table

    def perturbation(self, node, kind: str, name: str) -> dict:
        """``normalmap`` / ``bumpmap``: its texture (Mitsuba's key -> the scene's), the bsdf it perturbs by name."""
        perturbation = PERTURBATIONS[kind]
        inner = self.nested_bsdfs(node)
        table: dict = {"type": kind}
        allowed = [k for k in perturbation.keys if k not in ("type", "bsdf", perturbation.texture_key)]
        for key in node.props.keys():
            with contextlib.suppress(_SkipProperty):  # lenient: this property left out
                if key in dict(inner):
                    continue
                if self.is_nested(node, key) and (key == perturbation.mitsuba_texture_key or (
                        kind == "bumpmap" and self.tag(self.nested(node, key)) == "texture")):
                    # Mitsuba's bumpmap takes its one nested texture under any name (bumpmap.cpp), its normalmap
                    # only under "normalmap"
                    if perturbation.texture_key in table:
                        self.refuse_property(node, key, "expected one nested texture, got a second")
                    table[perturbation.texture_key] = {"texture": self.texture(self.nested(node, key))}
                elif key in allowed and not self.is_nested(node, key):
                    table[key] = self.value(node, key)
                else:
                    self.refuse_property(node, key, f"expected {perturbation.mitsuba_texture_key} (a texture), "
                                                    f"{', '.join(allowed)} and one nested bsdf")
        if len(inner) != 1:
            self.refuse_node(node, f"expected one nested bsdf, got {len(inner)}")
        table["bsdf"] = self.material(inner[0][1], f"{name}-bsdf")
        return table

    # ---- textures --------------------------------------------------------------------------------------------------

    def texture(self, node) -> str:
        """A texture node's table in ``[textures]`` (one per distinct content); a bitmap's file copied."""
        kind = node.props.plugin_name()
        if self.tag(node) != "texture" or kind not in TEXTURE_KEYS:
            self.refuse_node(node, f"expected a texture of type {', '.join(TEXTURE_KEYS)} (a spectrum is not "
                                   f"taken: the scene format is RGB)")
        table: dict = {"type": kind, **self.plain_keys(node, TEXTURE_KEYS[kind], kind)}
        if "to_uv" in table:
            table["to_uv"] = self.to_uv(node, table["to_uv"])
        stem = "checkerboard"
        if kind == "bitmap":
            stem, table["filename"] = self.copy_file(node, "filename", IMAGE_SUFFIXES, TEXTURE_DIR)
        content = json.dumps(table, sort_keys=True)
        if content not in self.texture_of_content:
            name = self.unique(node.props.id() or stem, self.textures)
            self.textures[name] = table
            self.texture_of_content[content] = name
        return self.texture_of_content[content]

    def to_uv(self, node, matrix: list) -> list:
        """A 4x4 ``to_uv`` as the scene format's 3x3 (rows and columns 0, 1 and 3); one that mixes in the third
        coordinate is refused."""
        m = np.asarray(matrix)
        keep = [0, 1, 3]
        rest = np.delete(np.delete(m, keep, axis=0), keep, axis=1)
        if not (np.all(m[np.ix_(keep, [2])] == 0) and np.all(m[np.ix_([2], keep)] == 0) and rest.size == 1):
            self.refuse_property(node, "to_uv", "expected a map of (u, v) alone (a 4x4 whose third row and column "
                                                "are the identity's)")
        return m[np.ix_(keep, keep)].tolist()

    def copy_file(self, node, key: str, suffixes: tuple, folder: str) -> tuple[str, str]:
        """Copy the file a property names (inside the scene's folder) into ``folder``; its stem and new path."""
        if key not in node.props.keys():
            self.refuse_node(node, f"expected a {key}")
        name = str(node.props[key])
        source = self.resolve(node, key, name)
        if source.suffix.lower() not in suffixes:
            self.refuse_file(node, key, f"expected a {', '.join(suffixes)} file, got {name!r}")
        data = source.read_bytes()
        stem = safe_name(source.stem)
        rel = f"{folder}/{stem}{source.suffix.lower()}"
        n = 2
        while rel in self.files and self.files[rel] != data:
            rel = f"{folder}/{stem}-{n}{source.suffix.lower()}"
            n += 1
        self.files[rel] = data
        return stem, rel

    def resolve(self, node, key: str, name: str) -> Path:
        """The file property ``key`` names, as Mitsuba's resolver finds it (relative to the scene's folder), through
        :func:`harness.scene.mesh_files.confined_path`: a regular file inside the scene's folder, else refused
        (:meth:`refuse_file`; a ``<path>`` element's folders are not searched: their files lie outside)."""
        try:
            return confined_path(self.folder, name, node.props.plugin_name(), "", outside_hint="")
        except HarnessError as err:
            self.refuse_file(node, key, err.message)
            raise  # not reached: refuse_file raises

    def refuse_file(self, node, key: str, expected: str) -> None:
        """Refuse the file a plugin cannot be without (a bitmap's, a mesh's, an envmap's): the property's line, but
        with ``lenient`` the plugin goes, and the top-level element it sits in with it (a bitmap without its image
        is no texture; leaving the property out kept the plugin and its parent lost the texture's key)."""
        self.refuse(self.where(node), f"{self.element(node)} property {key!r}", expected)

    # ---- shapes ----------------------------------------------------------------------------------------------------

    def shape(self, node, placement: np.ndarray | None) -> dict:
        """A shape's ``[[shapes]]`` entry; ``placement``: an instance's to_world, applied after the shape's own."""
        kind = node.props.plugin_name()
        if kind not in SHAPE_KEYS:
            self.refuse_node(node, f"expected a shape of type {', '.join(SHAPE_KEYS)}, shapegroup or instance")
        entry: dict = {"name": node.props.id() or f"shape{len(self.shapes)}"}
        material, emission = None, None
        for key in node.props.keys():
            if not self.is_nested(node, key):
                continue
            child = self.nested(node, key)
            if self.tag(child) == "bsdf":
                try:
                    material = self.material(child, child.props.id() or f"{entry['name']}-bsdf")
                except _Dropped:
                    self.refuse_node(node, f"expected a bsdf the scene format has: its {self.element(child)} was "
                                           f"dropped")
            elif self.tag(child) == "emitter":
                emission = self.area(child)
            elif self.tag(child) == "medium" and key in ("interior", "exterior"):
                entry[key] = self.medium(child, f"{entry['name']}-{key}")
            else:
                self.refuse_node(child, "expected a bsdf, an area emitter or an interior / exterior medium in a "
                                        "shape")
        values = self.plain_keys(node, SHAPE_KEYS[kind], kind)
        to_world = np.asarray(values.pop("to_world", np.eye(4).tolist()))
        if placement is not None:
            to_world = placement @ to_world
        if kind in ANALYTIC:
            entry["type"] = kind
        else:
            entry.update(self.mesh(node, kind, values))
        if not np.array_equal(to_world, np.eye(4)):
            entry["to_world"] = to_world.tolist()
        entry.update(values)
        if material is None:
            material = self.default_material()
        entry["material"] = material
        if emission is not None:
            entry["emission"] = emission
        return entry

    def medium(self, node, name: str) -> str:
        """The ``[media.NAME]`` table of a medium node (a node read before keeps its name): Mitsuba's
        ``homogeneous`` with its ``albedo``, ``sigma_t``, ``scale`` and its phase plugin (``isotropic`` or ``hg``);
        anything else refused in one line."""
        index = self.node_index(node)
        if index in self.medium_of_node:
            return self.medium_of_node[index]
        kind = node.props.plugin_name()
        if kind == "heterogeneous":
            self.refuse_node(node, "expected a homogeneous medium: heterogeneous media are not supported yet")
        if kind != "homogeneous":
            self.refuse_node(node, "expected a homogeneous medium")
        table: dict = {"type": kind}
        for key in node.props.keys():
            with contextlib.suppress(_SkipProperty):  # lenient: this property left out
                if self.is_nested(node, key):
                    child = self.nested(node, key)
                    if key in MEDIUM_KEYS and self.tag(child) == "volume" and child.props.plugin_name() == "constvolume":
                        table[key] = self.value(child, "value")  # a constant volume: its one value
                        continue
                    if self.tag(child) != "phase":
                        self.refuse_property(node, key, "expected a number, an rgb colour or a constvolume (another "
                                                        "volume is not taken: the scene format's media are "
                                                        "homogeneous)")
                    table["phase"] = self.phase(child)
                elif key in MEDIUM_KEYS:
                    table[key] = self.value(node, key)
                elif key not in MEDIUM_IGNORED:
                    self.refuse_property(node, key, "expected one of the homogeneous properties the scene format "
                                                    f"has: {', '.join(MEDIUM_KEYS)}, phase")
        name = self.unique(node.props.id() or name, self.media)
        self.media[name] = table
        self.medium_of_node[index] = name
        return name

    def phase(self, node) -> dict:
        """A phase plugin as the scene format's ``phase`` inline table."""
        kind = node.props.plugin_name()
        if kind not in PHASE_KEYS:
            self.refuse_node(node, f"expected a phase function of type {', '.join(PHASE_KEYS)}")
        return {"type": kind, **self.plain_keys(node, PHASE_KEYS[kind], f"{kind} phase")}

    def default_material(self) -> str:
        """Mitsuba's BSDF of a shape without one: diffuse, reflectance 0.5."""
        for name, table in self.materials.items():
            if table == {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}:
                return name
        name = self.unique("default-diffuse", self.materials)
        self.materials[name] = {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}
        return name

    def area(self, node) -> list | dict:
        if node.props.plugin_name() != "area":
            self.refuse_node(node, "expected an area emitter in a shape")
        for key in node.props.keys():
            if key != "radiance":
                self.refuse_property(node, key, "expected radiance only")
        if "radiance" not in node.props.keys():
            return [1.0, 1.0, 1.0]  # Mitsuba's default
        if self.is_nested(node, "radiance"):
            return {"texture": self.texture(self.nested(node, "radiance"))}
        return self.value(node, "radiance", colour=True)

    def mesh(self, node, kind: str, values: dict) -> dict:
        """A mesh: a PLY copied; an OBJ's or a serialized file's mesh as Mitsuba reads it (object space) as PLY."""
        if kind == "ply":
            stem, rel = self.copy_file(node, "filename", (".ply",), MESH_DIR)
            values.pop("filename")
            return {"type": "mesh", "file": rel}
        source = self.resolve(node, "filename", str(values.get("filename", "")))
        props = self.mi.Properties(kind)
        for key in ("filename", "face_normals", "flip_tex_coords", "shape_index"):
            if key in values:
                props[key] = values.pop(key) if key != "filename" else str(source)
        values.pop("filename", None)
        mesh = self.mi.PluginManager.instance().create_object(props)
        vertices = np.array(mesh.vertex_positions_buffer(), dtype=np.float32).reshape(-1, 3)
        triangles = np.array(mesh.faces_buffer(), dtype=np.int64).reshape(-1, 3)
        uv = (np.array(mesh.vertex_texcoords_buffer(), dtype=np.float32).reshape(-1, 2)
              if mesh.has_vertex_texcoords() else None)
        normals = (np.array(mesh.vertex_normals_buffer(), dtype=np.float32).reshape(-1, 3)
                   if mesh.has_vertex_normals() else None)
        rel = f"{MESH_DIR}/{safe_name(source.stem)}-{len(self.shapes)}.ply"
        self.files[rel] = ply_bytes(vertices, triangles, uv, normals)
        out = {"type": "mesh", "file": rel}
        if normals is None:
            out["face_normals"] = True
        return out

    def instance(self, node) -> None:
        """An instance: each shape of its shapegroup, placed by the instance's to_world."""
        values, group = {}, None
        for key in node.props.keys():
            if self.is_nested(node, key):
                group = self.nested(node, key)
            elif key == "to_world":
                values[key] = self.value(node, key)
            else:
                self.refuse_property(node, key, "expected to_world and a shapegroup")
        if group is None or group.props.plugin_name() != "shapegroup":
            self.refuse_node(node, "expected a reference to a shapegroup")
        placement = np.asarray(values.get("to_world", np.eye(4).tolist()))
        for key in group.props.keys():
            child = self.nested(group, key)
            if child.props.plugin_name() in ("shapegroup", "instance"):
                self.refuse_node(child, "expected shapes in a shapegroup (no nested groups)")
            entry = self.shape(child, placement)
            if "emission" in entry:
                self.refuse_node(child, "expected no emitter in a shapegroup (Mitsuba refuses one too)")
            entry["name"] = f"{node.props.id() or 'instance'}-{entry['name']}"
            self.shapes.append(entry)

    # ---- emitters --------------------------------------------------------------------------------------------------

    def emitter(self, node) -> dict:
        kind = node.props.plugin_name()
        if kind not in EMITTER_KEYS:
            self.refuse_node(node, f"expected an emitter of type {', '.join(EMITTER_KEYS)} (an area emitter "
                                   f"belongs in a shape)")
        for key in node.props.keys():
            with contextlib.suppress(_SkipProperty):  # lenient: this property left out
                if self.is_nested(node, key):
                    self.refuse_property(node, key, "expected a value (the scene format's emitters take no texture "
                                                    "but an envmap's file)")
        entry: dict = {"type": kind, "name": node.props.id() or f"emitter{len(self.emitters)}",
                       **self.plain_keys(node, EMITTER_KEYS[kind], kind)}
        if kind == "envmap":
            _, entry["file"] = self.copy_file(node, "filename", (".exr",), TEXTURE_DIR)
            del entry["filename"]
            if "to_world" in entry:  # Mitsuba turns only directions by it (envmap.cpp): its translation is left out,
                entry["to_world"] = [row[:3] + [0.0] for row in entry["to_world"][:3]] + [entry["to_world"][3]]
                # which the scene format refuses (mitsuba-data's matpreview.xml places its envmap at z = 8.87)
        if kind in ("point", "directional") and "to_world" in entry:
            entry.update(self.placed(node, kind, entry.pop("to_world")))
        return {**entry, **{k: v for k, v in MITSUBA_DEFAULTS.get(kind, {}).items() if k not in entry}}

    def placed(self, node, kind: str, matrix: list) -> dict:
        """A point light's to_world as its position (the translation), a directional's as its direction (the
        matrix's third column): what Mitsuba makes of them."""
        m = np.asarray(matrix)
        if kind == "point":
            if "position" in node.props.keys():
                self.refuse_property(node, "to_world", "expected position or to_world, not both")
            return {"position": m[:3, 3].tolist()}
        if "direction" in node.props.keys():
            self.refuse_property(node, "to_world", "expected direction or to_world, not both")
        return {"direction": m[:3, 2].tolist()}

    # ---- the TOML text ---------------------------------------------------------------------------------------------

    def merge_copies(self) -> None:
        """A nested material whose table is a named material's (an export writes nested copies) becomes that
        material: the file keeps one table per distinct material."""
        changed = True
        while changed:
            changed = False
            for name in list(self.nested_names):
                same = [other for other, table in self.materials.items()
                        if other != name and other not in self.nested_names and table == self.materials[name]]
                if same:
                    self.rename_material(name, same[0])
                    changed = True

    def rename_material(self, old: str, new: str) -> None:
        del self.materials[old]
        self.nested_names.discard(old)
        for table in self.materials.values():
            bsdf = table.get("bsdf")
            if bsdf == old:
                table["bsdf"] = new
            elif isinstance(bsdf, list):
                table["bsdf"] = [new if b == old else b for b in bsdf]
        for shape in self.shapes:
            if shape["material"] == old:
                shape["material"] = new

    def toml(self) -> str:
        self.merge_copies()
        if self.camera is None or self.film is None:
            # lenient: the sensor was refused and dropped; the line says why (mitsuba-data's test scenes: a
            # perspective sensor without fov)
            why = next((f"; its sensor was refused: {line}" for line in self.dropped
                        if "<sensor " in line or "<film " in line), "")
            raise HarnessError(str(self.path), f"expected a sensor with a film (the scene format needs a camera){why}")
        description = f"Imported from {self.path.name} (Mitsuba 3 XML) by harness import."
        if self.dropped:
            description += " Dropped (--lenient): " + "; ".join(self.dropped)
        lines = [f"name = {toml_value(safe_name(self.path.stem))}", f"description = {toml_value(description)}", ""]
        _unique_names(self.shapes)
        _unique_names(self.emitters)
        lines += _table("camera", self.camera) + _table("film", self.film)
        if self.max_depth is not None:
            lines += _table("integrator", {"max_depth": self.max_depth})
        for name, table in self.textures.items():
            lines += _table(f"textures.{toml_key(name)}", table)
        for name, table in self.materials.items():
            lines += _table(f"materials.{toml_key(name)}", table)
        for name, table in self.media.items():
            lines += _table(f"media.{toml_key(name)}", table)
        for entry in self.shapes:
            lines += _table("shapes", entry, array=True)
        for entry in self.emitters:
            lines += _table("emitters", entry, array=True)
        return "\n".join(lines)


def _unique_names(entries: list[dict]) -> None:
    """Each entry's ``name`` made unique (an id may be another entry's made-up name): ``-2``, ``-3``, ... added."""
    taken: dict = {}
    for entry in entries:
        entry["name"] = _Importer.unique(entry["name"], taken)
        taken[entry["name"]] = True


def _table(key: str, table: dict, array: bool = False) -> list[str]:
    head = f"[[{key}]]" if array else f"[{key}]"
    return [head] + [f"{toml_key(k)} = {toml_value(v)}" for k, v in table.items()] + [""]


def _first_line(text: str) -> str:
    """The first line of Mitsuba's message, without its source file's place (``[parser.cpp:451]``)."""
    lines = [line.strip() for line in text.strip().splitlines() if line.strip()]
    return re.sub(r"^\[[\w.]+:\d+\]\s*", "", lines[0]) if lines else "Mitsuba could not read it"
