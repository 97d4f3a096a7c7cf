"""Assembling one self-contained HTML page: inline CSS, images as base64 PNG data URIs, no scripts, no external
resources. Every string that comes from a suite, scene, results file or renderer goes through :func:`esc`."""

from __future__ import annotations

import html
import math
from collections.abc import Iterable, Sequence
from typing import Any

from harness.files.previews import ReportImage


class Raw(str):
    """HTML that is already safe (built here from escaped parts); every other string is escaped."""


def esc(value: Any) -> str:
    """``html.escape`` of ``str(value)`` (quotes too), unless it is :class:`Raw`."""
    if isinstance(value, Raw):
        return str(value)
    return html.escape("" if value is None else str(value), quote=True)


def fmt(value: Any, digits: int = 4) -> str:
    """A number for a table: ``digits`` significant digits, '-' for None / non-finite; other values as text."""
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


def cell(value: Any, digits: int = 4) -> Raw:
    return Raw(esc(fmt(value, digits)) if not isinstance(value, Raw) else value)


def table(headers: Sequence[Any], rows: Iterable[Sequence[Any]], cls: str = "") -> Raw:
    """An HTML table; every header and cell is escaped (numbers formatted by :func:`fmt`) unless :class:`Raw`."""
    head = "".join(f"<th>{cell(h)}</th>" for h in headers)
    body = "".join("<tr>" + "".join(f"<td>{cell(v)}</td>" for v in row) + "</tr>" for row in rows)
    klass = f' class="{esc(cls)}"' if cls else ""
    return Raw(f"<table{klass}><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")


def kv_table(pairs: Iterable[tuple[Any, Any]]) -> Raw:
    """A two-column table of names and values."""
    body = "".join(f"<tr><th>{cell(k)}</th><td>{cell(v)}</td></tr>" for k, v in pairs)
    return Raw(f'<table class="kv"><tbody>{body}</tbody></table>')


def badge(status: str, ok: bool | None = None) -> Raw:
    klass = {"pass": "pass", "fail": "fail", "error": "error"}.get(str(status), "other")
    text = esc(status)
    if ok is not None:
        text += " (as expected)" if ok else " (NOT as expected)"
        klass += " ok" if ok else " bad"
    return Raw(f'<span class="badge {klass}">{text}</span>')


def legend(spec: dict | None) -> Raw:
    """A colour bar in CSS (linear gradient through the colormap's stops) with its limits."""
    if not spec:
        return Raw("")
    stops = ", ".join(esc(c) for c in spec["stops"])
    mid = (spec["vmin"] + spec["vmax"]) / 2
    return Raw(
        f'<div class="legend"><div class="bar" style="background: linear-gradient(to right, {stops});"></div>'
        f'<div class="ticks"><span>{esc(fmt(spec["vmin"], 3))}</span><span>{esc(fmt(mid, 3))}</span>'
        f'<span>{esc(fmt(spec["vmax"], 3))}</span></div></div>'
    )


def image_figure(image: ReportImage, width: int = 200, link_base: str | None = None, pixelated: bool = True) -> Raw:
    """<figure> with the embedded PNG, its title, legend, description and links to its EXR and PNG files."""
    klass = ' class="px"' if pixelated else ""
    links = ""
    if link_base is not None and image.exr is not None:
        links = (f'<div class="files"><a href="{esc(link_base + image.exr.name)}">EXR</a> · '
                 f'<a href="{esc(link_base + image.png_path.name)}">PNG</a></div>') if image.png_path else ""
    return Raw(
        f'<figure class="img"><img{klass} src="{image.data_uri()}" width="{int(width)}" alt="{esc(image.title)}">'
        f"<figcaption><b>{esc(image.title)}</b>{legend(image.legend)}"
        f'<div class="desc">{esc(image.description)}</div>{links}</figcaption></figure>'
    )


