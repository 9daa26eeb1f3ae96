// The result's data as served by `jellysim view` (docs/viewer.md, "Endpoints"): metadata, static
// arrays, and frames fetched in chunks, kept in memory up to a byte budget. Every request
// carries the session's token (from the page's address) and stays within the limits the server
// reports in its metadata: no answer larger than `max_response_bytes`, no more than
// `requests_per_client` requests at once, and a 429 ("busy") retried after its Retry-After.

const CHUNK = 16; // frames per /frames request, fewer where that would be too large
const BUDGET_BYTES = 256 * 1024 * 1024; // chunks kept in memory, least recently used dropped
const TOKEN_HEADER = "X-Jellysim-Token";
const MAX_RETRY_SECONDS = 8; // the longest wait before asking again after a 429

const token = new URLSearchParams(window.location.search).get("token") ?? "";
const littleEndian = new Uint8Array(new Uint16Array([1]).buffer)[0] === 1;
const sleep = (seconds) => new Promise((resolve) => setTimeout(resolve, 1000 * seconds));

// Requests in flight, at most `limit` (1 until the metadata says more); the others wait in turn.
const slots = { limit: 1, busy: 0, waiting: [] };

function setRequestLimit(limit) {
  slots.limit = Math.max(1, limit);
  while (slots.waiting.length > 0 && slots.busy < slots.limit) slots.waiting.shift()();
}

async function inSlot(work) {
  while (slots.busy >= slots.limit) await new Promise((resolve) => slots.waiting.push(resolve));
  slots.busy++;
  try {
    return await work();
  } finally {
    slots.busy--;
    if (slots.waiting.length > 0) slots.waiting.shift()();
  }
}

// GET `url` with the token and `read` its body (within one slot); a 429 is asked again after
// the server's Retry-After, doubled on each refusal up to MAX_RETRY_SECONDS.
function request(url, read) {
  return inSlot(async () => {
    for (let refusals = 0; ; refusals++) {
      const response = await fetch(url, { headers: { [TOKEN_HEADER]: token } });
      if (response.status === 429) {
        await response.arrayBuffer();
        const after = Number(response.headers.get("Retry-After")) || 1;
        await sleep(Math.min(after * 2 ** refusals, MAX_RETRY_SECONDS));
        continue;
      }
      if (!response.ok) {
        throw new Error(`${url}: ${response.status} ${(await response.text()).trim()}`);
      }
      return read(response);
    }
  });
}

// The body of `url` as a typed array of `Type` (little-endian on the wire).
async function fetchArray(url, Type) {
  const buffer = await request(url, (response) => response.arrayBuffer());
  if (littleEndian || Type.BYTES_PER_ELEMENT === 1) return new Type(buffer);
  const view = new DataView(buffer);
  const out = new Type(buffer.byteLength / Type.BYTES_PER_ELEMENT);
  const read = Type === Float32Array ? (i) => view.getFloat32(4 * i, true) : (i) => view.getUint32(4 * i, true);
  for (let i = 0; i < out.length; i++) out[i] = read(i);
  return out;
}

export async function fetchMeta() {
  const meta = await request("/meta.json", (response) => response.json());
  setRequestLimit(meta.limits.requests_per_client);
  return meta;
}

// Tentacles of `group` (an entry of meta.tentacles.groups) in one frame at `interpolation`, as
// the server draws them: a ribbon group's arms as simulated, a thread group's ring T N, its
// clusters of m roots (m - 1) N + 1 each.
export function drawnCount(group, interpolation) {
  if (group.form === "ribbon") return group.simulated;
  if (group.clusters.length === 1) return group.clusters[0] * interpolation;
  return group.clusters.reduce((sum, m) => sum + (m - 1) * interpolation + 1, 0);
}

export const fetchBellFaces = () => fetchArray("/bell-faces", Uint32Array);
export const fetchFluidKinds = () => fetchArray("/fluid-kinds", Uint8Array);

