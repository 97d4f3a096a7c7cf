"""Plots of study data (convergence, shadow rays, strategies), drawn with matplotlib's Agg canvas (no pyplot state, no display), returned as PNG bytes."""

from __future__ import annotations

import io
import math

import numpy as np

DPI = 100


def _figure(width: float, height: float, layout: str | None = None):
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # optional: heavy matplotlib, loaded to draw
    from matplotlib.figure import Figure  # optional: heavy matplotlib, loaded to draw

    fig = Figure(figsize=(width, height), dpi=DPI, layout=layout)
    FigureCanvasAgg(fig)
    return fig


#: colours of a line plot's PNG: a palette of 256 (lines, markers, text and their anti-aliasing fit; the report
#: embeds every plot, and a palette PNG is about a quarter of the RGBA one: 3.4 -> 0.8 MB over the canonical run's
#: plots). Never for a figure that shows images: 256 colours turn a render's smooth shading into bands.
PLOT_COLOURS = 256


def to_png(fig, *, palette: bool = True) -> bytes:
    """The figure as PNG bytes: with ``palette`` (line plots) a palette PNG of :data:`PLOT_COLOURS` (Pillow's fast
    octree quantizer, no dithering); without it (any figure that shows images) lossless: :func:`lossless_png`."""
    from PIL import Image  # optional: Pillow (matplotlib's own dependency), loaded only to write a plot

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=DPI)
    rgb = Image.open(io.BytesIO(buffer.getvalue())).convert("RGB")
    if not palette:
        return lossless_png(np.asarray(rgb))
    quantized = rgb.quantize(colors=PLOT_COLOURS, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE)
    out = io.BytesIO()
    quantized.save(out, format="PNG", compress_level=9)
    return out.getvalue()


def lossless_png(pixels: np.ndarray) -> bytes:
    """``pixels`` (uint8 RGB) as a PNG that keeps every pixel: a palette of exactly its colours where it has at most
    256 (a grey panel: about 3/4 the size of full colour), else full-colour RGB."""
    from PIL import Image  # optional: Pillow (matplotlib's own dependency), loaded only to write a plot

    pixels = np.ascontiguousarray(pixels[..., :3], dtype=np.uint8)
    packed = (pixels[..., 0].astype(np.uint32) << 16) | (pixels[..., 1].astype(np.uint32) << 8) | pixels[..., 2]
    colours, index = np.unique(packed.ravel(), return_inverse=True)
    if len(colours) <= 256:
        image = Image.fromarray(index.reshape(packed.shape).astype(np.uint8), mode="P")
        image.putpalette(np.stack([colours >> 16, colours >> 8, colours], axis=1).astype(np.uint8).ravel().tolist())
    else:
        image = Image.fromarray(pixels, mode="RGB")
    out = io.BytesIO()
    image.save(out, format="PNG", compress_level=9, optimize=True)
    return out.getvalue()


def _colour(index: int):
    import matplotlib  # optional: heavy matplotlib, loaded to draw

    return matplotlib.colormaps["tab10"](index % 10)


