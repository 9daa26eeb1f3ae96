// The result's data as served by `jellysim view` (docs/viewer.md, "Endpoints"): metadata, static
// arrays, and frames fetched in chunks of CHUNK frames, kept in memory up to a byte budget.

export const CHUNK = 16; // frames per /frames request
const BUDGET_BYTES = 256 * 1024 * 1024; // chunks kept in memory, least recently used dropped

const littleEndian = new Uint8Array(new Uint16Array([1]).buffer)[0] === 1;

async function fetchOk(url) {
  const response = await fetch(url);
  if (!response.ok) {
    throw new Error(`${url}: ${response.status} ${(await response.text()).trim()}`);
  }
  return response;
}

// The body of `url` as a typed array of `Type` (little-endian on the wire).
async function fetchArray(url, Type) {
  const buffer = await (await fetchOk(url)).arrayBuffer();
  if (littleEndian || Type.BYTES_PER_ELEMENT === 1) return new Type(buffer);
  const view = new DataView(buffer);
  const out = new Type(buffer.byteLength / Type.BYTES_PER_ELEMENT);
  const read = Type === Float32Array ? (i) => view.getFloat32(4 * i, true) : (i) => view.getUint32(4 * i, true);
  for (let i = 0; i < out.length; i++) out[i] = read(i);
  return out;
}

export async function fetchMeta() {
  return (await fetchOk("/meta.json")).json();
}

export const fetchBellFaces = () => fetchArray("/bell-faces", Uint32Array);
export const fetchFluidKinds = () => fetchArray("/fluid-kinds", Uint8Array);

// Chunks of frames per part ("bell", "tentacles", "fluid"; tentacles per interpolation factor).
export class FrameStore {
  constructor(meta) {
    this.frames = meta.frames;
    this.chunks = new Map(); // key -> {array, floatsPerFrame} (Map order: least recent first)
    this.pending = new Map(); // key -> Promise
    this.bytes = 0;
    this.onError = () => {};
  }

  key(part, chunk, interpolation) {
    return part === "tentacles" ? `${part}:${interpolation}:${chunk}` : `${part}:${chunk}`;
  }

  // The float32 positions of `frame` (a view into its chunk), or null while it loads.
  get(part, frame, interpolation) {
    const chunk = Math.floor(frame / CHUNK);
    const key = this.key(part, chunk, interpolation);
    const entry = this.chunks.get(key);
    if (entry === undefined) {
      this.load(part, chunk, interpolation);
      return null;
    }
    this.chunks.delete(key); // most recently used last
    this.chunks.set(key, entry);
    const offset = (frame - chunk * CHUNK) * entry.floatsPerFrame;
    return entry.array.subarray(offset, offset + entry.floatsPerFrame);
  }

  load(part, chunk, interpolation) {
    const key = this.key(part, chunk, interpolation);
    if (this.chunks.has(key) || this.pending.has(key)) return;
    const start = chunk * CHUNK;
    if (start < 0 || start >= this.frames) return;
    const count = Math.min(CHUNK, this.frames - start);
    let url = `/frames?part=${part}&start=${start}&count=${count}`;
    if (part === "tentacles") url += `&interpolation=${interpolation}`;
    const request = fetchArray(url, Float32Array)
      .then((array) => {
        this.chunks.set(key, { array, floatsPerFrame: array.length / count });
        this.bytes += array.byteLength;
        this.evict(key);
      })
      .catch((error) => this.onError(error))
      .finally(() => this.pending.delete(key));
    this.pending.set(key, request);
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
