// Protocol Buffers and gRPC-web for the viewer, with no toolchain.
//
// The page fetches the server's schema (GET /schema.json, made at start
// from the very descriptors the server's own code was generated from), so
// this one generic codec encodes requests and decodes answers and frames of
// every message the service has: nothing here can drift from the .proto
// files. Calls go to the same `meshless.v1.Simulation` service as any gRPC
// client, as gRPC-web over fetch: the same token check, access rules and
// limits.

const TEXT_DECODER = new TextDecoder();
const TEXT_ENCODER = new TextEncoder();

/** Wire types (the low three bits of a field's tag). */
const VARINT = 0;
const FIXED64 = 1;
const LEN = 2;
const FIXED32 = 5;

/** Scalar types stored as varints. */
const VARINT_TYPES = new Set([
  "int32", "int64", "uint32", "uint64", "sint32", "sint64", "bool", "enum",
]);
/** Scalar types that a repeated field packs. */
const PACKABLE = new Set([...VARINT_TYPES, "double", "float", "fixed32", "fixed64", "sfixed32", "sfixed64"]);

/** A message that does not decode: truncated, or a type that does not match. */
export class DecodeError extends Error {}

/** Reads the protobuf wire format from a byte array, without copying bytes fields. */
class Reader {
  constructor(bytes) {
    this.buf = bytes;
    this.pos = 0;
    this.view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  }

  /** A varint as a BigInt when it needs more than 28 bits, else a Number. */
  varint() {
    let byte = this.byte();
    if (byte < 0x80) return byte;
    let small = byte & 0x7f;
    for (let shift = 7; shift < 28; shift += 7) {
      byte = this.byte();
      small |= (byte & 0x7f) << shift;
      if (byte < 0x80) return small;
    }
    let big = BigInt(small);
    for (let shift = 28n; shift < 70n; shift += 7n) {
      byte = this.byte();
      big |= BigInt(byte & 0x7f) << shift;
      if (byte < 0x80) return BigInt.asUintN(64, big);
    }
    throw new DecodeError("a varint longer than 10 bytes");
  }

  byte() {
    if (this.pos >= this.buf.length) throw new DecodeError("truncated message");
    return this.buf[this.pos++];
  }

  take(n) {
    if (n > this.buf.length - this.pos) throw new DecodeError("truncated message");
    const out = this.buf.subarray(this.pos, this.pos + n);
    this.pos += n;
    return out;
  }

  skip(wire) {
    switch (wire) {
      case VARINT: this.varint(); break;
      case FIXED64: this.take(8); break;
      case LEN: this.take(Number(this.varint())); break;
      case FIXED32: this.take(4); break;
      default: throw new DecodeError(`wire type ${wire} is not supported`);
    }
  }
}

/** Appends the protobuf wire format to a growing buffer. */
class Writer {
  constructor() {
    this.buf = new Uint8Array(64);
    this.len = 0;
  }

  room(n) {
    if (this.len + n <= this.buf.length) return;
    let size = this.buf.length * 2;
    while (size < this.len + n) size *= 2;
    const grown = new Uint8Array(size);
    grown.set(this.buf.subarray(0, this.len));
    this.buf = grown;
  }

  varint(value) {
    let v = BigInt.asUintN(64, BigInt(value));
    this.room(10);
    while (v >= 0x80n) {
      this.buf[this.len++] = Number(v & 0x7fn) | 0x80;
      v >>= 7n;
    }
    this.buf[this.len++] = Number(v);
  }

  tag(number, wire) {
    this.varint(number * 8 + wire);
  }

  bytes(data) {
    this.varint(data.length);
    this.room(data.length);
    this.buf.set(data, this.len);
    this.len += data.length;
  }

  fixed(n, write) {
    this.room(n);
    write(new DataView(this.buf.buffer, this.len, n));
    this.len += n;
  }

  finish() {
    return this.buf.slice(0, this.len);
  }
}

/** The value a scalar field has when the wire does not carry it. */
function defaultOf(field) {
  switch (field.type) {
    case "string": return "";
    case "bytes": return new Uint8Array(0);
    case "bool": return false;
    case "message": return undefined;
    default: return 0;
  }
}

function zigzag(v) {
  const big = BigInt(v);
  return (big >> 1n) ^ -(big & 1n);
}

/** A varint read as the field's type; 64-bit integers become Numbers (exact up to 2^53). */
function fromVarint(type, raw) {
  switch (type) {
    case "bool": return raw !== 0 && raw !== 0n;
    case "int32":
    case "enum": return Number(BigInt.asIntN(32, BigInt(raw)));
    case "uint32": return Number(BigInt.asUintN(32, BigInt(raw)));
    case "int64": return Number(BigInt.asIntN(64, BigInt(raw)));
    case "uint64": return Number(raw);
    case "sint32":
    case "sint64": return Number(zigzag(raw));
    default: throw new DecodeError(`${type} is not a varint type`);
  }
}