def _plain_log_ticks(ax, axis: str = "both") -> None:
    """Log axes labelled 0.02, 0.05, 0.1 ... (at 1, 2 and 5 times powers of ten) rather than 2x10^-2."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter  # optional: heavy matplotlib, loaded to draw

    targets = [ax.xaxis, ax.yaxis] if axis == "both" else [ax.xaxis if axis == "x" else ax.yaxis]
    for a in targets:
        a.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
        a.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        a.set_minor_formatter(NullFormatter())


def _valid(xs, ys):
    pts = [(float(x), float(y)) for x, y in zip(xs, ys)
           if x is not None and y is not None and x > 0 and y > 0 and math.isfinite(x) and math.isfinite(y)]
    return [p[0] for p in pts], [p[1] for p in pts]


def convergence_figure(conv: dict, title: str = "") -> bytes:
    """RMSE and relMSE (GT-noise corrected) against spp and against render time, log-log, one colour per series;
    dashed: the fitted line of slope -1/2 (RMSE) or -1 (relMSE) anchored on the points before any departure; a ring
    marks the point where a curve leaves it (bias); dotted grey: the ground truth's noise floor."""
    fig = _figure(11.0, 7.6)
    axes = fig.subplots(2, 2)
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.08, top=0.92, wspace=0.22, hspace=0.3)
    panels = [
        (axes[0, 0], "spp", "rmse_corrected", "fit_rmse", "RMSE", -0.5),
        (axes[0, 1], "seconds", "rmse_corrected", "fit_rmse", "RMSE", -0.5),
        (axes[1, 0], "spp", "relmse_corrected", "fit_relmse", "relMSE", -1.0),
        (axes[1, 1], "seconds", "relmse_corrected", "fit_relmse", "relMSE", -1.0),
    ]
    for ax, xkey, ykey, fkey, yname, slope in panels:
        for i, s in enumerate(conv["series"]):
            pts = s["points"]
            xs, ys = _valid([p[xkey] for p in pts], [p[ykey] for p in pts])
            if not xs:
                continue
            colour = _colour(i)
            fit = s.get(fkey) or {}
            label = s["label"]
            if xkey == "spp" and fit.get("slope") is not None and math.isfinite(fit["slope"]):
                label += f" (slope {fit['slope']:.3f})"
            ax.plot(xs, ys, "o-", color=colour, label=label, markersize=4)
            _repeat_band(ax, pts, xkey, ykey, colour)
            if xkey == "spp" and fit.get("points", 0) >= 1:
                fx = np.asarray(fit["spp"], dtype=float)
                stop = fit["departure_index"] if fit.get("departure_index") is not None else len(fx)
                lookup = {float(p["spp"]): p[ykey] for p in pts if p[ykey] is not None and p[ykey] > 0}
                fy = np.array([lookup.get(float(v), np.nan) for v in fx])
                pre = np.isfinite(fy[:stop])
                if pre.any():
                    anchor = float(np.mean(np.log(fy[:stop][pre]) - slope * np.log(fx[:stop][pre])))
                    line_x = np.array([fx.min(), fx.max()])
                    ax.plot(line_x, np.exp(anchor + slope * np.log(line_x)), "--", color=colour, linewidth=1,
                            alpha=0.8)
                if fit.get("departure_spp") is not None:
                    dep_y = lookup.get(float(fit["departure_spp"]))
                    if dep_y is not None:
                        ax.plot([fit["departure_spp"]], [dep_y], "o", markersize=11, markerfacecolor="none",
                                markeredgecolor="red", markeredgewidth=1.8)
                        ax.annotate(f"bias from {fit['departure_spp']:g} spp", (fit["departure_spp"], dep_y),
                                    textcoords="offset points", xytext=(6, 8), fontsize=8, color="red")
            floor_key = "floor_mse" if yname == "RMSE" else "floor_relmse"
            floors = [p.get(floor_key) for p in pts if p.get(floor_key)]
            if floors:
                level = float(np.mean(floors))
                level = math.sqrt(level) if yname == "RMSE" else level
                if level > 0 and i == 0:
                    ax.axhline(level, color="grey", linestyle=":", linewidth=1, label="ground-truth noise")
        ax.set_xscale("log")
        ax.set_yscale("log")
        _plain_log_ticks(ax)
        ax.set_xlabel("samples per pixel" if xkey == "spp" else "render time [s]")
        ax.set_ylabel(yname)
        ax.grid(True, which="both", alpha=0.25)
        if ax is axes[0, 0] and ax.get_legend_handles_labels()[0]:  # none where every error is 0 (a closed form met)
            ax.legend(fontsize=8)
    fig.suptitle((title + ": " if title else "") + "errors with the ground truth's own noise removed")
    return to_png(fig)


