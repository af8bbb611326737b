#!/usr/bin/env node
// mixstep's firmware on an emulated Raspberry Pi Pico (rp2040js), driven as a host
// drives a printer. `mixstep emu print` writes the run's description (RUN.json) and
// reads back what this script writes; run it by hand only to debug:
//
//   node emu/harness.mjs RUN.json
//
// RUN.json:
//   uf2, bootrom       MicroPython's firmware.uf2 for the Pico; the RP2040 boot ROM
//                      (bootrom.js exporting bootromB1, or a raw 16 KiB bootrom .bin)
//   fs_image, fs_offset  littlefs image of the Pico's filesystem and its flash offset
//   gcode              the file to print, streamed one line per `ok` over USB CDC
//   edges              out: every level change of the recorded pins, little-endian
//                      u64 words (time_ns << 8 | gpio << 1 | level), mixstep.trace's form
//   result             out: JSON with the console's answers and the emulator's figures
//   record_pins        GPIOs to record (STEP, DIR, ENABLE)
//   endstops           [{axis, min_gpio, step_gpio, dir_gpio, forward_level, active_high}]:
//                      each min endstop is triggered while the axis is at or below 0
//                      steps, counted from the STEP/DIR pins (the axes start at home)
//   heaters            [{name, heater_gpio, adc_channel, pullup_ohm, r25_ohm, beta,
//                      capacity_j_k, heater_w, loss_w_k, fan_loss_w_k}], fan_gpio:
//                      a first-order thermal model per heater, read through the ADC
//   diag_every         send M122 after every this many lines of the file (0: at the end only)
//   max_emu_s, max_wall_s   give up after this much emulated / wall time
//
// Time is the emulator's: the chip runs at its own clock whatever the host machine
// does, and the host answers at once, so a run is repeatable.
import fs from 'node:fs';
import { pathToFileURL } from 'node:url';

function die(msg, code = 2) {
  process.stderr.write(`emu: ${msg}\n`);
  process.exit(code);
}

let rp2040js;
try {
  rp2040js = await import('rp2040js');
} catch (e) {
  die('the npm package rp2040js is not installed: run `make emu-setup` (npm ci in emu/)');
}
const { Simulator, USBCDC, GPIOPinState, ConsoleLogger, LogLevel } = rp2040js;

if (process.argv.length !== 3) die('usage: node emu/harness.mjs RUN.json');
const run = JSON.parse(fs.readFileSync(process.argv[2], 'utf8'));

// ---------------------------------------------------------------- images
const FLASH_START = 0x10000000;
const FLASH_BYTES = 2 * 1024 * 1024;
const UF2_MAGIC0 = 0x0a324655, UF2_MAGIC1 = 0x9e5d5157, UF2_MAGIC_END = 0x0ab16f30;
const UF2_NOT_MAIN_FLASH = 0x1, UF2_FAMILY_PRESENT = 0x2000;
const RP2040_FAMILY = 0xe48bff56;

function loadUf2(mcu, file) {
  const data = fs.readFileSync(file);
  let blocks = 0;
  for (let off = 0; off + 512 <= data.length; off += 512) {
    const w = (i) => data.readUInt32LE(off + i);
    if (w(0) !== UF2_MAGIC0 || w(4) !== UF2_MAGIC1 || w(508) !== UF2_MAGIC_END) {
      die(`${file} is not a UF2 file (bad block at byte ${off})`);
    }
    const flags = w(8), addr = w(12), size = w(16);
    if (flags & UF2_NOT_MAIN_FLASH) continue;
    if ((flags & UF2_FAMILY_PRESENT) && w(28) !== RP2040_FAMILY) continue; // another chip's part
    if (addr < FLASH_START || addr + size > FLASH_START + FLASH_BYTES || size > 476) {
      die(`${file}: block at 0x${addr.toString(16)} is outside the Pico's flash: is it a Pico (RP2040) image?`);
    }
    mcu.flash.set(data.subarray(off + 32, off + 32 + size), addr - FLASH_START);
    blocks++;
  }
  if (!blocks) die(`${file} holds no RP2040 flash blocks: is it a Pico (RP2040) image?`);
  return blocks;
}

async function loadBootrom(file) {
  if (file.endsWith('.bin')) {
    const b = fs.readFileSync(file);
    return new Uint32Array(b.buffer, b.byteOffset, b.length >> 2);
  }
  const mod = await import(pathToFileURL(file).href);
  if (!mod.bootromB1) die(`${file} does not export bootromB1`);
  return mod.bootromB1;
}