function readFixed(reader, type) {
  const at = reader.pos;
  switch (type) {
    case "double": reader.take(8); return reader.view.getFloat64(at, true);
    case "fixed64": reader.take(8); return Number(reader.view.getBigUint64(at, true));
    case "sfixed64": reader.take(8); return Number(reader.view.getBigInt64(at, true));
    case "float": reader.take(4); return reader.view.getFloat32(at, true);
    case "fixed32": reader.take(4); return reader.view.getUint32(at, true);
    case "sfixed32": reader.take(4); return reader.view.getInt32(at, true);
    default: throw new DecodeError(`${type} is not a fixed-width type`);
  }
}

function wireOf(type) {
  if (VARINT_TYPES.has(type)) return VARINT;
  if (type === "double" || type === "fixed64" || type === "sfixed64") return FIXED64;
  if (type === "float" || type === "fixed32" || type === "sfixed32") return FIXED32;
  return LEN;
}

/**
 * The service's messages, enums and methods as the server describes them:
 * `{messages: {name: {fields: [{name, number, type, ref?, repeated, optional}]}},
 *   enums: {name: {VALUE: number}}, methods: {name: {input, output, stream}}}`.
 */
export class Schema {
  constructor(json) {
    this.messages = json.messages;
    this.enums = json.enums;
    this.methods = json.methods;
    this.byNumber = new Map();
    for (const [name, message] of Object.entries(this.messages)) {
      this.byNumber.set(name, new Map(message.fields.map((f) => [f.number, f])));
    }
  }

  /** Fetches the schema of the server that serves this page. */
  static async load(base = "") {
    const response = await fetch(`${base}/schema.json`);
    if (!response.ok) throw new Error(`the schema did not load: HTTP ${response.status}`);
    return new Schema(await response.json());
  }

  /** An enum's value names by number, for showing states in words. */
  enumName(type, number) {
    const values = this.enums[type] ?? {};
    for (const [name, value] of Object.entries(values)) if (value === number) return name;
    return String(number);
  }

  /** Message `type` decoded from `bytes`; bytes fields are views into `bytes`. */
  decode(type, bytes) {
    return this.read(type, new Reader(bytes), bytes.length);
  }

  read(type, reader, end) {
    const fields = this.byNumber.get(type);
    if (!fields) throw new DecodeError(`no message ${type} in the schema`);
    const out = {};
    for (const field of this.messages[type].fields) {
      if (field.repeated) out[field.name] = [];
      else if (!field.optional && !field.oneof) out[field.name] = defaultOf(field);
    }
    while (reader.pos < end) {
      const tag = Number(reader.varint());
      const number = Math.floor(tag / 8);
      const wire = tag & 7;
      const field = fields.get(number);
      if (!field) {
        reader.skip(wire);
        continue;
      }
      if (field.repeated && wire === LEN && PACKABLE.has(field.type)) {
        const len = Number(reader.varint());
        const stop = reader.pos + len;
        if (stop > end) throw new DecodeError(`${type}.${field.name} overruns its message`);
        while (reader.pos < stop) out[field.name].push(this.scalar(field, reader));
        continue;
      }
      if (wire !== wireOf(field.type)) {
        throw new DecodeError(`${type}.${field.name} has wire type ${wire}`);
      }
      const value = this.value(field, reader);
      if (field.repeated) out[field.name].push(value);
      else out[field.name] = value;
    }
    if (reader.pos !== end) throw new DecodeError(`${type} overruns its length`);
    return out;
  }

  scalar(field, reader) {
    return VARINT_TYPES.has(field.type)
      ? fromVarint(field.type, reader.varint())
      : readFixed(reader, field.type);
  }

  value(field, reader) {
    switch (field.type) {
      case "message": {
        const len = Number(reader.varint());
        const end = reader.pos + len;
        if (end > reader.buf.length) throw new DecodeError("truncated message");
        return this.read(field.ref, reader, end);
      }
      case "string": return TEXT_DECODER.decode(reader.take(Number(reader.varint())));
      case "bytes": return reader.take(Number(reader.varint()));
      default: return this.scalar(field, reader);
    }
  }

  /** Message `type` encoded from a plain object; absent (undefined or null) fields are left out. */
  encode(type, value) {
    const writer = new Writer();
    this.write(type, value ?? {}, writer);
    return writer.finish();
  }

