/* The comparison viewer: its controls, wired to the data (viewer_data.js), tone curves (viewer_tonemap.js), maps
   (viewer_maps.js, viewer_colormaps.js), canvas (viewer_canvas.js) and probe (viewer_probe.js).

   Each case's "Open the comparison viewer" button ([data-open-viewer], hidden without scripts) names its data file
   (data-viewer-src) and the slot it opens in (aria-controls); the first click clones the page's
   <template id="harness-viewer-template"> into the slot and loads the data with a script element (src). A button with
   data-autoopen opens at load (harness view's page).

   Stable hooks (docs/report.md): the viewer's root [data-viewer] has data-state ("loading" | "ready" | "error"),
   data-current-mode (the mode's key), data-shown (what the canvas shows: "render", "truth", "side" or the map's
   key) and the instance as its harnessViewer property (pixelCenter(x, y) gives an image pixel's centre in CSS pixels of the
   canvas); buttons [data-mode=KEY] and [data-action="flip" | "fit" | "one" | "zoom-in" | "zoom-out"], the inputs
   [data-control="ev"] (a range, stops) and [data-control="curve"] ("clamp" | "filmic"), the checkboxes
   [data-option="hover-swap" | "outline"], the canvas [data-canvas] and the probe's cells [data-probe=KEY]. */
