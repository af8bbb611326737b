#!/usr/bin/env node
// mixstep's firmware on an emulated Raspberry Pi Pico (rp2040js), driven as a host
// drives a printer. mixstep.emu.Chip writes the run's description (RUN.json), starts
// this script, and then drives it with requests on stdin (see "the controller" below):
// send bytes over the emulated USB CDC port, run the chip until an answer or for a
// while, read the pin edges. It boots the chip first and answers once main.py has
// answered M115.
//
//   node emu/harness.mjs RUN.json
//
// RUN.json:
//   uf2, bootrom       MicroPython's firmware.uf2 for the Pico; the RP2040 boot ROM
//                      (bootrom.js exporting bootromB1, or a raw 16 KiB bootrom .bin)
//   fs_image, fs_offset  littlefs image of the Pico's filesystem and its flash offset
//   record_pins        GPIOs to record (STEP, DIR, ENABLE); the edge files hold every
//                      level change as little-endian u64 words (time_ns << 8 | gpio << 1
//                      | level), mixstep.trace's form
//   endstops           [{axis, min_gpio, step_gpio, dir_gpio, forward_level, active_high}]:
//                      each min endstop is triggered while the axis is at or below 0
//                      steps, counted from the STEP/DIR pins (the axes start at home)
//   inputs             [{gpio, level}]: inputs held at a level (the runout sensors,
//                      filament present); rp2040js reads an undriven pad low, pull-up
//                      or not
//   heaters            [{name, heater_gpio, adc_channel, pullup_ohm, r25_ohm, beta,
//                      capacity_j_k, heater_w, loss_w_k, fan_loss_w_k}], fan_gpio:
//                      a first-order thermal model per heater, read through the ADC
//   max_emu_s, max_wall_s   give up after this much emulated / wall time
//
// Time is the emulator's: the chip runs at its own clock whatever the host machine
// does, and the host answers at once, so a run is repeatable.
import fs from 'node:fs';
import readline from 'node:readline';
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

// ---------------------------------------------------------------- the program counter's profile
// Off unless asked ('profile' below): the cycles spent at each instruction address,
// thread mode and interrupts apart. MicroPython's own code runs from flash, and the
// firmware's native and viper code from the heap in RAM (above NATIVE_FROM: below it
// lie the C runtime's few RAM functions, such as the divider's); flash cycles are also
// summed by the native function they serve, the last one run in that context until it
// returns into flash (0: none, as when bytecode runs).
// With `gated`, only while the chip's last write to WATCHDOG SCRATCH0 (0x4005800C, free
// for programs) was 1: the code profiled marks its own window.
const NATIVE_FROM = 0x20004000, SRAM_END = 0x20042000;
const WATCHDOG_BASE = 0x40058000, SCRATCH0 = 0x0c;
const prof = { on: false, armed: false, gated: false, self: [new Map(), new Map()],
  by: [new Map(), new Map()], last: [0, 0] };
{
  const wd = mcu.findPeripheral(WATCHDOG_BASE);
  const write = wd.writeUint32.bind(wd);
  wd.writeUint32 = (offset, value) => {
    if (offset === SCRATCH0 && prof.armed && prof.gated) prof.on = value === 1;
    write(offset, value);
  };
}
function profAdd(pc, ins, cyc) {
  const k = excNow ? 1 : 0;
  const self = prof.self[k];
  self.set(pc, (self.get(pc) || 0) + cyc);
  if (pc >= NATIVE_FROM && pc < SRAM_END) {
    // pop {..., pc} or bx lr into flash: the native function returned to its caller
    prof.last[k] = ((ins & 0xff00) === 0xbd00 || ins === 0x4770) && (core.PC >>> 0) < 0x20000000 ? 0 : pc;
  } else {
    const by = prof.by[k], fn = prof.last[k];
    by.set(fn, (by.get(fn) || 0) + cyc);
  }
}
function profileDump(path) {
  const o = { clk_sys_hz: 1e9 / cycleNs };
  ['thread', 'irq'].forEach((name, k) => {
    o[name] = { self: Object.fromEntries(prof.self[k]), by: Object.fromEntries(prof.by[k]) };
  });
  fs.writeFileSync(path, JSON.stringify(o));
}

