"""The report's HTML, from Jinja2 templates (``harness/report/templates/*.html.j2``): one self-contained page, inline
CSS, images as base64 PNG data URIs, no external resources; the suite page's scripts are the package's own,
inline (:func:`static_script`): ``static/summary.js`` (the summary table's filters and sorting) and the comparison
viewer's ``static/viewer_*.js`` (:mod:`harness.report.viewer`), with its style ``static/viewer.css``
(:func:`static_style`). The viewer loads each case's data from ``report/<case>/viewer.js`` when it is opened.

Autoescape is on, and every value a template writes with ``{{ ... }}`` that is not markup made by a template is
escaped by the engine with :func:`html.escape` (quotes too; None writes nothing): the templates never mark a string
from a suite, scene, results file or renderer as safe. Filters: ``fmt`` (numbers for tables), ``pct``.
"""

from __future__ import annotations

import base64
import functools
import html
import math
import re
from importlib import resources
from typing import Any

import jinja2
from markupsafe import Markup

from harness.files.previews import ReportImage

#: a legend's colour stops go into a style attribute: only plain hex colours are written there
_HEX_COLOUR = re.compile(r"#[0-9a-fA-F]{6}")


def fmt(value: Any, digits: int = 4) -> str:
    """A number for a table: ``digits`` significant digits, '–' for None / non-finite; other values as text."""
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return "–"
        return f"{value:.{digits}g}"
    return str(value)


def _fmt_filter(value: Any, digits: int = 4) -> Any:
    """``fmt`` for templates: markup made by a template (a macro's output) is left as it is."""
    return value if isinstance(value, Markup) else fmt(value, digits)


def pct(value: Any, digits: int = 0) -> str:
    """A fraction as a percentage (0.05 -> "5%"); '–' where it is not a finite number."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return "–"
    return f"{value:.{digits}%}"


def _escape(value: Any) -> Any:
    """The engine's escaping of every written value (``finalize``): :func:`html.escape` with quotes, None as
    nothing; template markup (macros, included sections) as it is."""
    if isinstance(value, Markup) or hasattr(value, "__html__"):
        return value
    return Markup(html.escape("" if value is None else str(value), quote=True))


class _TemplateCache(jinja2.FileSystemBytecodeCache):
    """Jinja2's cache of compiled templates, in its folder of the user's temporary folder (made private by Jinja2),
    each entry under the template's name and checked against the SHA-1 of its source: the report's templates are
    compiled once, not on every ``harness report`` (a tenth of its own time, docs/performance.md). It only speeds:
    an entry that cannot be read is a miss, one that cannot be written is not kept, never an error."""

    def load_bytecode(self, bucket: jinja2.bccache.Bucket) -> None:
        try:
            super().load_bytecode(bucket)
        except Exception:  # noqa: BLE001 - a damaged entry (pickle, marshal, I/O errors) is a miss
            bucket.reset()

    def dump_bytecode(self, bucket: jinja2.bccache.Bucket) -> None:
        try:
            super().dump_bytecode(bucket)
        except OSError:  # a full or read-only temporary folder: compiled again next time
            pass


def _template_cache() -> _TemplateCache | None:
    """The templates' cache, or None where no private folder can be had (Jinja2 refuses a shared one)."""
    try:
        return _TemplateCache()
    except (OSError, RuntimeError):
        return None


ENV = jinja2.Environment(
    loader=jinja2.PackageLoader("harness.report", "templates"),
    bytecode_cache=_template_cache(),
    autoescape=True,
    finalize=_escape,
    undefined=jinja2.StrictUndefined,
    trim_blocks=True,
    lstrip_blocks=True,
    keep_trailing_newline=True,
)
ENV.filters["fmt"] = _fmt_filter
ENV.filters["pct"] = pct


def render(template: str, **context: Any) -> Markup:
    """The template ``template`` (a name under templates/) rendered with ``context``: markup, safe to include in
    another template."""
    return Markup(ENV.get_template(template).render(**context))


@functools.cache
def static_script(name: str) -> Markup:
    """The package's script ``static/<name>`` as markup for an inline ``<script>`` (a file of the package, never
    of a run: nothing in it is escaped; it must not hold ``</script``)."""
    text = resources.files("harness.report").joinpath("static", name).read_text(encoding="utf-8")
    if "</script" in text.lower():
        raise ValueError(f"static/{name} holds '</script': it cannot be inlined")
    return Markup(text)


@functools.cache
def static_style(name: str) -> Markup:
    """The package's style sheet ``static/<name>`` as markup for an inline ``<style>`` (a file of the package: nothing
    in it is escaped; it must not hold ``</style``)."""
    text = resources.files("harness.report").joinpath("static", name).read_text(encoding="utf-8")
    if "</style" in text.lower():
        raise ValueError(f"static/{name} holds '</style': it cannot be inlined")
    return Markup(text)


def data_uri(png: bytes) -> str:
    """PNG bytes as a ``data:`` URI (the page embeds every image)."""
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def legend_view(spec: Any) -> dict | None:
    """A heat map's legend for the templates: its colour stops (hex colours only) and its limits."""
    if not isinstance(spec, dict):
        return None
    stops = [c for c in spec.get("stops") or [] if isinstance(c, str) and _HEX_COLOUR.fullmatch(c)]
    low, high = spec.get("vmin"), spec.get("vmax")
    numbers = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (low, high))
    return {"stops": ", ".join(stops) or "#000000, #ffffff", "vmin": low, "vmax": high,
            "mid": (low + high) / 2 if numbers else None}


def figure_view(image: ReportImage, link_base: str | None = None, width: int = 200, pixelated: bool = True) -> dict:
    """A report image for the ``image_figure`` macro: its data URI, title, legend, description and links to its
    EXR and PNG files (``link_base`` + file name)."""
    links = None
    if link_base is not None and image.exr is not None and image.png_path is not None:
        links = {"exr": link_base + image.exr.name, "png": link_base + image.png_path.name}
    return {"uri": data_uri(image.png), "title": image.title, "description": image.description,
            "legend": legend_view(image.legend), "links": links, "width": int(width), "pixelated": pixelated}
