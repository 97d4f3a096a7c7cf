/* The comparison viewer's colour maps: matplotlib's RdBu_r, viridis and magma (the report's PNG maps use the same,
   harness.files.previews), each as 33 colours evenly spaced over [0, 1] and interpolated linearly between them
   (tests/report/test_viewer.py checks them against matplotlib). HarnessViewer.colorize writes RGBA bytes of a
   scalar map: non-finite values in `missing` (default magenta, as the PNG maps), values outside [low, high]
   clipped. */
window.HarnessViewer = window.HarnessViewer || {};
(function (HV) {
  "use strict";
  var STOPS = {
    RdBu_r: "053061 0e4179 175290 1f63a8 2a71b2 3480b9 3f8ec0 529dc8 6bacd1 84bcd9 9bc9e0 aed3e6 c2ddec d4e6f1 " +
            "e0ecf3 ecf2f5 f7f6f6 f9eee7 fbe5d8 fddcc9 fbccb4 f8bb9e f5aa89 ee9677 e48066 db6b55 d05548 c53e3d " +
            "ba2832 ab162a 930e26 7c0722 67001f",
    viridis: "440154 470d60 48186a 482374 472d7b 453781 424086 3e4989 3b528b 375b8d 33638d 2f6b8e 2c728e 297a8e " +
             "26828e 23898e 21918c 1f988b 1fa088 22a785 28ae80 32b67a 3fbc73 4ec36b 5ec962 70cf57 84d44b 98d83e " +
             "addc30 c2df23 d8e219 ece51b fde725",
    magma: "000004 030312 0a0822 130d34 1d1147 29115a 36106b 440f76 51127c 5d177f 6a1c81 762181 832681 902a81 " +
           "9c2e7f aa337d b73779 c43c75 d0416f dc4869 e75263 ef5d5e f56b5c f9795d fc8961 fd9869 fea772 feb67c " +
           "fec488 fed395 fde2a3 fcf0b2 fcfdbf"
  };
  var tables = {};
  Object.keys(STOPS).forEach(function (name) {
    tables[name] = STOPS[name].split(" ").map(function (hex) {
      return [parseInt(hex.slice(0, 2), 16), parseInt(hex.slice(2, 4), 16), parseInt(hex.slice(4, 6), 16)];
    });
  });
  HV.colormapNames = Object.keys(STOPS);

  /* The colour of t in [0, 1] in the map `name`: [r, g, b] bytes. */
  HV.colour = function (name, t) {
    var table = tables[name], last = table.length - 1;
    var x = (t < 0 ? 0 : (t > 1 ? 1 : t)) * last, i = Math.min(Math.floor(x), last - 1), f = x - i;
    var a = table[i], b = table[i + 1];
    return [Math.round(a[0] + (b[0] - a[0]) * f), Math.round(a[1] + (b[1] - a[1]) * f),
            Math.round(a[2] + (b[2] - a[2]) * f)];
  };

  /* CSS for a legend's bar: the map as a linear gradient, left to right. */
  HV.gradient = function (name) {
    return "linear-gradient(to right, " + tables[name].map(function (c) {
      return "rgb(" + c.join(",") + ")";
    }).join(", ") + ")";
  };

  HV.colorize = function (values, low, high, name, out, missing) {
    var span = high - low, miss = missing || [255, 0, 255];
    for (var p = 0; p < values.length; p++) {
      var v = values[p], o = 4 * p, c;
      c = isFinite(v) ? HV.colour(name, span > 0 ? (v - low) / span : 0.5) : miss;
      out[o] = c[0]; out[o + 1] = c[1]; out[o + 2] = c[2]; out[o + 3] = 255;
    }
    return out;
  };
}(window.HarnessViewer));