def plot_figure(png_uri: str, alt: str, caption: str = "", width: int | None = None) -> Raw:
    w = f' width="{int(width)}"' if width else ""
    cap = f"<figcaption>{esc(caption)}</figcaption>" if caption else ""
    return Raw(f'<figure class="plot"><img src="{esc(png_uri)}"{w} alt="{esc(alt)}">{cap}</figure>')


def details(summary: Any, body: Any, open_: bool = False) -> Raw:
    flag = " open" if open_ else ""
    return Raw(f"<details{flag}><summary>{esc(summary)}</summary>{esc(body)}</details>")


def pre(text: Any) -> Raw:
    return Raw(f"<pre>{esc(text)}</pre>")


CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, Helvetica, Arial, sans-serif; margin: 0 auto;
       max-width: 1400px; padding: 1em 2em; color: #1b1b1b; background: #fdfdfd; line-height: 1.4; }
h1 { margin-bottom: 0.2em; } h2 { border-bottom: 2px solid #ddd; padding-bottom: 0.2em; margin-top: 2em; }
h3 { margin-top: 1.6em; } .muted, .desc { color: #666; font-size: 0.85em; }
nav { background: #f3f3f3; padding: 0.5em 1em; border-radius: 6px; font-size: 0.9em; }
nav a { margin-right: 1em; }
table { border-collapse: collapse; margin: 0.6em 0; font-size: 0.85em; }
th, td { border: 1px solid #ddd; padding: 0.25em 0.5em; text-align: left; vertical-align: top; }
thead th { background: #f0f0f0; } table.kv th { background: #fafafa; font-weight: 600; }
td { font-variant-numeric: tabular-nums; }
.badge { padding: 0.1em 0.5em; border-radius: 4px; font-weight: 600; font-size: 0.85em; }
.badge.pass { background: #d9f2dd; color: #1e6b2d; } .badge.fail { background: #f9dcdc; color: #8a1c1c; }
.badge.error { background: #fde9c8; color: #7a4a00; } .badge.bad { outline: 2px solid #c00; }
.images { display: flex; flex-wrap: wrap; gap: 14px; align-items: flex-start; }
figure { margin: 0; } figure.img { width: 210px; } figure.img img { border: 1px solid #ccc; display: block; }
img.px { image-rendering: pixelated; image-rendering: crisp-edges; }
figure.plot img { max-width: 100%; height: auto; border: 1px solid #eee; }
figcaption { font-size: 0.85em; margin-top: 0.3em; }
.legend .bar { height: 10px; border: 1px solid #aaa; margin-top: 3px; }
.legend .ticks { display: flex; justify-content: space-between; font-size: 0.75em; color: #444; }
.files { font-size: 0.8em; } .case { border-top: 1px solid #e5e5e5; margin-top: 1.5em; }
.columns { display: flex; flex-wrap: wrap; gap: 1.5em; } .columns > div { flex: 1 1 340px; min-width: 0; }
.columns table { width: 100%; } td { overflow-wrap: anywhere; } table.kv th { white-space: nowrap; }
table.summary td { overflow-wrap: normal; white-space: nowrap; } table.summary td:last-child { white-space: normal; }
.badge { white-space: nowrap; } pre { background: #f6f6f6; padding: 0.6em; overflow-x: auto;
       font-size: 0.8em; white-space: pre-wrap; }
.note { background: #f7f7ff; border-left: 4px solid #99c; padding: 0.4em 0.8em; font-size: 0.9em; }
.warn { background: #fff6e5; border-left: 4px solid #e0a030; padding: 0.4em 0.8em; font-size: 0.9em; }
"""


def page(title: str, body: Iterable[Any], subtitle: Any = "") -> str:
    """The whole document. ``body`` parts are escaped unless :class:`Raw`."""
    parts = "\n".join(esc(b) for b in body)
    sub = f'<p class="muted">{esc(subtitle)}</p>' if subtitle else ""
    return (
        "<!DOCTYPE html>\n"
        '<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{esc(title)}</title><style>{CSS}</style></head>\n"
        f"<body><h1>{esc(title)}</h1>{sub}\n{parts}\n</body></html>\n"
    )
