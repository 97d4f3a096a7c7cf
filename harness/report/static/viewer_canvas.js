/* The comparison viewer's canvas: one pane, or two side by side that share zoom and pan; images drawn with
   nearest-neighbour pixels (no smoothing) at zoom levels from 1/8 to 64 screen pixels per image pixel; the failing
   tiles outlined. Drag to pan, the wheel zooms about the cursor, a double click fits. Positions are CSS pixels of
   the canvas; HarnessViewer.View#pixelAt maps one to an image pixel, #pixelCenter an image pixel to one. */
window.HarnessViewer = window.HarnessViewer || {};
(function (HV) {
  "use strict";
  var LEVELS = [0.125, 0.25, 0.5, 1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64];
  var GAP = 8;
  var OUTLINE = "#00ffff";

  function View(canvas, container, width, height, onChange) {
    this.canvas = canvas;
    this.container = container;  // the element whose width the panes share
    this.width = width;          // the image's pixels
    this.height = height;
    this.onChange = onChange || function () {};
    this.panes = 1;
    this.sources = [];           // one offscreen canvas per pane, each width x height
    this.outline = null;         // [{x, y, w, h}] in image pixels
    this.scale = 1;
    this.offsetX = 0;
    this.offsetY = 0;
    this.layout(1);
    this.fit();
    this.bind();
  }

  /* The pane size: 512 CSS pixels wide (less where the container is narrower), the image's aspect within limits. */
  View.prototype.layout = function (panes) {
    var available = (this.container && this.container.clientWidth - 24) || 1024;
    this.panes = panes;
    this.paneWidth = Math.max(160, Math.min(512, Math.floor((available - GAP * (panes - 1)) / panes)));
    this.paneHeight = Math.max(160, Math.min(640, Math.round(this.paneWidth * this.height / this.width)));
    var cssWidth = this.paneWidth * panes + GAP * (panes - 1), ratio = window.devicePixelRatio || 1;
    this.canvas.style.width = cssWidth + "px";
    this.canvas.style.height = this.paneHeight + "px";
    if (this.canvas.parentNode) { this.canvas.parentNode.style.width = cssWidth + "px"; }  // captions wrap to it
    this.canvas.width = Math.round(cssWidth * ratio);
    this.canvas.height = Math.round(this.paneHeight * ratio);
  };

  View.prototype.setPanes = function (panes) {
    if (panes !== this.panes) {
      var fitted = this.isFitted();
      this.layout(panes);
      if (fitted) { this.fit(); }
    }
  };

  View.prototype.fitScale = function () {
    var s = Math.min(this.paneWidth / this.width, this.paneHeight / this.height);
    return s >= 1 ? Math.floor(s) : s;
  };

  View.prototype.isFitted = function () { return this.scale === this.fitScale(); };

  /* The largest scale at which the whole image fits in a pane (whole screen pixels per image pixel where it is
     at least 1), centred. */
  View.prototype.fit = function () {
    var s = this.fitScale();
    this.scale = s;
    this.offsetX = Math.round((this.paneWidth - this.width * s) / 2);
    this.offsetY = Math.round((this.paneHeight - this.height * s) / 2);
    this.draw();
  };

  /* Zoom to `scale`, keeping the image point under (cx, cy) in the pane (default: its centre) where it is. */
  View.prototype.setScale = function (scale, cx, cy) {
    if (cx === undefined) {
      cx = this.paneWidth / 2;
      cy = this.paneHeight / 2;
    }
    var ix = (cx - this.offsetX) / this.scale, iy = (cy - this.offsetY) / this.scale;
    this.scale = scale;
    this.offsetX = Math.round(cx - ix * scale);
    this.offsetY = Math.round(cy - iy * scale);
    this.draw();
  };

  /* One zoom level in (`steps` > 0) or out, about (cx, cy) in the pane. */
  View.prototype.zoom = function (steps, cx, cy) {
    var i = 0;
    while (i < LEVELS.length - 1 && LEVELS[i] < this.scale - 1e-9) { i++; }
    if (steps > 0 && LEVELS[i] <= this.scale + 1e-9) { i = Math.min(LEVELS.length - 1, i + 1); }
    if (steps < 0) { i = Math.max(0, i - 1); }
    this.setScale(LEVELS[i], cx, cy);
  };

  View.prototype.setSources = function (sources, outline) {
    this.sources = sources;
    this.outline = outline;
    this.draw();
  };

  View.prototype.draw = function () {
    var ctx = this.canvas.getContext("2d"), ratio = this.canvas.width / parseFloat(this.canvas.style.width);
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = "#3a3a3a";
    ctx.fillRect(0, 0, this.canvas.width, this.canvas.height);
    for (var pane = 0; pane < this.panes; pane++) {
      var left = pane * (this.paneWidth + GAP);
      ctx.save();
      ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
      ctx.beginPath();
      ctx.rect(left, 0, this.paneWidth, this.paneHeight);
      ctx.clip();
      ctx.imageSmoothingEnabled = false;
      var source = this.sources[pane];
      if (source) {
        ctx.drawImage(source, left + this.offsetX, this.offsetY, this.width * this.scale, this.height * this.scale);
      }
      if (this.outline && this.outline.length) {
        ctx.strokeStyle = OUTLINE;
        ctx.lineWidth = this.scale >= 4 ? 2 : 1;
        var s = this.scale;
        this.outline.forEach(function (r) {
          ctx.strokeRect(left + this.offsetX + r.x * s + 0.5, this.offsetY + r.y * s + 0.5,
                         Math.max(r.w * s - 1, 1), Math.max(r.h * s - 1, 1));
        }, this);
      }
      ctx.restore();
    }
    this.onChange();
  };

  /* The image pixel under (px, py), CSS pixels of the canvas: {x, y, pane}, or null outside the image. */
  View.prototype.pixelAt = function (px, py) {
    var pane = Math.floor(px / (this.paneWidth + GAP));
    var lx = px - pane * (this.paneWidth + GAP);
    if (pane < 0 || pane >= this.panes || lx > this.paneWidth) { return null; }
    var x = Math.floor((lx - this.offsetX) / this.scale), y = Math.floor((py - this.offsetY) / this.scale);
    if (x < 0 || y < 0 || x >= this.width || y >= this.height) { return null; }
    return {x: x, y: y, pane: pane};
  };

  /* The centre of image pixel (x, y) in CSS pixels of the canvas (in pane `pane`, default 0). */
  View.prototype.pixelCenter = function (x, y, pane) {
    return {x: (pane || 0) * (this.paneWidth + GAP) + this.offsetX + (x + 0.5) * this.scale,
            y: this.offsetY + (y + 0.5) * this.scale};
  };

  View.prototype.local = function (event) {
    var box = this.canvas.getBoundingClientRect();
    return {x: event.clientX - box.left, y: event.clientY - box.top};
  };

  View.prototype.bind = function () {
    var view = this, drag = null;
    this.canvas.addEventListener("pointerdown", function (event) {
      drag = {x: event.clientX, y: event.clientY, ox: view.offsetX, oy: view.offsetY};
      if (view.canvas.setPointerCapture) { view.canvas.setPointerCapture(event.pointerId); }
    });
    this.canvas.addEventListener("pointermove", function (event) {
      if (drag) {
        view.offsetX = drag.ox + event.clientX - drag.x;
        view.offsetY = drag.oy + event.clientY - drag.y;
        view.draw();
      }
    });
    function end() { drag = null; }
    this.canvas.addEventListener("pointerup", end);
    this.canvas.addEventListener("pointercancel", end);
    this.canvas.addEventListener("wheel", function (event) {
      event.preventDefault();
      var at = view.local(event), pane = Math.max(0, Math.floor(at.x / (view.paneWidth + GAP)));
      view.zoom(event.deltaY < 0 ? 1 : -1, at.x - pane * (view.paneWidth + GAP), at.y);
    }, {passive: false});
    this.canvas.addEventListener("dblclick", function () { view.fit(); });
  };

  HV.View = View;
  HV.zoomLevels = LEVELS;
}(window.HarnessViewer));
