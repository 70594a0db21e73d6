// The control panel: every widget reads and writes the render state, then calls
// onChange(interactive) — true while a slider or point is being dragged, false when it is let go
// or a value is chosen. The lists of models, modes and colormaps come from the server's hello
// message, so the page offers exactly what the library has; whether a combination works is the
// server's to say (its error appears on the page).
(function () {
  "use strict";
  const SC = (window.SC = window.SC || {});
  const SLIDER_STEPS = 1000;

  function $(id) { return document.getElementById(id); }

  function fill(select, names) {
    select.replaceChildren(...names.map((n) => new Option(n, n)));
  }

  function format(v) {
    const a = Math.abs(v);
    if (a !== 0 && (a >= 1e5 || a < 1e-3)) return v.toExponential(3);
    return String(Number(v.toPrecision(5)));
  }

  class Controls {
    constructor(hello, state, onChange) {
      this.hello = hello;
      this.state = state;
      this.onChange = onChange;
      const hist = hello.histogram;
      this.lo = hist.lo;
      this.hi = hist.hi;
      this.bounds = hello.volume.bounds; // [[x0, y0, z0], [x1, y1, z1]] world
      this.isoHistogram = new SC.Histogram($("iso-histogram"), hist);
      this.windowHistogram = new SC.Histogram($("window-histogram"), hist);
      this.tfEditor = new SC.TransferFunctionEditor($("tf-editor"), hist, (interactive) => {
        this.state.tf.opacity = this.tfEditor.points.map((p) => [p[0], p[1]]);
        this.onChange(interactive);
      });
      this.surfaces = [];
      this.selected = 0;
      this._buildSelectors();
      this._buildTime();
      this._buildIso();
      this._buildWindow();
      this._buildDvr();
      this._buildClip();
      this._buildLighting();
      this._buildChannels();
      this._buildLabels();
      $("ortho").addEventListener("change", (e) => {
        this.state.camera.ortho = e.target.checked;
        this.onChange(false);
      });
      $("volume-name").textContent = `${hello.volume.name} · ${hello.volume.shape.join("×")} ` +
        `${hello.volume.dtype}`;
      this.sync();
    }

    // Value <-> slider position over the histogram's range.
    toSlider(v) { return Math.round(((v - this.lo) / (this.hi - this.lo)) * SLIDER_STEPS); }
    fromSlider(s) { return this.lo + (Number(s) / SLIDER_STEPS) * (this.hi - this.lo); }

    // ------------------------------------------------------------------ model and mode
    _buildSelectors() {
      fill($("model"), this.hello.models);
      fill($("mode"), this.hello.modes);
      $("model").addEventListener("change", (e) => { this.state.model = e.target.value; this.onChange(false); });
      $("mode").addEventListener("change", (e) => this.setMode(e.target.value));
    }

    setMode(mode) {
      this.state.mode = mode;
      this.sync();
      this.onChange(false);
    }

    // ------------------------------------------------------------------ time points
    // A time series (hello.timepoints > 1, protocol 1.4) gets a slider; the time point is sent
    // when the slider is let go (each one is read from the file: no request per step of a drag).
    _buildTime() {
      const count = this.hello.timepoints || 1;
      const slider = $("time-slider");
      $("section-time").hidden = count <= 1;
      slider.max = String(Math.max(0, count - 1));
      slider.addEventListener("input", () => this._drawTime(Number(slider.value)));
      slider.addEventListener("change", () => this.setTime(Number(slider.value)));
    }

    setTime(timepoint) {
      const count = this.hello.timepoints || 1;
      const t = Math.min(count - 1, Math.max(0, Math.round(timepoint)));
      if (t === (this.state.timepoint || 0)) { this._drawTime(t); return; }
      this.state.timepoint = t;
      $("time-slider").value = String(t);
      this._drawTime(t);
      this.onChange(false);
    }

    stepTime(direction) { this.setTime((this.state.timepoint || 0) + direction); }

    _drawTime(t) {
      const count = this.hello.timepoints || 1;
      $("time-label").textContent = `${t} of 0–${count - 1}`;
    }

    // ------------------------------------------------------------------ isosurfaces
    _buildIso() {
      const slider = $("iso-slider");
      slider.addEventListener("input", () => this.setIso(this.fromSlider(slider.value), true));
      slider.addEventListener("change", () => this.setIso(this.fromSlider(slider.value), false));
      $("iso-value").addEventListener("change", (e) => {
        const v = Number(e.target.value);
        if (Number.isFinite(v)) this.setIso(Math.min(this.hi, Math.max(this.lo, v)), false);
      });
      $("add-surface").addEventListener("click", () => {
        const current = this.surfaces[this.selected];
        const span = this.hi - this.lo;
        const value = Math.min(this.hi, current.value + 0.1 * span);
        // Surfaces nest: the ones already there become translucent so the new one shows.
        for (const s of this.surfaces) s.opacity = Math.min(s.opacity, 0.4);
        this.surfaces.push({ value, opacity: 1 });
        this.selected = this.surfaces.length - 1;
        this._applySurfaces();
        this.onChange(false);
      });
    }

    setIso(value, interactive) {
      this.surfaces[this.selected].value = value;
      this._applySurfaces(!interactive);
      this.onChange(interactive);
    }

    stepIso(direction) {
      const s = this.surfaces[this.selected];
      this.setIso(Math.min(this.hi, Math.max(this.lo, s.value + direction * 0.01 * (this.hi - this.lo))), false);
    }

    _applySurfaces(rebuild = true) {
      const s = this.surfaces;
      if (s.length === 1) {
        this.state.iso = s[0].value;
        this.state.opacity = null;
      } else {
        this.state.iso = s.map((x) => x.value);
        this.state.opacity = s.map((x) => x.opacity);
      }
      $("iso-slider").value = this.toSlider(s[this.selected].value);
      $("iso-value").value = format(s[this.selected].value);
      if (rebuild) this._surfaceList();
      else this._surfaceValues();
      this._drawIso();
    }

    _surfaceList() {
      const list = $("surfaces");
      list.replaceChildren();
      if (this.surfaces.length < 2) return;
      this.surfaces.forEach((s, i) => {
        const li = document.createElement("li");
        li.className = i === this.selected ? "selected" : "";
        const value = document.createElement("span");
        value.className = "value";
        value.textContent = format(s.value);
        const opacity = document.createElement("input");
        opacity.type = "range";
        opacity.min = "0";
        opacity.max = "100";
        opacity.value = String(Math.round(s.opacity * 100));
        opacity.title = "opacity";
        opacity.addEventListener("input", () => { s.opacity = opacity.value / 100; this._applySurfaces(false); this.onChange(true); });
        opacity.addEventListener("change", () => this.onChange(false));
        const remove = document.createElement("button");
        remove.type = "button";
        remove.textContent = "×";
        remove.title = "remove this surface";
        remove.addEventListener("click", (e) => {
          e.stopPropagation();
          this.surfaces.splice(i, 1);
          this.selected = Math.min(this.selected, this.surfaces.length - 1);
          this._applySurfaces();
          this.onChange(false);
        });
        li.addEventListener("click", () => { this.selected = i; this._applySurfaces(); });
        li.append(value, opacity, remove);
        list.append(li);
      });
    }

    _surfaceValues() {
      const spans = $("surfaces").querySelectorAll(".value");
      spans.forEach((span, i) => { span.textContent = format(this.surfaces[i].value); });
    }

    _drawIso() {
      this.isoHistogram.draw({
        markers: this.surfaces.map((s, i) => ({
          value: s.value, color: i === this.selected ? "#e8b45a" : "#8fa6d6", width: 2,
        })),
      });
    }

    // ------------------------------------------------------------------ MIP window
    _buildWindow() {
      fill($("mip-colormap"), Object.keys(this.hello.colormaps));
      const low = $("window-low");
      const high = $("window-high");
      const update = (which, interactive) => {
        let a = Number(low.value);
        let b = Number(high.value);
        if (a >= b) { // keep lo < hi: push the other handle
          if (which === "low") {
            b = Math.min(SLIDER_STEPS, a + 1);
            a = b - 1;
          } else {
            a = Math.max(0, b - 1);
            b = a + 1;
          }
          low.value = a;
          high.value = b;
        }
        this.state.window = [this.fromSlider(a), this.fromSlider(b)];
        this._drawWindow();
        this.onChange(interactive);
      };
      low.addEventListener("input", () => update("low", true));
      high.addEventListener("input", () => update("high", true));
      low.addEventListener("change", () => update("low", false));
      high.addEventListener("change", () => update("high", false));
      $("mip-colormap").addEventListener("change", (e) => {
        this.state.colormap = e.target.value;
        this._drawWindow();
        this.onChange(false);
      });
      // The tolerance in levels of an 8-bit image (k / 255 of the window): the slider's frame
      // is the settled one, so only its release asks for a frame (previews leave it out).
      const tolerance = $("mip-tolerance");
      tolerance.addEventListener("input", () => this._drawTolerance(Number(tolerance.value)));
      tolerance.addEventListener("change", () => {
        this.state.tolerance = Number(tolerance.value) / 255;
        this._drawTolerance(Number(tolerance.value));
        this.onChange(false);
      });
    }

    _drawTolerance(levels) {
      $("tolerance-label").textContent = levels === 0
        ? "exact projection"
        : `each pixel at most ${levels}/255 of the window from the exact projection`;
    }

    // The window shown: the state's, or (null) the automatic one of the projection on screen.
    _window() {
      const auto = (this.hello.auto_window || {})[this.state.mode];
      return this.state.window || auto || [this.lo, this.hi];
    }

    _drawWindow() {
      const w = this._window();
      $("window-label").textContent = `window ${format(w[0])} … ${format(w[1])}`;
      this.windowHistogram.draw({ window: w, gradient: this.hello.colormaps[this.state.colormap] });
    }

    // ------------------------------------------------------------------ DVR
    _buildDvr() {
      fill($("tf-colormap"), Object.keys(this.hello.colormaps));
      $("tf-colormap").addEventListener("change", (e) => {
        this.state.tf.colormap = e.target.value;
        this._drawTf();
        this.onChange(false);
      });
      $("dvr-step").addEventListener("change", (e) => {
        const v = Number(e.target.value);
        if (Number.isFinite(v) && v > 0) { this.state.dvr.step = v; this.onChange(false); }
      });
      $("dvr-shade").addEventListener("change", (e) => { this.state.dvr.shade = e.target.checked; this.onChange(false); });
      $("iso-smooth").addEventListener("change", (e) => { this.state.normals = e.target.checked ? "smooth" : "exact"; this.onChange(false); });
      $("dvr-termination").addEventListener("change", (e) => {
        // Checked: the server's default threshold (what Scene.render uses without settings).
        this.state.dvr.termination = e.target.checked ? (this.hello.defaults.dvr.termination ?? 0.99) : null;
        this.onChange(false);
      });
    }

    _drawTf() {
      this.tfEditor.set(this.state.tf.opacity, this.hello.colormaps[this.state.tf.colormap || "viridis"]);
    }

    // ------------------------------------------------------------------ clip plane and crop box
    _buildClip() {
      for (const id of ["clip-on", "clip-axis", "clip-flip"]) {
        $(id).addEventListener("change", () => { this._applyClip(); this.onChange(false); });
      }
      $("clip-position").addEventListener("input", () => { this._applyClip(); this.onChange(true); });
      $("clip-position").addEventListener("change", () => { this._applyClip(); this.onChange(false); });
      $("clip-position").value = SLIDER_STEPS / 2;
      const box = $("crop-sliders");
      this.cropSliders = [];
      ["x", "y", "z"].forEach((axis) => {
        ["min", "max"].forEach((end) => {
          const label = document.createElement("label");
          label.className = "row";
          label.textContent = `${axis} ${end}`;
          const input = document.createElement("input");
          input.type = "range";
          input.min = "0";
          input.max = String(SLIDER_STEPS);
          input.value = end === "min" ? "0" : String(SLIDER_STEPS);
          input.addEventListener("input", () => { this._applyCrop(); this.onChange(true); });
          input.addEventListener("change", () => { this._applyCrop(); this.onChange(false); });
          label.append(input);
          box.append(label);
          this.cropSliders.push(input);
        });
      });
      $("crop-on").addEventListener("change", () => { this._applyCrop(); this.onChange(false); });
    }

    _world(axis, fraction) {
      const [lo, hi] = [this.bounds[0][axis], this.bounds[1][axis]];
      return lo + fraction * (hi - lo);
    }

    _applyClip() {
      if (!$("clip-on").checked) { this.state.clip = []; return; }
      const axis = Number($("clip-axis").value);
      const c = this._world(axis, Number($("clip-position").value) / SLIDER_STEPS);
      const n = [0, 0, 0];
      const sign = $("clip-flip").checked ? -1 : 1;
      n[axis] = sign;
      this.state.clip = [[n[0], n[1], n[2], -sign * c]]; // keeps sign * (x_axis - c) >= 0
    }

    toggleClip() {
      $("clip-on").checked = !$("clip-on").checked;
      this._applyClip();
      this.onChange(false);
    }

    _applyCrop() {
      if (!$("crop-on").checked) { this.state.crop = null; return; }
      const crop = [];
      for (let axis = 0; axis < 3; axis++) {
        let a = Number(this.cropSliders[2 * axis].value);
        let b = Number(this.cropSliders[2 * axis + 1].value);
        if (b <= a) { b = Math.min(SLIDER_STEPS, a + 1); a = b - 1; } // a box needs lo < hi
        crop.push(this._world(axis, a / SLIDER_STEPS), this._world(axis, b / SLIDER_STEPS));
      }
      this.state.crop = crop;
    }

    // ------------------------------------------------------------------ lighting
    _buildLighting() {
      const box = $("lighting-sliders");
      this.lightSliders = {};
      const ranges = { ambient: [0, 1], diffuse: [0, 1.5], specular: [0, 1], shininess: [1, 200] };
      for (const [name, [lo, hi]] of Object.entries(ranges)) {
        const label = document.createElement("label");
        label.className = "row";
        label.textContent = name;
        const input = document.createElement("input");
        input.type = "range";
        input.min = String(lo);
        input.max = String(hi);
        input.step = String((hi - lo) / 100);
        input.addEventListener("input", () => { this.state.lighting[name] = Number(input.value); this.onChange(true); });
        input.addEventListener("change", () => this.onChange(false));
        label.append(input);
        box.append(label);
        this.lightSliders[name] = input;
      }
    }

    // ------------------------------------------------------------------ state -> widgets
    sync() {
      const s = this.state;
      $("model").value = s.model;
      $("mode").value = s.mode;
      $("time-slider").value = String(s.timepoint || 0);
      this._drawTime(s.timepoint || 0);
      // A control is shown when the mode reads one of the render keywords it names (the
      // registry's answer, hello.mode_keywords): a new mode needs no change here.
      const reads = (this.hello.mode_keywords || {})[s.mode] || [];
      for (const element of document.querySelectorAll("[data-reads]")) {
        element.hidden = !element.dataset.reads.split(" ").some((k) => reads.includes(k));
      }
      const isos = Array.isArray(s.iso) ? s.iso : [s.iso];
      const opacity = s.opacity || isos.map((_, i) => (i === isos.length - 1 ? 1 : 0.5));
      this.surfaces = isos.map((v, i) => ({ value: v, opacity: opacity[i] }));
      this.selected = Math.min(this.selected, this.surfaces.length - 1);
      this._applySurfaces();
      const w = this._window();
      $("window-low").value = this.toSlider(w[0]);
      $("window-high").value = this.toSlider(w[1]);
      $("mip-colormap").value = s.colormap;
      this._drawWindow();
      const levels = Math.round((s.tolerance || 0) * 255);
      $("mip-tolerance").value = levels;
      this._drawTolerance(levels);
      $("tf-colormap").value = s.tf.colormap || "viridis";
      $("dvr-step").value = s.dvr.step;
      $("dvr-shade").checked = s.dvr.shade;
      $("iso-smooth").checked = s.normals !== "exact";
      $("dvr-termination").checked = s.dvr.termination !== null;
      this._drawTf();
      $("ortho").checked = s.camera.ortho;
      for (const [name, input] of Object.entries(this.lightSliders)) input.value = s.lighting[name];
      this._syncChannels();
      this._syncLabels();
    }

    // ------------------------------------------------------------------ labels
    // A label volume (hello.labels, protocol 1.7): a row per label with its colour swatch, its
    // name or value and a box that shows or hides it; all / none; one opacity for every label.
    // The isovalue, window and transfer function do not apply (the server leaves them out).
    _buildLabels() {
      const labels = this.hello.labels;
      if (!labels) return;
      $("section-labels").hidden = false;
      $("panel").classList.add("single-hidden");
      if (!this.state.labels) this.state.labels = structuredClone(this.hello.defaults.labels);
      const values = labels.map((l) => l.value);
      // The shown labels as a list (null in the state: every label).
      const shown = () => (this.state.labels.show === null ? values.slice() : this.state.labels.show.slice());
      const setShown = (list) => {
        const set = new Set(list);
        // Every label shown is sent as null: the state says "all", as the defaults do.
        this.state.labels.show = values.every((v) => set.has(v)) ? null : values.filter((v) => set.has(v));
        this.sync();
        this.onChange(false);
      };
      this.labelRows = labels.map((info) => {
        const li = document.createElement("li");
        const box = document.createElement("input");
        box.type = "checkbox";
        const text = info.name ? `${info.name} (${info.value})` : `label ${info.value}`;
        box.setAttribute("aria-label", `show ${text}`);
        const swatch = document.createElement("span");
        swatch.className = "swatch";
        swatch.style.background = info.color;
        const name = document.createElement("span");
        name.className = "label";
        name.textContent = text;
        box.addEventListener("change", () => {
          const list = shown().filter((v) => v !== info.value);
          if (box.checked) list.push(info.value);
          setShown(list);
        });
        li.append(box, swatch, name);
        return { li, box, value: info.value };
      });
      $("labels").replaceChildren(...this.labelRows.map((r) => r.li));
      $("labels-all").addEventListener("click", () => setShown(values));
      $("labels-none").addEventListener("click", () => setShown([]));
      const opacity = $("labels-opacity");
      opacity.addEventListener("input", () => { this.state.labels.opacity = Number(opacity.value); this.onChange(true); });
      opacity.addEventListener("change", () => { this.state.labels.opacity = Number(opacity.value); this.onChange(false); });
    }

    _syncLabels() {
      if (!this.labelRows) return;
      const show = this.state.labels.show;
      for (const row of this.labelRows) row.box.checked = show === null || show.includes(row.value);
      const a = this.state.labels.opacity;
      $("labels-opacity").value = typeof a === "number" ? a : 1;
    }

    // ------------------------------------------------------------------ channels
    // Several channels shown together (hello.channels, protocol 1.5): a row per channel with
    // its visibility, colour, and its window (mip, minip) or isovalue (iso); an empty field is
    // the channel's automatic value. The single volume's isovalue, window and transfer function
    // give way to it (the server leaves them out).
    _buildChannels() {
      const channels = this.hello.channels;
      if (!channels) return;
      $("section-channels").hidden = false;
      $("panel").classList.add("single-hidden");
      // What each mode shows of the channels, as the server's registry says it (1.8): the
      // modes grouped by their rule's words, e.g. "iso: the nearest channel's surface".
      const shows = new Map();
      for (const [mode, summary] of Object.entries(this.hello.mode_compositing || {})) {
        if (summary) shows.set(summary, [...(shows.get(summary) || []), mode]);
      }
      $("channels-note").textContent =
        [...shows].map(([summary, modes]) => `${modes.join(", ")}: ${summary}`).join("; ");
      if (!Array.isArray(this.state.channels)) this.state.channels = structuredClone(this.hello.defaults.channels);
      const list = $("channels");
      list.replaceChildren();
      this.channelRows = channels.map((info, i) => {
        const li = document.createElement("li");
        const visible = document.createElement("input");
        visible.type = "checkbox";
        visible.title = "show this channel";
        visible.setAttribute("aria-label", `show ${info.label}`);
        const color = document.createElement("input");
        color.type = "color";
        color.title = "colour";
        color.setAttribute("aria-label", `colour of ${info.label}`);
        const label = document.createElement("span");
        label.className = "label";
        label.textContent = info.label;
        const settings = document.createElement("div");
        settings.className = "settings";
        const number = (name) => {
          const input = document.createElement("input");
          input.type = "number";
          input.step = "any";
          input.placeholder = "auto";
          input.setAttribute("aria-label", `${name} of ${info.label}`);
          return input;
        };
        const low = number("window low");
        const high = number("window high");
        const iso = number("isovalue");
        const windowBox = document.createElement("span");
        windowBox.append("window ", low, " … ", high);
        const isoBox = document.createElement("span");
        isoBox.append("iso ", iso);
        settings.append(windowBox, isoBox);
        const entry = () => this.state.channels[i];
        visible.addEventListener("change", () => { entry().visible = visible.checked; this.onChange(false); });
        color.addEventListener("input", () => { entry().color = color.value; this.onChange(true); });
        color.addEventListener("change", () => { entry().color = color.value; this.onChange(false); });
        const setWindow = () => {
          const a = low.value === "" ? NaN : Number(low.value);
          const b = high.value === "" ? NaN : Number(high.value);
          if (low.value === "" && high.value === "") entry().window = null;
          else if (Number.isFinite(a) && Number.isFinite(b) && a < b) entry().window = [a, b];
          else return; // incomplete: wait for the other end
          this.onChange(false);
        };
        low.addEventListener("change", setWindow);
        high.addEventListener("change", setWindow);
        iso.addEventListener("change", () => {
          const v = iso.value === "" ? null : Number(iso.value);
          if (v !== null && !Number.isFinite(v)) return;
          entry().iso = v;
          this.onChange(false);
        });
        li.append(visible, color, label, settings);
        list.append(li);
        return { visible, color, low, high, iso, windowBox, isoBox };
      });
    }

    _syncChannels() {
      if (!this.channelRows) return;
      const mode = this.state.mode;
      this.channelRows.forEach((row, i) => {
        const c = this.state.channels[i];
        row.visible.checked = c.visible !== false;
        row.color.value = c.color || this.hello.channels[i].color;
        row.low.value = c.window ? String(c.window[0]) : "";
        row.high.value = c.window ? String(c.window[1]) : "";
        row.iso.value = c.iso === null || c.iso === undefined ? "" : String(c.iso);
        const reads = (this.hello.mode_keywords || {})[mode] || [];
        row.windowBox.hidden = !reads.includes("window");
        row.isoBox.hidden = !reads.includes("iso");
      });
    }

    // Canvases drawn at their CSS size: redraw when the panel appears or the window resizes.
    redraw() {
      this._drawIso();
      this._drawWindow();
      this._drawTf();
    }
  }

  SC.Controls = Controls;
})();
