// The viewer: lists the server's sessions, shows one live, and drives it
// through the same gRPC service any client calls (gRPC-web, codec.js).
// Frames come by NextFrame polls: one frame in flight per page, and a page
// that falls behind skips frames instead of queueing them.

import { Schema, Service, GrpcError, fieldArray } from "./codec.js";
import { Renderer, colourAt, sub, add, scale, normalise, cross } from "./render.js";
import { Plot } from "./plot.js";

const $ = (id) => document.getElementById(id);

/** Longest a NextFrame poll waits on the server for a newer frame, ms. */
const FRAME_WAIT_MS = 5000;
/** The session list is read again this often, ms. */
const LIST_PERIOD_MS = 1000;
/** Frame timings kept for the page's speed figures. */
const TIMINGS_KEPT = 300;

const FIELD_LABELS = {
  FIELD_KIND_POSITION: "position",
  FIELD_KIND_VELOCITY: "velocity",
  FIELD_KIND_DENSITY: "density",
  FIELD_KIND_PRESSURE: "pressure",
  FIELD_KIND_MASS: "mass",
  FIELD_KIND_VOLUME: "volume",
  FIELD_KIND_KINETIC_ENERGY: "kinetic energy",
  FIELD_KIND_ELASTIC_ENERGY: "elastic energy",
  FIELD_KIND_FRAGMENT: "fragment",
  FIELD_KIND_ID: "id",
};

/** What the page measured, for people and for the browser tests. */
const stats = {
  frames: 0,
  lastStep: -1,
  // Per frame, ms: decoding the message, uploading particles and
  // surfaces to the GPU, and all the page does with it (colours, plots,
  // the time line, the upload included).
  decodeMs: [],
  uploadMs: [],
  showMs: [],
  // Per pulled frame (`meshless.pull`), ms: from the NextFrame call to
  // its answer decoded out of the gRPC-web body (the server's part, the
  // transport and the browser's network stack).
  fetchMs: [],
  errors: [],
};

let schema;
let service;
let renderer;
let current = null;
let sessionsById = new Map();
const plots = {};

function banner(text, kind = "error") {
  const el = $("banner");
  if (!text) {
    el.hidden = true;
    return;
  }
  el.textContent = text;
  el.className = kind === "info" ? "info" : "";
  el.hidden = false;
}

/** Says what went wrong in words; a missing or refused token asks for one. */
function report(error, what) {
  const text = error instanceof GrpcError ? error.message : String(error?.message ?? error);
  stats.errors.push(`${what}: ${text}`);
  if (error instanceof GrpcError && error.codeName === "UNAUTHENTICATED") {
    banner(`This server needs a token: enter yours above. (${what}: ${error.detail})`);
  } else if (error instanceof GrpcError && error.codeName === "PERMISSION_DENIED") {
    banner(`${what}: not allowed for this token (${error.detail})`);
  } else {
    banner(`${what}: ${text}`);
  }
}

async function call(method, request, what = method) {
  try {
    return await service.unary(method, request);
  } catch (error) {
    report(error, what);
    throw error;
  }
}

function stateName(state) {
  return schema.enumName("meshless.v1.SessionState", state).replace("SESSION_STATE_", "").toLowerCase();
}

// --- the session list -------------------------------------------------

async function refreshList() {
  let list;
  try {
    list = await service.unary("ListSessions", {});
  } catch (error) {
    if (!(error instanceof GrpcError && error.codeName === "UNAUTHENTICATED" && !service.token)) {
      report(error, "ListSessions");
    } else {
      banner("This server needs a token: enter yours above.");
    }
    return;
  }
  sessionsById = new Map(list.sessions.map((s) => [s.id, s]));
  const body = $("sessions").querySelector("tbody");
  body.replaceChildren(
    ...list.sessions.map((s) => {
      const row = document.createElement("tr");
      row.dataset.id = s.id;
      if (current && current.id === s.id) row.className = "selected";
      const cells = [
        `${s.name} (${s.id})`,
        stateName(s.status?.state ?? 0),
        (s.system_kinds ?? []).join(", "),
        String(s.particle_count),
        s.realtime_factor > 0 ? s.realtime_factor.toPrecision(3) : "–",
      ];
      for (const text of cells) {
        const cell = document.createElement("td");
        cell.textContent = text;
        row.append(cell);
      }
      row.addEventListener("click", () => select(s.id));
      return row;
    }),
  );
  if (current && !sessionsById.has(current.id)) {
    current.close();
    current = null;
    $("session-title").textContent = "No session";
  }
}

// --- one session, live -------------------------------------------------

/** A session shown in the view: its scene, its status stream and its frame poll. */
class SessionView {
  constructor(session) {
    this.id = session.id;
    this.session = session;
    this.abort = new AbortController();
    this.frameNumber = 0;
    this.frame = null;
    this.fields = new Map();
    this.status = session.status;
    this.fitted = false;
    this.constraints = [];
    this.design = null;
    this.handles = 0;
    // Each modal solid's and shell's rest positions, by system: what a
    // grab names.
    this.rest = new Map(
      [...(session.modal_modes ?? []), ...(session.shell_nodes ?? [])].map((m) => [
        m.system,
        fieldArray({ data: m.rest_positions, scalar: 1 }),
      ]),
    );
    this.kinds = session.system_kinds ?? [];
    for (const plot of Object.values(plots)) plot.clear();
    this.watch();
    this.poll();
    this.readConstraints();
  }

