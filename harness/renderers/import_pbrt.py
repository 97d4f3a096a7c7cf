"""A pbrt-v4 scene file read into this project's scene format (docs/import.md, "pbrt-v4"): a subset parser of our own.

The file is split into tokens (``#`` comments, quoted strings, ``[`` ``]``, numbers, bare directive names), each with
its line and column; each directive takes its arguments and a parameter list (``"float fov" [ 45 ]``). The graphics
state (the current transform, named materials and textures, the area light) is kept as pbrt-v4 keeps it
(src/pbrt/parser.cpp, scene.cpp); shapes are baked into world space as PLY meshes (spheres stay analytic), pbrt's
cameras, materials and lights are given Mitsuba's names and meanings (docs/scene-format.md). Whatever the format
cannot express is refused in one line ``FILE:LINE:COL: Directive "type": why``; with ``lenient`` it is dropped instead
and listed in :attr:`ImportedScene.dropped` and the scene's description, and approximations are stated there too.

pbrt is left-handed where Mitsuba is not: the same ``LookAt`` puts the image's left edge toward -cross(up, dir) in
pbrt and +cross(up, dir) in Mitsuba. A camera whose world-from-camera matrix has det > 0 (a plain LookAt) is
therefore rendered exactly by mirroring the whole world through x = 0 (every point, direction and the camera; the
triangles are rewound so their front sides stay the same surfaces); one with det < 0 (``Scale -1 1 1`` before
``LookAt``, as exporters write) needs no mirror.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness.core.errors import HarnessError, not_regular
from harness.renderers.imports import ImportedScene, toml_key, toml_table, toml_value
from harness.renderers.meshfiles import MESH_DIR, TEXTURE_DIR, ply_bytes, safe_name
from harness.scene.mesh_files import confined_path, read_mesh

MAX_FILE_BYTES = 64 << 20
MAX_INCLUDE_DEPTH = 16
#: The parameter types pbrt-v4 declares (parser.cpp); ``spectrum`` values are read only as a constant (one number).
PARAMETER_TYPES = ("integer", "float", "point2", "vector2", "point3", "vector3", "normal3", "normal", "point",
                   "vector", "bool", "string", "texture", "rgb", "spectrum", "blackbody")
#: Directives that change nothing the scene format holds and are noted: pbrt-v4's options for its own sampling.
IGNORED = ("Sampler", "Option", "ColorSpace", "Accelerator")
#: The mirror through x = 0 (see the module's docstring).
DEFAULT_PARAMS: dict = {}  # pbrt-v4's default material: diffuse of reflectance 0.5
MIRROR = np.diag([-1.0, 1.0, 1.0, 1.0])


class ValueRefused(HarnessError):
    """A parameter's value the scene format cannot hold (a named or sampled spectrum, a blackbody, a texture that was
    itself refused), at the parameter's place: the element it belongs to is refused, and with ``lenient`` dropped
    (the material with its shapes, the light)."""


@dataclass
class Token:
    text: str
    line: int
    col: int
    quoted: bool = False


@dataclass
class Param:
    type: str
    name: str
    values: list
    token: Token


@dataclass
class State:
    ctm: np.ndarray = field(default_factory=lambda: np.eye(4))
    material: tuple | None = None          # (kind, params, where) or ("named", name)
    area_light: dict | None = None
    reverse: bool = False


def tokenize(text: str, filename: str) -> list[Token]:
    """pbrt's tokens with their 1-based line and column: quoted strings (``\\`` escapes), ``[`` and ``]``, and runs
    of other characters; ``#`` starts a comment to the end of the line."""
    tokens, i, line, col, n = [], 0, 1, 1, len(text)
    while i < n:
        c = text[i]
        if c == "\n":
            i, line, col = i + 1, line + 1, 1
        elif c in " \t\r":
            i, col = i + 1, col + 1
        elif c == "#":
            while i < n and text[i] != "\n":
                i += 1
        elif c in "[]":
            tokens.append(Token(c, line, col))
            i, col = i + 1, col + 1
        elif c == '"':
            start_line, start_col, j, out = line, col, i + 1, []
            while True:
                if j >= n or text[j] == "\n":
                    raise HarnessError(f"{filename}:{start_line}:{start_col}", "an unterminated string")
                if text[j] == "\\" and j + 1 < n:
                    out.append({"n": "\n", "t": "\t", "b": "\b", "f": "\f", "r": "\r"}.get(text[j + 1], text[j + 1]))
                    j += 2
                    continue
                if text[j] == '"':
                    break
                out.append(text[j])
                j += 1
            tokens.append(Token("".join(out), start_line, start_col, quoted=True))
            col += j + 1 - i
            i = j + 1
        else:
            j = i
            while j < n and text[j] not in ' \t\r\n"[]#':
                j += 1
            tokens.append(Token(text[i:j], line, col))
            col += j - i
            i = j
    return tokens


def number(token: Token, filename: str) -> float:
    try:
        value = float(token.text)
    except ValueError:
        raise HarnessError(f"{filename}:{token.line}:{token.col}", f"expected a number, got {token.text!r}") from None
    if token.quoted or not math.isfinite(value):
        raise HarnessError(f"{filename}:{token.line}:{token.col}", f"expected a finite number, got {token.text!r}")
    return value