// Chunks of frames per part ("bell", "tentacles", "fluid"; tentacles per interpolation factor).
export class FrameStore {
  constructor(meta) {
    this.meta = meta;
    this.frames = meta.frames;
    this.chunks = new Map(); // key -> {array, floatsPerFrame} (Map order: least recent first)
    this.pending = new Map(); // key -> Promise
    this.bytes = 0;
    this.onError = () => {};
    this.tooLarge = new Set(); // part:factor of which one frame is over the server's limit
  }

  // Bytes of one frame of `part` as the server sends it.
  frameBytes(part, interpolation) {
    const groups = this.meta.tentacles.groups;
    if (part === "tentacles" && groups) {
      return groups.reduce((sum, g) => sum + drawnCount(g, interpolation) * g.particles * 12, 0);
    }
    return this.meta[part].frame_bytes * (part === "tentacles" ? interpolation : 1);
  }

  // Frames per chunk of `part`: CHUNK, or as many as one answer of the server may carry (0 if
  // not even one frame fits).
  chunkFrames(part, interpolation) {
    const { max_response_bytes: maxBytes, max_frames_per_request: maxFrames } = this.meta.limits;
    return Math.min(CHUNK, maxFrames, Math.floor(maxBytes / this.frameBytes(part, interpolation)));
  }

  key(part, chunk, interpolation) {
    return part === "tentacles" ? `${part}:${interpolation}:${chunk}` : `${part}:${chunk}`;
  }

  // The float32 positions of `frame` (a view into its chunk), or null while it loads.
  get(part, frame, interpolation) {
    const size = this.chunkFrames(part, interpolation);
    const chunk = Math.floor(frame / size);
    const key = this.key(part, chunk, interpolation);
    const entry = this.chunks.get(key);
    if (entry === undefined) {
      this.load(part, chunk, interpolation);
      return null;
    }
    this.chunks.delete(key); // most recently used last
    this.chunks.set(key, entry);
    const offset = (frame - chunk * size) * entry.floatsPerFrame;
    return entry.array.subarray(offset, offset + entry.floatsPerFrame);
  }

  // Read ahead: the chunk after the one holding `frame`, wrapping to the start.
  loadAfter(part, frame, interpolation) {
    const size = this.chunkFrames(part, interpolation);
    if (size < 1) return;
    this.load(part, (Math.floor(frame / size) + 1) % Math.ceil(this.frames / size), interpolation);
  }

  load(part, chunk, interpolation) {
    const size = this.chunkFrames(part, interpolation);
    if (size < 1) {
      const what = `${part}:${interpolation}`;
      if (!this.tooLarge.has(what)) {
        this.tooLarge.add(what);
        const mebibytes = (bytes) => (bytes / 2 ** 20).toFixed(1);
        const frame = mebibytes(this.frameBytes(part, interpolation));
        const limit = mebibytes(this.meta.limits.max_response_bytes);
        this.onError(new Error(`one frame of the ${part} is ${frame} MiB, over the ${limit} MiB of one answer`));
      }
      return;
    }
    const key = this.key(part, chunk, interpolation);
    if (this.chunks.has(key) || this.pending.has(key)) return;
    const start = chunk * size;
    if (start < 0 || start >= this.frames) return;
    const count = Math.min(size, this.frames - start);
    let url = `/frames?part=${part}&start=${start}&count=${count}`;
    if (part === "tentacles") url += `&interpolation=${interpolation}`;
    const loading = fetchArray(url, Float32Array)
      .then((array) => {
        this.chunks.set(key, { array, floatsPerFrame: array.length / count });
        this.bytes += array.byteLength;
        this.evict(key);
      })
      .catch((error) => this.onError(error))
      .finally(() => this.pending.delete(key));
    this.pending.set(key, loading);
  }

  evict(keep) {
    for (const [key, entry] of this.chunks) {
      if (this.bytes <= BUDGET_BYTES) break;
      if (key === keep) continue;
      this.chunks.delete(key);
      this.bytes -= entry.array.byteLength;
    }
  }
}