  close() {
    this.abort.abort();
  }

  async watch() {
    try {
      for await (const status of service.stream("WatchStatus", { session_id: this.id }, { signal: this.abort.signal })) {
        this.status = status;
        showStatus(this);
      }
    } catch (error) {
      if (!this.abort.signal.aborted) report(error, "WatchStatus");
    }
  }

  /** Asks for the first frame newer than frame `after`, waiting up to
   * `waitMs` for one. A call the page stops waiting for (the session
   * closed) is not reported as unhandled. */
  nextFrame(after, waitMs) {
    const answer = service.unary(
      "NextFrame",
      { session_id: this.id, after, wait_ms: waitMs },
      { signal: this.abort.signal },
    );
    answer.catch(() => {});
    return answer;
  }

  /**
   * Shows the session's frames as they come. The next frame is asked for
   * before the one just received is shown, so the page's work on a frame
   * overlaps the transfer of the next: still one frame in flight, and a
   * frame rate set by the slower of the two, not by their sum.
   */
  async poll() {
    let pending = this.nextFrame(this.frameNumber, FRAME_WAIT_MS);
    while (!this.abort.signal.aborted) {
      let reply;
      try {
        reply = await pending;
      } catch (error) {
        if (this.abort.signal.aborted) return;
        report(error, "NextFrame");
        // A refused poll (a deleted session, a lost token) is not retried
        // in a tight loop.
        await new Promise((resolve) => setTimeout(resolve, 1000));
        pending = this.nextFrame(this.frameNumber, FRAME_WAIT_MS);
        continue;
      }
      // An empty answer: no newer frame came within the wait.
      const fresh = reply.frame.length > 0;
      if (fresh) this.frameNumber = reply.number;
      pending = this.nextFrame(this.frameNumber, FRAME_WAIT_MS);
      if (fresh) this.take(reply.frame);
    }
  }

  /** Decodes and shows a frame's bytes, timing each part; `redraw` asks
   * for the view to be drawn again. */
  take(bytes, redraw = true) {
    const started = performance.now();
    const frame = schema.decode("meshless.v1.Frame", bytes);
    const decoded = performance.now();
    const upload = this.show(frame);
    keep(stats.decodeMs, decoded - started);
    keep(stats.uploadMs, upload);
    keep(stats.showMs, performance.now() - decoded);
    stats.frames += 1;
    stats.lastStep = frame.header?.step ?? -1;
    if (redraw) requestAnimationFrame(draw);
  }

  /**
   * The page's capacity, apart from the session's pace: fetches the
   * latest frame `count` times in a row (a NextFrame that need not wait),
   * decoding each and uploading it to the GPU as a new one; returns
   * frames per second. The view is drawn once, at the end: drawing is the
   * GPU's work, and headless Chromium without one draws on the CPU,
   * which would time its software rasteriser instead.
   */
  async pull(count) {
    // Draws already asked for run first, and are waited for to their end:
    // headless Chromium draws on the CPU, and the frames shown before the
    // pull would otherwise be drawn during its first fetches.
    await new Promise((resolve) => requestAnimationFrame(resolve));
    renderer.finish();
    const started = performance.now();
    let asked = performance.now();
    let pending = this.nextFrame(0, 0);
    for (let k = 0; k < count; k += 1) {
      const reply = await pending;
      if (reply.frame.length === 0) throw new Error("the session has no frame yet");
      keep(stats.fetchMs, performance.now() - asked);
      // As `poll` does: the next is asked for before this one is shown.
      if (k + 1 < count) {
        asked = performance.now();
        pending = this.nextFrame(0, 0);
      }
      this.take(reply.frame, false);
    }
    const rate = (count * 1000) / (performance.now() - started);
    requestAnimationFrame(draw);
    return rate;
  }

  /** Shows a frame; returns the milliseconds its upload to the GPU took. */
  show(frame) {
    this.frame = frame;
    const kindName = (k) => schema.enumName("meshless.v1.FieldKind", k);
    this.fields = new Map(frame.fields.map((f) => [kindName(f.kind), f]));
    const header = frame.header ?? {};
    const n = header.particle_count ?? 0;
    const positionField = this.fields.get("FIELD_KIND_POSITION");
    let positions = new Float32Array(0);
    if (positionField) {
      const raw = fieldArray(positionField);
      positions = positionField.components === 3 ? raw : widen(raw, positionField.components, n);
    }
    this.positions = positions;
    fieldChoices(this);
    const values = colourValues(this, n);
    const uploading = performance.now();
    if ($("show-particles").checked) renderer.setParticles(positions, values);
    else renderer.setParticles(new Float32Array(0), null);
    this.showSurfaces(frame);
    const upload = performance.now() - uploading;
    this.showBodies(frame);
    this.showMarkers();
    if (!this.fitted && positions.length > 0) {
      fitCamera(this, positions);
      this.fitted = true;
    }
    showTimeline(this, header);
    this.plot(header, n);
    return upload;
  }

