/* The comparison viewer's tone mapping: linear radiance x 2^EV through a tone curve, then the sRGB transfer
   function, to 8 bits. Curves: "clamp" (clip to [0, 1]: the harness's previews, harness.files.imageio.tonemap_srgb8)
   and "filmic" (Narkowicz's fit of the ACES filmic curve, "ACES Filmic Tone Mapping Curve", 2015: with the 0.6
   exposure factor of his post, x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14), clipped to [0, 1]). A pixel with a
   NaN channel is magenta, one with +Inf white, as in the previews. */
window.HarnessViewer = window.HarnessViewer || {};
(function (HV) {
  "use strict";

  function clamp01(v) { return v < 0 ? 0 : (v > 1 ? 1 : v); }

  /* sRGB's transfer function (IEC 61966-2-1) of a value in [0, 1], rounded to 8 bits. */
  function srgb8(v) {
    return Math.round(255 * (v <= 0.0031308 ? 12.92 * v : 1.055 * Math.pow(v, 1 / 2.4) - 0.055));
  }

  HV.toneCurves = {
    clamp: {label: "clamp sRGB", apply: clamp01},
    filmic: {label: "filmic (ACES, Narkowicz 2015)", apply: function (x) {
      x = Math.max(x, 0) * 0.6;
      return clamp01((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14));
    }}
  };

  /* RGB values (3 per pixel, `count` pixels) to RGBA bytes in `out`, at `ev` stops through the curve `name`. */
  HV.toneMap = function (rgb, count, ev, name, out) {
    var curve = (HV.toneCurves[name] || HV.toneCurves.clamp).apply, gain = Math.pow(2, ev);
    for (var p = 0; p < count; p++) {
      var r = rgb[3 * p], g = rgb[3 * p + 1], b = rgb[3 * p + 2], o = 4 * p;
      if (r !== r || g !== g || b !== b) {
        out[o] = 255; out[o + 1] = 0; out[o + 2] = 255;
      } else if (r === Infinity || g === Infinity || b === Infinity) {
        out[o] = 255; out[o + 1] = 255; out[o + 2] = 255;
      } else {
        out[o] = srgb8(curve(r * gain));
        out[o + 1] = srgb8(curve(g * gain));
        out[o + 2] = srgb8(curve(b * gain));
      }
      out[o + 3] = 255;
    }
    return out;
  };
}(window.HarnessViewer));