def rotation(angle_deg: float, axis) -> np.ndarray:
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    s, c = math.sin(math.radians(angle_deg)), math.cos(math.radians(angle_deg))
    x, y, z = a
    m = np.eye(4)
    m[:3, :3] = [[x * x + (1 - x * x) * c, x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
                 [x * y * (1 - c) + z * s, y * y + (1 - y * y) * c, y * z * (1 - c) - x * s],
                 [x * z * (1 - c) - y * s, y * z * (1 - c) + x * s, z * z + (1 - z * z) * c]]
    return m


def look_at(eye, look, up) -> np.ndarray:
    """pbrt's LookAt: the camera-from-world matrix (the inverse of the frame right = cross(up, dir), cross(dir,
    right), dir at eye)."""
    eye, look, up = (np.asarray(v, float) for v in (eye, look, up))
    d = look - eye
    d = d / np.linalg.norm(d)
    right = np.cross(up / np.linalg.norm(up), d)
    right = right / np.linalg.norm(right)
    new_up = np.cross(d, right)
    world_from_camera = np.eye(4)
    world_from_camera[:3, 0], world_from_camera[:3, 1], world_from_camera[:3, 2] = right, new_up, d
    world_from_camera[:3, 3] = eye
    return np.linalg.inv(world_from_camera)


class _Importer:
    def __init__(self, path: Path, lenient: bool) -> None:
        self.path, self.lenient = path, lenient
        self.folder = path.resolve().parent
        self.dropped: list[str] = []
        self.notes: list[str] = []
        self.files: dict[str, bytes] = {}
        self.state = State()
        self.stack: list[State] = []
        self.named_coords: dict[str, np.ndarray] = {}
        self.named_materials: dict[str, tuple] = {}
        self.textures: dict[str, dict] = {}
        self.refused_textures: set[str] = set()  # lenient: textures dropped, which a material may still name
        self.materials: dict[str, dict] = {}
        self.material_keys: dict[tuple, str] = {}
        self.shapes: list[dict] = []       # world-space shapes, before the mirror
        self.emitters: list[dict] = []
        self.camera: dict | None = None
        self.film = {"width": 1280, "height": 720, "filter": "gaussian"}
        self.filter_seen = False
        self.max_depth = 6
        self.world = False
        self.serial = 0  # each Material directive's number: its material's key
        self.object: tuple[str, list] | None = None  # the ObjectBegin being read: its name and shapes
        self.objects: dict[str, list] = {}

    # -- refusals --

    def where(self, token: Token, file: str) -> str:
        return f"{file}:{token.line}:{token.col}"

    def refuse(self, file: str, token: Token, element: str, message: str) -> None:
        if not self.lenient:
            raise HarnessError(f"{self.where(token, file)}: {element}", message)
        self.dropped.append(f"{self.where(token, file)}: {element}: {message} (dropped)")

    def refuse_value(self, err: ValueRefused, element: str) -> None:
        """A :class:`ValueRefused` raised again, or (lenient) its element listed as dropped."""
        if not self.lenient:
            raise err
        self.dropped.append(f"{err.where}: {err.message}: {element} (dropped)")

    # -- files --

    def inside(self, file: str, token: Token, name: str, what: str) -> Path:
        """The file ``name`` (relative to the folder of ``file``, the pbrt file naming it) through
        :func:`harness.scene.mesh_files.confined_path`: a regular file inside the scene's folder, refused in one line
        even with ``lenient``; an absolute name is refused too (pbrt-v4 reads it, a scene folder would not move)."""
        where = self.where(token, file)
        if Path(name).is_absolute():
            raise HarnessError(where, f"{what} file {name!r}: expected a relative path inside the scene's folder "
                                      f"{str(self.folder)!r}")
        return confined_path(self.folder, name, what, where, base=Path(file).resolve().parent, outside_hint="")

    def read_text(self, path: Path, where: str) -> str:
        if path.stat().st_size > MAX_FILE_BYTES:
            raise HarnessError(where, f"expected a pbrt file of at most 64 MiB, got {path.stat().st_size} bytes")
        try:
            return path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as err:
            raise HarnessError(where, f"cannot read: {err}") from None

    # -- parsing --

    def parse_file(self, path: Path, depth: int) -> None:
        file = str(path)
        tokens = tokenize(self.read_text(path, file), file)
        i = 0
        while i < len(tokens):
            tok = tokens[i]
            if tok.quoted or not re.fullmatch(r"[A-Z][A-Za-z]*", tok.text):
                raise HarnessError(self.where(tok, file), f"expected a directive, got {tok.text!r}")
            i = self.directive(tokens, i, file, depth)

    def args(self, tokens, i, file, count, what):
        """``count`` numbers after token i (a directive's fixed arguments, bracketed or not)."""
        out, j = [], i + 1
        bracket = j < len(tokens) and tokens[j].text == "[" and not tokens[j].quoted
        if bracket:
            j += 1
        for _ in range(count):
            if j >= len(tokens):
                raise HarnessError(self.where(tokens[i], file), f"{what}: expected {count} numbers")
            out.append(number(tokens[j], file))
            j += 1
        if bracket:
            if j >= len(tokens) or tokens[j].text != "]":
                raise HarnessError(self.where(tokens[i], file), f"{what}: expected ']' after {count} numbers")
            j += 1
        return out, j

    def string_arg(self, tokens, i, file, what):
        if i + 1 >= len(tokens) or not tokens[i + 1].quoted:
            raise HarnessError(self.where(tokens[i], file), f"{what}: expected a quoted string")
        return tokens[i + 1].text, i + 2

    def params(self, tokens, j, file) -> tuple[dict, int]:
        """The parameter list from token j: ``"type name" value`` or ``"type name" [ values ]``."""
        out: dict[str, Param] = {}
        while j < len(tokens) and tokens[j].quoted:
            tok = tokens[j]
            parts = tok.text.split()
            if len(parts) != 2 or parts[0] not in PARAMETER_TYPES:
                raise HarnessError(self.where(tok, file), f"expected a parameter \"type name\" (types: "
                                                          f"{', '.join(PARAMETER_TYPES)}), got {tok.text!r}")
            j += 1
            values = []
            if j < len(tokens) and tokens[j].text == "[" and not tokens[j].quoted:
                j += 1
                while j < len(tokens) and not (tokens[j].text == "]" and not tokens[j].quoted):
                    values.append(tokens[j])
                    j += 1
                if j >= len(tokens):
                    raise HarnessError(self.where(tok, file), f"{tok.text!r}: expected ']'")
                j += 1
            elif j < len(tokens):
                values.append(tokens[j])
                j += 1
            kind = {"point": "point3", "vector": "vector3", "normal": "normal3"}.get(parts[0], parts[0])
            if kind in ("string", "texture"):
                if not all(v.quoted for v in values):
                    raise HarnessError(self.where(tok, file), f"{tok.text!r}: expected quoted strings")
                parsed = [v.text for v in values]
            elif kind == "bool":
                parsed = []
                for v in values:
                    if v.text not in ("true", "false"):
                        raise HarnessError(self.where(v, file), f"{tok.text!r}: expected true or false")
                    parsed.append(v.text == "true")
            elif kind == "spectrum" and values and values[0].quoted:
                parsed = [v.text for v in values]
            else:
                parsed = [number(v, file) for v in values]
                if kind == "integer" and any(p != int(p) for p in parsed):
                    raise HarnessError(self.where(tok, file), f"{tok.text!r}: expected integers")
            out[parts[1]] = Param(kind, parts[1], parsed, tok)
        return out, j

    def directive(self, tokens, i, file, depth) -> int:
        tok = tokens[i]
        name = tok.text
        st = self.state
        transforms = {"Translate": 3, "Scale": 3, "Rotate": 4, "LookAt": 9, "Transform": 16, "ConcatTransform": 16}
        if name in transforms:
            v, j = self.args(tokens, i, file, transforms[name], name)
            if name == "Translate":
                m = np.eye(4)
                m[:3, 3] = v
            elif name == "Scale":
                m = np.diag([*v, 1.0])
            elif name == "Rotate":
                if not any(v[1:]):
                    raise HarnessError(self.where(tok, file), "Rotate: expected an axis other than 0 0 0")
                m = rotation(v[0], v[1:])
            elif name == "LookAt":
                m = look_at(v[0:3], v[3:6], v[6:9])
            else:
                m = np.asarray(v, float).reshape(4, 4).T  # pbrt's 16 numbers are column-major
            if name == "Transform":
                st.ctm = m
            else:
                st.ctm = st.ctm @ m
            return j
        if name == "Identity":
            st.ctm = np.eye(4)
            return i + 1
        if name == "CoordinateSystem":
            s, j = self.string_arg(tokens, i, file, name)
            self.named_coords[s] = st.ctm.copy()
            return j
        if name == "CoordSysTransform":
            s, j = self.string_arg(tokens, i, file, name)
            if s not in self.named_coords:
                raise HarnessError(self.where(tok, file), f"CoordSysTransform \"{s}\": no such coordinate system "
                                                          f"(known: {', '.join(sorted(self.named_coords))})")
            st.ctm = self.named_coords[s].copy()
            return j
        if name in ("AttributeBegin", "TransformBegin"):
            self.stack.append(State(st.ctm.copy(), st.material, st.area_light, st.reverse))
            return i + 1
        if name in ("AttributeEnd", "TransformEnd"):
            if not self.stack:
                raise HarnessError(self.where(tok, file), f"{name} without a matching Begin")
            restored = self.stack.pop()
            if name == "TransformEnd":
                st.ctm = restored.ctm
            else:
                self.state = restored
            return i + 1
        if name == "ReverseOrientation":
            st.reverse = not st.reverse
            return i + 1
        if name == "WorldBegin":
            self.world = True
            self.named_coords["camera"] = self.named_coords.get("camera", np.eye(4))
            st.ctm = np.eye(4)
            return i + 1
        if name in ("Include", "Import"):
            s, j = self.string_arg(tokens, i, file, name)
            target = self.inside(file, tokens[i + 1], s, name)
            if depth >= MAX_INCLUDE_DEPTH:
                raise HarnessError(self.where(tok, file), f"{name}: more than {MAX_INCLUDE_DEPTH} nested files")
            self.parse_file(target, depth + 1)
            return j
        if name == "ObjectBegin":
            s_, j = self.string_arg(tokens, i, file, name)
            if self.object is not None:
                raise HarnessError(self.where(tok, file), "ObjectBegin inside ObjectBegin")
            self.stack.append(State(st.ctm.copy(), st.material, st.area_light, st.reverse))
            self.object = (s_, [])
            return j
        if name == "ObjectEnd":
            if self.object is None or not self.stack:
                raise HarnessError(self.where(tok, file), "ObjectEnd without ObjectBegin")
            self.objects[self.object[0]] = self.object[1]
            self.object = None
            self.state = self.stack.pop()
            return i + 1
        if name == "ObjectInstance":
            s_, j = self.string_arg(tokens, i, file, name)
            if s_ not in self.objects:
                raise HarnessError(self.where(tok, file), f"ObjectInstance \"{s_}\": no such object")
            saved = self.state
            for kind, params, sfile, stok, element, defined in self.objects[s_]:
                # pbrt-v4: world-from-instance (the CTM here) times the shape's CTM where the object defined it
                self.state = State(st.ctm @ defined.ctm, defined.material, None, defined.reverse)
                self.on_shape(kind, dict(params), sfile, stok, element)
            self.state = saved
            return j
        if name in ("MakeNamedMedium", "MediumInterface", "Attribute", "ActiveTransform", "TransformTimes"):
            # skip the arguments: strings, numbers and a parameter list (ActiveTransform: one bare word)
            j = i + 1
            if name == "ActiveTransform" and j < len(tokens):
                j += 1
            while j < len(tokens) and (tokens[j].quoted or tokens[j].text in "[]" or
                                       re.fullmatch(r"[-+.0-9eE]+", tokens[j].text)):
                j += 1
            self.refuse(file, tok, name, "not imported (media, attribute defaults and motion are not part of the "
                                         "scene format)")
            return j
        if name == "MakeNamedMaterial":
            s, j = self.string_arg(tokens, i, file, name)
            params, j = self.params(tokens, j, file)
            kind = params.pop("type", None)
            if kind is None or kind.type != "string" or not kind.values:
                raise HarnessError(self.where(tok, file), f"MakeNamedMaterial \"{s}\": expected \"string type\"")
            self.named_materials[s] = (kind.values[0], params, (file, tok))
            return j
        if name == "NamedMaterial":
            s, j = self.string_arg(tokens, i, file, name)
            if s not in self.named_materials:
                raise HarnessError(self.where(tok, file), f"NamedMaterial \"{s}\": no such material")
            st.material = ("named", s)
            return j
        # directives with a type string and a parameter list
        if name == "Texture":
            tname, j = self.string_arg(tokens, i, file, name)
            ttype, j = self.string_arg(tokens, j - 1, file, name)
            tclass, j = self.string_arg(tokens, j - 1, file, name)
            params, j = self.params(tokens, j, file)
            try:
                self.texture(tname, ttype, tclass, params, file, tok)
            except ValueRefused as err:
                self.refuse_value(err, f'Texture "{tname}"')
            if tname not in self.textures:  # lenient: dropped, so a material naming it goes too
                self.refused_textures.add(tname)
            else:
                self.refused_textures.discard(tname)
            return j
        if name not in ("Camera", "Film", "Sampler", "Integrator", "PixelFilter", "Shape", "Material",
                        "AreaLightSource", "LightSource", "Option", "ColorSpace", "Accelerator", "MakeNamedMedium"):
            raise HarnessError(self.where(tok, file), f"unknown directive {name!r}")
        kind, j = self.string_arg(tokens, i, file, name)
        params, j = self.params(tokens, j, file)
        element = f'{name} "{kind}"'
        if name in IGNORED:
            if name in ("Sampler",):
                self.notes.append(f"{self.where(tok, file)}: {element}: not read (the harness chooses the samples)")
            elif name == "ColorSpace" and kind != "srgb":
                self.refuse(file, tok, element, "expected srgb (the scene format's colours are linear sRGB)")
            return j
        try:
            getattr(self, "on_" + name.lower())(kind, params, file, tok, element)
        except ValueRefused as err:
            self.refuse_value(err, element)
        return j

    # -- parameters --

    def take(self, params: dict, name: str, types: tuple, default=None, count: int | None = None):
        p = params.pop(name, None)
        if p is None:
            return default
        if p.type == "blackbody" and "rgb" in types:
            raise ValueRefused(self.where(p.token, self.cur_file),
                               f"\"blackbody {name}\": expected \"rgb {name}\" (the scene format is RGB)")
        if p.type not in types:
            raise HarnessError(self.where(p.token, self.cur_file), f"\"{p.type} {name}\": expected type "
                                                                   f"{' or '.join(types)}")
        if p.type == "spectrum":
            if len(p.values) != 1 or isinstance(p.values[0], str):
                raise ValueRefused(self.where(p.token, self.cur_file),
                                   f"\"spectrum {name}\": a named or sampled spectrum; expected \"rgb {name}\" or "
                                   f"one constant value (the scene format is RGB)")
            return [p.values[0]] * 3 if count == 3 else p.values[0]
        if p.type == "blackbody":
            raise HarnessError(self.where(p.token, self.cur_file),
                               f"\"blackbody {name}\": expected \"rgb {name}\" (the scene format is RGB)")
        if count is not None and len(p.values) != count:
            raise HarnessError(self.where(p.token, self.cur_file), f"\"{p.type} {name}\": expected {count} "
                                                                   f"values, got {len(p.values)}")
        return p.values[0] if count == 1 else p.values

    def leftover(self, params: dict, file, tok, element) -> bool:
        """Refuse the parameters not read; True where the element must be dropped."""
        if params:
            names = ", ".join(f'"{p.type} {p.name}"' for p in params.values())
            self.refuse(file, tok, element, f"parameters the scene format has no counterpart for: {names}")
            return True
        return False

    # -- camera, film, integrator --

    def on_camera(self, kind, params, file, tok, element):
        self.cur_file = file
        camera_from_world = self.state.ctm.copy()
        self.named_coords["camera"] = np.linalg.inv(camera_from_world)
        if kind not in ("perspective", "orthographic"):
            raise HarnessError(f"{self.where(tok, file)}: {element}",
                               "expected perspective or orthographic (the scene format's cameras)")
        m = np.linalg.inv(camera_from_world)
        lin = m[:3, :3]
        if not np.allclose(lin.T @ lin, np.eye(3), atol=1e-9):
            raise HarnessError(f"{self.where(tok, file)}: {element}",
                               "expected a rigid camera transform (rotation, translation, mirror); it scales")
        lens = self.take(params, "lensradius", ("float",), 0.0, 1)
        focus = self.take(params, "focaldistance", ("float",), 1e6, 1)
        cam = {"matrix": m, "kind": kind}
        if kind == "perspective":
            cam["fov"] = self.take(params, "fov", ("float",), 90.0, 1)
            if lens > 0:
                cam["aperture_radius"], cam["focus_distance"] = lens, focus
        else:
            if lens > 0:
                self.refuse(file, tok, element, "a lens radius on an orthographic camera (the format's "
                                                "orthographic camera is a pinhole)")
            cam["screenwindow"] = self.take(params, "screenwindow", ("float",), None, 4)
        if "frameaspectratio" in params or (kind == "perspective" and "screenwindow" in params):
            self.refuse(file, tok, element, "frameaspectratio / screenwindow on a perspective camera")
            params.pop("frameaspectratio", None), params.pop("screenwindow", None)
        params.pop("shutteropen", None), params.pop("shutterclose", None)
        self.leftover(params, file, tok, element)
        self.camera = cam

    def on_film(self, kind, params, file, tok, element):
        self.cur_file = file
        if kind not in ("rgb", "gbuffer", "spectral"):
            raise HarnessError(f"{self.where(tok, file)}: {element}", "expected rgb")
        self.film["width"] = int(self.take(params, "xresolution", ("integer",), 1280, 1))
        self.film["height"] = int(self.take(params, "yresolution", ("integer",), 720, 1))
        for key in ("filename", "iso", "whitebalance", "exposuretime", "sensor", "savefp16", "diagonal"):
            params.pop(key, None)
        crop = params.pop("cropwindow", None)
        if crop is not None and crop.values != [0, 1, 0, 1]:
            self.refuse(file, crop.token, element, "a crop window (the format renders the whole film)")
        pbounds = params.pop("pixelbounds", None)
        if pbounds is not None:
            self.refuse(file, pbounds.token, element, "pixel bounds (the format renders the whole film)")
        self.leftover(params, file, tok, element)

    def on_pixelfilter(self, kind, params, file, tok, element):
        self.cur_file = file
        self.filter_seen = True
        radius = self.take(params, "xradius", ("float",), None, 1)
        yradius = self.take(params, "yradius", ("float",), None, 1)
        sigma = self.take(params, "sigma", ("float",), None, 1) if kind == "gaussian" else None
        if kind == "box" and radius in (None, 0.5) and yradius in (None, 0.5):
            self.film["filter"] = "box"
        elif kind == "triangle" and radius == 1 and yradius == 1:
            self.film["filter"] = "tent"
        elif kind == "gaussian" and radius in (None, 1.5) and yradius in (None, 1.5) and sigma in (None, 0.5):
            self.film["filter"] = "gaussian"  # pbrt-v4's default filter written out: as no PixelFilter (run)
            self.notes.append(f"{self.where(tok, file)}: {element}: pbrt-v4's Gaussian (radius 1.5, sigma 0.5) "
                              "read as the format's gaussian (sigma 0.5, radius 2)")
        else:
            self.film["filter"] = "box"
            self.refuse(file, tok, element, "expected box of radius 0.5 or triangle of radius 1 (the format's "
                                            "box and tent); the film's filter stays box")
        params.clear()

    def on_integrator(self, kind, params, file, tok, element):
        self.cur_file = file
        if kind in ("ambientocclusion", "aov"):
            raise HarnessError(f"{self.where(tok, file)}: {element}", "not a light transport estimate")
        depth = int(self.take(params, "maxdepth", ("integer",), 5, 1))
        if depth < 0:
            raise HarnessError(f"{self.where(tok, file)}: {element}", f"maxdepth {depth}: expected >= 0")
        self.max_depth = depth + 1
        if self.take(params, "regularize", ("bool",), False, 1):
            self.refuse(file, tok, element, "regularize = true (biased roughening of specular paths)")
        for key in ("lightsampler", "visualizestrategies", "visualizeweights"):
            params.pop(key, None)
        self.leftover(params, file, tok, element)

    # -- textures and materials --

    def texture(self, tname, ttype, tclass, params, file, tok):
        self.cur_file = file
        element = f'Texture "{tname}" "{ttype}" "{tclass}"'
        if ttype != "spectrum" or tclass != "imagemap":
            self.refuse(file, tok, element, "expected a \"spectrum\" \"imagemap\" texture (the format's bitmap)")
            return
        fname = self.take(params, "filename", ("string",), None, 1)
        if fname is None:
            raise HarnessError(f"{self.where(tok, file)}: {element}", "expected \"string filename\"")
        target = self.inside(file, tok, fname, "imagemap")
        if target.suffix.lower() not in (".png", ".exr", ".jpg", ".jpeg"):
            raise HarnessError(f"{self.where(tok, file)}: {element}", f"{fname!r}: expected PNG, JPEG or EXR")
        entry = {"filename": f"{TEXTURE_DIR}/{safe_name(tname)}{target.suffix.lower()}"}
        self.files[entry["filename"]] = target.read_bytes()
        filt = self.take(params, "filter", ("string",), "bilinear", 1)
        if filt == "point":
            entry["filter_type"] = "nearest"
        elif filt == "bilinear":
            entry["filter_type"] = "bilinear"
        else:
            entry["filter_type"] = "bilinear"
            self.notes.append(f"{self.where(tok, file)}: {element}: filter {filt!r} read as bilinear (no mipmaps)")
        wrap = self.take(params, "wrap", ("string",), "repeat", 1)
        if wrap not in ("repeat", "clamp"):
            self.refuse(file, tok, element, f"wrap {wrap!r}: expected repeat or clamp")
            return
        entry["wrap_mode"] = wrap
        encoding = self.take(params, "encoding", ("string",), "sRGB", 1)
        if encoding not in ("sRGB", "linear"):
            self.refuse(file, tok, element, f"encoding {encoding!r}: expected sRGB or linear")
            return
        entry["raw"] = encoding == "linear"
        if target.suffix.lower() == ".exr":
            entry.pop("raw")
        su = self.take(params, "uscale", ("float",), 1.0, 1)
        sv = self.take(params, "vscale", ("float",), 1.0, 1)
        du = self.take(params, "udelta", ("float",), 0.0, 1)
        dv = self.take(params, "vdelta", ("float",), 0.0, 1)
        # pbrt looks the image up at (s, 1 - t) with its top row at 0; the format's top row is v = 0
        entry["to_uv"] = [[su, 0.0, du], [0.0, -sv, 1.0 - dv], [0.0, 0.0, 1.0]]
        mapping = self.take(params, "mapping", ("string",), "uv", 1)
        if mapping != "uv":
            self.refuse(file, tok, element, f"mapping {mapping!r}: expected uv")
            return
        if self.take(params, "scale", ("float",), 1.0, 1) != 1 or self.take(params, "invert", ("bool",), False, 1):
            self.refuse(file, tok, element, "scale other than 1 or invert (the format's bitmap has neither)")
            return
        params.pop("maxanisotropy", None)
        if self.leftover(params, file, tok, element):
            return
        self.textures[tname] = entry

    def colour(self, params, name, default, file):
        """An rgb parameter, a constant spectrum, or a texture's name (``{texture = NAME}``)."""
        p = params.get(name)
        if p is not None and p.type == "texture":
            params.pop(name)
            tname = p.values[0]
            if tname in self.refused_textures:
                raise ValueRefused(self.where(p.token, file), f"\"texture {name}\": the texture {tname!r} was "
                                                              "refused")
            if tname not in self.textures:
                raise HarnessError(self.where(p.token, file), f"\"texture {name}\": no such spectrum texture "
                                                              f"{tname!r}")
            return {"texture": tname}
        return self.take(params, name, ("rgb", "spectrum"), default, 3)

    def material_entry(self, kind, params, file, tok, element):
        """Mitsuba's material for pbrt's; None where refused."""
        self.cur_file = file
        params = dict(params)
        for key in ("displacement", "normalmap"):
            if key in params:
                self.refuse(file, params[key].token, element, f"\"{key}\" (not imported)")
                params.pop(key)
        if kind == "diffuse":
            entry = {"type": "diffuse", "reflectance": self.colour(params, "reflectance", [0.5] * 3, file),
                     "two_sided": True}
        elif kind in ("conductor", "dielectric"):
            remap = self.take(params, "remaproughness", ("bool",), True, 1)
            rough = self.take(params, "roughness", ("float",), None, 1)
            u = self.take(params, "uroughness", ("float",), rough if rough is not None else 0.0, 1)
            v = self.take(params, "vroughness", ("float",), rough if rough is not None else 0.0, 1)
            if u != v:
                self.refuse(file, tok, element, f"uroughness {u} and vroughness {v} differ (the format's alpha is "
                                                "isotropic)")
                return None
            alpha = math.sqrt(u) if remap else u
            if kind == "conductor":
                if "reflectance" in params:
                    self.refuse(file, tok, element, "\"reflectance\" (pbrt's artist conductor) not imported")
                    return None
                if "eta" not in params or "k" not in params:
                    self.refuse(file, tok, element, "the default metal-Cu spectra: give \"rgb eta\" and \"rgb k\"")
                    return None
                entry = {"type": "conductor", "eta": self.take(params, "eta", ("rgb", "spectrum"), None, 3),
                         "k": self.take(params, "k", ("rgb", "spectrum"), None, 3), "two_sided": True}
            else:
                eta = self.take(params, "eta", ("float", "spectrum"), 1.5, 1)
                if isinstance(eta, list):
                    eta = eta[0]
                entry = {"type": "dielectric", "int_ior": eta, "ext_ior": 1.0}
            if alpha >= 1e-3:  # pbrt's TrowbridgeReitz EffectivelySmooth: alpha < 1e-3 is a smooth interface
                if alpha > 1:
                    self.refuse(file, tok, element, f"alpha {alpha} above 1 (the format's range)")
                    return None
                entry["type"] = "rough" + entry["type"]
                entry["alpha"], entry["distribution"] = alpha, "ggx"
        elif kind in ("interface", ""):
            self.refuse(file, tok, element, "an interface material (media are not part of the scene format)")
            return None
        else:
            self.refuse(file, tok, element, "expected diffuse, conductor or dielectric (coateddiffuse, "
                                            "coatedconductor, diffusetransmission, hair, measured, mix, "
                                            "subsurface, thindielectric have no exact counterpart)")
            return None
        if self.leftover(params, file, tok, element):
            return None
        return entry

    def on_material(self, kind, params, file, tok, element):
        self.serial += 1
        self.state.material = (kind, params, (file, tok), self.serial)

    def material_name(self) -> str | None:
        mat = self.state.material
        if mat is None:
            mat = ("diffuse", DEFAULT_PARAMS, None)
        if mat[0] == "named":
            key = ("named", mat[1])
            kind, params, (file, tok) = self.named_materials[mat[1]]
            label = mat[1]
        else:
            kind, params, loc = mat[:3]
            key = ("anon", mat[3] if len(mat) > 3 else 0)
            file, tok = loc if loc else (str(self.path), Token("", 0, 0))
            label = None
        if key in self.material_keys:
            return self.material_keys[key]
        element = f'Material "{kind}"' if label is None else f'MakeNamedMaterial "{label}"'
        try:
            entry = self.material_entry(kind, params, file, tok, element)
        except ValueRefused as err:
            self.refuse_value(err, element)
            entry = None
        if entry is None:
            self.material_keys[key] = None  # refused once, listed once; each of its shapes says so
            return None
        name = label or f"material{len(self.materials)}"
        while name in self.materials:
            name += "_"
        self.materials[name] = entry
        self.material_keys[key] = name
        return name

    # -- lights --

    def on_arealightsource(self, kind, params, file, tok, element):
        self.cur_file = file
        self.state.area_light = None
        if kind != "diffuse":
            self.refuse(file, tok, element, "expected diffuse")
            return
        if "power" in params or "filename" in params:
            self.refuse(file, tok, element, "\"power\" / \"filename\" (photometric normalisation, image lights)")
            return
        L = self.take(params, "L", ("rgb",), [1.0, 1.0, 1.0], 3)
        scale = self.take(params, "scale", ("float",), 1.0, 1)
        if self.take(params, "twosided", ("bool",), False, 1):
            self.refuse(file, tok, element, "twosided (the format's area lights emit from the front side only)")
            return
        if self.leftover(params, file, tok, element):
            return
        self.state.area_light = {"emission": [scale * c for c in L]}

    def on_lightsource(self, kind, params, file, tok, element):
        self.cur_file = file
        m = self.state.ctm
        if "power" in params or "illuminance" in params:
            self.refuse(file, tok, element, "\"power\" / \"illuminance\" (photometric normalisation) not imported")
            return
        scale = self.take(params, "scale", ("float",), 1.0, 1)
        if kind == "point":
            intensity = self.take(params, "I", ("rgb",), [1.0] * 3, 3)
            frm = self.take(params, "from", ("point3",), [0.0, 0.0, 0.0], 3)
            entry = {"type": "point", "position": point(m, frm), "intensity": [scale * c for c in intensity]}
        elif kind == "spot":
            intensity = self.take(params, "I", ("rgb",), [1.0] * 3, 3)
            frm = self.take(params, "from", ("point3",), [0.0, 0.0, 0.0], 3)
            to = self.take(params, "to", ("point3",), [0.0, 0.0, 1.0], 3)
            cone = self.take(params, "coneangle", ("float",), 30.0, 1)
            delta = self.take(params, "conedelta", ("float",), 5.0, 1)
            if not 0 <= delta < cone <= 90:
                self.refuse(file, tok, element, f"coneangle {cone}, conedelta {delta}: expected 0 <= conedelta < "
                                                "coneangle <= 90 (the format's beam width is > 0)")
                return
            entry = {"type": "spot", "position": point(m, frm), "target": point(m, to),
                     "intensity": [scale * c for c in intensity], "cutoff_angle": cone,
                     "beam_width": cone - delta}
            if delta > 0:
                self.notes.append(f"{self.where(tok, file)}: {element}: pbrt's falloff is smoothstep in cos theta "
                                  "between cos(coneangle) and cos(coneangle - conedelta); Mitsuba's is linear in "
                                  "theta between the same angles")
        elif kind == "distant":
            L = self.take(params, "L", ("rgb",), [1.0] * 3, 3)
            frm = self.take(params, "from", ("point3",), [0.0, 0.0, 0.0], 3)
            to = self.take(params, "to", ("point3",), [0.0, 0.0, 1.0], 3)
            d = m[:3, :3] @ (np.asarray(to) - np.asarray(frm))
            entry = {"type": "directional", "direction": list(d / np.linalg.norm(d)),
                     "irradiance": [scale * c for c in L]}
        elif kind == "infinite":
            if "filename" in params:
                self.refuse(file, tok, element, "an image infinite light (pbrt-v4's equal-area octahedral map; the "
                                                "format's envmap is latitude-longitude)")
                return
            L = self.take(params, "L", ("rgb",), [1.0] * 3, 3)
            entry = {"type": "constant", "radiance": [scale * c for c in L]}
        else:
            self.refuse(file, tok, element, "expected point, spot, distant or infinite")
            return
        if self.leftover(params, file, tok, element):
            return
        self.emitters.append(entry)

    # -- shapes --

    def on_shape(self, kind, params, file, tok, element):
        self.cur_file = file
        if self.object is not None:  # a prototype's shape: placed by each ObjectInstance
            if self.state.area_light is not None:
                self.refuse(file, tok, element, "an area light in an object instance (pbrt-v4 does not support it)")
                return
            self.object[1].append((kind, dict(params), file, tok, element,
                                   State(self.state.ctm.copy(), self.state.material, None, self.state.reverse)))
            return
        m = self.state.ctm
        if kind not in ("trianglemesh", "plymesh", "sphere"):
            self.refuse(file, tok, element, "expected trianglemesh, plymesh or sphere")
            return
        for key in ("alpha", "emissionfilename", "displacement"):
            if key in params:
                self.refuse(file, params[key].token, element, f"\"{key}\" (not imported)")
                return
        material = self.material_name()
        if material is None:
            self.refuse(file, tok, element, "its material was refused")
            return
        entry: dict = {"name": f"shape{len(self.shapes)}", "material": material}
        if kind == "sphere":
            radius = self.take(params, "radius", ("float",), 1.0, 1)
            for key in ("zmin", "zmax", "phimax"):
                if key in params:
                    self.refuse(file, tok, element, f"\"{key}\": a partial sphere")
                    return
            if self.leftover(params, file, tok, element):
                return
            lin = m[:3, :3]
            s = abs(np.linalg.det(lin)) ** (1 / 3)
            if not np.allclose(lin.T @ lin, s * s * np.eye(3), atol=1e-9 * max(1.0, s * s)):
                self.refuse(file, tok, element, "a sphere under a transform that is not a rotation, uniform scale "
                                                "and translation")
                return
            entry.update(type="sphere", center=list(m[:3, 3]), radius=radius * s)
            if self.state.reverse:
                entry["flip_normals"] = True
            entry["_kind"] = "sphere"
        else:
            if kind == "plymesh":
                fname = self.take(params, "filename", ("string",), None, 1)
                if fname is None:
                    raise HarnessError(f"{self.where(tok, file)}: {element}", "expected \"string filename\"")
                target = self.inside(file, tok, fname, "plymesh")
                try:
                    P, idx, N, uv, nonplanar = plymesh(target.read_bytes())
                except ValueError as err:
                    raise HarnessError(f"{self.where(tok, file)}: {element}", f"{fname!r}: {err}") from None
                if nonplanar:
                    self.notes.append(f"{self.where(tok, file)}: {element}: {nonplanar} non-planar quads (pbrt-v4's "
                                      "bilinear patches) as two triangles each, split along their 0-2 diagonal")
            else:
                idx = self.take(params, "indices", ("integer",), None)
                P = self.take(params, "P", ("point3",), None)
                if P is None or len(P) % 3:
                    raise HarnessError(f"{self.where(tok, file)}: {element}", "expected \"point3 P\" of 3 n values")
                P = np.asarray(P, float).reshape(-1, 3)
                if idx is None:
                    if len(P) != 3:
                        raise HarnessError(f"{self.where(tok, file)}: {element}", "expected \"integer indices\"")
                    idx = [0, 1, 2]
                if len(idx) % 3 or min(idx) < 0 or max(idx) >= len(P):
                    raise HarnessError(f"{self.where(tok, file)}: {element}",
                                       f"expected 3 n indices into the {len(P)} points")
                idx = np.asarray(idx, np.int64).reshape(-1, 3)
                N = self.take(params, "N", ("normal3",), None)
                uv = self.take(params, "uv", ("point2",), None)
                for arr, w, what in ((N, 3, "N"), (uv, 2, "uv")):
                    if arr is not None and len(arr) != w * len(P):
                        raise HarnessError(f"{self.where(tok, file)}: {element}",
                                           f"expected {len(P)} values of \"{what}\"")
                N = None if N is None else np.asarray(N, float).reshape(-1, 3)
                uv = None if uv is None else np.asarray(uv, float).reshape(-1, 2)
                for key in ("S", "faceIndices"):
                    if key in params:
                        self.refuse(file, params[key].token, element, f"\"{key}\" (not imported)")
                        params.pop(key)
            if self.leftover(params, file, tok, element):
                return
            world = P @ m[:3, :3].T + m[:3, 3]
            if N is not None:
                N = N @ np.linalg.inv(m[:3, :3])
                N = N / np.linalg.norm(N, axis=1, keepdims=True)
                if self.state.reverse:
                    N = -N
                # pbrt's front side faces the (reversed) normals: each triangle wound to agree with them
                corners = world[idx]
                geo = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
                flip = np.einsum("ij,ij->i", geo, N[idx].sum(axis=1)) < 0
            else:
                swaps = np.linalg.det(m[:3, :3]) < 0
                flip = np.full(len(idx), bool(self.state.reverse) ^ bool(swaps))
            idx = idx.copy()
            idx[flip] = idx[flip][:, ::-1]
            entry.update(type="mesh", _P=world, _idx=idx, _N=N,
                         _uv=uv)  # pbrt's (u, v) as they are; each texture's to_uv flips v
            if N is None:
                entry["face_normals"] = True
        if self.state.area_light is not None:
            entry["emission"] = self.state.area_light["emission"]
            if kind != "sphere":
                entry["face_normals"] = True  # the format's area lights are flat (Mitsuba's samples them so)
        self.shapes.append(entry)

    # -- the scene --

    def run(self) -> ImportedScene:
        self.parse_file(self.path, 0)
        if self.camera is None:
            raise HarnessError(str(self.path), "expected a Camera directive (the scene format needs one)")
        if not self.filter_seen:
            self.notes.append("no PixelFilter: pbrt-v4's default Gaussian (radius 1.5, sigma 0.5) read as the "
                              "format's gaussian (sigma 0.5, radius 2)")
        return ImportedScene(toml=self.text(), files=self.files, dropped=list(self.dropped), source=self.path)

    def text(self) -> str:
        cam = self.camera
        m = cam["matrix"]
        mirror = np.linalg.det(m[:3, :3]) > 0
        f = MIRROR if mirror else np.eye(4)
        mm = f @ m
        origin = mm[:3, 3]
        camera = {"type": "perspective", "origin": list(origin), "target": list(origin + mm[:3, 2]),
                  "up": list(mm[:3, 1])}
        w, h = self.film["width"], self.film["height"]
        if cam["kind"] == "perspective":
            camera.update(fov=cam["fov"], fov_axis="smaller")
            if "aperture_radius" in cam:
                camera.update(type="thinlens", aperture_radius=cam["aperture_radius"],
                              focus_distance=cam["focus_distance"])
        else:
            aspect = w / h
            sw = cam["screenwindow"] or ([-aspect, aspect, -1.0, 1.0] if aspect > 1
                                          else [-1.0, 1.0, -1 / aspect, 1 / aspect])
            if sw[0] != -sw[1] or sw[2] != -sw[3] or sw[1] <= 0 or sw[3] <= 0:
                raise HarnessError(str(self.path), f"Camera \"orthographic\": screenwindow {sw}: expected one "
                                                   "symmetric about the axis")
            camera.update(type="orthographic", scale=[sw[1], sw[3] * aspect, 1.0])
        lines = [f"{self.path.stem}: imported from {self.path.name} (pbrt-v4) by harness import"]
        if mirror:
            lines.append("the world mirrored through x = 0 (pbrt's left-handed camera; the image is pbrt's)")
        lines += [f"approximated: {n}" for n in self.notes]
        lines += [f"dropped: {d}" for d in self.dropped]
        out = [f"name = {toml_value(self.path.stem)}", f"description = {toml_value('; '.join(lines))}"]
        out += toml_table("camera", camera)
        out += toml_table("film", self.film)
        out += toml_table("integrator", {"max_depth": self.max_depth})
        for name, entry in self.textures.items():
            if any(e.get("reflectance") == {"texture": name} for e in self.materials.values()):
                out += toml_table(f"textures.{toml_key(name)}", entry)
        for name, entry in self.materials.items():
            out += toml_table(f"materials.{toml_key(name)}", entry)
        for shape in self.shapes:
            s = {k: v for k, v in shape.items() if not k.startswith("_")}
            if shape["type"] == "sphere":
                s["center"] = list((f[:3, :3] @ np.asarray(s["center"])))
            else:
                P = shape["_P"] @ f[:3, :3].T
                idx = shape["_idx"][:, ::-1] if mirror else shape["_idx"]
                N = None if shape["_N"] is None or s.get("face_normals") else shape["_N"] @ f[:3, :3].T
                rel = f"{MESH_DIR}/{safe_name(s['name'])}.ply"
                self.files[rel] = ply_bytes(P, idx, shape["_uv"], N)
                s = {"name": s["name"], "type": "mesh", "file": rel, **{k: v for k, v in s.items()
                                                                        if k not in ("name", "type")}}
            out += toml_table("[[shapes]]", s)
        for e in self.emitters:
            e = dict(e)
            for key in ("position", "target"):
                if key in e:
                    e[key] = list(f[:3, :3] @ np.asarray(e[key]))
            if "direction" in e:
                e["direction"] = list(f[:3, :3] @ np.asarray(e["direction"]))
            out += toml_table("[[emitters]]", e)
        return "\n".join(out) + "\n"


def plymesh(data: bytes):
    """A PLY file's (points (V, 3), triangles (F, 3), normals or None, uv or None, the number of non-planar quads) as
    pbrt-v4's plymesh reads one, through the harness's one mesh reader (:func:`harness.scene.mesh_files.read_mesh`,
    with its refusals): ``x y z``, ``nx ny nz``, ``u v`` (or ``s t``, ``texture_u texture_v``), faces of 3 or 4
    vertices (a quad split into (0 1 2), (2 3 0): pbrt-v4 makes it a bilinear patch, the same surface where the quad
    is planar; a quad is non-planar where its fourth corner leaves the plane of the first three by more than 1e-9
    of the largest coordinate cubed, the triple product's scale). ValueError: one line why not."""
    points, idx, normals, uv, polygons = read_mesh(data, "ply")
    sizes = {len(face) for face in polygons}
    if sizes - {3, 4}:
        raise ValueError(f"a face of {min(sizes - {3, 4})} vertices (pbrt reads triangles and quads)")
    if len(idx) == 0 or idx.min() < 0 or idx.max() >= len(points):
        raise ValueError(f"expected faces indexing the {len(points)} vertices")
    q = points[np.asarray([face for face in polygons if len(face) == 4], np.int64).reshape(-1, 4)]
    nonplanar = int((np.abs(np.einsum("ij,ij->i", np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]),
                                      q[:, 3] - q[:, 0])) > 1e-9 * np.abs(q).max(initial=1.0) ** 3).sum())
    return points, idx, normals, uv, nonplanar


def point(m: np.ndarray, p) -> list:
    return list(m[:3, :3] @ np.asarray(p, float) + m[:3, 3])


def import_pbrt(path: Path, *, lenient: bool = False) -> ImportedScene:
    """The pbrt-v4 scene file ``path`` as an :class:`ImportedScene` (docs/import.md, "pbrt-v4").

    Refuses (:class:`HarnessError` ``FILE:LINE:COL: Directive "type": why``) what the scene format cannot express;
    with ``lenient`` drops it instead and lists it in ``dropped`` and the description."""
    path = Path(path)
    irregular = not_regular(path)  # a named pipe would block the read
    if irregular is not None:
        raise irregular
    if not path.is_file():
        raise HarnessError(str(path), "no such file")
    importer = _Importer(path, lenient)
    importer.cur_file = str(path)
    return importer.run()