  showSurfaces(frame) {
    if (!$("show-surfaces").checked) {
      renderer.setMeshes([]);
      return;
    }
    const meshes = [];
    const mesh = (m, colour) => ({
      vertices: fieldArray({ data: m.vertices, scalar: 1 }),
      triangles: fieldArray({ data: m.triangles, scalar: 2 }),
      normals: fieldArray({ data: m.normals, scalar: 1 }),
      colour,
    });
    if (frame.surface && frame.surface.triangles.length > 0) meshes.push(mesh(frame.surface, [0.3, 0.55, 0.95, 0.55]));
    for (const s of frame.solid_surfaces) if (s.mesh) meshes.push(mesh(s.mesh, [0.95, 0.7, 0.4, 1]));
    // A fracturing solid's crack faces, each carried by its own side.
    for (const s of frame.crack_surfaces ?? []) if (s.mesh) meshes.push(mesh(s.mesh, [0.85, 0.2, 0.2, 1]));
    renderer.setMeshes(meshes);
  }

  /** Each rigid body's shape as a wireframe at its pose, with its axes. */
  showBodies(frame) {
    const segments = [];
    const length = this.extent * 0.08;
    const systems = this.session.scene?.systems ?? [];
    for (const body of frame.bodies) {
      const p = vec(body.position);
      const q = body.orientation ?? { x: 0, y: 0, z: 0, w: 1 };
      const place = (local) => add(p, rotate(q, local));
      const axes = [[1, 0, 0], [0, 1, 0], [0, 0, 1]];
      axes.forEach((axis, k) => {
        const colour = [0, 0, 0];
        colour[k] = 1;
        segments.push(...p, ...colour, ...place(scale(axis, length)), ...colour);
      });
      const white = [0.92, 0.92, 0.92];
      for (const [a, b] of outline(systems[body.system]?.rigid_body?.shape)) {
        segments.push(...place(a), ...white, ...place(b), ...white);
      }
    }
    renderer.setLines("axes", segments);
  }

  /** Crosses at grab targets (red) and handle targets (yellow). */
  showMarkers() {
    const segments = [];
    const r = this.extent * 0.03;
    const cross3 = (p, colour) => {
      for (const axis of [[r, 0, 0], [0, r, 0], [0, 0, r]]) {
        segments.push(...sub(p, axis), ...colour, ...add(p, axis), ...colour);
      }
    };
    for (const c of this.constraints) {
      if (c.grab?.position) cross3(vec(c.grab.position), [1, 0.25, 0.25]);
      const targets = c.handle?.target?.positions?.positions ?? [];
      for (const t of targets) cross3(vec(t), [1, 0.9, 0.2]);
    }
    if (this.design) {
      const { rest, displacement } = this.design;
      for (let i = 0; i < rest.length; i += 3) {
        const p = [rest[i] + displacement[i], rest[i + 1] + displacement[i + 1], rest[i + 2] + displacement[i + 2]];
        cross3(p, [1, 0.55, 0.1]);
      }
    }
    renderer.setLines("markers", segments);
  }

  get extent() {
    return this.size ?? 1;
  }

  plot(header, n) {
    const time = header.time ?? 0;
    plots.kinetic.push(time, kineticEnergy(this, n));
    const elastic = this.fields.get("FIELD_KIND_ELASTIC_ENERGY");
    plots.elastic.push(time, elastic ? sum(fieldArray(elastic)) : NaN);
    plots.density.push(time, header.density_error ?? NaN);
    for (const plot of Object.values(plots)) plot.draw();
  }

  async readConstraints() {
    try {
      const list = await service.unary("ListConstraints", { session_id: this.id });
      this.constraints = list.constraints;
      showConstraints(this);
      this.showMarkers();
      requestAnimationFrame(draw);
    } catch (error) {
      report(error, "ListConstraints");
    }
  }

  /** The solid range a particle lies in: `{system, first, count}`, or null for the fluid's. */
  rangeOf(index) {
    for (const range of this.frame?.solids ?? []) {
      if (index >= range.first && index < range.first + range.count) return range;
    }
    return null;
  }
}

function keep(list, value) {
  list.push(value);
  if (list.length > TIMINGS_KEPT) list.shift();
}

function vec(v) {
  return [v?.x ?? 0, v?.y ?? 0, v?.z ?? 0];
}

function toVec3(p) {
  return { x: p[0], y: p[1], z: p[2] };
}

/**
 * A shape's outline in its body's frame, as segments: a box's edges, three
 * great circles of a sphere, a capsule's (along y) rims and sides. A
 * plane or a mesh has none here (its axes still show where it is).
 */