def _repeat_band(ax, points: list[dict], xkey: str, ykey: str, colour) -> None:
    """The 10-90 % band of the K runs of each point (``repeats``: harness convergence --repeats), shaded: of RMSE
    (the root of each run's corrected MSE) or of relMSE."""
    source = "mse_corrected_band" if ykey == "rmse_corrected" else "relmse_corrected_band"
    xs, lows, highs = [], [], []
    for p in points:
        band = (p.get("repeats") or {}).get(source)
        x = p.get(xkey)
        if not band or x is None or not x > 0 or band[0] is None or band[1] is None:
            continue
        low, high = band
        if ykey == "rmse_corrected":
            low, high = math.sqrt(max(low, 0.0)), math.sqrt(max(high, 0.0))
        if high > 0:
            xs.append(float(x))
            lows.append(max(low, high * 1e-3))  # a log axis: a band reaching 0 is drawn to 1/1000 of its top
            highs.append(high)
    if len(xs) >= 2:
        order = np.argsort(xs)
        ax.fill_between(np.asarray(xs)[order], np.asarray(lows)[order], np.asarray(highs)[order], color=colour,
                        alpha=0.18, linewidth=0)


def spectrum_figure(conv: dict, title: str = "") -> bytes | None:
    """The error spectrum ensemble (harness convergence): for each series a panel of power against spatial
    frequency (log-log), one curve per rung (the mean over its runs and R, G, B), with the ground truth's own white
    noise (its floor, dashed grey) and the level of the renders' own variance estimate (dotted, per rung). None
    where no point has a spectrum."""
    series = [s for s in conv.get("series", []) if any(p.get("spectrum") for p in s.get("points", []))]
    if not series:
        return None
    fig = _figure(5.6 * min(len(series), 3), 4.4 * math.ceil(len(series) / 3), layout="constrained")
    axes = np.atleast_1d(fig.subplots(math.ceil(len(series) / 3), min(len(series), 3))).ravel()
    for ax, s in zip(axes, series):
        floor = None
        points = [p for p in s["points"] if p.get("spectrum")]
        for i, p in enumerate(points):
            spec = p["spectrum"]
            xs, ys = _valid(spec["frequency"], spec["power"])
            budget = p["budget"]
            label = f"{budget['spp']} spp" if "spp" in budget else f"{budget['seconds']:g} s"
            colour = matplotlib_colour(i, len(points))
            ax.plot(xs, ys, "-", color=colour, label=f"{label} (K = {spec['renders']})", linewidth=1.2)
            if spec.get("render_variance"):
                ax.axhline(spec["render_variance"], color=colour, linestyle=":", linewidth=0.8)
            floor = spec.get("floor")
        if floor:
            ax.axhline(floor, color="grey", linestyle="--", linewidth=1, label="ground-truth noise (floor)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("spatial frequency [cycles / pixel]")
        ax.set_ylabel("error power (mean over runs, R, G, B)")
        ax.set_title(s["label"], fontsize=10)
        ax.grid(True, which="both", alpha=0.25)
        ax.legend(fontsize=7)
    for ax in axes[len(series):]:
        ax.set_axis_off()
    fig.suptitle((title + ": " if title else "") + "error spectrum ensemble\n(flat: white noise; "
                 "rising to the left: structured error)", fontsize=10)
    return to_png(fig)


def matplotlib_colour(index: int, count: int):
    """A colour of the viridis map, from dark (first rung) to light (last)."""
    import matplotlib  # optional: heavy matplotlib, loaded to draw

    return matplotlib.colormaps["viridis"](0.85 * index / max(count - 1, 1))


def panel_figure(tiles: list[tuple[str, np.ndarray]], columns: int = 4, title: str = "") -> bytes:
    """A grid of images (uint8 RGB) with a title above each, like the slides' Figure 5.9."""
    rows = max(1, math.ceil(len(tiles) / columns))
    fig = _figure(2.6 * columns, 2.8 * rows + 0.4)
    axes = np.atleast_1d(fig.subplots(rows, columns)).ravel()
    fig.subplots_adjust(left=0.02, right=0.98, bottom=0.02, top=0.88 if title else 0.94, wspace=0.08, hspace=0.15)
    for ax, (name, pixels) in zip(axes, tiles):
        ax.imshow(pixels, interpolation="nearest")
        ax.set_title(name, fontsize=10)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in axes[len(tiles):]:
        ax.set_axis_off()
    if title:
        fig.suptitle(title)
    return to_png(fig, palette=False)  # images: full colour (a palette would band their shading)


def shadow_rays_figure(study: dict) -> bytes:
    """RMSE in the penumbra (GT noise removed) and render time against the number of shadow rays, log-log."""
    fig = _figure(11.0, 4.0)
    ax1, ax2 = fig.subplots(1, 2)
    fig.subplots_adjust(left=0.085, right=0.98, bottom=0.13, top=0.9, wspace=0.22)
    rows = study["rows"]
    xs, ys = _valid([r["shadow_rays"] for r in rows], [r["penumbra"]["rmse_corrected"] for r in rows])
    ax1.plot(xs, ys, "o-", color=_colour(0), label="RMSE in the penumbra")
    xa, ya = _valid([r["shadow_rays"] for r in rows], [r["image"]["rmse_corrected"] for r in rows])
    ax1.plot(xa, ya, "s-", color=_colour(1), alpha=0.7, label="RMSE, whole image")
    if xs:
        line = np.array([min(xs), max(xs)])
        ax1.plot(line, ys[0] * (line / xs[0]) ** -0.5, "--", color="grey", label="slope -1/2 from N = 1")
    fit = study.get("fit") or {}
    if fit.get("slope") is not None and math.isfinite(fit["slope"]):
        ax1.set_title(f"fitted slope {fit['slope']:.3f}", fontsize=10)
    ax1.set_xscale("log")
    ax1.set_yscale("log")
    _plain_log_ticks(ax1)
    ax1.set_xlabel("shadow rays per viewing ray (spp = 1)")
    ax1.set_ylabel("RMSE")
    ax1.grid(True, which="both", alpha=0.25)
    ax1.legend(fontsize=8)
    xt, yt = _valid([r["shadow_rays"] for r in rows], [r["seconds"] for r in rows])
    ax2.plot(xt, yt, "o-", color=_colour(2))
    ax2.set_xscale("log")
    ax2.set_yscale("log")
    _plain_log_ticks(ax2)
    ax2.set_xlabel("shadow rays per viewing ray (spp = 1)")
    ax2.set_ylabel("render time [s]")
    ax2.grid(True, which="both", alpha=0.25)
    return to_png(fig)


def strategies_figure(rows: list[dict], title: str = "", best: str | None = None) -> bytes:
    """Efficiency relative to the default, one horizontal bar per strategy (log scale) with its confidence interval
    where the row has one (``relative_efficiency_interval``), the ``best`` one (told apart from the others)
    highlighted."""
    usable = [r for r in rows if r.get("relative_efficiency") and r["relative_efficiency"] > 0]
    height = 0.42 * max(len(usable), 1) + 1.3
    fig = _figure(8.5, height)
    ax = fig.subplots()
    fig.subplots_adjust(left=0.3, right=0.95, bottom=0.75 / height, top=1 - 0.45 / height)
    if not usable:
        ax.text(0.5, 0.5, "no strategy could be measured", ha="center", va="center")
        ax.set_axis_off()
        return to_png(fig)
    labels = [r["label"] for r in usable]
    values = [r["relative_efficiency"] for r in usable]
    colours = ["#d62728" if r["label"] == best else ("#7f7f7f" if r.get("is_default") else "#1f77b4") for r in usable]
    y = np.arange(len(usable))
    ax.barh(y, values, color=colours)
    bounds = [(r.get("relative_efficiency_interval") or {}) for r in usable]
    ends = [(v - b["low"], b["high"] - v) if b.get("low") is not None and b.get("high") is not None else (0.0, 0.0)
            for v, b in zip(values, bounds)]
    ax.errorbar(values, y, xerr=np.array(ends).T, fmt="none", ecolor="black", elinewidth=0.8, capsize=2)
    ax.set_yticks(y, labels, fontsize=9)
    ax.invert_yaxis()
    ax.set_xscale("log")
    _plain_log_ticks(ax, "x")
    ax.axvline(1.0, color="black", linewidth=0.8)
    ax.set_xlabel("efficiency 1 / (MSE x time) at equal time relative to the default, 95 % interval (log scale)")
    for yi, v in zip(y, values):
        ax.annotate(f"{v:.3g}", (v, yi), textcoords="offset points", xytext=(3, -3), fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    return to_png(fig)