// ---------------------------------------------------------------- the chip
const sim = new Simulator(); // for its RP2040 and clock; the loop below runs it
const clock = sim.clock;
const mcu = sim.rp2040;
const core = mcu.core;
mcu.logger = new ConsoleLogger(LogLevel.Error); // its default logs every SEV and USB transfer
mcu.loadBootrom(await loadBootrom(run.bootrom));
const uf2Blocks = loadUf2(mcu, run.uf2);
if (run.fs_image) mcu.flash.set(fs.readFileSync(run.fs_image), run.fs_offset);
mcu.onBreak = (code) => halt(`the chip stopped at a breakpoint (BKPT ${code}, pc=0x${(core.PC >>> 0).toString(16)})`);
let cycleNs = 1e9 / mcu.clkSys;
mcu.addClockListener((hz) => { cycleNs = 1e9 / hz; });

// Emulated time per exception number (0: thread mode), nested handlers counted apart,
// and the time the core slept (WFE/WFI). Time, not core.cycles: rp2040js adds the
// hardware divider's 8 cycles to core.cycles without advancing the clock.
const excNanos = new Float64Array(64), excEntries = new Float64Array(64);
const excStack = [];
let excNow = 0, excMark = 0, sleptNanos = 0;
{
  const entry = core.exceptionEntry.bind(core), ret = core.exceptionReturn.bind(core);
  core.exceptionEntry = (n) => {
    excNanos[excNow] += clock.nanos - excMark; excMark = clock.nanos;
    excStack.push(excNow); excNow = n; excEntries[n]++;
    entry(n);
  };
  core.exceptionReturn = (r) => {
    excNanos[excNow] += clock.nanos - excMark; excMark = clock.nanos;
    excNow = excStack.length ? excStack.pop() : 0;
    ret(r);
  };
}
function cpuSnapshot() {
  excNanos[excNow] += clock.nanos - excMark; excMark = clock.nanos;
  return { nanos: clock.nanos, slept: sleptNanos, exc: Float64Array.from(excNanos), entries: Float64Array.from(excEntries) };
}

// ---------------------------------------------------------------- pins: record, endstops
let edges = new Float64Array(1 << 20), nEdges = 0; // (time_ns, gpio, level) triples
function record(gpio, level) {
  if (nEdges * 3 + 3 > edges.length) { const e = new Float64Array(edges.length * 2); e.set(edges); edges = e; }
  edges[nEdges * 3] = clock.nanos; edges[nEdges * 3 + 1] = gpio; edges[nEdges * 3 + 2] = level;
  nEdges++;
}
const level = (s) => (s === GPIOPinState.High ? 1 : s === GPIOPinState.Low ? 0 : -1);
const pinListeners = new Map(); // gpio -> [fn(level)]
function onPin(gpio, fn) {
  if (!pinListeners.has(gpio)) {
    const fns = [];
    pinListeners.set(gpio, fns);
    mcu.gpio[gpio].addListener((s) => { const l = level(s); if (l >= 0) for (const f of fns) f(l); });
  }
  pinListeners.get(gpio).push(fn);
}
for (const g of run.record_pins) onPin(g, (l) => record(g, l));

for (const es of run.endstops || []) {
  let pos = 0, dir = 0;
  const pin = mcu.gpio[es.min_gpio];
  const update = () => pin.setInputValue((pos <= 0) === es.active_high);
  onPin(es.dir_gpio, (l) => { dir = l; });
  onPin(es.step_gpio, (l) => { if (l) { pos += dir === es.forward_level ? 1 : -1; update(); } });
  update();
}

// ---------------------------------------------------------------- thermal model
// One lumped mass per heater: heater power while its PWM pin is high, loss to ambient
// (and to the part fan for the hot end). The pin levels are piecewise constant, so the
// temperature is advanced exactly at each edge and at each ADC read.
const AMBIENT_C = 22.0;
const bodies = [];
let fanLevel = 0;
for (const h of run.heaters || []) {
  const b = { ...h, temp_c: AMBIENT_C, level: 0, at: 0 };
  b.advance = (t) => {
    const dt = (t - b.at) / 1e9;
    b.at = t;
    if (dt <= 0) return;
    const k = b.loss_w_k + (b.fan_loss_w_k || 0) * fanLevel;
    const final = AMBIENT_C + (b.heater_w * b.level) / k;
    b.temp_c = final + (b.temp_c - final) * Math.exp((-k * dt) / b.capacity_j_k);
  };
  onPin(h.heater_gpio, (l) => { b.advance(clock.nanos); b.level = l; });
  bodies.push(b);
}
if (run.fan_gpio != null && run.fan_gpio >= 0) {
  onPin(run.fan_gpio, (l) => { for (const b of bodies) b.advance(clock.nanos); fanLevel = l; });
}
function adcValue(b) {
  const r = b.r25_ohm * Math.exp(b.beta * (1 / (b.temp_c + 273.15) - 1 / 298.15));
  return Math.min(4095, Math.max(0, Math.round((4095 * r) / (r + b.pullup_ohm))));
}
{
  const adc = mcu.adc;
  const read = adc.onADCRead;
  adc.onADCRead = (channel) => {
    for (const b of bodies) {
      if (b.adc_channel === channel) { b.advance(clock.nanos); adc.channelValues[channel] = adcValue(b); }
    }
    read(channel);
  };
}