function outline(shape) {
  const out = [];
  if (shape?.box) {
    const h = vec(shape.box.half_extents);
    const corner = (i) => [i & 1 ? h[0] : -h[0], i & 2 ? h[1] : -h[1], i & 4 ? h[2] : -h[2]];
    for (let i = 0; i < 8; i++) {
      for (const bit of [1, 2, 4]) if (!(i & bit)) out.push([corner(i), corner(i | bit)]);
    }
  }
  const circle = (centre, u, v, r) => {
    const steps = 32;
    for (let k = 0; k < steps; k++) {
      const a = (2 * Math.PI * k) / steps;
      const b = (2 * Math.PI * (k + 1)) / steps;
      const at = (t) => add(centre, add(scale(u, r * Math.cos(t)), scale(v, r * Math.sin(t))));
      out.push([at(a), at(b)]);
    }
  };
  const [x, y, z] = [[1, 0, 0], [0, 1, 0], [0, 0, 1]];
  if (shape?.sphere) {
    const r = shape.sphere.radius;
    circle([0, 0, 0], x, y, r);
    circle([0, 0, 0], y, z, r);
    circle([0, 0, 0], z, x, r);
  }
  if (shape?.capsule) {
    const { half_length: l, radius: r } = shape.capsule;
    for (const end of [-l, l]) circle([0, end, 0], z, x, r);
    for (const side of [x, z, scale(x, -1), scale(z, -1)]) {
      out.push([add(scale(side, r), [0, -l, 0]), add(scale(side, r), [0, l, 0])]);
    }
  }
  return out;
}

/** Rotates a vector by a unit quaternion. */
function rotate(q, v) {
  const u = [q.x, q.y, q.z];
  const t = scale(cross(u, v), 2);
  return add(add(v, scale(t, q.w)), cross(u, t));
}

function sum(array) {
  let s = 0;
  for (let i = 0; i < array.length; i++) if (Number.isFinite(array[i])) s += array[i];
  return s;
}

/** 2D positions as 3D (z = 0), so one renderer draws both. */
function widen(raw, components, n) {
  const out = new Float32Array(n * 3);
  for (let i = 0; i < n; i++) {
    for (let k = 0; k < components && k < 3; k++) out[3 * i + k] = raw[components * i + k];
  }
  return out;
}

function kineticEnergy(view, n) {
  const ke = view.fields.get("FIELD_KIND_KINETIC_ENERGY");
  if (ke) return sum(fieldArray(ke));
  const velocity = view.fields.get("FIELD_KIND_VELOCITY");
  const mass = view.fields.get("FIELD_KIND_MASS");
  if (!velocity || !mass) return NaN;
  const v = fieldArray(velocity);
  const m = fieldArray(mass);
  const c = velocity.components;
  let e = 0;
  for (let i = 0; i < n; i++) {
    let v2 = 0;
    for (let k = 0; k < c; k++) v2 += v[c * i + k] ** 2;
    if (Number.isFinite(v2) && Number.isFinite(m[i])) e += 0.5 * m[i] * v2;
  }
  return e;
}

/** The box the particles fill now. */
function bounds(positions) {
  const min = [Infinity, Infinity, Infinity];
  const max = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < positions.length; i += 3) {
    for (let k = 0; k < 3; k++) {
      const x = positions[i + k];
      if (!Number.isFinite(x)) continue;
      if (x < min[k]) min[k] = x;
      if (x > max[k]) max[k] = x;
    }
  }
  return { min, max };
}

/**
 * Frames the scene's domain (where everything will move), or the
 * particles where the domain is unknown; sizes the sprites to about one
 * particle spacing.
 */
function fitCamera(view, positions) {
  const { min, max } = bounds(positions);
  if (!Number.isFinite(min[0])) return;
  const planar = max[2] - min[2] < 1e-9;
  const domain = view.session.scene?.domain;
  const box = domain?.min && domain?.max ? { min: vec(domain.min), max: vec(domain.max) } : { min, max };
  if (planar) {
    box.min[2] = 0;
    box.max[2] = 0;
    renderer.camera.faceFront();
  }
  view.size = Math.max(box.max[0] - box.min[0], box.max[1] - box.min[1], box.max[2] - box.min[2], 1e-3);
  renderer.camera.fit(box.min, box.max);
  if (domain?.min && domain?.max) renderer.setLines("domain", boxEdges(box.min, box.max, [0.4, 0.44, 0.5]));
  else renderer.setLines("domain", null);
  // Sprites about one particle spacing across: the box shared out among the particles.
  const n = positions.length / 3;
  const volume = planar
    ? (max[0] - min[0]) * (max[1] - min[1])
    : (max[0] - min[0]) * (max[1] - min[1]) * Math.max(max[2] - min[2], view.size * 0.05);
  baseSize = Math.max((volume / Math.max(n, 1)) ** (planar ? 1 / 2 : 1 / 3), view.size * 2e-3);
  renderer.pointSize = baseSize * Number($("point-size").value);
}

let baseSize = 0.01;

/** The twelve edges of a box, as line segments with a colour. */
function boxEdges(min, max, colour) {
  const corner = (i) => [i & 1 ? max[0] : min[0], i & 2 ? max[1] : min[1], i & 4 ? max[2] : min[2]];
  const segments = [];
  for (let i = 0; i < 8; i++) {
    for (const bit of [1, 2, 4]) {
      if (!(i & bit)) segments.push(...corner(i), ...colour, ...corner(i | bit), ...colour);
    }
  }
  return segments;
}