window.HarnessViewer = window.HarnessViewer || {};
(function (HV) {
  "use strict";
  var SINGLE = {render: "truth", truth: "render"};

  function Viewer(root, data) {
    this.root = root;
    this.images = HV.decode(data);
    var im = this.images;
    this.mode = "render";
    this.hovering = false;
    this.curve = "clamp";
    this.ev = Math.round((im.exposure || 0) * 10) / 10;
    this.cache = {};
    this.outline = this.failingTiles();
    this.canvas = root.querySelector("[data-canvas]");
    this.probeTable = root.querySelector("[data-probe-table]");
    this.caption = root.querySelector("[data-caption]");
    this.legend = root.querySelector("[data-legend]");
    var viewer = this;
    this.view = new HV.View(this.canvas, root, im.width, im.height, function () { viewer.showZoom(); });
    this.labels();
    this.bind();
    this.update();
    HV.probe(this.probeTable, im, null);
    root.harnessViewer = this;
    root.setAttribute("data-state", "ready");
  }

  /* The failing tiles as rectangles in image pixels (any channel failing). */
  Viewer.prototype.failingTiles = function () {
    var t = this.images.tiles, rects = [];
    if (!t) { return rects; }
    for (var row = 0; row < t.rows; row++) {
      for (var col = 0; col < t.cols; col++) {
        var k = 3 * (row * t.cols + col);
        if (t.failing[k] || t.failing[k + 1] || t.failing[k + 2]) {
          rects.push({x: col * t.size, y: row * t.size, w: Math.min(t.size, this.images.width - col * t.size),
                      h: Math.min(t.size, this.images.height - row * t.size)});
        }
      }
    }
    return rects;
  };

  Viewer.prototype.has = function (what) {
    var im = this.images;
    return what === "truth" ? !!im.truth : what === "tiles" ? !!im.tiles : what === "flip" ? !!im.flip : true;
  };

  /* Names, availability and the counts the controls show. */
  Viewer.prototype.labels = function () {
    var viewer = this, im = this.images, root = this.root;
    Array.prototype.forEach.call(root.querySelectorAll("[data-mode]"), function (button) {
      var key = button.getAttribute("data-mode");
      var needs = key === "truth" || key === "side" ? ["truth"] : (HV.maps[key] ? HV.maps[key].needs : []);
      var missing = needs.filter(function (n) { return !viewer.has(n); });
      if (missing.length) {
        button.disabled = true;
        button.title = "not available: this case has no " + missing.join(", ").replace("truth", "ground truth");
      }
    });
    if (!im.truth) { root.querySelector('[data-action="flip"]').disabled = true; }
    var outline = root.querySelector('[data-option="outline"]');
    if (!im.tiles) { outline.disabled = true; outline.checked = false; }
    var count = root.querySelector("[data-failing-count]");
    if (count) { count.textContent = im.tiles ? String(this.outline.length) : "\u2013"; }
    var ev = root.querySelector('[data-control="ev"]');
    ev.value = String(this.ev);
    var note = root.querySelector("[data-note]");
    if (note) {
      var parts = [im.note];
      if (im.tiles && im.tiles.recomputed) {
        parts.push("the tiles' z and p were computed again from the case's images (a run by an older harness)");
      }
      note.textContent = parts.filter(Boolean).join("; ");
    }
  };

  Viewer.prototype.bind = function () {
    var viewer = this, root = this.root;
    Array.prototype.forEach.call(root.querySelectorAll("[data-mode]"), function (button) {
      button.addEventListener("click", function () { viewer.setMode(button.getAttribute("data-mode")); });
    });
    root.querySelector('[data-action="flip"]').addEventListener("click", function () { viewer.flip(); });
    root.querySelector('[data-action="fit"]').addEventListener("click", function () { viewer.view.fit(); });
    root.querySelector('[data-action="one"]').addEventListener("click", function () { viewer.view.setScale(1); });
    root.querySelector('[data-action="zoom-in"]').addEventListener("click", function () { viewer.view.zoom(1); });
    root.querySelector('[data-action="zoom-out"]').addEventListener("click", function () { viewer.view.zoom(-1); });
    var ev = root.querySelector('[data-control="ev"]');
    ev.addEventListener("input", function () { viewer.ev = parseFloat(ev.value) || 0; viewer.update(); });
    var curve = root.querySelector('[data-control="curve"]');
    curve.addEventListener("change", function () { viewer.curve = curve.value; viewer.update(); });
    var hover = root.querySelector('[data-option="hover-swap"]');
    hover.addEventListener("change", function () { viewer.update(); });
    root.querySelector('[data-option="outline"]').addEventListener("change", function () { viewer.update(); });
    this.canvas.addEventListener("pointerenter", function () { viewer.hovering = true; viewer.update(); });
    this.canvas.addEventListener("pointerleave", function () { viewer.hovering = false; viewer.update(); });
    this.canvas.addEventListener("pointermove", function (event) {
      var at = viewer.view.local(event);
      HV.probe(viewer.probeTable, viewer.images, viewer.view.pixelAt(at.x, at.y));
    });
    root.addEventListener("keydown", function (event) {
      if (event.target.tagName === "INPUT" || event.target.tagName === "SELECT") { return; }
      var actions = {f: function () { viewer.flip(); }, "+": function () { viewer.view.zoom(1); },
                     "=": function () { viewer.view.zoom(1); }, "-": function () { viewer.view.zoom(-1); },
                     "0": function () { viewer.view.fit(); }, "1": function () { viewer.view.setScale(1); }};
      if (actions[event.key]) { event.preventDefault(); actions[event.key](); }
    });
  };

  Viewer.prototype.setMode = function (mode) {
    this.mode = mode;
    this.update();
  };

  /* Between the render and the ground truth (from any other mode: to the ground truth). */
  Viewer.prototype.flip = function () {
    if (!this.images.truth) { return; }
    this.setMode(this.mode === "truth" ? "render" : "truth");
  };

  /* What the canvas shows now: the mode, with render and truth exchanged while the pointer hovers with hover-swap. */
  Viewer.prototype.shown = function () {
    var hover = this.root.querySelector('[data-option="hover-swap"]').checked;
    if (SINGLE[this.mode] && hover && this.hovering && this.images.truth) { return SINGLE[this.mode]; }
    return this.mode;
  };

  /* An offscreen canvas holding `key` ("render", "truth" at the current EV and curve, or a map). */
  Viewer.prototype.source = function (key) {
    var im = this.images, map = HV.maps[key];
    var id = map ? key : key + "|" + this.ev + "|" + this.curve;
    if (this.cache[id]) { return this.cache[id]; }
    var canvas = document.createElement("canvas");
    canvas.width = im.width;
    canvas.height = im.height;
    var ctx = canvas.getContext("2d"), pixels = ctx.createImageData(im.width, im.height);
    if (map) {
      var m = map.compute(im);
      HV.colorize(m.values, m.low, m.high, m.cmap, pixels.data, m.missing);
      canvas.legend = m;
    } else {
      HV.toneMap(key === "truth" ? im.truth : im.render, im.width * im.height, this.ev, this.curve, pixels.data);
    }
    ctx.putImageData(pixels, 0, 0);
    if (!map) {  // keep the tone-mapped images of the last setting only
      var stale = Object.keys(this.cache).filter(function (k) { return k.indexOf("|") >= 0 && k !== id; });
      stale.forEach(function (k) { delete this.cache[k]; }, this);
    }
    this.cache[id] = canvas;
    return canvas;
  };

  Viewer.prototype.update = function () {
    var im = this.images, shown = this.shown(), root = this.root;
    var outline = root.querySelector('[data-option="outline"]').checked ? this.outline : null;
    this.view.setPanes(shown === "side" ? 2 : 1);
    var sources = shown === "side" ? [this.source("render"), this.source("truth")] : [this.source(shown)];
    this.view.setSources(sources, outline);
    root.setAttribute("data-current-mode", this.mode);
    root.setAttribute("data-shown", shown);
    Array.prototype.forEach.call(root.querySelectorAll("[data-mode]"), function (button) {
      button.setAttribute("aria-pressed", String(button.getAttribute("data-mode") === this.mode));
    }, this);
    root.querySelector("[data-ev-value]").textContent = (this.ev >= 0 ? "+" : "") + this.ev.toFixed(1);
    var curve = HV.toneCurves[this.curve].label, exposure = "EV " + (this.ev >= 0 ? "+" : "") + this.ev.toFixed(1);
    var labels = im.labels, map = HV.maps[shown], text;
    if (shown === "side") {
      text = "left: render (" + (labels.render || "") + "), right: ground truth (" + (labels.truth || "") + "); " +
             exposure + ", " + curve;
    } else if (map) {
      text = map.title + ": " + this.cache[shown].legend.description;
    } else {
      text = (shown === "truth" ? "Ground truth" : "Render") + " (" +
             ((shown === "truth" ? labels.truth : labels.render) || "") + "); " + exposure + ", " + curve;
    }
    this.caption.textContent = text;
    this.showLegend(map ? this.cache[shown].legend : null);
  };

  Viewer.prototype.showLegend = function (m) {
    this.legend.hidden = !m;
    if (!m) { return; }
    this.legend.querySelector(".bar").style.background = HV.gradient(m.cmap);
    var ticks = this.legend.querySelectorAll(".ticks span");
    for (var i = 0; i < ticks.length; i++) { ticks[i].textContent = m.ticks[i] || ""; }
  };

  Viewer.prototype.showZoom = function () {
    if (!this.view) { return; }  // the view draws once while it is made
    var out = this.root.querySelector("[data-zoom-value]"), s = this.view.scale;
    if (out) { out.textContent = (s >= 1 ? s + ":1" : "1:" + Math.round(1 / s)) + " zoom"; }
  };

  /* The centre of image pixel (x, y) in CSS pixels of the canvas (first pane): for tests and scripts. */
  Viewer.prototype.pixelCenter = function (x, y) { return this.view.pixelCenter(x, y, 0); };

  HV.Viewer = Viewer;

  /* Open (or close) the viewer a button controls. */
  function toggle(button) {
    var slot = document.getElementById(button.getAttribute("aria-controls"));
    if (!slot) { return; }
    var open = button.getAttribute("aria-expanded") === "true";
    button.setAttribute("aria-expanded", String(!open));
    button.textContent = open ? "Open the comparison viewer" : "Close the viewer";
    slot.hidden = open;
    if (open || slot.firstElementChild) { return; }
    var template = document.getElementById("harness-viewer-template");
    var root = document.importNode(template.content, true).firstElementChild;
    slot.appendChild(root);
    var status = root.querySelector("[data-status]"), src = button.getAttribute("data-viewer-src");
    root.setAttribute("data-state", "loading");
    status.textContent = "loading " + src + " \u2026";
    HV.load(button.getAttribute("data-viewer-key"), src, function (error, data) {
      if (error) {
        root.setAttribute("data-state", "error");
        status.textContent = error.message;
        return;
      }
      try {
        new Viewer(root, data);
        status.textContent = "";
      } catch (err) {
        root.setAttribute("data-state", "error");
        status.textContent = "this case's viewer data could not be read: " + err.message;
        if (window.console) { console.error(err); }  // a fault of the page's own code: let the console say so
      }
    });
  }

  Array.prototype.forEach.call(document.querySelectorAll("[data-open-viewer]"), function (button) {
    button.hidden = false;
    button.addEventListener("click", function () { toggle(button); });
    if (button.hasAttribute("data-autoopen")) { toggle(button); }
  });
}(window.HarnessViewer));
