// The 3D view: particles as shaded round sprites coloured by a field,
// surfaces with their normals, rigid bodies' axes, and an orbit camera.
// Plain WebGL2: a point cloud and a few triangle meshes need two small
// shader programs, not a scene-graph library.

const POINT_VS = `#version 300 es
uniform mat4 u_view;
uniform mat4 u_proj;
uniform float u_size;      // sprite diameter in metres
uniform float u_viewport;  // viewport height in pixels
uniform vec2 u_range;
in vec3 a_position;
in float a_value;
out float v_t;
out float v_nan;
void main() {
  vec4 eye = u_view * vec4(a_position, 1.0);
  gl_Position = u_proj * eye;
  gl_PointSize = max(2.0, u_size * u_proj[1][1] * u_viewport * 0.5 / max(-eye.z, 1e-6));
  float span = u_range.y - u_range.x;
  v_nan = (a_value != a_value) ? 1.0 : 0.0;
  v_t = span > 0.0 ? clamp((a_value - u_range.x) / span, 0.0, 1.0) : 0.5;
}`;

const POINT_FS = `#version 300 es
precision highp float;
uniform sampler2D u_colormap;
uniform vec3 u_flat;
uniform bool u_colored;
in float v_t;
in float v_nan;
out vec4 colour;
void main() {
  vec2 p = gl_PointCoord * 2.0 - 1.0;
  float r2 = dot(p, p);
  if (r2 > 1.0) discard;
  vec3 base = u_colored ? texture(u_colormap, vec2(v_t, 0.5)).rgb : u_flat;
  if (v_nan > 0.5) base = vec3(0.55);
  // A sphere's shading, lit from the viewer's upper left.
  vec3 n = vec3(p.x, -p.y, sqrt(1.0 - r2));
  float light = 0.55 + 0.45 * max(dot(n, normalize(vec3(-0.4, 0.5, 0.8))), 0.0);
  colour = vec4(base * light, 1.0);
}`;

const MESH_VS = `#version 300 es
uniform mat4 u_view;
uniform mat4 u_proj;
in vec3 a_position;
in vec3 a_normal;
out vec3 v_normal;
void main() {
  v_normal = mat3(u_view) * a_normal;
  gl_Position = u_proj * u_view * vec4(a_position, 1.0);
}`;

const MESH_FS = `#version 300 es
precision highp float;
uniform vec4 u_colour;
in vec3 v_normal;
out vec4 colour;
void main() {
  vec3 n = normalize(v_normal);
  if (!gl_FrontFacing) n = -n;
  float light = 0.3 + 0.7 * abs(dot(n, normalize(vec3(-0.4, 0.5, 0.8))));
  colour = vec4(u_colour.rgb * light, u_colour.a);
}`;

const LINE_VS = `#version 300 es
uniform mat4 u_view;
uniform mat4 u_proj;
in vec3 a_position;
in vec3 a_colour;
out vec3 v_colour;
void main() {
  v_colour = a_colour;
  gl_Position = u_proj * u_view * vec4(a_position, 1.0);
}`;

const LINE_FS = `#version 300 es
precision highp float;
in vec3 v_colour;
out vec4 colour;
void main() { colour = vec4(v_colour, 1.0); }`;

/** Viridis (van der Walt & Smith, matplotlib), sampled at 9 stops. */
const VIRIDIS = [
  [68, 1, 84], [71, 44, 122], [59, 81, 139], [44, 113, 142], [33, 144, 141],
  [39, 173, 129], [92, 200, 99], [170, 220, 50], [253, 231, 37],
];

/** The colour map at t in [0, 1], as CSS for the colour bar. */
export function colourAt(t) {
  const x = Math.min(Math.max(t, 0), 1) * (VIRIDIS.length - 1);
  const i = Math.min(Math.floor(x), VIRIDIS.length - 2);
  const f = x - i;
  const c = VIRIDIS[i].map((a, k) => Math.round(a + (VIRIDIS[i + 1][k] - a) * f));
  return `rgb(${c[0]},${c[1]},${c[2]})`;
}