// ---------------------------------------------------------------- USB CDC host
// A real host completes an OUT transfer only when it has data (it NAKs otherwise);
// rp2040js's stock host would answer every read at once with an empty packet.
const cdc = new USBCDC(mcu.usbCtrl);
let toDevice = [];
let armed = null; // size of the device's pending OUT read, while we had nothing
mcu.usbCtrl.onEndpointRead = (endpoint, size) => {
  if (endpoint !== cdc.outEndpoint) return;
  if (!toDevice.length) { armed = size; return; }
  deliver(size);
};
function deliver(size) {
  const chunk = Uint8Array.from(toDevice.slice(0, size));
  toDevice = toDevice.slice(size);
  mcu.usbCtrl.endpointReadDone(cdc.outEndpoint, chunk);
}
function send(text) {
  for (const c of Buffer.from(text, 'latin1')) toDevice.push(c);
  if (armed != null) { const s = armed; armed = null; deliver(s); }
}
let connectedNs = null;
cdc.onDeviceConnected = () => { connectedNs = clock.nanos; host.connected(); };
let rxText = '';
cdc.onSerialData = (buf) => {
  rxText += Buffer.from(buf).toString('latin1');
  let k;
  while ((k = rxText.indexOf('\n')) >= 0) {
    const line = rxText.slice(0, k).replace(/\r$/, '');
    rxText = rxText.slice(k + 1);
    host.line(line);
  }
};

// ---------------------------------------------------------------- the host
const gcode = fs.readFileSync(run.gcode, 'latin1').split('\n');
if (gcode.length && gcode[gcode.length - 1] === '') gcode.pop();
const result = {
  lines: 0, errors: [], console: [], boot_lines: [], diagnostics: [], uf2_blocks: uf2Blocks,
  connected_emu_s: null, start_emu_s: null, end_emu_s: null, stopped: null,
};
const diagEvery = run.diag_every || 0;
let printStart = null, printEnd = null;
const host = {
  state: 'boot', // boot -> hello -> print -> drain -> diag -> done
  next: 0, sinceDiag: 0, replies: [], awaiting: null,
  connected() {
    // main.py's `start` went out before the host was there, as on a board plugged in
    // late: ask who is there, as hosts do, and begin once it answers.
    this.state = 'hello';
    this.sendLine('M115', 'hello');
  },
  sendLine(text, what) {
    this.awaiting = what;
    this.replies = [];
    send(text + '\n');
  },
  line(text) {
    if (this.state === 'boot') { result.boot_lines.push(text); return; }
    this.replies.push(text);
    if (this.awaiting === 'file') {
      if (text.startsWith('Error:')) result.errors.push(`line ${this.next}: ${text}`);
      if (text !== 'ok' && result.console.length < 1000) result.console.push(`line ${this.next}: ${text}`);
    }
    if (text === 'ok' || text.startsWith('ok ')) this.answered();
  },
  answered() {
    const what = this.awaiting;
    this.awaiting = null;
    if (what === 'hello') {
      result.boot_lines.push(...this.replies);
      this.startPrint();
    } else if (what === 'diag' || what === 'final-diag') {
      const d = this.replies.find((l) => l.startsWith('echo:underruns:'));
      if (d) result.diagnostics.push({ line: this.next, emu_s: clock.nanos / 1e9, text: d });
      if (what === 'final-diag') { this.state = 'done'; return; }
      this.sendNext();
    } else if (what === 'file') {
      result.lines++;
      this.sendNext();
    } else if (what === 'drain') {
      printEnd = cpuSnapshot();
      this.sendLine('M122', 'final-diag');
    }
  },
  startPrint() {
    this.state = 'print';
    printStart = cpuSnapshot();
    result.start_emu_s = clock.nanos / 1e9;
    this.sendNext();
  },
  sendNext() {
    if (diagEvery && this.sinceDiag >= diagEvery) {
      this.sinceDiag = 0;
      this.sendLine('M122', 'diag');
      return;
    }
    if (this.next >= gcode.length) {
      this.sendLine('M400', 'drain');
      return;
    }
    const text = gcode[this.next].replace(/\r$/, '');
    this.next++;
    this.sinceDiag++;
    this.sendLine(text, 'file');
  },
};
host.line = host.line.bind(host);