  write(type, value, writer) {
    const message = this.messages[type];
    if (!message) throw new Error(`no message ${type} in the schema`);
    const known = new Set(message.fields.map((f) => f.name));
    for (const key of Object.keys(value)) {
      if (!known.has(key)) throw new Error(`${type} has no field ${key}`);
    }
    for (const field of message.fields) {
      const v = value[field.name];
      if (v === undefined || v === null) continue;
      if (field.repeated) {
        if (PACKABLE.has(field.type)) {
          if (v.length === 0) continue;
          const inner = new Writer();
          for (const item of v) this.writeScalar(field, item, inner);
          writer.tag(field.number, LEN);
          writer.bytes(inner.finish());
        } else {
          for (const item of v) this.writeValue(field, item, writer);
        }
      } else {
        this.writeValue(field, v, writer);
      }
    }
  }

  writeValue(field, v, writer) {
    if (field.type === "message") {
      const inner = new Writer();
      this.write(field.ref, v, inner);
      writer.tag(field.number, LEN);
      writer.bytes(inner.finish());
    } else if (field.type === "string") {
      writer.tag(field.number, LEN);
      writer.bytes(TEXT_ENCODER.encode(v));
    } else if (field.type === "bytes") {
      writer.tag(field.number, LEN);
      writer.bytes(v);
    } else {
      writer.tag(field.number, wireOf(field.type));
      this.writeScalar(field, v, writer);
    }
  }

  writeScalar(field, v, writer) {
    switch (field.type) {
      case "bool": writer.varint(v ? 1 : 0); break;
      case "sint32":
      case "sint64": {
        const big = BigInt(v);
        writer.varint((big << 1n) ^ (big >> 63n));
        break;
      }
      case "double": writer.fixed(8, (d) => d.setFloat64(0, v, true)); break;
      case "float": writer.fixed(4, (d) => d.setFloat32(0, v, true)); break;
      case "fixed64": writer.fixed(8, (d) => d.setBigUint64(0, BigInt(v), true)); break;
      case "sfixed64": writer.fixed(8, (d) => d.setBigInt64(0, BigInt(v), true)); break;
      case "fixed32": writer.fixed(4, (d) => d.setUint32(0, v, true)); break;
      case "sfixed32": writer.fixed(4, (d) => d.setInt32(0, v, true)); break;
      default: writer.varint(v);
    }
  }
}

/** A field's data as a typed array: a view of the frame where aligned, else a copy. */
export function fieldArray(field) {
  const data = field.data;
  const Type = field.scalar === 2 ? Uint32Array : Float32Array;
  if (data.byteOffset % 4 === 0) {
    return new Type(data.buffer, data.byteOffset, data.byteLength >> 2);
  }
  return new Type(data.slice().buffer);
}

/** gRPC status codes by number, for messages in words. */
export const CODES = [
  "OK", "CANCELLED", "UNKNOWN", "INVALID_ARGUMENT", "DEADLINE_EXCEEDED", "NOT_FOUND",
  "ALREADY_EXISTS", "PERMISSION_DENIED", "RESOURCE_EXHAUSTED", "FAILED_PRECONDITION",
  "ABORTED", "OUT_OF_RANGE", "UNIMPLEMENTED", "INTERNAL", "UNAVAILABLE", "DATA_LOSS",
  "UNAUTHENTICATED",
];

/** A call that ended with a gRPC status other than OK. */
export class GrpcError extends Error {
  constructor(code, message) {
    super(`${CODES[code] ?? code}: ${message}`);
    this.code = code;
    this.codeName = CODES[code] ?? String(code);
    this.detail = message;
  }
}

/** Splits a gRPC-web response body into its messages and its trailers. */
class Frames {
  constructor() {
    // The received chunks not yet framed, in order; `length` bytes in all.
    // A large message arrives in many chunks: they are joined once, when
    // the message is whole, not on every arrival (which copied what had
    // arrived again for each chunk).
    this.chunks = [];
    this.length = 0;
  }

  push(chunk) {
    if (chunk.length === 0) return;
    this.chunks.push(chunk);
    this.length += chunk.length;
  }

  /** The first `n` pending bytes (n <= length) as one array, consumed;
   * a view of a chunk where they lie in one. */
  take(n) {
    const first = this.chunks[0];
    if (n === 0) return new Uint8Array(0);
    if (first.length >= n) {
      if (first.length === n) this.chunks.shift();
      else this.chunks[0] = first.subarray(n);
      this.length -= n;
      return first.subarray(0, n);
    }
    const out = new Uint8Array(n);
    let at = 0;
    while (at < n) {
      const chunk = this.chunks[0];
      const used = Math.min(chunk.length, n - at);
      out.set(chunk.subarray(0, used), at);
      at += used;
      if (used === chunk.length) this.chunks.shift();
      else this.chunks[0] = chunk.subarray(used);
    }
    this.length -= n;
    return out;
  }

  /** The next frame's header, `{trailers, len}`, or null before its 5 bytes arrive. */
  peekHeader() {
    if (this.length < 5) return null;
    const head = new Uint8Array(5);
    let at = 0;
    for (const chunk of this.chunks) {
      const used = Math.min(chunk.length, 5 - at);
      head.set(chunk.subarray(0, used), at);
      at += used;
      if (at === 5) break;
    }
    return { trailers: (head[0] & 0x80) !== 0, len: new DataView(head.buffer).getUint32(1) };
  }

