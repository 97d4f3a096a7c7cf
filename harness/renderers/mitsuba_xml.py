"""A :class:`~harness.renderers.mitsuba_spec.MitsubaSpec` as Mitsuba 3 XML, and the files the XML names.

Each plugin becomes the element of its category (``<bsdf type="diffuse">``); a top-level plugin carries its key as
``id``, a nested one as ``name``, except where the key is the category itself (``film``, ``bsdf``, ...), which
Mitsuba needs no name for. Properties become ``<boolean>``, ``<integer>``, ``<float>``, ``<string>``, ``<rgb>``,
``<point>``, ``<vector>``, ``<transform>`` (a ``<matrix>`` or a ``<lookat>``) and ``<ref>``; a
:class:`~harness.renderers.mitsuba_spec.Parameter` is written ``$name`` with its ``<default>`` at the top. Numbers
are the shortest repr that round-trips, so the XML holds exactly the spec's float64 values.

What the XML adds to ``mi.load_dict``'s form: a comment before each material, shape and emitter, and files where the
spec holds arrays: a :class:`~harness.renderers.mitsuba_spec.MeshFile` is a binary PLY (float32 vertices) and an
:class:`~harness.renderers.mitsuba_spec.ImageFile` an OpenEXR file (float32 RGB), each named by ``filename``.
"""

from __future__ import annotations

from xml.sax.saxutils import quoteattr

import numpy as np

from harness.files.imageio import encode_png, exr_bytes
from harness.renderers.meshfiles import ply_bytes
from harness.renderers.mitsuba_spec import (ImageFile, LookAt, MeshFile, MitsubaSpec, Parameter, Point, UVTransform,
                                            Vector)

INDENT = "    "
#: the category (XML element) of each Mitsuba plugin type a spec holds
CATEGORIES = {
    **dict.fromkeys(("path", "volpath", "moment", "aov"), "integrator"),
    **dict.fromkeys(("perspective", "thinlens", "orthographic"), "sensor"),
    "hdrfilm": "film",
    **dict.fromkeys(("box", "tent", "gaussian"), "rfilter"),
    **dict.fromkeys(("independent", "stratified", "multijitter", "orthogonal", "ldsampler"), "sampler"),
    **dict.fromkeys(("diffuse", "conductor", "roughconductor", "dielectric", "roughdielectric", "thindielectric",
                      "plastic", "roughplastic", "principled", "twosided", "normalmap", "bumpmap", "blendbsdf", "mask", "null"),
                     "bsdf"),
    **dict.fromkeys(("area", "point", "spot", "directional", "constant", "envmap"), "emitter"),
    **dict.fromkeys(("rectangle", "cube", "sphere", "ply"), "shape"),
    **dict.fromkeys(("bitmap", "checkerboard"), "texture"),
    "homogeneous": "medium",
    **dict.fromkeys(("isotropic", "hg"), "phase"),
}
TAGS = frozenset(CATEGORIES.values())


def spec_xml(spec: MitsubaSpec, header: str) -> tuple[str, dict[str, bytes]]:
    """The spec as an XML document, and the files it names.

    Parameters
    ----------
    spec : MitsubaSpec
        The scene's plugins and comments.
    header : str
        The comment on the document's first line after the declaration.

    Returns
    -------
    text : str
        The XML document.
    files : dict
        ``{path relative to the XML: bytes}`` of every mesh and image the spec holds, in the order named.
    """
    files: dict[str, bytes] = {}
    body = []
    for key, item in spec.plugins.items():
        if key == "type":
            continue
        if key in spec.comments:
            body.append(f"{INDENT}<!-- {spec.comments[key]} -->")
        body += _plugin(key, item, INDENT, files, top=True)
    lines = ['<?xml version="1.0" encoding="utf-8"?>', f"<!-- {header} -->", '<scene version="3.0.0">']
    lines += [f"{INDENT}<default name={quoteattr(p.name)} value={quoteattr(str(p.default))}/>"
              for p in _parameters(spec.plugins)]
    return "\n".join(lines + body + ["</scene>"]) + "\n", files


def _parameters(item) -> list[Parameter]:
    """Every :class:`Parameter` in a spec value, in the order written, each once."""
    if isinstance(item, Parameter):
        return [item]
    found: list[Parameter] = []
    if isinstance(item, dict):
        for value in item.values():
            found += [p for p in _parameters(value) if p not in found]
    return found