// --- colour by field ---------------------------------------------------

function fieldChoices(view) {
  const select = $("field-select");
  const wanted = ["none"];
  for (const name of view.fields.keys()) {
    if (name === "FIELD_KIND_POSITION") continue;
    wanted.push(name);
  }
  const have = [...select.options].map((o) => o.value);
  if (have.join() === wanted.join()) return;
  const chosen = select.value;
  select.replaceChildren(
    ...wanted.map((name) => {
      const option = document.createElement("option");
      option.value = name;
      const label = FIELD_LABELS[name] ?? name.replace("FIELD_KIND_", "").toLowerCase();
      option.textContent = name === "FIELD_KIND_VELOCITY" ? "speed |v|" : name === "none" ? "one colour" : label;
      return option;
    }),
  );
  select.value = wanted.includes(chosen) ? chosen : wanted.includes("FIELD_KIND_VELOCITY") ? "FIELD_KIND_VELOCITY" : "none";
}

/** One value per particle for the chosen field (vectors by their length), and the colour bar. */
function colourValues(view, n) {
  const name = $("field-select").value;
  const field = view.fields.get(name);
  if (!field || name === "none") {
    colourBar(null);
    return null;
  }
  const raw = fieldArray(field);
  const c = field.components || 1;
  let values = raw;
  if (c > 1) {
    values = new Float32Array(n);
    for (let i = 0; i < n; i++) {
      let s = 0;
      for (let k = 0; k < c; k++) s += raw[c * i + k] ** 2;
      values[i] = Math.sqrt(s);
    }
  } else if (!(raw instanceof Float32Array)) {
    values = Float32Array.from(raw);
  }
  if (!$("hold-range").checked || !view.range) {
    let lo = Infinity;
    let hi = -Infinity;
    for (let i = 0; i < values.length; i++) {
      const x = values[i];
      if (!Number.isFinite(x)) continue;
      if (x < lo) lo = x;
      if (x > hi) hi = x;
    }
    view.range = Number.isFinite(lo) ? [lo, hi] : [0, 1];
  }
  renderer.range = view.range;
  colourBar(view.range);
  return values;
}

function colourBar(range) {
  const bar = $("colourbar");
  bar.hidden = range === null;
  if (range === null) return;
  const canvas = $("colourbar-canvas");
  const g = canvas.getContext("2d");
  for (let y = 0; y < canvas.height; y++) {
    g.fillStyle = colourAt(1 - y / (canvas.height - 1));
    g.fillRect(0, y, canvas.width, 1);
  }
  $("colourbar-max").textContent = range[1].toPrecision(4);
  $("colourbar-min").textContent = range[0].toPrecision(4);
}

// --- the time line -----------------------------------------------------

function showStatus(view) {
  const s = view.status ?? {};
  $("t-state").textContent = stateName(s.state ?? 0) + (s.reason ? ` (${s.reason})` : "");
  const warnings = $("warnings");
  warnings.querySelectorAll(".fault").forEach((el) => el.remove());
  if (stateName(s.state ?? 0) === "faulted") {
    const el = document.createElement("div");
    el.className = "fault";
    el.textContent = `Faulted: ${s.reason}. Reset clears the fault; the last good frame is shown.`;
    warnings.append(el);
  }
}

function showTimeline(view, h) {
  $("t-step").textContent = String(h.step ?? 0);
  $("t-time").textContent = `${(h.time ?? 0).toFixed(4)} s`;
  $("t-substeps").textContent = `${h.substeps ?? 0} × ${(h.substep_dt ?? 0).toExponential(2)} s`;
  $("t-solver").textContent = `${h.solver_iterations ?? 0} iterations, density error ${((h.density_error ?? 0) * 100).toFixed(3)} %`;
  const decode = stats.decodeMs.at(-1) ?? 0;
  const upload = stats.uploadMs.at(-1) ?? 0;
  $("t-frames").textContent = `${stats.frames} received; decode ${decode.toFixed(2)} ms, upload ${upload.toFixed(2)} ms`;
  const warnings = $("warnings");
  warnings.querySelectorAll(".warn").forEach((el) => el.remove());
  const warn = (text) => {
    const el = document.createElement("div");
    el.className = "warn";
    el.textContent = text;
    warnings.append(el);
  };
  if (h.capped) warn("Sub-steps capped: the step needed more sub-steps than max_substeps allows, so it ran at a larger, less stable sub-step.");
  if (h.unconverged > 0) warn(`${h.unconverged} pressure solve(s) stopped at their iteration limit before reaching the tolerance.`);
}

// --- constraints: grabs and handles ------------------------------------

function showConstraints(view) {
  $("constraints").replaceChildren(
    ...view.constraints.map((c) => {
      const li = document.createElement("li");
      const kind = c.handle ? "handle" : c.grab ? "grab" : c.velocity ? "velocity" : c.obstacle ? "obstacle" : "?";
      li.textContent = `${c.name}: ${kind}`;
      return li;
    }),
  );
  $("design-row").hidden = !view.kinds.includes("solid");
}

