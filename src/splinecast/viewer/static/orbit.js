// Orbit, zoom and pan of the camera with mouse, wheel and touch (pointer events).
//
// The camera state is the server's: {azimuth, elevation, zoom, pan: [x, y], fov, ortho}, angles
// in degrees, pan in view heights. Dragging right turns the object to the right (the camera
// moves left around it: azimuth decreases); dragging down tilts its top towards the viewer
// (elevation increases, clamped short of the poles). Right-drag, shift-drag, middle-drag or two
// fingers pan so the data follows the pointer; the wheel and a pinch zoom.
(function () {
  "use strict";
  const SC = (window.SC = window.SC || {});

  const DEGREES_PER_PIXEL = 0.4;
  const MAX_ELEVATION = 89.5;
  const ZOOM_LIMITS = [0.02, 200];

  function clamp(v, lo, hi) { return Math.min(hi, Math.max(lo, v)); }

  class OrbitControls {
    // element: the canvas; camera(): the current camera object (mutated in place);
    // onChange(interactive): called after every change (interactive false when input ends).
    constructor(element, camera, onChange) {
      this.element = element;
      this.camera = camera;
      this.onChange = onChange;
      this.pointers = new Map(); // pointerId -> {x, y}
      this.mode = null; // "orbit" | "pan" | "pinch"
      this.pinch = null;
      this.wheelTimer = null;
      element.addEventListener("pointerdown", (e) => this._down(e));
      element.addEventListener("pointermove", (e) => this._move(e));
      element.addEventListener("pointerup", (e) => this._up(e));
      element.addEventListener("pointercancel", (e) => this._up(e));
      element.addEventListener("wheel", (e) => this._wheel(e), { passive: false });
      element.addEventListener("contextmenu", (e) => e.preventDefault());
    }

    rotate(dAzimuth, dElevation) {
      const c = this.camera();
      c.azimuth = (((c.azimuth + dAzimuth) % 360) + 540) % 360 - 180;
      c.elevation = clamp(c.elevation + dElevation, -MAX_ELEVATION, MAX_ELEVATION);
    }

    zoomBy(factor) {
      const c = this.camera();
      c.zoom = clamp(c.zoom * factor, ZOOM_LIMITS[0], ZOOM_LIMITS[1]);
    }

    panBy(dxPixels, dyPixels) {
      const c = this.camera();
      const h = Math.max(1, this.element.clientHeight);
      c.pan = [c.pan[0] - dxPixels / h, c.pan[1] + dyPixels / h];
    }

    _down(e) {
      this.element.focus({ preventScroll: true });
      this.element.setPointerCapture(e.pointerId);
      this.pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
      if (this.pointers.size === 2) {
        this.mode = "pinch";
        this.pinch = this._pinchState();
      } else if (this.pointers.size === 1) {
        const pan = e.button === 1 || e.button === 2 || e.shiftKey;
        this.mode = pan ? "pan" : "orbit";
      }
      this.element.classList.add("dragging");
    }

    _pinchState() {
      const [a, b] = [...this.pointers.values()];
      return { d: Math.hypot(a.x - b.x, a.y - b.y), x: (a.x + b.x) / 2, y: (a.y + b.y) / 2 };
    }

    _move(e) {
      const p = this.pointers.get(e.pointerId);
      if (!p) return;
      const dx = e.clientX - p.x;
      const dy = e.clientY - p.y;
      p.x = e.clientX;
      p.y = e.clientY;
      if (this.mode === "orbit") {
        this.rotate(-dx * DEGREES_PER_PIXEL, dy * DEGREES_PER_PIXEL);
      } else if (this.mode === "pan") {
        this.panBy(dx, dy);
      } else if (this.mode === "pinch") {
        const now = this._pinchState();
        if (this.pinch.d > 0 && now.d > 0) this.zoomBy(now.d / this.pinch.d);
        this.panBy(now.x - this.pinch.x, now.y - this.pinch.y);
        this.pinch = now;
      } else {
        return;
      }
      if (dx !== 0 || dy !== 0 || this.mode === "pinch") this.onChange(true);
    }

    _up(e) {
      if (!this.pointers.has(e.pointerId)) return;
      this.pointers.delete(e.pointerId);
      if (this.element.hasPointerCapture(e.pointerId)) {
        this.element.releasePointerCapture(e.pointerId);
      }
      if (this.pointers.size === 1) {
        this.mode = "pan"; // one finger left after a pinch keeps panning, never jumps to orbit
        return;
      }
      if (this.pointers.size === 0) {
        this.mode = null;
        this.element.classList.remove("dragging");
        this.onChange(false); // released: the full-resolution frame now
      }
    }

    _wheel(e) {
      e.preventDefault();
      const lines = e.deltaMode === 1 ? 33 : e.deltaMode === 2 ? 400 : 1;
      this.zoomBy(Math.exp(-e.deltaY * lines * 0.0015));
      this.onChange(true); // the server sends the full frame once the wheel rests
    }
  }

  SC.OrbitControls = OrbitControls;
})();