def _plugin(key: str, plugin: dict, indent: str, files: dict, top: bool = False) -> list[str]:
    """A plugin's element: its properties and nested plugins one level in."""
    tag = CATEGORIES[plugin["type"]]
    attrs = f"type={quoteattr(plugin['type'])}" + _label(key, tag, "id" if top else "name")
    lines = [f"{indent}<{tag} {attrs}>"]
    for name, value in plugin.items():
        if name != "type":
            lines += _property(name, value, indent + INDENT, files)
    return lines + [f"{indent}</{tag}>"]


def _label(key: str, tag: str, attribute: str) -> str:
    """`` id="key"`` (top level) or `` name="key"``; nothing where the key is the category's own name."""
    return "" if key == tag else f" {attribute}={quoteattr(key)}"


def _property(key: str, value, indent: str, files: dict) -> list[str]:
    """One property as XML lines; a file reference's bytes go into ``files``."""
    name = f"name={quoteattr(key)}"
    if isinstance(value, dict) and value["type"] == "rgb":
        return [f'{indent}<rgb {name} value="{_numbers(value["value"])}"/>']
    if isinstance(value, dict) and value["type"] == "ref":
        label = "" if key in TAGS and key != "medium" else f" {name}"  # a sensor's medium: named, as Mitsuba's docs
        return [f"{indent}<ref{label} id={quoteattr(value['id'])}/>"]
    if isinstance(value, dict):
        return _plugin(key, value, indent, files)
    if isinstance(value, LookAt) and value.scale is not None:  # the scale acts first: listed first
        return [f"{indent}<transform {name}>", f'{indent}{INDENT}<scale value="{_numbers(value.scale)}"/>',
                f"{indent}{INDENT}{_transform(value)}", f"{indent}</transform>"]
    if isinstance(value, (np.ndarray, LookAt)):
        return [f"{indent}<transform {name}>", f"{indent}{INDENT}{_transform(value)}", f"{indent}</transform>"]
    if isinstance(value, UVTransform):
        return [f"{indent}<transform {name}>", f"{indent}{INDENT}{_transform(value.as_4x4())}", f"{indent}</transform>"]
    if isinstance(value, (Point, Vector)):
        return [f'{indent}<{type(value).__name__.lower()} {name} value="{_numbers(value.xyz)}"/>']
    if isinstance(value, (MeshFile, ImageFile)):
        files[value.path] = _file_bytes(value)
        return [f"{indent}<string {name} value={quoteattr(value.path)}/>"]
    if isinstance(value, Parameter):
        return [f'{indent}<{_scalar_tag(value.default)} {name} value="${value.name}"/>']
    tag = _scalar_tag(value)
    if tag is None:
        raise TypeError(f"cannot write {key!r} = {value!r} as Mitsuba XML")
    return [f"{indent}<{tag} {name} value={quoteattr(_scalar_text(value))}/>"]


def _transform(value) -> str:
    """The element inside a ``<transform>``: a ``<lookat>`` or the row-major ``<matrix>``."""
    if isinstance(value, LookAt):
        origin, target, up = (_numbers(v) for v in (value.origin, value.target, value.up))
        return f'<lookat origin="{origin}" target="{target}" up="{up}"/>'
    matrix = np.asarray(value, dtype=np.float64).ravel()
    return f'<matrix value="{" ".join(_number(v) for v in matrix)}"/>'


def _file_bytes(reference) -> bytes:
    """A mesh as a binary PLY, an image as an OpenEXR file."""
    if isinstance(reference, MeshFile):
        return ply_bytes(reference.vertices, reference.triangles, reference.uv, reference.normals)
    if reference.image.dtype == np.uint8:
        return encode_png(reference.image)
    return exr_bytes(reference.image)


def _scalar_tag(value) -> str | None:
    """The element of a bool, int, float or string (None for anything else)."""
    for kind, tag in ((bool, "boolean"), ((int, np.integer), "integer"), ((float, np.floating), "float"),
                      (str, "string")):
        if isinstance(value, kind):
            return tag
    return None


def _scalar_text(value) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return _number(value)
    return value


def _number(value: float) -> str:
    """The shortest repr that round-trips."""
    return repr(float(value))


def _numbers(values) -> str:
    return ", ".join(_number(v) for v in values)
