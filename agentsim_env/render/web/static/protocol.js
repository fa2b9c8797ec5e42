// Wire protocol of the agentsim web viewer (see docs/viewer.md): binary "ASF1" frames and the socket.

const MAGIC = [0x41, 0x53, 0x46, 0x31]; // "ASF1"
const DTYPES = { f4: Float32Array, i4: Int32Array, i2: Int16Array, u1: Uint8Array };
const decoder = new TextDecoder();

/**
 * Parse one binary frame into typed-array views on its ArrayBuffer (no copy).
 * Returns {seq, step, episode, arrays: {name: TypedArray}, shapes: {name: [...]}}; throws on a malformed frame.
 */
export function parseFrame(buffer) {
  const bytes = new Uint8Array(buffer);
  if (bytes.length < 8 || MAGIC.some((b, i) => bytes[i] !== b)) throw new Error('not an ASF1 frame');
  const headerLength = new DataView(buffer).getUint32(4, true);
  const header = JSON.parse(decoder.decode(bytes.subarray(8, 8 + headerLength)));
  const arrays = {};
  const shapes = {};
  for (const [name, spec] of Object.entries(header.arrays || {})) {
    const Ctor = DTYPES[spec.dtype];
    if (!Ctor) throw new Error(`frame array ${name}: unknown dtype ${spec.dtype}`);
    const length = spec.shape.reduce((a, b) => a * b, 1);
    // Offsets are multiples of 8 from the frame start, so every view is aligned.
    arrays[name] = new Ctor(buffer, spec.offset, length);
    shapes[name] = spec.shape;
  }
  return { seq: header.seq, step: header.step, episode: header.episode, arrays, shapes };
}

/**
 * A WebSocket to /ws on the page's own host that reconnects every 2 s after a close.
 * handlers: {onJson(obj), onFrame(frame), onBadMessage(text), onOpen(), onClose()}.
 */
export class Connection {
  constructor(handlers) {
    this.handlers = handlers;
    this.ws = null;
    this.connect();
  }

  connect() {
    const scheme = location.protocol === 'https:' ? 'wss:' : 'ws:';
    const ws = new WebSocket(`${scheme}//${location.host}/ws`);
    ws.binaryType = 'arraybuffer';
    ws.onopen = () => this.handlers.onOpen();
    ws.onmessage = (event) => {
      let parsed;
      try {
        parsed = typeof event.data === 'string' ? JSON.parse(event.data) : parseFrame(event.data);
      } catch (err) {
        this.handlers.onBadMessage(`bad message from the server: ${err.message}`);
        return;
      }
      if (typeof event.data === 'string') this.handlers.onJson(parsed);
      else this.handlers.onFrame(parsed);
    };
    ws.onclose = () => {
      this.ws = null;
      this.handlers.onClose();
      setTimeout(() => this.connect(), 2000);
    };
    this.ws = ws;
  }

  get open() {
    return this.ws !== null && this.ws.readyState === WebSocket.OPEN;
  }

  send(obj) {
    if (this.open) this.ws.send(JSON.stringify(obj));
  }
}