// ---------------------------------------------------------------- PIO on the emulated clock
// rp2040js 1.4.1 runs the PIO state machines from Node's event loop, 1000 instructions
// at a time whatever the emulated time, skips instructions' delay cycles, ignores the
// clock divider and never joins the FIFOs. Here each enabled state machine runs one
// cycle per clk_sys / CLKDIV on the emulated clock (the fractional divider spreading
// its cycles over whole clk_sys cycles, as the chip's does), an instruction's delay
// cycles pass before the next one, and FJOIN gives the joined FIFO 8 words.
const SM_SHIFTCTRL = 0x0d0 - 0x0c8; // a state machine's registers, from its CLKDIV
const FJOIN_TX = 1 << 30, FJOIN_RX = 1 << 31;
for (const pio of mcu.pio) {
  pio.run = () => {}; // its event-loop runner; the alarms below run it instead
  for (const sm of pio.machines) {
    const Fifo = sm.txFIFO.constructor;
    const write = sm.writeUint32.bind(sm);
    sm.writeUint32 = (offset, value) => {
      write(offset, value);
      if (offset === SM_SHIFTCTRL) { // changing FJOIN empties both FIFOs
        sm.txFIFO = new Fifo(value & FJOIN_TX ? 8 : value & FJOIN_RX ? 0 : 4);
        sm.rxFIFO = new Fifo(value & FJOIN_RX ? 8 : value & FJOIN_TX ? 0 : 4);
      }
    };
    // 1/256 clk_sys cycles into the divider; delay cycles left; an alarm pending
    let phase = 0, owed = 0, running = false;
    sm.clkDivRestart = () => { phase = 0; };
    const alarm = clock.createAlarm(() => {
      if (!sm.enabled) { running = false; return; } // CTRL's next enable starts it again
      if (owed > 0) owed--;
      else {
        const c0 = sm.cycles;
        sm.step();
        owed = Math.max(0, sm.cycles - c0 - 1);
      }
      pio.checkChangedPins();
      next();
    });
    const next = () => {
      const div = ((sm.clockDivInt || 0x10000) << 8) + sm.clockDivFrac;
      const whole = (phase + div) >> 8;
      phase = (phase + div) & 0xff;
      alarm.schedule(whole * cycleNs);
    };
    sm.clocked = () => { if (sm.enabled && !running) { running = true; next(); } };
  }
  const write = pio.writeUint32.bind(pio);
  pio.writeUint32 = (offset, value) => {
    write(offset, value);
    for (const sm of pio.machines) sm.clocked();
  };
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

for (const input of run.inputs || []) mcu.gpio[input.gpio].setInputValue(!!input.level);

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
// What crossed the USB, stamped with emulated seconds, since the last answer to the
// controller: [t, '>', bytes delivered to the chip] and [t, '<', a line it sent].
let events = [];
function deliver(size) {
  const chunk = Uint8Array.from(toDevice.slice(0, size));
  toDevice = toDevice.slice(size);
  events.push([clock.nanos / 1e9, '>', Buffer.from(chunk).toString('latin1')]);
  mcu.usbCtrl.endpointReadDone(cdc.outEndpoint, chunk);
}
function send(text) {
  for (const c of Buffer.from(text, 'latin1')) toDevice.push(c);
  if (armed != null) { const s = armed; armed = null; deliver(s); }
}
let connectedNs = null;
cdc.onDeviceConnected = () => { connectedNs = clock.nanos; };
let rxText = '';
cdc.onSerialData = (buf) => {
  rxText += Buffer.from(buf).toString('latin1');
  let k;
  while ((k = rxText.indexOf('\n')) >= 0) {
    const line = rxText.slice(0, k).replace(/\r$/, '');
    rxText = rxText.slice(k + 1);
    events.push([clock.nanos / 1e9, '<', line]);
    if (goal && goal.line) goal.line(line);
  }
};

// ---------------------------------------------------------------- running the chip
// The chip runs only toward a goal (the boot, or the controller's `run`): between goals
// its clock stands still, so whatever the controller does in between costs no
// emulated time, and the same requests give the same run.
let goal = null; // {met, deadline (ns), line(text)?, connected()?}
let stopped = null; // why the emulation can't go on: a limit, a breakpoint
const wall0 = performance.now();
const maxEmuNs = (run.max_emu_s ?? 600) * 1e9;
const maxWallMs = (run.max_wall_s ?? 3600) * 1e3;
function halt(reason) { if (!stopped) stopped = reason; }
const isOk = (text) => text === 'ok' || text.startsWith('ok ');

// Run until g.met, g.deadline (ns) or a stop; resolves with g.
function runToward(g) {
  goal = g;
  return new Promise((resolve) => {
    const slice = () => {
      const t0 = performance.now();
      while (!g.met && !stopped) {
        for (let i = 0; i < 20000 && !g.met; i++) {
          const left = g.deadline - clock.nanos;
          if (left <= 0) break;
          if (core.waiting) {
            const dt = clock.nanosToNextAlarm;
            if (dt <= 0) { clock.tick(0); if (core.waiting) break; continue; }
            const step = Math.min(dt, left);
            clock.tick(step);
            sleptNanos += step;
          } else if (prof.on) {
            const pc = core.PC >>> 0;
            const ins = pc >= NATIVE_FROM && pc < SRAM_END ? mcu.readUint16(pc) : 0;
            const cyc = core.executeInstruction();
            clock.tick(cyc * cycleNs);
            profAdd(pc, ins, cyc);
          } else {
            clock.tick(core.executeInstruction() * cycleNs);
          }
        }
        if (g.met) break;
        if (clock.nanos >= g.deadline) { if (g.byTime) g.met = true; break; }
        if (core.waiting && clock.nanosToNextAlarm <= 0) {
          halt(`the chip sleeps with nothing left to wake it (it said: ${lastSaid()})`);
          break;
        }
        if (clock.nanos > maxEmuNs) { halt(`emulated-time limit of ${run.max_emu_s} s reached`); break; }
        const now = performance.now();
        if (now - wall0 > maxWallMs) { halt(`wall-time limit of ${run.max_wall_s} s reached`); break; }
        if (now - t0 > 50) { setImmediate(slice); return; }
      }
      goal = null;
      resolve(g);
    };
    slice();
  });
}
const lastSaid = () => events.filter((e) => e[1] === '<').slice(-8).map((e) => e[2]).join(' | ') || 'nothing';

// Until a line starting with `match`, `oks` lines `ok`, or `for_s` emulated seconds
// (whichever first); at most `max_s`.
function goalFor(op) {
  const now = clock.nanos;
  const g = { met: false, byTime: op.for_s != null, oks: op.oks || 0, match: op.match ?? null };
  g.deadline = Math.min(op.for_s != null ? now + op.for_s * 1e9 : Infinity,
    now + (op.max_s ?? 60) * 1e9, maxEmuNs + 1);
  g.line = (text) => {
    if (g.match != null && text.startsWith(g.match)) g.met = true;
    if (g.oks && isOk(text) && --g.oks === 0) g.met = true;
  };
  return g;
}

const HELLO_NS = 20e9; // boot, USB and main.py's answer to M115 take about 1 s
async function boot() {
  const up = await runToward({ met: false, deadline: HELLO_NS, connected() { this.met = true; } });
  if (!up.met) {
    halt(`the USB console did not come up within ${HELLO_NS / 1e9} emulated s: is the image MicroPython for the Pico?`);
    return;
  }
  // main.py's `start` went out before the host was there, as on a board plugged in
  // late: ask who is there, as hosts do, and begin once it answers.
  send('M115\n');
  const g = { met: false, deadline: clock.nanos + HELLO_NS, line(text) { if (isOk(text)) this.met = true; } };
  if (!(await runToward(g)).met) halt(`main.py did not answer M115 within ${HELLO_NS / 1e9} emulated s (it said: ${lastSaid()})`);
}
cdc.onDeviceConnected = () => { connectedNs = clock.nanos; if (goal && goal.connected) goal.connected(); };

// ---------------------------------------------------------------- the controller
// mixstep.emu.Chip sends one JSON request a line on stdin; each gets one answer on
// stdout, a line starting with ANSWER (anything else there is not ours), holding the
// emulated time, the USB traffic since the last answer (events) and `stopped`.
//   {op: "send", data}                  bytes (latin1) to the chip; they go as soon as
//                                       its USB reads, within the next run
//   {op: "run", oks, match, for_s, max_s}  run the chip; answers met: true/false
//   {op: "cpu"}                         emulated time per exception so far (cpu)
//   {op: "edges", path}                 the pin edges so far into path
//   {op: "profile", on, gated, path}    on: profile the program counter from now (gated:
//                                       while the chip says so); off: stop, write to path
//   {op: "end", edges}                  the edges into edges, the heaters, the wall
//                                       time; then the harness exits
const ANSWER = '@emu ';
function answer(obj) {
  const out = { emu_s: clock.nanos / 1e9, stopped, ...obj, events };
  events = [];
  process.stdout.write(ANSWER + JSON.stringify(out) + '\n');
}

function writeEdges(path) {
  const words = new BigUint64Array(nEdges);
  for (let i = 0; i < nEdges; i++) {
    words[i] = (BigInt(Math.round(edges[i * 3])) << 8n) | BigInt((edges[i * 3 + 1] << 1) | edges[i * 3 + 2]);
  }
  fs.writeFileSync(path, words);
  return nEdges;
}

async function serve(op) {
  switch (op.op) {
    case 'send':
      send(op.data);
      return answer({});
    case 'run':
      if (stopped) return answer({ met: false });
      return answer({ met: (await runToward(goalFor(op))).met });
    case 'cpu':
      return answer({ cpu: cpuSnapshot() });
    case 'edges':
      return answer({ edges: writeEdges(op.path) });
    case 'profile': // {on: true, gated}: start afresh; {on: false, path}: stop, write it there
      if (op.on) Object.assign(prof, { self: [new Map(), new Map()], by: [new Map(), new Map()], last: [0, 0] });
      else if (op.path) profileDump(op.path);
      prof.armed = !!op.on;
      prof.gated = !!op.gated;
      prof.on = prof.armed && !prof.gated;
      return answer({});
    case 'end': {
      const heaters = bodies.map((b) => { b.advance(clock.nanos); return { name: b.name, temp_c: b.temp_c }; });
      answer({ edges: writeEdges(op.edges), heaters, wall_seconds: (performance.now() - wall0) / 1e3,
        clk_sys_hz: 1e9 / cycleNs, cycles: core.cycles });
      process.exit(0);
    }
    default:
      die(`unknown request ${JSON.stringify(op)}`);
  }
}
function cpuSnapshot() {
  excNanos[excNow] += clock.nanos - excMark; excMark = clock.nanos;
  return { nanos: clock.nanos, slept: sleptNanos, exc: Array.from(excNanos), entries: Array.from(excEntries) };
}

core.PC = FLASH_START; // boot2 and then MicroPython, as after the boot ROM's own start
await boot();
answer({ ready: !stopped, uf2_blocks: uf2Blocks, connected_emu_s: connectedNs == null ? null : connectedNs / 1e9 });
const requests = readline.createInterface({ input: process.stdin });
for await (const text of requests) await serve(JSON.parse(text));
process.exit(0); // the controller went away
