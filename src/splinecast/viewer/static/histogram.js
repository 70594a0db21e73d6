// The value histogram drawn behind the sliders, and the transfer-function editor drawn over it.
// Both map data values to x over the histogram's range [lo, hi] (data units, as everywhere).
(function () {
  "use strict";
  const SC = (window.SC = window.SC || {});

  // Match a canvas's backing store to its CSS size (sharp on high-DPI screens).
  function fitCanvas(canvas) {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(canvas.clientWidth * dpr));
    const h = Math.max(1, Math.round(canvas.clientHeight * dpr));
    if (canvas.width !== w || canvas.height !== h) {
      canvas.width = w;
      canvas.height = h;
    }
    return { w, h, dpr };
  }

  function rgb(c) {
    return `rgb(${Math.round(c[0] * 255)},${Math.round(c[1] * 255)},${Math.round(c[2] * 255)})`;
  }

  class Histogram {
    // hist: {lo, hi, counts} from the server's hello message.
    constructor(canvas, hist) {
      this.canvas = canvas;
      this.hist = hist;
      // Counts span orders of magnitude (background voxels): draw log(1 + count).
      const logs = hist.counts.map((c) => Math.log1p(c));
      const top = Math.max(...logs, 1e-9);
      this.heights = logs.map((v) => v / top);
    }

    get lo() { return this.hist.lo; }
    get hi() { return this.hist.hi; }

    valueToFraction(v) { return (v - this.lo) / (this.hi - this.lo); }
    fractionToValue(f) { return this.lo + f * (this.hi - this.lo); }

    // Draw the bars; options: markers [{value, color, width}], window [lo, hi], gradient [[r,g,b]].
    draw(options = {}) {
      const { w, h, dpr } = fitCanvas(this.canvas);
      const ctx = this.canvas.getContext("2d");
      ctx.clearRect(0, 0, w, h);
      if (options.gradient) {
        const g = options.gradient;
        for (let i = 0; i < g.length; i++) {
          ctx.fillStyle = rgb(g[i]);
          const x0 = Math.floor((i / g.length) * w);
          const x1 = Math.ceil(((i + 1) / g.length) * w);
          ctx.fillRect(x0, h - 6 * dpr, x1 - x0, 6 * dpr);
        }
      }
      if (options.window) {
        const a = this.valueToFraction(options.window[0]) * w;
        const b = this.valueToFraction(options.window[1]) * w;
        ctx.fillStyle = "rgba(232, 180, 90, 0.12)";
        ctx.fillRect(Math.min(a, b), 0, Math.abs(b - a), h);
      }
      const n = this.heights.length;
      ctx.fillStyle = "#5b5b6b";
      for (let i = 0; i < n; i++) {
        const x0 = (i / n) * w;
        const bar = this.heights[i] * (h - 8 * dpr);
        ctx.fillRect(x0, h - 6 * dpr - bar, Math.max(1, w / n - 0.5), bar);
      }
      for (const m of options.markers || []) {
        const x = this.valueToFraction(m.value) * w;
        ctx.fillStyle = m.color || "#e8b45a";
        ctx.fillRect(x - ((m.width || 2) * dpr) / 2, 0, (m.width || 2) * dpr, h);
      }
    }
  }

  // Opacity control points (value, alpha) dragged over the histogram. The y axis shows
  // sqrt(alpha): useful per-voxel opacities are small, and a square root spreads them out.
  class TransferFunctionEditor {
    constructor(canvas, hist, onChange) {
      this.canvas = canvas;
      this.histogram = new Histogram(canvas, hist);
      this.onChange = onChange; // onChange(interactive)
      this.points = [];
      this.gradient = null;
      this.dragging = -1;
      this.radius = 6;
      canvas.addEventListener("pointerdown", (e) => this._down(e));
      canvas.addEventListener("pointermove", (e) => this._move(e));
      canvas.addEventListener("pointerup", (e) => this._up(e));
      canvas.addEventListener("pointercancel", (e) => this._up(e));
      canvas.addEventListener("dblclick", (e) => this._remove(e));
      canvas.addEventListener("contextmenu", (e) => { e.preventDefault(); this._remove(e); });
    }

    set(points, gradient) {
      this.points = points.map((p) => [p[0], p[1]]);
      this.gradient = gradient;
      this.draw();
    }

    _xy(p) {
      const { w, h, dpr } = fitCanvas(this.canvas);
      const x = this.histogram.valueToFraction(p[0]) * w;
      const y = (1 - Math.sqrt(Math.max(0, Math.min(1, p[1])))) * (h - 8 * dpr) + 4 * dpr;
      return [x, y];
    }

    _point(e) {
      const r = this.canvas.getBoundingClientRect();
      const f = Math.min(1, Math.max(0, (e.clientX - r.left) / r.width));
      const g = Math.min(1, Math.max(0, 1 - (e.clientY - r.top - 4) / (r.height - 8)));
      return [this.histogram.fractionToValue(f), g * g];
    }

    _hit(e) {
      const r = this.canvas.getBoundingClientRect();
      const dpr = this.canvas.width / r.width;
      const mx = (e.clientX - r.left) * dpr;
      const my = (e.clientY - r.top) * dpr;
      let best = -1;
      let bestD = (this.radius + 4) * dpr;
      this.points.forEach((p, i) => {
        const [x, y] = this._xy(p);
        const d = Math.hypot(x - mx, y - my);
        if (d < bestD) { best = i; bestD = d; }
      });
      return best;
    }

    _down(e) {
      if (e.button !== 0) return;
      let i = this._hit(e);
      if (i < 0) {
        const p = this._point(e);
        i = this.points.findIndex((q) => q[0] > p[0]);
        if (i < 0) i = this.points.length;
        this.points.splice(i, 0, p);
      }
      this.dragging = i;
      this.canvas.setPointerCapture(e.pointerId);
      this.draw();
      this.onChange(true);
    }

    _move(e) {
      if (this.dragging < 0) return;
      const i = this.dragging;
      const p = this._point(e);
      // A point stays between its neighbours, so the values stay in increasing order.
      const lo = i > 0 ? this.points[i - 1][0] : -Infinity;
      const hi = i < this.points.length - 1 ? this.points[i + 1][0] : Infinity;
      this.points[i] = [Math.min(hi, Math.max(lo, p[0])), p[1]];
      this.draw();
      this.onChange(true);
    }

    _up(e) {
      if (this.dragging < 0) return;
      this.dragging = -1;
      if (this.canvas.hasPointerCapture(e.pointerId)) this.canvas.releasePointerCapture(e.pointerId);
      this.onChange(false);
    }

    _remove(e) {
      const i = this._hit(e);
      if (i >= 0 && this.points.length > 1) {
        this.points.splice(i, 1);
        this.draw();
        this.onChange(false);
      }
    }

    draw() {
      this.histogram.draw({ gradient: this.gradient });
      const ctx = this.canvas.getContext("2d");
      const { w, dpr } = fitCanvas(this.canvas);
      if (!this.points.length) return;
      ctx.strokeStyle = "#e8b45a";
      ctx.lineWidth = 1.5 * dpr;
      ctx.beginPath();
      const first = this._xy(this.points[0]);
      ctx.moveTo(0, first[1]);
      for (const p of this.points) {
        const [x, y] = this._xy(p);
        ctx.lineTo(x, y);
      }
      ctx.lineTo(w, this._xy(this.points[this.points.length - 1])[1]);
      ctx.stroke();
      ctx.fillStyle = "#e8b45a";
      for (const p of this.points) {
        const [x, y] = this._xy(p);
        ctx.beginPath();
        ctx.arc(x, y, (this.radius / 1.5) * dpr, 0, 2 * Math.PI);
        ctx.fill();
      }
    }
  }

  SC.fitCanvas = fitCanvas;
  SC.Histogram = Histogram;
  SC.TransferFunctionEditor = TransferFunctionEditor;
})();
