// The page of `arlux serve`: plain JavaScript, no build step, no network
// beyond this server. Every request carries the token from the address.
"use strict";
const token = new URLSearchParams(location.search).get("token") || "";
const $ = (id) => document.getElementById(id);
let state = null;
let view = "final";
let evOffset = 0;
let shown = -1;

// This tab's id: an edit names it with the state version it was made on,
// and the server refuses one made on a state another tab has changed.
const client = Array.from(crypto.getRandomValues(new Uint8Array(8)), (b) => b.toString(16).padStart(2, "0")).join("");
const stamped = ["/api/place", "/api/object", "/api/light", "/api/add", "/api/save", "/api/undo", "/api/redo"];

async function api(path, body) {
  const init = { headers: { "x-arlux-token": token } };
  if (body !== undefined) {
    if (stamped.includes(path) && state) body = Object.assign({ version: state.version, client }, body);
    init.method = "POST";
    init.headers["content-type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  const r = await fetch(path, init);
  const json = await r.json().catch(() => ({ error: { message: "unreadable reply" } }));
  if (!r.ok) {
    const e = json.error || {};
    const err = new Error((e.field ? e.field + ": " : "") + (e.message || r.status));
    err.reply = json;
    throw err;
  }
  return json;
}

// Another tab's change: its state and image replace this one's.
async function adopt(s) {
  state = Object.assign(state, s);
  fillControls();
  await refresh();
}

// While idle, the page looks for changes made elsewhere once a second.
async function follow() {
  for (;;) {
    await new Promise((done) => setTimeout(done, 1000));
    if (busy || watching) continue;
    try {
      const s = await api("/api/state");
      if (!busy && s.ready && s.version !== state.version) {
        await adopt(s);
        say("another page changed the scene: this shows its state");
      }
    } catch (e) { /* the server may be gone; the next look says so */ }
  }
}

async function fetchImage(which) {
  const ev = state.exposure + evOffset;
  const r = await fetch(`/api/image?view=${which}&ev=${ev}`, { headers: { "x-arlux-token": token } });
  if (!r.ok) throw new Error("image: " + r.status);
  const w = +r.headers.get("x-width"), h = +r.headers.get("x-height");
  const version = +r.headers.get("x-version");
  const data = new Uint8ClampedArray(await r.arrayBuffer());
  return { image: new ImageData(data, w, h), version };
}

function draw(canvas, image) {
  if (canvas.width !== image.width) { canvas.width = image.width; canvas.height = image.height; }
  canvas.getContext("2d").putImageData(image, 0, 0);
}

// The exposure the image is shown at: the session's (the photo's mean to
// 0.18) plus the slider's offset, in stops.
function showExposure() {
  const ev = state.exposure + evOffset;
  $("ev-value").textContent = `${ev >= 0 ? "+" : ""}${ev.toFixed(2)} EV`;
}

async function refresh() {
  showExposure();
  const which = view === "wipe" ? "final" : view;
  const main = await fetchImage(which);
  draw($("view"), main.image);
  drawOutline();
  shown = main.version;
  $("view").dataset.version = String(main.version);
  const before = $("before");
  before.hidden = view !== "wipe";
  $("wipe").hidden = view !== "wipe";
  if (view === "wipe") {
    draw(before, (await fetchImage("photo")).image);
    wipe();
  }
}

function wipe() {
  const f = +$("wipe").value;
  $("before").style.clipPath = `inset(0 ${100 * (1 - f)}% 0 0)`;
}

function say(text) { $("message").textContent = text; }

function showOutcome(r) {
  const p = r.path;
  const what = p.kind === "update"
    ? `update: ${p.pixels_recomputed} pixels recomputed, ${p.pixels_retraced} re-traced, ${p.rays} rays`
    : p.kind === "full" ? `full render (${p.reason})`
    : p.kind === "relight" ? "relit: the kept pixel data at the new scales" : p.kind;
  $("last").textContent = `${what} — ${r.update_ms.toFixed(1)} ms`;
}

function selected() { return state.objects[$("object").selectedIndex]; }

// The selected object's outline (the rectangle its box covers), on a
// canvas of its own over the image.
function drawOutline() {
  const canvas = $("outline"), view = $("view");
  if (canvas.width !== view.width) { canvas.width = view.width; canvas.height = view.height; }
  const ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  const o = selected();
  const b = o && o.enabled && o.screen_box;
  canvas.dataset.box = b ? b.map((v) => v.toFixed(1)).join(",") : "";
  if (!b) return;
  ctx.setLineDash([4, 3]);
  ctx.strokeStyle = "#ffd24a";
  ctx.lineWidth = 1;
  ctx.strokeRect(b[0] + 0.5, b[1] + 0.5, b[2] - b[0] - 1, b[3] - b[1] - 1);
}

// A ring where each light that is on projects into the frame (on the
// outline's canvas, drawn after it).
function drawLights() {
  const canvas = $("outline");
  const ctx = canvas.getContext("2d");
  const seen = [];
  for (const l of state.lights) {
    const p = l.screen;
    if (!p || l.scale === 0 || p[0] < 0 || p[1] < 0 || p[0] > canvas.width || p[1] > canvas.height) continue;
    seen.push(l.name);
    ctx.setLineDash([]);
    ctx.strokeStyle = l.real ? "#ffffff" : "#7fd4ff";
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    ctx.arc(p[0], p[1], 6, 0, 2 * Math.PI);
    ctx.stroke();
  }
  canvas.dataset.lights = seen.join(",");
}

function fillControls() {
  if ($("object").options.length !== state.objects.length) buildObjects();
  drawOutline();
  drawLights();
  const h = state.history || { undo: 0, redo: 0 };
  $("undo").disabled = h.undo === 0;
  $("redo").disabled = h.redo === 0;
  const o = selected();
  if (!o) return;
  $("enabled").checked = o.enabled;
  $("yaw").value = Math.round(((o.yaw_deg + 540) % 360) - 180);
  $("yaw-value").textContent = $("yaw").value;
  $("scale").value = Math.log2(o.scale);
  $("scale-value").textContent = o.scale.toFixed(2);
  for (const l of state.lights) {
    const row = document.querySelector(`[data-light="${CSS.escape(l.name)}"]`);
    if (!row) continue;
    row.querySelector("input[type=checkbox]").checked = l.scale > 0;
    if (l.scale > 0) row.querySelector("input[type=range]").value = l.scale;
  }
}

// The object menu, kept in step with the state's objects (an added one
// joins it and is selected).
function buildObjects() {
  const sel = $("object");
  const had = sel.options.length;
  const keep = sel.value;
  sel.replaceChildren(...state.objects.map((o) => new Option(o.name, o.name)));
  if (had > 0 && state.objects.length > had) sel.selectedIndex = state.objects.length - 1;
  else if (keep) sel.value = keep;
  const none = state.objects.length === 0;
  for (const id of ["object", "enabled", "yaw", "scale"]) $(id).disabled = none;
}

function buildControls() {
  $("scene").textContent = state.scene;
  buildObjects();
  const assets = state.assets || [];
  $("adding").hidden = assets.length === 0;
  $("asset").replaceChildren(...assets.map((a) => new Option(a, a)));
  // No objects: nothing to place, turn, scale or show.
  const none = state.objects.length === 0;
  if (none) say("this scene has no [[virtual]] objects: only its lights can be changed");
  const lights = $("lights");
  lights.replaceChildren();
  for (const l of state.lights) {
    const row = document.createElement("div");
    row.className = "light";
    row.dataset.light = l.name;
    const initial = l.scale > 0 ? l.scale : 1;
    row.innerHTML = `<input type="checkbox"><span class="name"></span>` +
      `<input type="range" min="0" max="4" step="0.05" value="${initial}"><span class="value"></span>`;
    row.querySelector(".name").textContent = l.name + (l.real ? "" : " (virtual)");
    const box = row.querySelector("input[type=checkbox]");
    const range = row.querySelector("input[type=range]");
    const value = row.querySelector(".value");
    value.textContent = (+range.value).toFixed(2);
    box.checked = l.scale > 0;
    const send = () => submit("light:" + l.name, "/api/light", { light: l.name, scale: box.checked ? +range.value : 0 });
    box.addEventListener("change", send);
    range.addEventListener("input", () => { value.textContent = (+range.value).toFixed(2); });
    range.addEventListener("change", () => { if (box.checked) send(); });
    if (!l.real && l.position) {
      // A virtual light is placed by a click on the photo, a height off the surface there.
      const place = document.createElement("button");
      place.className = "place-light";
      place.textContent = "place";
      place.title = "then click the photo: the light goes this height off the surface there";
      const height = document.createElement("input");
      Object.assign(height, { type: "number", min: "0.05", max: "5", step: "0.05", value: "0.5", className: "height", title: "height off the surface, m" });
      place.addEventListener("click", () => {
        placingLight = { name: l.name, height };
        say(`click the photo to place ${l.name} ${(+height.value).toFixed(2)} m off the surface there`);
      });
      row.append(place, height);
    }
    lights.appendChild(row);
  }
  $("render").disabled = !state.can_render;
  fillControls();
}

// With `--samples`, the server refines the image while no edit waits: the
// page asks for the state a few times a second until the last level is
// shown, and fetches the image at each new level (an edit stops it).
let watching = false;
function showRefined() {
  const r = state.refined;
  $("refining").textContent = !r || r.target === 0 || (r.rounds === 0 && busy) ? ""
    : r.rounds < r.target ? `refining: ${r.rounds} of ${r.target} rounds`
    : `refined: ${r.rounds} rounds`;
}
async function watchRefining() {
  showRefined();
  if (watching) return;
  watching = true;
  try {
    for (;;) {
      const r = state.refined || { rounds: 0, target: 0 };
      if (r.rounds >= r.target) break;
      await new Promise((done) => setTimeout(done, 300));
      if (busy) break;
      const s = await api("/api/state");
      if (busy || s.version !== state.version) break;
      const before = r.rounds;
      state = Object.assign(state, s);
      if (state.refined.rounds !== before) {
        await refresh();
        showRefined();
      }
    }
  } catch (e) {
    say(e.message);
  } finally {
    watching = false;
  }
}

// One edit in flight; a drag's moves that come meanwhile keep only the latest.
let busy = false;
let pendingMove = null;

// Changes made while one is in flight wait, the latest per control (a
// slider's moves coalesce); a change that takes over 100 ms says so.
const waiting = new Map();
function submit(key, path, body) {
  if (busy) waiting.set(key, [path, body]); else edit(path, body);
}

async function edit(path, body) {
  busy = true;
  $("refining").textContent = "";
  const slow = setTimeout(() => {
    $("status").textContent = "working…";
    $("status").dataset.working = "true";
  }, 100);
  try {
    const r = await api(path, body);
    if (!r.superseded) {
      state = Object.assign(state, r.state);
      showOutcome(r);
      say("");
      fillControls();
      await refresh();
      watchRefining();
    }
  } catch (e) {
    say(e.message);
    if (e.reply && e.reply.state) {
      pendingMove = null;
      waiting.clear();
      await adopt(e.reply.state);
    }
  } finally {
    clearTimeout(slow);
    $("status").textContent = "ready";
    $("status").dataset.working = "false";
    busy = false;
  }
  if (pendingMove) {
    const next = pendingMove;
    pendingMove = null;
    await edit("/api/place", next);
  } else if (waiting.size > 0) {
    const [key, [nextPath, nextBody]] = waiting.entries().next().value;
    waiting.delete(key);
    await edit(nextPath, nextBody);
  }
}

function pixelOf(ev) {
  const c = $("view");
  const r = c.getBoundingClientRect();
  return { x: (ev.clientX - r.left) * c.width / r.width, y: (ev.clientY - r.top) * c.height / r.height };
}

let dragging = false;
// A virtual light waiting for its place (its "place" button was pressed).
let placingLight = null;
// An asset waiting for its place (the "add" button was pressed).
let adding = null;
$("add").addEventListener("click", () => {
  adding = $("asset").value;
  say(`click the photo where ${adding} should stand`);
});
$("view").addEventListener("pointerdown", (ev) => {
  if (state && adding) {
    const p = pixelOf(ev);
    const asset = adding;
    adding = null;
    submit(`add#${steps++}`, "/api/add", { asset, x: p.x, y: p.y });
    return;
  }
  if (state && placingLight) {
    const p = pixelOf(ev);
    const { name, height } = placingLight;
    placingLight = null;
    submit(`light:${name}:place`, "/api/light", { light: name, x: p.x, y: p.y, height_m: +height.value });
    return;
  }
  if (!state || !selected()) return;
  dragging = true;
  $("view").setPointerCapture(ev.pointerId);
  const p = pixelOf(ev);
  const body = { object: selected().name, x: p.x, y: p.y, drag: false };
  if (busy) pendingMove = body; else edit("/api/place", body);
});
$("view").addEventListener("pointermove", (ev) => {
  if (!dragging || !selected()) return;
  const p = pixelOf(ev);
  const body = { object: selected().name, x: p.x, y: p.y, drag: true };
  if (busy) pendingMove = body; else edit("/api/place", body);
});
const stop = () => { dragging = false; };
$("view").addEventListener("pointerup", stop);
$("view").addEventListener("pointercancel", stop);

$("object").addEventListener("change", fillControls);
// Undo and redo, by button or key; Delete hides the selected object.
// Each press is its own step (not coalesced like a slider's moves).
let steps = 0;
const step = (path) => submit(`${path}#${steps++}`, path, {});
$("undo").addEventListener("click", () => step("/api/undo"));
$("redo").addEventListener("click", () => step("/api/redo"));
document.addEventListener("keydown", (ev) => {
  if (ev.target.matches && ev.target.matches("input[type=text], input:not([type]), select")) return;
  const key = ev.key.toLowerCase();
  if ((ev.ctrlKey || ev.metaKey) && key === "z") {
    ev.preventDefault();
    step(ev.shiftKey ? "/api/redo" : "/api/undo");
  } else if ((ev.ctrlKey || ev.metaKey) && key === "y") {
    ev.preventDefault();
    step("/api/redo");
  } else if (ev.key === "Delete" && selected() && selected().enabled) {
    ev.preventDefault();
    submit(selected().name + ":enabled", "/api/object", { object: selected().name, enabled: false });
  } else if (ev.key.startsWith("Arrow") && selected() && selected().enabled) {
    // 5 cm a press (1 cm with Shift) along the floor, as the camera sees it.
    ev.preventDefault();
    const d = ev.shiftKey ? 0.01 : 0.05;
    const [r, f] = { ArrowLeft: [-d, 0], ArrowRight: [d, 0], ArrowUp: [0, d], ArrowDown: [0, -d] }[ev.key];
    submit(`${selected().name}:nudge#${steps++}`, "/api/object", { object: selected().name, nudge: [r, f] });
  }
});
// Each object control edits the selected object; a scene without objects has none.
const onObject = (f) => () => { const o = selected(); if (o) f(o); };
$("enabled").addEventListener("change", onObject((o) => submit(o.name + ":enabled", "/api/object", { object: o.name, enabled: $("enabled").checked })));
$("yaw").addEventListener("input", () => { $("yaw-value").textContent = $("yaw").value; });
$("yaw").addEventListener("change", onObject((o) => submit(o.name + ":yaw", "/api/object", { object: o.name, yaw_deg: +$("yaw").value })));
$("scale").addEventListener("input", () => { $("scale-value").textContent = (2 ** +$("scale").value).toFixed(2); });
$("scale").addEventListener("change", onObject((o) => submit(o.name + ":scale", "/api/object", { object: o.name, scale: 2 ** +$("scale").value })));
for (const r of document.querySelectorAll("input[name=view]")) {
  r.addEventListener("change", () => { view = r.value; refresh().catch((e) => say(e.message)); });
}
$("wipe").addEventListener("input", wipe);
$("ev").addEventListener("change", () => { evOffset = +$("ev").value; refresh().catch((e) => say(e.message)); });
$("save").addEventListener("click", async () => {
  const name = $("variant-name").value.trim();
  try {
    const r = await api("/api/save", name ? { name } : {});
    $("saved").textContent = `saved variant ${r.variant} in ${r.file}` + (r.scene_file_changed
      ? " (the scene file was edited since the session began: the save holds the session's scene, as shown; restart the server to use the edit)"
      : "");
    $("saved").dataset.file = r.file;
    $("saved").dataset.variant = r.variant;
  } catch (e) {
    say(e.message);
    if (e.reply && e.reply.state) await adopt(e.reply.state);
  }
});
$("render").addEventListener("click", async () => {
  try {
    const r = await api("/api/render", {});
    $("saved").textContent = `wrote ${r.file}`;
  } catch (e) { say(e.message); }
});

// The preprocess's stages until the first image, then the controls.
async function start() {
  for (;;) {
    let s;
    try { s = await api("/api/state"); } catch (e) { say(e.message); return; }
    if (s.failed) { $("status").textContent = "failed: " + s.failed; return; }
    if (s.ready) { state = s; break; }
    $("status").textContent = "preparing: " + s.stage;
    await new Promise((r) => setTimeout(r, 250));
  }
  buildControls();
  await refresh();
  if (state.last) showOutcome(state.last);
  $("status").textContent = "ready";
  $("status").dataset.ready = "true";
  watchRefining();
  follow();
}
start();
