// Runs MicroPython 1.27 (the npm package @micropython/micropython-webassembly-pyscript,
// pinned in ../package.json) as a session driven over stdin/stdout, one JSON object per
// line. Requests: {"write": {path: text, ...}} puts files into the interpreter's
// filesystem (folders made as needed; /lib is on sys.path); {"run": code} runs Python in
// the session's __main__ (globals persist between runs). Each request gets one answer
// line: {"ok": true, "out": printed text} or {"ok": false, "out": ..., "error": traceback}.
// Used by firmware/test/conftest.py and bench/firmware_loop.py.
import { createInterface } from 'node:readline';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const { loadMicroPython } = await import(join(
  here, '..', 'node_modules', '@micropython', 'micropython-webassembly-pyscript',
  'micropython.mjs'));

let out = [];
const mp = await loadMicroPython({
  heapsize: 1024 * 1024,
  stdout: (line) => out.push(line),
  stderr: (line) => out.push(line),
});

function makeDirs(path) {
  let current = '';
  for (const part of dirname(path).split('/').filter((p) => p)) {
    current += '/' + part;
    try { mp.FS.mkdir(current); } catch (error) { /* exists */ }
  }
}

function answer(request) {
  out = [];
  try {
    if (request.write) {
      for (const [path, text] of Object.entries(request.write)) {
        makeDirs(path);
        mp.FS.writeFile(path, text);
      }
    }
    if (request.run !== undefined) mp.runPython(request.run);
    return { ok: true, out: out.join('\n') };
  } catch (error) {
    return { ok: false, out: out.join('\n'), error: String(error.message || error) };
  }
}

const lines = createInterface({ input: process.stdin, crlfDelay: Infinity });
process.stdout.write(JSON.stringify({ ok: true, out: 'ready' }) + '\n');
for await (const line of lines) {
  if (!line.trim()) continue;
  process.stdout.write(JSON.stringify(answer(JSON.parse(line))) + '\n');
}
