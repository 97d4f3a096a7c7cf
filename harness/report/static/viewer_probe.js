/* The comparison viewer's probe: the numbers under the cursor. For image pixel (x, y): the render's and the ground
   truth's values (R, G, B, as decoded: float16 precision) and their variances (of the means), the pixel's z per
   channel, (render - truth) / sqrt(var render + var truth), its tile (row, column) with the verdict's z and
   two-sided p per channel (untested channels "–") and whether it fails by itself, and the FLIP value. Each cell
   [data-probe=KEY] gets the text and, in data-values, the numbers in full (space-separated, "NaN" for none): the
   hook the browser test reads. */
window.HarnessViewer = window.HarnessViewer || {};
(function (HV) {
  "use strict";

  function text(v) {
    if (v === null || v === undefined || v !== v) { return "\u2013"; }
    if (!isFinite(v)) { return v > 0 ? "+inf" : "-inf"; }
    var a = Math.abs(v);
    return a !== 0 && (a < 1e-3 || a >= 1e5) ? v.toExponential(4) : String(+v.toPrecision(5));
  }

  function triple(values, i) {
    return values ? [values[i], values[i + 1], values[i + 2]] : null;
  }

  function set(table, key, values, label) {
    var cell = table.querySelector('[data-probe="' + key + '"]');
    if (!cell) { return; }
    cell.textContent = label !== undefined ? label : (values ? values.map(text).join(", ") : "\u2013");
    cell.setAttribute("data-values", values ? values.map(function (v) { return String(v); }).join(" ") : "");
  }

  /* Fill `table` for pixel (x, y) of `images` (HarnessViewer.decode); a null pixel empties it. */
  HV.probe = function (table, images, pixel) {
    var keys = ["pixel", "render", "render_var", "truth", "truth_var", "pixel_z", "tile", "tile_z", "tile_p",
                "flip"];
    if (!pixel) {
      keys.forEach(function (key) { set(table, key, null, "\u2013"); });
      table.removeAttribute("data-x");
      table.removeAttribute("data-y");
      return;
    }
    var x = pixel.x, y = pixel.y, i = 3 * (y * images.width + x);
    table.setAttribute("data-x", String(x));
    table.setAttribute("data-y", String(y));
    set(table, "pixel", [x, y], "x " + x + ", y " + y);
    var r = triple(images.render, i), rv = triple(images.renderVar, i);
    var t = triple(images.truth, i), tv = triple(images.truthVar, i);
    set(table, "render", r);
    set(table, "render_var", rv);
    set(table, "truth", t);
    set(table, "truth_var", tv);
    var z = null;
    if (r && t && rv && tv) {
      z = [0, 1, 2].map(function (c) {
        var s = Math.sqrt(rv[c] + tv[c]);
        return s > 0 ? (r[c] - t[c]) / s : NaN;
      });
    }
    set(table, "pixel_z", z);
    var tiles = images.tiles;
    if (tiles) {
      var row = Math.floor(y / tiles.size), col = Math.floor(x / tiles.size), k = 3 * (row * tiles.cols + col);
      var failing = tiles.failing[k] || tiles.failing[k + 1] || tiles.failing[k + 2];
      set(table, "tile", [row, col], "row " + row + ", column " + col + " (pixels " + col * tiles.size + "\u2013" +
          (Math.min((col + 1) * tiles.size, images.width) - 1) + ", " + row * tiles.size + "\u2013" +
          (Math.min((row + 1) * tiles.size, images.height) - 1) + ")" + (failing ? ": fails" : ""));
      var tz = [0, 1, 2].map(function (c) { return tiles.tested[k + c] ? tiles.z[k + c] : NaN; });
      var tp = [0, 1, 2].map(function (c) { return tiles.tested[k + c] ? tiles.p[k + c] : NaN; });
      set(table, "tile_z", tz);
      set(table, "tile_p", tp);
    } else {
      ["tile", "tile_z", "tile_p"].forEach(function (key) { set(table, key, null); });
    }
    set(table, "flip", images.flip ? [images.flip[y * images.width + x]] : null);
  };
}(window.HarnessViewer));
