/* The comparison viewer's data (docs/report.md, "The comparison viewer"). Each case's report/<case>/viewer.js,
   written by harness.files.viewer_data, is one call HarnessViewer.register({...}); HarnessViewer.load(key, src, done)
   adds the script element (src) that runs it (a page opened from file:// may load scripts beside it, not fetch files)
   and calls done(error, data). HarnessViewer.decodePlane turns a plane (base64 little-endian half floats scaled by
   2^exponent, float32, bytes, or all zeros) into a Float64Array. */
window.HarnessViewer = window.HarnessViewer || {};
(function (HV) {
  "use strict";
  var registry = Object.create(null);
  var waiting = Object.create(null);

  function settle(key, error, data) {
    var callbacks = waiting[key] || [];
    delete waiting[key];
    callbacks.forEach(function (done) { done(error, data); });
  }

  /* Called by a viewer.js: its data is kept under the key of the script element that loaded it (else its name). */
  HV.register = function (data) {
    var script = document.currentScript;
    var key = script && script.getAttribute("data-viewer-key");
    if (!key) { key = data && data.name; }
    registry[key] = data;
    settle(key, null, data);
  };

  HV.load = function (key, src, done) {
    if (key in registry) { done(null, registry[key]); return; }
    if (waiting[key]) { waiting[key].push(done); return; }
    waiting[key] = [done];
    var script = document.createElement("script");
    script.setAttribute("data-viewer-key", key);
    script.onload = function () {  // register() ran while the script ran: nothing is waiting any more
      if (waiting[key]) { settle(key, new Error(src + " did not register any data")); }
    };
    script.onerror = function () {
      script.parentNode.removeChild(script);
      settle(key, new Error("cannot load " + src + " (the report's files must stay beside its page)"));
    };
    script.src = src;
    document.head.appendChild(script);
  };

  var half = null;
  /* Every IEEE 754 half float, by its 16 bits. */
  function halfTable() {
    if (half) { return half; }
    half = new Float64Array(65536);
    for (var bits = 0; bits < 65536; bits++) {
      var sign = (bits & 0x8000) ? -1 : 1, exponent = (bits >> 10) & 0x1f, mantissa = bits & 0x3ff, value;
      if (exponent === 0) {
        value = mantissa * Math.pow(2, -24);
      } else if (exponent === 31) {
        value = mantissa ? NaN : Infinity;
      } else {
        value = (1 + mantissa / 1024) * Math.pow(2, exponent - 15);
      }
      half[bits] = sign * value;
    }
    return half;
  }

  function bytesOf(text) {
    var binary = atob(text), bytes = new Uint8Array(binary.length);
    for (var i = 0; i < binary.length; i++) { bytes[i] = binary.charCodeAt(i); }
    return bytes;
  }

  /* A plane of `count` values (pixels x channels) as a Float64Array; null where the plane is absent. */
  HV.decodePlane = function (plane, count) {
    if (!plane) { return null; }
    var out = new Float64Array(count), i;
    if (plane.encoding === "zero") { return out; }
    var bytes = bytesOf(plane.data);
    if (plane.encoding === "f16") {
      var table = halfTable(), scale = Math.pow(2, -plane.exponent);
      for (i = 0; i < count; i++) { out[i] = table[bytes[2 * i] | (bytes[2 * i + 1] << 8)] * scale; }
    } else if (plane.encoding === "f32") {
      var view = new DataView(bytes.buffer);
      for (i = 0; i < count; i++) { out[i] = view.getFloat32(4 * i, true); }
    } else if (plane.encoding === "u8") {
      for (i = 0; i < count; i++) { out[i] = bytes[i]; }
    } else {
      throw new Error("unknown plane encoding " + plane.encoding);
    }
    return out;
  };

  /* The decoded images of a case's data: {width, height, render, renderVar, truth, truthVar, flip, tiles}
     (variances are the squares of the stored standard deviations; absent planes are null). */
  HV.decode = function (data) {
    var w = data.width, h = data.height, n = w * h, planes = data.planes || {};
    function squared(values) {
      if (!values) { return null; }
      for (var i = 0; i < values.length; i++) { values[i] = values[i] * values[i]; }
      return values;
    }
    var images = {
      width: w, height: h, name: data.name, labels: data.labels || {}, exposure: data.exposure || 0,
      note: data.note || "",
      render: HV.decodePlane(planes.render, 3 * n),
      renderVar: squared(HV.decodePlane(planes.render_sd, 3 * n)),
      truth: HV.decodePlane(planes.truth, 3 * n),
      truthVar: squared(HV.decodePlane(planes.truth_sd, 3 * n)),
      flip: HV.decodePlane(planes.flip, n),
      tiles: null
    };
    var t = data.tiles;
    if (t) {
      var cells = t.rows * t.cols * 3;
      images.tiles = {
        size: t.size, rows: t.rows, cols: t.cols, alpha: t.alpha, threshold: t.threshold, count: t.count,
        zCritical: t.z_critical, recomputed: !!t.recomputed,
        z: HV.decodePlane(t.z, cells), p: HV.decodePlane(t.p, cells),
        tested: HV.decodePlane(t.tested, cells), failing: HV.decodePlane(t.failing, cells)
      };
    }
    return images;
  };
}(window.HarnessViewer));