// ---------------------------------------------------------------- run
let stopped = false;
const wall0 = performance.now();
const maxEmuNs = (run.max_emu_s ?? 600) * 1e9;
const maxWallMs = (run.max_wall_s ?? 3600) * 1e3;
const said = () => result.boot_lines.concat(host.replies).slice(-8).join(' | ');
const HELLO_NS = 20e9; // boot, USB and main.py's answer to M115 take about 1 s
function halt(reason) { if (!stopped) { stopped = true; result.stopped = reason; } }

function slice() {
  const t0 = performance.now();
  while (!stopped) {
    for (let i = 0; i < 20000; i++) {
      if (core.waiting) {
        const dt = clock.nanosToNextAlarm;
        if (dt <= 0) { clock.tick(0); if (core.waiting) break; continue; }
        clock.tick(dt);
        sleptNanos += dt;
      } else {
        clock.tick(core.executeInstruction() * cycleNs);
      }
    }
    if (host.state === 'done') { stopped = true; break; }
    if (core.waiting && clock.nanosToNextAlarm <= 0) {
      halt(`the chip sleeps with nothing left to wake it (${host.state}; it said: ${said() || 'nothing'})`);
      break;
    }
    if (host.state !== 'print' && host.state !== 'done' && clock.nanos > HELLO_NS &&
        (connectedNs == null || clock.nanos - connectedNs > HELLO_NS)) {
      halt(connectedNs == null
        ? `the USB console did not come up within ${HELLO_NS / 1e9} emulated s: is the image MicroPython for the Pico?`
        : `main.py did not answer M115 within ${HELLO_NS / 1e9} emulated s (it said: ${said() || 'nothing'})`);
      break;
    }
    if (clock.nanos > maxEmuNs) { halt(`emulated-time limit of ${run.max_emu_s} s reached (${host.state}, line ${host.next})`); break; }
    const now = performance.now();
    if (now - wall0 > maxWallMs) { halt(`wall-time limit of ${run.max_wall_s} s reached (${host.state}, line ${host.next})`); break; }
    if (now - t0 > 50) { setImmediate(slice); return; }
  }
  finish();
}

function finish() {
  const wall = (performance.now() - wall0) / 1e3;
  const end = printEnd || cpuSnapshot();
  result.connected_emu_s = connectedNs == null ? null : connectedNs / 1e9;
  result.end_emu_s = end.nanos / 1e9;
  result.emu_seconds = clock.nanos / 1e9;
  result.wall_seconds = wall;
  result.clk_sys_hz = 1e9 / cycleNs;
  result.cycles = core.cycles;
  if (printStart) {
    const exc = {};
    for (let n = 0; n < 64; n++) {
      const ns = end.exc[n] - printStart.exc[n];
      if (ns > 0) exc[n] = { seconds: ns / 1e9, entries: end.entries[n] - printStart.entries[n] };
    }
    result.print = { emu_seconds: (end.nanos - printStart.nanos) / 1e9,
      slept_seconds: (end.slept - printStart.slept) / 1e9, exceptions: exc };
  }
  result.heaters = bodies.map((b) => { b.advance(clock.nanos); return { name: b.name, temp_c: b.temp_c }; });
  const words = new BigUint64Array(nEdges);
  for (let i = 0; i < nEdges; i++) {
    words[i] = (BigInt(Math.round(edges[i * 3])) << 8n) | BigInt((edges[i * 3 + 1] << 1) | edges[i * 3 + 2]);
  }
  fs.writeFileSync(run.edges, words);
  result.edges = nEdges;
  fs.writeFileSync(run.result, JSON.stringify(result, null, 1) + '\n');
  process.exit(result.stopped ? 1 : 0);
}
process.on('SIGINT', () => { halt('interrupted'); finish(); });
process.on('SIGTERM', () => { halt('terminated'); finish(); });

core.PC = FLASH_START; // boot2 and then MicroPython, as after the boot ROM's own start
slice();