async function edit(view, edits) {
  const list = await call("EditConstraints", { session_id: view.id, edits }, "EditConstraints");
  view.constraints = list.constraints;
  showConstraints(view);
  view.showMarkers();
  requestAnimationFrame(draw);
}

/**
 * One constraint edit in flight per drag: moves that come while one is
 * on its way replace each other, so a fast mouse never queues edits.
 */
class Throttle {
  constructor() {
    this.busy = false;
    this.next = null;
  }

  push(job) {
    this.next = job;
    if (!this.busy) this.run();
  }

  async run() {
    this.busy = true;
    while (this.next) {
      const job = this.next;
      this.next = null;
      try {
        await job();
      } catch {
        // Reported by `call`; the next move tries again.
      }
    }
    this.busy = false;
  }

  async idle() {
    while (this.busy) await new Promise((resolve) => setTimeout(resolve, 10));
  }
}

const throttle = new Throttle();
let drag = null;

function pointer(event) {
  const rect = $("canvas").getBoundingClientRect();
  return { x: event.clientX - rect.left, y: event.clientY - rect.top };
}

function onPointerDown(event) {
  if (!current || !current.positions) return startOrbit(event);
  const { x, y } = pointer(event);
  const index = renderer.pick(x, y);
  const range = index >= 0 ? current.rangeOf(index) : null;
  const kind = range ? current.kinds[range.system] : null;
  const p = index >= 0 ? [current.positions[3 * index], current.positions[3 * index + 1], current.positions[3 * index + 2]] : null;
  if (range && (kind === "modal_solid" || kind === "shell") && current.rest.has(range.system)) {
    const local = index - range.first;
    const rest = current.rest.get(range.system);
    drag = {
      kind: "grab",
      system: range.system,
      point: [rest[3 * local], rest[3 * local + 1], rest[3 * local + 2]],
      anchor: p,
      start: { x, y },
      turn: event.shiftKey,
    };
    $("canvas").setPointerCapture(event.pointerId);
    return;
  }
  if (range && kind === "solid" && $("design-mode").checked) {
    const local = index - range.first;
    current.handles += 1;
    const name = `handle-${current.handles}`;
    drag = { kind: "handle", name, system: range.system, local, anchor: p, start: { x, y } };
    throttle.push(() =>
      edit(current, [{ add: handle(name, range.system, local, p) }]),
    );
    $("canvas").setPointerCapture(event.pointerId);
    return;
  }
  const marker = pickHandle(x, y);
  if (marker) {
    drag = { kind: "handle", ...marker, start: { x, y } };
    $("canvas").setPointerCapture(event.pointerId);
    return;
  }
  startOrbit(event);
}

function handle(name, system, local, target) {
  return {
    name,
    handle: {
      points: { particles: { system, indices: [local] } },
      target: { positions: { positions: [toVec3(target)] } },
    },
  };
}

/** A handle whose target marker lies under the pointer. */
function pickHandle(x, y) {
  for (const c of current.constraints) {
    const selection = c.handle?.points?.particles;
    const targets = c.handle?.target?.positions?.positions ?? [];
    if (!selection || selection.indices.length !== 1 || targets.length !== 1) continue;
    const at = renderer.project(vec(targets[0]));
    if (at && (at.x - x) ** 2 + (at.y - y) ** 2 < 14 ** 2) {
      return { name: c.name, system: selection.system, local: selection.indices[0], anchor: vec(targets[0]) };
    }
  }
  return null;
}

function startOrbit(event) {
  drag = { kind: event.button === 2 || event.ctrlKey ? "pan" : "orbit", last: { x: event.clientX, y: event.clientY } };
  $("canvas").setPointerCapture(event.pointerId);
}

function onPointerMove(event) {
  if (!drag) return;
  if (drag.kind === "orbit" || drag.kind === "pan") {
    const dx = event.clientX - drag.last.x;
    const dy = event.clientY - drag.last.y;
    drag.last = { x: event.clientX, y: event.clientY };
    if (drag.kind === "orbit") renderer.camera.orbit(dx, dy);
    else renderer.camera.pan(dx, dy, $("canvas").clientHeight);
    requestAnimationFrame(draw);
    return;
  }
  const { x, y } = pointer(event);
  const view = current;
  if (drag.kind === "grab") {
    const grab = { system: drag.system, point: toVec3(drag.point) };
    if (drag.turn) {
      // A turn about the axis in the view plane across the drag, a
      // quarter turn per 200 pixels.
      const camera = renderer.camera.view();
      const right = [camera[0], camera[4], camera[8]];
      const up = [camera[1], camera[5], camera[9]];
      const dx = x - drag.start.x;
      const dy = y - drag.start.y;
      const angle = (Math.hypot(dx, dy) / 200) * (Math.PI / 2);
      const axis = normalise(add(scale(up, dx), scale(right, dy)));
      grab.rotation = toVec3(scale(axis, angle));
    } else {
      drag.target = renderer.unproject(x, y, drag.anchor);
      grab.position = toVec3(drag.target);
    }
    throttle.push(upsert(view, { name: "grab", grab }));
  } else if (drag.kind === "handle") {
    drag.target = renderer.unproject(x, y, drag.anchor);
    const { name, system, local, target } = drag;
    throttle.push(upsert(view, handle(name, system, local, target)));
  }
}