function compile(gl, vs, fs) {
  const program = gl.createProgram();
  for (const [type, source] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
    const shader = gl.createShader(type);
    gl.shaderSource(shader, source);
    gl.compileShader(shader);
    if (!gl.getShaderParameter(shader, gl.COMPILE_STATUS)) {
      throw new Error(`shader: ${gl.getShaderInfoLog(shader)}`);
    }
    gl.attachShader(program, shader);
  }
  gl.linkProgram(program);
  if (!gl.getProgramParameter(program, gl.LINK_STATUS)) {
    throw new Error(`program: ${gl.getProgramInfoLog(program)}`);
  }
  const uniforms = {};
  const count = gl.getProgramParameter(program, gl.ACTIVE_UNIFORMS);
  for (let i = 0; i < count; i++) {
    const name = gl.getActiveUniform(program, i).name;
    uniforms[name] = gl.getUniformLocation(program, name);
  }
  return { program, uniforms, attribute: (name) => gl.getAttribLocation(program, name) };
}

// Column-major 4x4 matrices, as WebGL takes them.
function perspective(fovy, aspect, near, far) {
  const f = 1 / Math.tan(fovy / 2);
  const nf = 1 / (near - far);
  return new Float32Array([f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0]);
}

function lookAt(eye, target, up) {
  const z = normalise(sub(eye, target));
  const x = normalise(cross(up, z));
  const y = cross(z, x);
  return new Float32Array([
    x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
    -dot(x, eye), -dot(y, eye), -dot(z, eye), 1,
  ]);
}

export const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
export const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
export const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
export const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
export const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
export const normalise = (a) => scale(a, 1 / (Math.hypot(a[0], a[1], a[2]) || 1));

/** Orbits a target: drag turns, shift-drag or right-drag pans, the wheel zooms. */
export class Camera {
  constructor() {
    this.target = [0, 0, 0];
    this.distance = 3;
    this.yaw = 0.6;
    this.pitch = 0.35;
    this.fovy = 0.8;
  }

  eye() {
    const c = Math.cos(this.pitch);
    return add(this.target, scale([c * Math.sin(this.yaw), Math.sin(this.pitch), c * Math.cos(this.yaw)], this.distance));
  }

  /** Frames a box: looks at its centre from far enough to see all of it. */
  fit(min, max) {
    this.target = scale(add(min, max), 0.5);
    const radius = Math.max(Math.hypot(max[0] - min[0], max[1] - min[1], max[2] - min[2]) / 2, 1e-3);
    this.distance = (radius / Math.sin(this.fovy / 2)) * 1.05;
  }

  /** Faces a plane scene (2D: z = 0) straight on. */
  faceFront() {
    this.yaw = 0;
    this.pitch = 0;
  }

  view() {
    return lookAt(this.eye(), this.target, [0, 1, 0]);
  }

  proj(aspect) {
    return perspective(this.fovy, aspect, this.distance / 1000, this.distance * 100);
  }

  orbit(dx, dy) {
    this.yaw -= dx * 0.008;
    this.pitch = Math.min(Math.max(this.pitch + dy * 0.008, -1.55), 1.55);
  }

  pan(dx, dy, height) {
    const view = this.view();
    const right = [view[0], view[4], view[8]];
    const up = [view[1], view[5], view[9]];
    const perPixel = (2 * this.distance * Math.tan(this.fovy / 2)) / height;
    this.target = add(this.target, add(scale(right, -dx * perPixel), scale(up, dy * perPixel)));
  }

  zoom(factor) {
    this.distance = Math.min(Math.max(this.distance * factor, 1e-4), 1e5);
  }
}

