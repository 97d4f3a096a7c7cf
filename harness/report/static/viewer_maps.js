/* The comparison viewer's false-colour maps, computed in the page from the decoded images (viewer_data.js):
   - error_signed: render - ground truth, mean over R, G, B; RdBu_r, symmetric limits at the 99th percentile of |v|
     (red: the render is brighter), as the report's PNG map (harness.files.previews.error_images);
   - error_relative: |render - ground truth| / (|ground truth| + 0.01), mean over R, G, B (MAPE's terms); viridis,
     0 to its 99th percentile;
   - tile_z: each tile's Welch z (the verdict's, on the normal scale) in the channel of largest |z|; RdBu_r,
     symmetric limits one above the z a tile needs to fail by itself (marked in the legend); untested tiles grey;
   - pvalue: each tile's -log10 p, the smallest two-sided p over its tested channels; magma from 0 to 8; untested
     tiles grey;
   - flip_map: the HDR-FLIP map of the run's comparison; magma from 0 to 1.
   HarnessViewer.maps[key].compute(images) returns {values (one per pixel), low, high, cmap, missing, ticks,
   description}. */
window.HarnessViewer = window.HarnessViewer || {};
(function (HV) {
  "use strict";
  var GREY = [128, 128, 128];
  var RELATIVE_EPS = 0.01;
  var PVALUE_TOP = 8;

  /* The `q`-th percentile of |values| over finite values (linear interpolation, as numpy's); else the largest,
     else 1: harness.files.previews.robust_limit. */
  HV.robustLimit = function (values, q) {
    var finite = [];
    for (var i = 0; i < values.length; i++) {
      if (isFinite(values[i])) { finite.push(Math.abs(values[i])); }
    }
    if (!finite.length) { return 1; }
    var sorted = Float64Array.from(finite).sort(), at = (sorted.length - 1) * q / 100;
    var lo = Math.floor(at), hi = Math.min(lo + 1, sorted.length - 1);
    var limit = sorted[lo] + (sorted[hi] - sorted[lo]) * (at - lo);
    if (!(limit > 0)) { limit = sorted[sorted.length - 1]; }
    return limit > 0 ? limit : 1;
  };

  function fmt(v) {
    return Math.abs(v) >= 1e4 || (v !== 0 && Math.abs(v) < 1e-3) ? v.toExponential(2) : String(+v.toPrecision(3));
  }

  function perPixel(images, compute) {
    var n = images.width * images.height, out = new Float64Array(n);
    for (var p = 0; p < n; p++) { out[p] = compute(3 * p); }
    return out;
  }

  /* For each pixel, its tile's value: pick(tileIndex) over the tile's three channels, NaN where untested. */
  function perTile(images, pick) {
    var t = images.tiles, w = images.width, h = images.height, out = new Float64Array(w * h);
    var byTile = new Float64Array(t.rows * t.cols);
    for (var k = 0; k < byTile.length; k++) { byTile[k] = pick(3 * k); }
    for (var y = 0; y < h; y++) {
      var row = Math.floor(y / t.size) * t.cols;
      for (var x = 0; x < w; x++) { out[y * w + x] = byTile[row + Math.floor(x / t.size)]; }
    }
    return out;
  }

  HV.maps = {
    error_signed: {
      title: "Signed error", needs: ["truth"],
      compute: function (im) {
        var r = im.render, t = im.truth;
        var values = perPixel(im, function (i) {
          return ((r[i] - t[i]) + (r[i + 1] - t[i + 1]) + (r[i + 2] - t[i + 2])) / 3;
        });
        var lim = HV.robustLimit(values, 99);
        return {values: values, low: -lim, high: lim, cmap: "RdBu_r", ticks: [fmt(-lim), "0", fmt(lim)],
                description: "render - ground truth, mean over R, G, B; red: render brighter; limits \u00b1" +
                             fmt(lim) + " (the 99th percentile of |error|)"};
      }
    },
    error_relative: {
      title: "Relative error", needs: ["truth"],
      compute: function (im) {
        var r = im.render, t = im.truth;
        var values = perPixel(im, function (i) {
          var s = 0;
          for (var c = 0; c < 3; c++) { s += Math.abs(r[i + c] - t[i + c]) / (Math.abs(t[i + c]) + RELATIVE_EPS); }
          return s / 3;
        });
        var lim = HV.robustLimit(values, 99);
        return {values: values, low: 0, high: lim, cmap: "viridis", ticks: ["0", fmt(lim / 2), fmt(lim)],
                description: "|render - ground truth| / (|ground truth| + 0.01), mean over R, G, B (MAPE's terms); " +
                             "limits 0.." + fmt(lim) + " (the 99th percentile)"};
      }
    },
    tile_z: {
      title: "Tile z", needs: ["tiles"],
      compute: function (im) {
        var t = im.tiles, crit = t.zCritical || 4, lim = Math.ceil(crit) + 1;
        var values = perTile(im, function (k) {
          var best = NaN;
          for (var c = 0; c < 3; c++) {
            if (t.tested[k + c] && !(Math.abs(t.z[k + c]) <= Math.abs(best))) { best = t.z[k + c]; }
          }
          return best;
        });
        return {values: values, low: -lim, high: lim, cmap: "RdBu_r", missing: GREY,
                ticks: [String(-lim), "0", String(lim)],
                description: "each " + t.size + " x " + t.size + " tile's Welch z in its channel of largest |z| " +
                             "(red: render brighter); a tile fails by itself beyond |z| = " + fmt(crit) +
                             " (" + t.count + " tested tile-channels); grey: not tested"};
      }
    },
    pvalue: {
      title: "Tile p-value", needs: ["tiles"],
      compute: function (im) {
        var t = im.tiles;
        var values = perTile(im, function (k) {
          var p = Infinity;
          for (var c = 0; c < 3; c++) { if (t.tested[k + c]) { p = Math.min(p, t.p[k + c]); } }
          return p === Infinity ? NaN : -Math.log10(Math.max(p, 1e-300));
        });
        return {values: values, low: 0, high: PVALUE_TOP, cmap: "magma", missing: GREY,
                ticks: ["p = 1", "1e-4", "\u2264 1e-8"],
                description: "-log10 of each tile's two-sided p-value (the smallest over R, G, B); uniform p " +
                             "when the images agree, so most tiles stay dark; grey: not tested"};
      }
    },
    flip_map: {
      title: "FLIP", needs: ["flip"],
      compute: function (im) {
        return {values: im.flip, low: 0, high: 1, cmap: "magma", ticks: ["0", "0.5", "1"],
                description: "HDR-FLIP error map of the run's comparison (flip-evaluator), 0..1"};
      }
    }
  };
}(window.HarnessViewer));
