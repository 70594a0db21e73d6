// The page's main script: the WebSocket connection, render requests, drawing received frames,
// the status line, keyboard shortcuts and screenshots. Protocol: docs/viewer-protocol.md.
(function () {
  "use strict";
  const SC = window.SC;
  const PROTOCOL_VERSION = 1;

  const token = new URLSearchParams(location.search).get("token") || "";
  const view = document.getElementById("view");
  const canvas = document.getElementById("canvas");
  const ctx = canvas.getContext("2d");
  const statusLine = document.getElementById("status");
  const errorBar = document.getElementById("error");

  let ws = null;
  let hello = null;
  let state = null;
  let controls = null;
  let orbit = null;
  let nextId = 1;
  let scheduled = false; // an interactive request waits for the next animation frame
  let drawnSeq = 0; // frames are decoded asynchronously: never draw an older one over a newer
  let frameSeq = 0;
  let errorId = -1;
  let lastViewId = 0; // id of the newest render request sent (screenshots not included)
  let frameStatus = ""; // the status line's part that describes the frame shown
  const sentAt = new Map(); // request id -> time sent (for the latency in the status line)
  const interactiveTimes = []; // arrival times of recent reduced frames (frames per second)

  // What tests and other scripts may read (the page itself never needs it).
  const api = (window.splinecastViewer = {
    ready: false,
    framesDrawn: 0,
    lastFrame: null, // header of the last frame drawn
    frameLog: [], // {id, pass, final, scale, render_ms, latency_ms, at} of recent frames drawn
    lastError: null,
    lastPick: null, // the last pick answer shown (label volumes): {label, name, position, ...}
    preparing: null, // what the server prepares (a model or mode's kernels), or null
    get state() { return state; },
    get hello() { return hello; },
    // Whether the canvas shows the full frame of the newest request, nothing being waited for:
    // what a script waits for before it compares the canvas with the state.
    get settled() {
      return !scheduled && lastViewId > 0 && api.lastFrame !== null && api.lastFrame.final &&
        api.lastFrame.id === lastViewId;
    },
    get lastViewId() { return lastViewId; },
    request: (interactive) => request(interactive),
  });

  // ------------------------------------------------------------------------ connection
  function connect() {
    const scheme = location.protocol === "https:" ? "wss" : "ws";
    ws = new WebSocket(`${scheme}://${location.host}/ws?token=${encodeURIComponent(token)}`);
    ws.binaryType = "arraybuffer";
    ws.addEventListener("message", (e) => {
      if (typeof e.data === "string") onMessage(JSON.parse(e.data));
      else onFrame(e.data);
    });
    ws.addEventListener("close", (e) => {
      api.ready = false;
      showError(`disconnected from the server${e.reason ? ": " + e.reason : ""} ` +
                "(restart `splinecast view` and open its new URL)");
      statusLine.textContent = "disconnected";
    });
  }

  function onMessage(msg) {
    if (msg.type === "hello") onHello(msg);
    else if (msg.type === "error") {
      errorId = msg.id === null ? errorId : msg.id;
      api.lastError = msg;
      picking = false; // a refused pick has no answer to wait for
      showError(msg.message);
    } else if (msg.type === "pick") {
      showPick(msg);
    } else if (msg.type === "status") {
      if ("preparing" in msg) {
        // New kernels: the page keeps showing what is ready and says what it waits for.
        api.preparing = msg.preparing ? msg.message : null;
        statusLine.textContent = [frameStatus, api.preparing].filter(Boolean).join(" · ");
      } else statusLine.textContent = msg.message + "…";
    }
  }

  // ------------------------------------------------------------------------ picking
  // Label volumes (hello.labels): the label under the cursor, asked of the server (one ray of
  // the state's camera through that pixel). One pick in flight at a time; the newest position
  // waits for its answer.
  const pickBar = document.getElementById("pick");
  let picking = false;
  let pickWanted = null; // [x, y] in full-resolution pixels, not yet asked

  function wantPick(e) {
    if (!hello || !hello.labels || e.buttons) return;
    const rect = canvas.getBoundingClientRect();
    const x = ((e.clientX - rect.left) / rect.width) * canvas.width;
    const y = ((e.clientY - rect.top) / rect.height) * canvas.height;
    if (x < 0 || y < 0 || x >= canvas.width || y >= canvas.height) return;
    pickWanted = [x, y];
    if (!picking) sendPick();
  }

  function sendPick() {
    if (!pickWanted || !ws || ws.readyState !== WebSocket.OPEN) return;
    const [x, y] = pickWanted;
    pickWanted = null;
    picking = true;
    ws.send(JSON.stringify({ v: PROTOCOL_VERSION, type: "pick", id: nextId++, x, y, state: wireState() }));
  }

  function showPick(msg) {
    picking = false;
    api.lastPick = msg;
    pickBar.hidden = false;
    if (!msg.label) pickBar.textContent = "no label";
    else {
      const p = msg.position ? ` at (${msg.position.map((v) => v.toPrecision(4)).join(", ")})` : "";
      pickBar.textContent = `label ${msg.label}${msg.name ? " · " + msg.name : ""}${p}`;
    }
    sendPick();
  }

  canvas.addEventListener("pointermove", wantPick);
  canvas.addEventListener("click", wantPick);
  canvas.addEventListener("pointerleave", () => { pickWanted = null; pickBar.hidden = true; });

  function onHello(msg) {
    if (Math.floor(msg.v) !== PROTOCOL_VERSION) {
      showError(`this page speaks protocol ${PROTOCOL_VERSION}, the server ${msg.v}`);
      return;
    }
    hello = msg;
    state = structuredClone(msg.defaults);
    controls = new SC.Controls(hello, state, (interactive) => request(interactive));
    orbit = new SC.OrbitControls(canvas, () => state.camera, (interactive) => request(interactive));
    new ResizeObserver(() => resize()).observe(view);
    resize(true);
    api.ready = true;
    request(false);
  }

  // ------------------------------------------------------------------------ requests
  // The canvas's backing store has the full-resolution size (CSS size x device pixels),
  // capped at the server's pixel limit.
  function resize(initial = false) {
    const dpr = window.devicePixelRatio || 1;
    let w = Math.max(1, Math.round(view.clientWidth * dpr));
    let h = Math.max(1, Math.round(view.clientHeight * dpr));
    const limit = hello ? hello.limits.max_pixels : 4096 * 4096;
    if (w * h > limit) {
      const f = Math.sqrt(limit / (w * h));
      w = Math.max(1, Math.floor(w * f));
      h = Math.max(1, Math.floor(h * f));
    }
    if (w === canvas.width && h === canvas.height) return;
    canvas.width = w;
    canvas.height = h;
    if (controls) controls.redraw();
    if (!initial && api.ready) request(true); // the server follows up at full size once resizing rests
  }

  function wireState() {
    const s = structuredClone(state);
    s.size = [canvas.width, canvas.height];
    return s;
  }

  function send(type, interactive) {
    if (!ws || ws.readyState !== WebSocket.OPEN) return -1;
    const id = nextId++;
    if (type === "render") lastViewId = id;
    sentAt.set(id, performance.now());
    if (sentAt.size > 256) sentAt.delete(sentAt.keys().next().value);
    ws.send(JSON.stringify({ v: PROTOCOL_VERSION, type, id, interactive, state: wireState() }));
    return id;
  }

  // Interactive changes are sent at most once per animation frame (the server keeps only the
  // newest anyway); a final change (a release, a choice) goes at once.
  function request(interactive) {
    if (!interactive) {
      scheduled = false;
      send("render", false);
      return;
    }
    if (scheduled) return;
    scheduled = true;
    requestAnimationFrame(() => {
      if (!scheduled) return;
      scheduled = false;
      send("render", true);
    });
  }

  // ------------------------------------------------------------------------ frames
  function onFrame(buffer) {
    const length = new DataView(buffer).getUint32(0, false);
    const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, length)));
    const type = header.format === "png" ? "image/png" : "image/jpeg";
    const blob = new Blob([new Uint8Array(buffer, 4 + length)], { type });
    if (header.pass === "screenshot") {
      download(blob);
      return;
    }
    const seq = ++frameSeq;
    const options = { colorSpaceConversion: "none", premultiplyAlpha: "none" };
    createImageBitmap(blob, options).then((bitmap) => {
      if (seq < drawnSeq) return;
      drawnSeq = seq;
      ctx.imageSmoothingEnabled = header.scale < 1;
      ctx.clearRect(0, 0, canvas.width, canvas.height);
      ctx.drawImage(bitmap, 0, 0, canvas.width, canvas.height);
      bitmap.close();
      if (header.id > errorId) hideError();
      api.framesDrawn += 1;
      api.lastFrame = header;
      const sent = sentAt.get(header.id);
      api.frameLog.push({ id: header.id, pass: header.pass, final: header.final,
                          scale: header.scale, render_ms: header.render_ms, at: performance.now(),
                          latency_ms: sent === undefined ? null : performance.now() - sent });
      if (api.frameLog.length > 2000) api.frameLog.shift();
      showStatus(header);
    });
  }

  function showStatus(h) {
    const now = performance.now();
    const parts = [`${h.width}×${h.height}`];
    if (h.scale < 1) parts[0] += ` (1/${Math.round(1 / h.scale)})`;
    parts.push(h.format.toUpperCase());
    parts.push(`${h.stats.model || ""} ${h.stats.mode || ""}`.trim());
    // The time point shown (protocol 1.4): while another one is read, still the previous one.
    if ((hello.timepoints || 1) > 1 && h.timepoint !== undefined) parts.push(`time point ${h.timepoint}`);
    parts.push(`frame ${Math.round(h.render_ms)} ms`);
    const sent = sentAt.get(h.id);
    if (sent !== undefined) parts.push(`latency ${Math.round(now - sent)} ms`);
    if (h.pass === "interactive") {
      interactiveTimes.push(now);
      while (interactiveTimes.length && now - interactiveTimes[0] > 1000) interactiveTimes.shift();
      parts.push(`${interactiveTimes.length} fps`);
    }
    // Pyramids report the bricks of the view (protocol 1.1); plain volumes have none.
    const b = h.bricks;
    if (b) {
      let text = `bricks ${b.cut_resident}/${b.cut} resident`;
      if (b.loading > 0) text += `, loading ${b.loading}`;
      // Bricks whose chunks cannot be read stay drawn from a coarser level: say so.
      if (b.unreadable > 0) text += `, ${b.unreadable} unreadable (drawn from a coarser level)`;
      else if (b.unavailable > 0) text += `, ${b.unavailable} unreadable`;
      parts.push(text);
      const stuck = b.unreadable > 0 && b.loading === 0;
      parts.push(b.complete ? "complete" : stuck ? "incomplete" : `${Math.round(b.progress * 100)}%`);
    } else if (h.stats.chunks !== undefined) {
      parts.push(`chunks ${h.stats.chunks}`);  // a wavelet store's reconstructed chunks
    }
    if (h.pass === "preparing") parts.push("previous settings");
    else if (!h.final || (b && !b.complete && b.loading > 0)) parts.push("refining…");
    frameStatus = parts.join(" · ");
    if (h.final && h.id === lastViewId) api.preparing = null;
    statusLine.textContent = [frameStatus, api.preparing].filter(Boolean).join(" · ");
  }

  function showError(text) {
    errorBar.textContent = text;
    errorBar.hidden = false;
  }

  function hideError() {
    errorBar.hidden = true;
  }

  // ------------------------------------------------------------------------ screenshot
  function screenshot() {
    send("screenshot", false);
    statusLine.textContent = "rendering screenshot…";
  }

  function download(blob) {
    const link = document.getElementById("download");
    const name = (hello.volume.name.split(/[\\/]/).pop() || "volume").replace(/[^A-Za-z0-9._-]+/g, "-");
    link.href = URL.createObjectURL(blob);
    link.download = `splinecast-${name}-${state.mode}.png`;
    link.click();
    setTimeout(() => URL.revokeObjectURL(link.href), 10000);
    statusLine.textContent = `screenshot saved (${link.download})`;
  }

  // ------------------------------------------------------------------------ buttons and keys
  function resetCamera() {
    state.camera = structuredClone(hello.defaults.camera);
    state.camera.ortho = document.getElementById("ortho").checked;
    request(false);
  }

  function toggleHelp() {
    const help = document.getElementById("help");
    help.hidden = !help.hidden;
  }

  document.getElementById("reset").addEventListener("click", resetCamera);
  document.getElementById("screenshot").addEventListener("click", screenshot);
  document.getElementById("help-button").addEventListener("click", toggleHelp);

  document.addEventListener("keydown", (e) => {
    if (!state || e.ctrlKey || e.metaKey || e.altKey) return;
    const tag = (e.target.tagName || "").toLowerCase();
    if ((tag === "input" && e.target.type !== "range") || tag === "select" || tag === "textarea") return;
    const k = e.key;
    let handled = true;
    if (k === "r") resetCamera();
    else if (k === "s") screenshot();
    else if (k === "?" || k === "h") toggleHelp();
    else if (k === "p") { document.getElementById("app").classList.toggle("panel-hidden"); }
    else if (k === "o") { state.camera.ortho = !state.camera.ortho; controls.sync(); request(false); }
    else if (k === "c") controls.toggleClip();
    else if (k === "[" || k === "]") controls.stepIso(k === "]" ? 1 : -1);
    else if ((k === "," || k === ".") && (hello.timepoints || 1) > 1) controls.stepTime(k === "." ? 1 : -1);
    else if (k >= "1" && k <= "9" && Number(k) <= hello.modes.length) controls.setMode(hello.modes[Number(k) - 1]);
    else if (k === "+" || k === "=") { orbit.zoomBy(1.15); request(false); }
    else if (k === "-" || k === "_") { orbit.zoomBy(1 / 1.15); request(false); }
    else if (k === "ArrowLeft" && tag !== "input") { orbit.rotate(5, 0); request(false); }
    else if (k === "ArrowRight" && tag !== "input") { orbit.rotate(-5, 0); request(false); }
    else if (k === "ArrowUp" && tag !== "input") { orbit.rotate(0, -5); request(false); }
    else if (k === "ArrowDown" && tag !== "input") { orbit.rotate(0, 5); request(false); }
    else handled = false;
    if (handled) e.preventDefault();
  });

  connect();
})();