function transform(m, p) {
  const x = m[0] * p[0] + m[4] * p[1] + m[8] * p[2] + m[12];
  const y = m[1] * p[0] + m[5] * p[1] + m[9] * p[2] + m[13];
  const z = m[2] * p[0] + m[6] * p[1] + m[10] * p[2] + m[14];
  const w = m[3] * p[0] + m[7] * p[1] + m[11] * p[2] + m[15];
  return [x, y, z, w];
}

/** Draws one session's frames into a canvas. */
export class Renderer {
  constructor(canvas) {
    const gl = canvas.getContext("webgl2", { antialias: true, preserveDrawingBuffer: true });
    if (!gl) throw new Error("this browser has no WebGL2");
    this.canvas = canvas;
    this.gl = gl;
    this.camera = new Camera();
    this.points = compile(gl, POINT_VS, POINT_FS);
    this.mesh = compile(gl, MESH_VS, MESH_FS);
    this.lines = compile(gl, LINE_VS, LINE_FS);
    this.positionBuffer = gl.createBuffer();
    this.valueBuffer = gl.createBuffer();
    this.count = 0;
    this.capacity = 0;
    this.range = [0, 1];
    this.coloured = false;
    this.pointSize = 0.01;
    this.meshes = [];
    this.domain = null;
    this.axes = null;
    this.markers = null;
    this.colormap = this.makeColormap();
  }