/**
 * The edit that adds `constraint`, or replaces the one of its name,
 * decided when the edit goes rather than when the pointer moved: a move
 * that comes while the drag's first add is on its way must replace what
 * that add made, and a move whose edit superseded a queued add must add.
 */
function upsert(view, constraint) {
  return () => {
    const exists = view.constraints.some((c) => c.name === constraint.name);
    return edit(view, [{ [exists ? "replace" : "add"]: constraint }]);
  };
}

async function onPointerUp(event) {
  const ended = drag;
  drag = null;
  if (!ended || !current) return;
  $("canvas").releasePointerCapture?.(event.pointerId);
  if (ended.kind === "grab" && !$("keep-grab").checked) {
    const view = current;
    await throttle.idle();
    if (view.constraints.some((c) => c.name === "grab")) {
      throttle.push(() => edit(view, [{ remove: "grab" }]));
    }
  }
}

async function optimise() {
  const view = current;
  if (!view) return;
  const system = view.kinds.indexOf("solid");
  if (system < 0) return;
  const progress = $("design-progress");
  progress.textContent = "optimising…";
  try {
    for await (const event of service.stream("Optimize", { session_id: view.id, system, shape: {}, playback: true })) {
      if (event.progress) {
        const e = event.progress.energies ?? {};
        progress.textContent = `iteration ${event.progress.iteration}: handle ${(e.handle ?? 0).toExponential(2)}, rigidity ${(e.rigidity ?? 0).toExponential(2)}`;
      }
      if (event.result) {
        const r = event.result;
        const info = r.info ?? {};
        progress.textContent = `${info.converged ? "converged" : "stopped"} after ${info.iterations} iterations`;
        const n = r.rest_positions.length;
        view.design = { rest: r.rest_positions, displacement: r.displacements.slice(0, n) };
        view.showMarkers();
        requestAnimationFrame(draw);
      }
    }
  } catch (error) {
    progress.textContent = "";
    report(error, "Optimize");
  }
}

// --- commands -----------------------------------------------------------

async function select(id) {
  if (current) current.close();
  let session;
  try {
    session = await service.unary("GetSession", { session_id: id });
  } catch (error) {
    report(error, "GetSession");
    return;
  }
  banner(null);
  current = new SessionView(session);
  $("session-title").textContent = `${session.name} (${session.id})`;
  for (const row of $("sessions").querySelectorAll("tbody tr")) {
    row.className = row.dataset.id === id ? "selected" : "";
  }
  showStatus(current);
  showConstraints(current);
}

async function command(method, extra = {}) {
  if (!current) return;
  try {
    await call(method, { session_id: current.id, ...extra }, method);
    banner(null);
  } catch {
    // Reported.
  }
  refreshList();
}

function download(name, bytes) {
  const url = URL.createObjectURL(new Blob([bytes], { type: "application/octet-stream" }));
  const a = document.createElement("a");
  a.href = url;
  a.download = name;
  a.click();
  setTimeout(() => URL.revokeObjectURL(url), 10_000);
}

async function create(request, what) {
  try {
    const session = await call("CreateSession", request, what);
    banner(null);
    await refreshList();
    await select(session.id);
  } catch {
    // Reported.
  }
}

async function loadScenes() {
  const response = await fetch("scenes.json");
  const scenes = response.ok ? await response.json() : [];
  $("scene-select").replaceChildren(
    ...scenes.map((s) => {
      const option = document.createElement("option");
      option.value = s.file;
      option.textContent = s.name;
      return option;
    }),
  );
  return scenes;
}

function draw() {
  renderer.draw();
}