  /** The next complete frame, `{trailers, body}`, or null. */
  next() {
    const head = this.peekHeader();
    if (!head || this.length < 5 + head.len) return null;
    this.take(5);
    return { trailers: head.trailers, body: this.take(head.len) };
  }
}

function parseTrailers(body) {
  const out = {};
  for (const line of TEXT_DECODER.decode(body).split("\r\n")) {
    const colon = line.indexOf(":");
    if (colon > 0) out[line.slice(0, colon).trim().toLowerCase()] = line.slice(colon + 1).trim();
  }
  return out;
}

function statusFrom(get) {
  const status = get("grpc-status");
  if (status === undefined || status === null) return null;
  let message = get("grpc-message") ?? "";
  try {
    message = decodeURIComponent(message);
  } catch {
    // Not percent-encoded: shown as it came.
  }
  return { code: Number(status), message };
}

/** Throws the GrpcError a call's final `status` stands for, if any. */
function ended(method, status) {
  if (!status) throw new GrpcError(13, `${method} ended without a status`);
  if (status.code !== 0) throw new GrpcError(status.code, status.message);
}

/**
 * The `meshless.v1.Simulation` service over gRPC-web. `token` (if any) goes
 * with every call as `authorization: Bearer TOKEN`, as from any client.
 */
export class Service {
  constructor(schema, { base = "", token = null, service = "meshless.v1.Simulation" } = {}) {
    this.schema = schema;
    this.base = base;
    this.token = token;
    this.service = service;
  }

  async open(method, request, signal) {
    const spec = this.schema.methods[method];
    if (!spec) throw new Error(`the service has no method ${method}`);
    const body = this.schema.encode(spec.input, request);
    const framed = new Uint8Array(5 + body.length);
    new DataView(framed.buffer).setUint32(1, body.length);
    framed.set(body, 5);
    const headers = {
      "content-type": "application/grpc-web+proto",
      "x-grpc-web": "1",
      accept: "application/grpc-web+proto",
    };
    if (this.token) headers.authorization = `Bearer ${this.token}`;
    const response = await fetch(`${this.base}/${this.service}/${method}`, {
      method: "POST",
      headers,
      body: framed,
      signal,
    });
    if (!response.ok) {
      throw new GrpcError(14, `HTTP ${response.status} ${response.statusText}`);
    }
    // A call refused before any answer carries its status in the headers.
    const early = statusFrom((name) => response.headers.get(name));
    if (early && early.code !== 0) throw new GrpcError(early.code, early.message);
    return { spec, response };
  }

  /**
   * Calls a unary method; resolves to its answer or rejects with a
   * GrpcError. The answer is read whole, as one buffer: Chromium hands a
   * body read chunk by chunk over in pieces of tens of kilobytes, and a
   * 2.4 MB frame read so took twice as long as read whole (docs/viewer.md).
   */
  async unary(method, request, { signal } = {}) {
    const { spec, response } = await this.open(method, request, signal);
    const frames = new Frames();
    frames.push(new Uint8Array(await response.arrayBuffer()));
    const call = { status: statusFrom((name) => response.headers.get(name)) };
    let answer;
    for (const message of this.messages(frames, spec, call)) answer = message;
    ended(method, call.status);
    if (answer === undefined) throw new GrpcError(13, `${method} answered nothing`);
    return answer;
  }

  /** Calls a server-streaming method; yields each message, throws a GrpcError at a failed end. */
  async *stream(method, request, { signal } = {}) {
    const { spec, response } = await this.open(method, request, signal);
    const call = { status: statusFrom((name) => response.headers.get(name)) };
    const reader = response.body.getReader();
    const frames = new Frames();
    let done = false;
    try {
      while (!done) {
        const chunk = await reader.read();
        done = chunk.done;
        if (!done) {
          frames.push(chunk.value);
          yield* this.messages(frames, spec, call);
        }
      }
    } finally {
      // A caller that stops reading early ends the call, as a gRPC client's
      // dropped stream does.
      if (!done) await reader.cancel().catch(() => {});
      reader.releaseLock();
    }
    ended(method, call.status);
  }

  /** Decodes the messages of the whole gRPC-web frames `frames` holds,
   * consuming them; a trailers frame sets `call.status` instead. */
  *messages(frames, spec, call) {
    for (let frame = frames.next(); frame; frame = frames.next()) {
      if (frame.trailers) {
        const trailers = parseTrailers(frame.body);
        call.status = statusFrom((name) => trailers[name]);
      } else {
        yield this.schema.decode(spec.output, frame.body);
      }
    }
  }
}