  makeColormap() {
    const gl = this.gl;
    const pixels = new Uint8Array(256 * 4);
    for (let i = 0; i < 256; i++) {
      const rgb = colourAt(i / 255).match(/\d+/g).map(Number);
      pixels.set([...rgb, 255], i * 4);
    }
    const texture = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, texture);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA8, 256, 1, 0, gl.RGBA, gl.UNSIGNED_BYTE, pixels);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    return texture;
  }

  /**
   * Uploads particle positions (x, y, z per particle) and one value per
   * particle to colour by (null: one colour). The buffers grow, never
   * shrink, so a steady stream of frames reallocates nothing.
   */
  setParticles(positions, values) {
    const gl = this.gl;
    const n = positions.length / 3;
    if (n > this.capacity) {
      this.capacity = Math.ceil(n * 1.25);
      gl.bindBuffer(gl.ARRAY_BUFFER, this.positionBuffer);
      gl.bufferData(gl.ARRAY_BUFFER, this.capacity * 12, gl.DYNAMIC_DRAW);
      gl.bindBuffer(gl.ARRAY_BUFFER, this.valueBuffer);
      gl.bufferData(gl.ARRAY_BUFFER, this.capacity * 4, gl.DYNAMIC_DRAW);
    }
    gl.bindBuffer(gl.ARRAY_BUFFER, this.positionBuffer);
    gl.bufferSubData(gl.ARRAY_BUFFER, 0, positions);
    this.coloured = values !== null;
    if (values) {
      gl.bindBuffer(gl.ARRAY_BUFFER, this.valueBuffer);
      gl.bufferSubData(gl.ARRAY_BUFFER, 0, values);
    }
    this.count = n;
    this.positions = positions;
  }

  /** Blocks until the GPU (or, without one, the browser's software
   * rasteriser) has carried out every command given so far. */
  finish() {
    this.gl.finish();
  }

  /** Triangle meshes: `[{vertices, triangles, normals, colour: [r, g, b, a]}]`. */
  setMeshes(meshes) {
    const gl = this.gl;
    for (const old of this.meshes) old.buffers.forEach((b) => gl.deleteBuffer(b));
    this.meshes = meshes
      .filter((m) => m.triangles.length > 0)
      .map((m) => {
        const buffers = [gl.createBuffer(), gl.createBuffer(), gl.createBuffer()];
        gl.bindBuffer(gl.ARRAY_BUFFER, buffers[0]);
        gl.bufferData(gl.ARRAY_BUFFER, m.vertices, gl.DYNAMIC_DRAW);
        gl.bindBuffer(gl.ARRAY_BUFFER, buffers[1]);
        gl.bufferData(gl.ARRAY_BUFFER, m.normals.length === m.vertices.length ? m.normals : faceless(m.vertices.length), gl.DYNAMIC_DRAW);
        gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers[2]);
        gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, m.triangles, gl.DYNAMIC_DRAW);
        return { buffers, count: m.triangles.length, colour: m.colour };
      });
  }

  /** Line segments with colours: axes of rigid bodies, grab and handle markers. */
  setLines(name, segments) {
    const gl = this.gl;
    if (this[name]) gl.deleteBuffer(this[name].buffer);
    if (!segments || segments.length === 0) {
      this[name] = null;
      return;
    }
    const data = new Float32Array(segments);
    const buffer = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.DYNAMIC_DRAW);
    this[name] = { buffer, count: data.length / 6 };
  }

  resize() {
    const ratio = window.devicePixelRatio || 1;
    const width = Math.max(1, Math.round(this.canvas.clientWidth * ratio));
    const height = Math.max(1, Math.round(this.canvas.clientHeight * ratio));
    if (this.canvas.width !== width || this.canvas.height !== height) {
      this.canvas.width = width;
      this.canvas.height = height;
    }
  }

  matrices() {
    const aspect = this.canvas.width / this.canvas.height;
    return { view: this.camera.view(), proj: this.camera.proj(aspect) };
  }

  draw() {
    const gl = this.gl;
    this.resize();
    gl.viewport(0, 0, this.canvas.width, this.canvas.height);
    gl.clearColor(0.09, 0.1, 0.12, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    const { view, proj } = this.matrices();

    if (this.count > 0) {
      const p = this.points;
      gl.useProgram(p.program);
      gl.uniformMatrix4fv(p.uniforms.u_view, false, view);
      gl.uniformMatrix4fv(p.uniforms.u_proj, false, proj);
      gl.uniform1f(p.uniforms.u_size, this.pointSize);
      gl.uniform1f(p.uniforms.u_viewport, this.canvas.height);
      gl.uniform2f(p.uniforms.u_range, this.range[0], this.range[1]);
      gl.uniform1i(p.uniforms.u_colored, this.coloured ? 1 : 0);
      gl.uniform3f(p.uniforms.u_flat, 0.35, 0.6, 0.95);
      gl.activeTexture(gl.TEXTURE0);
      gl.bindTexture(gl.TEXTURE_2D, this.colormap);
      gl.uniform1i(p.uniforms.u_colormap, 0);
      bind(gl, this.positionBuffer, p.attribute("a_position"), 3);
      if (this.coloured) {
        bind(gl, this.valueBuffer, p.attribute("a_value"), 1);
      } else {
        gl.disableVertexAttribArray(p.attribute("a_value"));
        gl.vertexAttrib1f(p.attribute("a_value"), 0);
      }
      gl.drawArrays(gl.POINTS, 0, this.count);
    }

    if (this.meshes.length > 0) {
      const m = this.mesh;
      gl.useProgram(m.program);
      gl.uniformMatrix4fv(m.uniforms.u_view, false, view);
      gl.uniformMatrix4fv(m.uniforms.u_proj, false, proj);
      gl.enable(gl.BLEND);
      gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA);
      for (const mesh of this.meshes) {
        gl.uniform4fv(m.uniforms.u_colour, mesh.colour);
        bind(gl, mesh.buffers[0], m.attribute("a_position"), 3);
        bind(gl, mesh.buffers[1], m.attribute("a_normal"), 3);
        gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, mesh.buffers[2]);
        gl.drawElements(gl.TRIANGLES, mesh.count, gl.UNSIGNED_INT, 0);
      }
      gl.disable(gl.BLEND);
    }

    for (const set of [this.domain, this.axes, this.markers]) {
      if (!set) continue;
      const l = this.lines;
      gl.useProgram(l.program);
      gl.uniformMatrix4fv(l.uniforms.u_view, false, view);
      gl.uniformMatrix4fv(l.uniforms.u_proj, false, proj);
      gl.bindBuffer(gl.ARRAY_BUFFER, set.buffer);
      gl.enableVertexAttribArray(l.attribute("a_position"));
      gl.vertexAttribPointer(l.attribute("a_position"), 3, gl.FLOAT, false, 24, 0);
      gl.enableVertexAttribArray(l.attribute("a_colour"));
      gl.vertexAttribPointer(l.attribute("a_colour"), 3, gl.FLOAT, false, 24, 12);
      gl.drawArrays(gl.LINES, 0, set.count);
    }
  }

  /** A world point in canvas CSS pixels (x right, y down) and its depth, or null behind the eye. */
  project(point) {
    const { view, proj } = this.matrices();
    const clip = transform(proj, transform(view, point));
    if (clip[3] <= 0) return null;
    const rect = this.canvas.getBoundingClientRect();
    return {
      x: ((clip[0] / clip[3] + 1) / 2) * rect.width,
      y: ((1 - clip[1] / clip[3]) / 2) * rect.height,
      depth: clip[3],
    };
  }

  /**
   * The particle nearest to a canvas point (CSS pixels) among `indices`
   * (all when null), within `radius` pixels, front-most first; or -1.
   */
  pick(x, y, radius = 12, indices = null) {
    const positions = this.positions;
    if (!positions) return -1;
    const { view, proj } = this.matrices();
    const m = multiply(proj, view);
    const rect = this.canvas.getBoundingClientRect();
    let best = -1;
    let bestScore = Infinity;
    const test = (i) => {
      const px = positions[3 * i];
      const py = positions[3 * i + 1];
      const pz = positions[3 * i + 2];
      const w = m[3] * px + m[7] * py + m[11] * pz + m[15];
      if (w <= 0) return;
      const sx = (((m[0] * px + m[4] * py + m[8] * pz + m[12]) / w + 1) / 2) * rect.width;
      const sy = ((1 - (m[1] * px + m[5] * py + m[9] * pz + m[13]) / w) / 2) * rect.height;
      const d2 = (sx - x) ** 2 + (sy - y) ** 2;
      if (d2 > radius * radius) return;
      // Nearest on screen, the nearer to the eye breaking close calls.
      const score = d2 + w * 1e-3;
      if (score < bestScore) {
        bestScore = score;
        best = i;
      }
    };
    if (indices) for (const i of indices) test(i);
    else for (let i = 0; i < this.count; i++) test(i);
    return best;
  }

  /** The point under a canvas point (CSS pixels) on the plane through `anchor` facing the eye. */
  unproject(x, y, anchor) {
    const rect = this.canvas.getBoundingClientRect();
    const eye = this.camera.eye();
    const view = this.camera.view();
    const right = [view[0], view[4], view[8]];
    const up = [view[1], view[5], view[9]];
    const forward = [-view[2], -view[6], -view[10]];
    const aspect = rect.width / rect.height;
    const t = Math.tan(this.camera.fovy / 2);
    const nx = ((x / rect.width) * 2 - 1) * t * aspect;
    const ny = (1 - (y / rect.height) * 2) * t;
    const ray = normalise(add(forward, add(scale(right, nx), scale(up, ny))));
    const s = dot(sub(anchor, eye), forward) / dot(ray, forward);
    return add(eye, scale(ray, s));
  }
}

function multiply(a, b) {
  const out = new Float32Array(16);
  for (let c = 0; c < 4; c++) {
    for (let r = 0; r < 4; r++) {
      let s = 0;
      for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
      out[c * 4 + r] = s;
    }
  }
  return out;
}

function bind(gl, buffer, location, size) {
  if (location < 0) return;
  gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
  gl.enableVertexAttribArray(location);
  gl.vertexAttribPointer(location, size, gl.FLOAT, false, 0, 0);
}

/** Normals for a mesh that has none: all facing +z, so it still draws. */
function faceless(length) {
  const normals = new Float32Array(length);
  for (let i = 2; i < length; i += 3) normals[i] = 1;
  return normals;
}