function wire(scenes) {
  $("token-form").addEventListener("submit", (event) => {
    event.preventDefault();
    service.token = $("token").value.trim() || null;
    if (service.token) sessionStorage.setItem("meshless-token", service.token);
    else sessionStorage.removeItem("meshless-token");
    banner(null);
    start();
  });
  $("create-shipped").addEventListener("click", async () => {
    const scene = scenes.find((s) => s.file === $("scene-select").value);
    if (scene) await create({ scene_toml: scene.toml }, `CreateSession (${scene.name})`);
  });
  $("scene-file").addEventListener("change", async (event) => {
    const file = event.target.files[0];
    if (file) await create({ scene_toml: await file.text() }, `CreateSession (${file.name})`);
    event.target.value = "";
  });
  $("restore-file").addEventListener("change", async (event) => {
    const file = event.target.files[0];
    if (!file) return;
    try {
      const session = await call("Restore", { data: new Uint8Array(await file.arrayBuffer()) }, "Restore");
      await refreshList();
      await select(session.id);
    } catch {
      // Reported.
    }
    event.target.value = "";
  });
  $("run").addEventListener("click", () =>
    command("Run", $("run-forever").checked ? { forever: true } : { until_time: Number($("run-until").value) }),
  );
  $("pause").addEventListener("click", () => command("Pause"));
  $("resume").addEventListener("click", () => command("Resume"));
  $("reset").addEventListener("click", () => command("Reset"));
  $("step").addEventListener("click", () => command("Step", { steps: Number($("step-count").value) }));
  $("delete").addEventListener("click", () => command("DeleteSession"));
  $("snapshot").addEventListener("click", async () => {
    if (!current) return;
    try {
      const snapshot = await call("Snapshot", { session_id: current.id }, "Snapshot");
      download(`${snapshot.session_id}-step${snapshot.step}.snapshot`, snapshot.data);
    } catch {
      // Reported.
    }
  });
  $("release").addEventListener("click", () => {
    if (current?.constraints.some((c) => c.name === "grab")) {
      throttle.push(() => edit(current, [{ remove: "grab" }]));
    }
  });
  $("optimise").addEventListener("click", optimise);
  $("clear-handles").addEventListener("click", () => {
    if (!current) return;
    const handles = current.constraints.filter((c) => c.handle).map((c) => ({ remove: c.name }));
    current.design = null;
    if (handles.length) throttle.push(() => edit(current, handles));
  });
  for (const id of ["field-select", "hold-range", "show-particles", "show-surfaces"]) {
    $(id).addEventListener("change", () => {
      if (current?.frame) current.show(current.frame);
      requestAnimationFrame(draw);
    });
  }
  $("point-size").addEventListener("input", () => {
    renderer.pointSize = baseSize * Number($("point-size").value);
    requestAnimationFrame(draw);
  });
  const canvas = $("canvas");
  canvas.addEventListener("pointerdown", onPointerDown);
  canvas.addEventListener("pointermove", onPointerMove);
  canvas.addEventListener("pointerup", onPointerUp);
  canvas.addEventListener("contextmenu", (event) => event.preventDefault());
  canvas.addEventListener(
    "wheel",
    (event) => {
      event.preventDefault();
      renderer.camera.zoom(Math.exp(event.deltaY * 0.001));
      requestAnimationFrame(draw);
    },
    { passive: false },
  );
  window.addEventListener("resize", () => requestAnimationFrame(draw));
}

let listTimer = null;

async function start() {
  try {
    const info = await service.unary("GetServerInfo", {});
    $("server").textContent = `server ${info.server_name || "(unnamed)"} · version ${info.version} · at most ${info.max_particles_per_session} particles per session`;
  } catch (error) {
    report(error, "GetServerInfo");
    $("server").textContent = "not connected";
    return;
  }
  await refreshList();
  clearInterval(listTimer);
  listTimer = setInterval(refreshList, LIST_PERIOD_MS);
  const wanted = new URLSearchParams(location.search).get("session");
  if (wanted && sessionsById.has(wanted) && !current) await select(wanted);
}

async function main() {
  schema = await Schema.load();
  service = new Service(schema, { token: sessionStorage.getItem("meshless-token") });
  renderer = new Renderer($("canvas"));
  // A scene pays only for the fields it names: the energies are plotted
  // when its frames carry them.
  plots.kinetic = new Plot($("plot-kinetic"), {
    label: "kinetic energy",
    unit: "J",
    colour: "#7fb4ff",
    missing: 'add "kinetic_energy" to [output] fields',
  });
  plots.elastic = new Plot($("plot-elastic"), {
    label: "elastic energy",
    unit: "J",
    colour: "#ffb36b",
    missing: 'add "elastic_energy" to [output] fields',
  });
  plots.density = new Plot($("plot-density"), { label: "density error", colour: "#8fe08a" });
  const scenes = await loadScenes();
  wire(scenes);
  // For people debugging the page and for the browser tests.
  window.meshless = {
    schema,
    service,
    stats,
    renderer,
    get view() {
      return current;
    },
    select,
    decodeFrameBase64(text) {
      const bytes = Uint8Array.from(atob(text), (c) => c.charCodeAt(0));
      const frame = schema.decode("meshless.v1.Frame", bytes);
      const mesh = (m) => ({
        vertices: Array.from(fieldArray({ data: m.vertices, scalar: 1 })),
        triangles: Array.from(fieldArray({ data: m.triangles, scalar: 2 })),
      });
      return {
        header: frame.header,
        fields: frame.fields.map((f) => ({ kind: f.kind, components: f.components, values: Array.from(fieldArray(f)) })),
        surfaces: frame.solid_surfaces.map((s) => mesh(s.mesh)),
      };
    },
    project: (p) => renderer.project(p),
    /** See `SessionView.pull`: the page's capacity in frames per second. */
    pull(count) {
      if (!current) throw new Error("no session is shown");
      return current.pull(count);
    },
    /** Whether a constraint edit of a drag is on its way. */
    get editing() {
      return throttle.busy || throttle.next !== null;
    },
  };
  requestAnimationFrame(draw);
  await start();
  document.body.dataset.ready = "true";
}

main().catch((error) => {
  banner(`The viewer did not start: ${error.message}`);
  document.body.dataset.ready = "failed";
});
