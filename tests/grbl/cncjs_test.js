#!/usr/bin/env node
// SPDX-License-Identifier: Apache-2.0
// The real cncjs (a GRBL sender) against armfw's pty with virtual servos, driven through
// cncjs's socket.io API as its web page would: open the port as a Grbl controller, read the
// state, jog, run a 50-line program with cncjs's sender, feed hold and resume, then check the
// end position against `armctl kin fk` of the joints armfw reports. See README.md beside this
// file (what cncjs needs from the firmware) and docs/grbl-senders.md (the user's set-up).
//
// usage: node cncjs_test.js --armfw PATH --armctl PATH [--workdir DIR] [--robot NAME]
//        node cncjs_test.js --port DEVICE     (an existing GRBL device: no armfw, no FK check)
// Exit status: 0 passed, 1 failed, 77 skipped (the reason on stderr).
'use strict';

const childProcess = require('child_process');
const crypto = require('crypto');
const fs = require('fs');
const net = require('net');
const os = require('os');
const path = require('path');

const SKIP = 77;
const here = __dirname;

function parseArgs(argv) {
  const a = { robot: 'puma560', workdir: '' };
  for (let i = 2; i < argv.length; ++i) {
    const k = argv[i];
    const v = () => {
      if (i + 1 >= argv.length) throw new Error(`${k} needs a value`);
      return argv[++i];
    };
    if (k === '--armfw') a.armfw = v();
    else if (k === '--armctl') a.armctl = v();
    else if (k === '--workdir') a.workdir = v();
    else if (k === '--robot') a.robot = v();
    else if (k === '--port') a.port = v();
    else throw new Error(`unknown argument '${k}'`);
  }
  if (!a.port && (!a.armfw || !a.armctl)) throw new Error('--armfw and --armctl (or --port) are required');
  return a;
}

function skip(reason) {
  process.stderr.write(`grbl_cncjs: SKIPPED: ${reason}\n`);
  process.exit(SKIP);
}

// The installed packages (bash .ci/npm); nothing is fetched at run time.
function requireInstalled() {
  const modules = path.join(here, 'node_modules');
  for (const p of ['cncjs/package.json', 'socket.io-client/package.json']) {
    try {
      require.resolve(path.join(modules, p));
    } catch (e) {
      skip(`${path.join(modules, p)} is not installed (run: bash .ci/npm)`);
    }
  }
  const version = require(path.join(modules, 'cncjs/package.json')).version;
  if (version !== '1.11.5') throw new Error(`cncjs ${version} installed, package-lock.json pins 1.11.5 (run: bash .ci/npm)`);
  return { io: require(path.join(modules, 'socket.io-client')), cncjsBin: path.join(modules, 'cncjs/bin/cncjs') };
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
const t0 = Date.now();
const stamp = () => ((Date.now() - t0) / 1000).toFixed(2).padStart(7);
let traffic = null;  // log of every line to and from the port, as cncjs reports it
function logTraffic(dir, text) {
  if (traffic) traffic.write(`${stamp()} ${dir} ${JSON.stringify(text)}\n`);
}
function step(msg) {
  process.stdout.write(`${stamp()} grbl: ${msg}\n`);
}

// Resolves with the first value of probe() that is not undefined; rejects after ms naming what.
// While `failFast` is set, it throws at once when failFast() names a failure.
let failFast = null;
async function until(what, ms, probe, every = 20) {
  const end = Date.now() + ms;
  for (;;) {
    const f = failFast && failFast();
    if (f) throw new Error(`waiting for ${what}: ${f}`);
    const v = probe();
    if (v !== undefined && v !== false) return v;
    if (Date.now() > end) throw new Error(`timeout (${ms / 1000} s) waiting for ${what}`);
    await sleep(every);
  }
}

// A child process whose output is kept (and written to a file); killed at exit.
const children = [];
function spawnLogged(name, cmd, args, opts, logPath) {
  const p = childProcess.spawn(cmd, args, { stdio: ['pipe', 'pipe', 'pipe'], ...opts });
  p.out = '';
  p.err = '';
  const log = fs.createWriteStream(logPath);
  p.stdout.on('data', (d) => { p.out += d; log.write(d); });
  p.stderr.on('data', (d) => { p.err += d; log.write(d); });
  p.on('exit', (code, sig) => { p.exited = { code, sig }; log.write(`\n[${name} exited: ${code} ${sig}]\n`); });
  p.logPath = logPath;
  children.push(p);
  return p;
}
function killChildren() {
  for (const p of children) {
    if (!p.exited) {
      try { p.kill('SIGTERM'); } catch (e) { /* already gone */ }
    }
  }
}

function freePort() {
  return new Promise((resolve, reject) => {
    const s = net.createServer();
    s.on('error', reject);
    s.listen(0, '127.0.0.1', () => {
      const { port } = s.address();
      s.close(() => resolve(port));
    });
  });
}

// cncjs authenticates socket.io clients with a JWT (HS256) signed with the `secret` of its
// configuration file, passed as the `token` query parameter of the handshake (socketio-jwt,
// handshake: true). With no `users` in the configuration any id/name is accepted.
function signToken(secret, payload) {
  const b64 = (o) => Buffer.from(JSON.stringify(o)).toString('base64url');
  const body = `${b64({ alg: 'HS256', typ: 'JWT' })}.${b64({ ...payload, iat: Math.floor(Date.now() / 1000) })}`;
  return `${body}.${crypto.createHmac('sha256', secret).update(body).digest('base64url')}`;
}

// ---- armfw ------------------------------------------------------------------------------

function armfwHelp(armfw) {
  const r = childProcess.spawnSync(armfw, ['--help'], { encoding: 'utf8', timeout: 20000 });
  return `${r.stdout || ''}${r.stderr || ''}`;
}

// armfw --sim in the GRBL dialect with a pty console; its stdin console (native language) is
// kept for reading the joints. Returns { proc, pty, native(line) }.
async function startArmfw(args, work) {
  for (const bin of [args.armfw, args.armctl]) {
    if (!fs.existsSync(bin)) throw new Error(`${bin} does not exist (build armfw and armctl first)`);
  }
  const help = armfwHelp(args.armfw);
  if (!/--dialect\b/.test(help)) skip(`${args.armfw} has no --dialect option (the GRBL dialect has not landed in armfw)`);
  const conf = path.join(work, 'armfw.toml');
  // A working pose for $H: the PUMA 560's zero pose has the wrist singular (joint 5 = 0),
  // where linear moves are refused; this one is well inside the workspace.
  let toml = 'motion.home_deg = [0, -30, 150, 0, -60, 0]\n';
  const argv = ['--sim', '--robot', args.robot, '--config', conf, '--pty', '--priority', '0'];
  // The GRBL dialect on the pty only, when armfw can say so (console.pty_dialect): stdin
  // keeps the native language the test reads the joints with. Otherwise every console.
  const keys = childProcess.spawnSync(args.armfw, ['--config-keys'], { encoding: 'utf8', timeout: 20000 }).stdout || '';
  if (/^console\.pty_dialect\b/m.test(keys)) toml += 'console.pty_dialect = "grbl"\n';
  else argv.push('--dialect', 'grbl');
  fs.writeFileSync(conf, toml);
  const proc = spawnLogged('armfw', args.armfw, argv, {}, path.join(work, 'armfw.log'));
  const pty = await until('armfw to print "console pty: PATH"', 30000, () => {
    if (proc.exited) throw new Error(`armfw exited (${proc.exited.code}) before opening its pty:\n${proc.err}`);
    const m = /console pty: (\S+)/.exec(proc.err + proc.out);
    return m ? m[1] : undefined;
  });
  // One line on armfw's stdin; resolves with everything it printed up to its final answer
  // (`ok ...`, `error...`; in the GRBL dialect data comes on [MSG:...] lines before `ok`).
  let pending = Promise.resolve();
  const native = (line) => {
    const run = pending.then(async () => {
      const from = proc.out.length;
      proc.stdin.write(`${line}\n`);
      return until(`armfw's answer to '${line}' on stdin`, 20000, () => {
        const out = proc.out.slice(from);
        const m = /^(ok.*|error.*)$/m.exec(out);
        return m ? out.slice(0, m.index + m[0].length) : undefined;
      });
    });
    pending = run.catch(() => {});
    return run;
  };
  return { proc, pty, native };
}

// ---- cncjs ------------------------------------------------------------------------------

async function startCncjs(cncjsBin, work, devicePath) {
  const home = path.join(work, 'home');  // cncjs keeps its sessions under $HOME
  fs.mkdirSync(home, { recursive: true });
  const secret = crypto.randomBytes(24).toString('hex');
  const rc = path.join(work, 'cncrc.json');
  // No users: the token's id/name are not checked against a list. `ports`: cncjs lists only
  // the serial ports udev knows, never a pty, unless it is named here (docs/grbl-senders.md).
  fs.writeFileSync(rc, JSON.stringify({ secret, ports: [{ path: devicePath, manufacturer: 'servoarm pty' }] }, null, 2));
  const port = await freePort();
  const proc = spawnLogged('cncjs', process.execPath,
    [cncjsBin, '--host', '127.0.0.1', '--port', String(port), '--config', rc, '--controller', 'Grbl', '-v'],
    { env: { ...process.env, HOME: home, NODE_ENV: 'production' } }, path.join(work, 'cncjs.log'));
  await until('cncjs to start its server', 60000, () => {
    if (proc.exited) throw new Error(`cncjs exited (${proc.exited.code}):\n${proc.out}${proc.err}`);
    return /Starting the server at http:\/\/127\.0\.0\.1:\d+/.test(proc.out + proc.err) || undefined;
  });
  return { proc, url: `http://127.0.0.1:${port}`, secret };
}

// The client side of cncjs's socket.io API, as its web page uses it.
class CncjsClient {
  constructor(io, url, token) {
    this.socket = io(url, { query: { token }, transports: ['websocket'], reconnection: false, timeout: 10000 });
    this.state = {};
    this.settings = {};
    this.workflow = '';
    this.sender = {};
    this.reads = [];     // every line cncjs read from the port (as it forwards them)
    this.states = [];    // every activeState seen, with time
    this.errors = [];
    this.senderMax = {};
    this.socket.on('controller:state', (type, state) => {
      this.state = state;
      const s = state.status || {};
      const last = this.states[this.states.length - 1];
      // cncjs keeps a sub-state only as a number (Number('') = 0): shown for Hold and Door
      const name = s.activeState + (['Hold', 'Door'].includes(s.activeState) ? `:${s.subState}` : '');
      if (s.activeState && (!last || last.name !== name)) this.states.push({ name, t: Date.now() });
    });
    this.socket.on('controller:settings', (type, settings) => { this.settings = settings; });
    this.socket.on('workflow:state', (w) => { this.workflow = w; });
    this.socket.on('sender:status', (s) => {
      this.sender = s;
      // cncjs rewinds its sender when the workflow stops: keep the highest count seen
      if (s.total && s.received > (this.senderMax.received || 0)) this.senderMax = { received: s.received, total: s.total };
    });
    this.socket.on('serialport:read', (line) => {
      logTraffic('<', line);
      this.reads.push(line);
      // errors, alarms, and armfw's word that a line it had acknowledged did not run
      if (/^(error|ALARM):/.test(line) || /^\[MSG:.*\b(refused|dropped|not run)\b/.test(line)) {
        // cncjs prints the program line an error answers as "> line (ln=N)" just before it
        const prev = this.reads[this.reads.length - 2] || '';
        this.errors.push(/^> /.test(prev) ? `${line} for ${prev.slice(2)}` : line);
      }
    });
    this.socket.on('serialport:write', (data) => logTraffic('>', data));
    this.socket.on('serialport:error', (e) => this.errors.push(`serialport:error ${JSON.stringify(e)}`));
  }
  connected() {
    return new Promise((resolve, reject) => {
      this.socket.on('startup', (s) => resolve(s));
      this.socket.on('connect_error', (e) => reject(new Error(`socket.io connect: ${e.message || e}`)));
      this.socket.on('error', (e) => reject(new Error(`socket.io: ${e.message || e}`)));
    });
  }
  open(port) {
    this.port = port;
    return new Promise((resolve, reject) => {
      this.socket.emit('open', port, { controllerType: 'Grbl', baudrate: 115200, rtscts: false }, (err) => {
        if (err) reject(new Error(`cncjs could not open ${port}: ${err.message || JSON.stringify(err)}`));
        else resolve();
      });
    });
  }
  command(cmd, ...args) {
    this.socket.emit('command', this.port, cmd, ...args);
  }
  commandCb(cmd, ...args) {
    return new Promise((resolve, reject) => {
      this.socket.emit('command', this.port, cmd, ...args, (err, data) => (err ? reject(err) : resolve(data)));
    });
  }
  writeln(data) {
    this.socket.emit('writeln', this.port, data);
  }
  close() {
    this.socket.close();
  }
  get active() {
    return (this.state.status || {}).activeState || '';
  }
  get subState() {
    return (this.state.status || {}).subState;
  }
  mpos() {
    const m = (this.state.status || {}).mpos || {};
    return [Number(m.x), Number(m.y), Number(m.z)];
  }
}

// ---- checks -----------------------------------------------------------------------------

// Positions cncjs shows (MPos: FK of the measured joints) against where the arm was sent: the
// virtual drives come to rest a few hundredths of a millimetre from the target (seen: up to
// 0.05 mm at 800 mm reach). FK of the joints `status` prints (3 decimals, 0.0005 deg
// rounding each, up to 1 m of lever arm: <= 0.05 mm) against MPos: 0.1 mm.
const POS_TOL = 0.1;
const FK_TOL = 0.1;
const fmt = (v) => `(${v.map((x) => x.toFixed(3)).join(', ')})`;
const dist = (a, b) => Math.hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]);
function expectNear(what, got, want, tol) {
  const d = dist(got, want);
  if (!(d <= tol)) throw new Error(`${what}: at ${fmt(got)}, expected ${fmt(want)} (off by ${d.toFixed(4)} mm, tolerance ${tol})`);
  worst[what.split(' ')[0]] = Math.max(worst[what.split(' ')[0]] || 0, d);
  return d;
}
const worst = {};

// Hold:0 says the commanded motion has stopped; MPos is the measured position, which
// still closes the drives' following error (a few hundredths of a mm, for a few ms; on a
// loaded machine the simulated drives ran late and it took longer than one 250 ms poll:
// 0.039 mm). So the still-standing check starts 0.5 s after Hold:0, and up to then the
// arm may only settle (0.5 mm: a hold that did not stop moves 5 mm in 0.5 s at 600 mm/min).
async function settledHold(c, what) {
  const first = c.mpos();
  await sleep(500);
  expectNear(`${what}: settling in the first 0.5 s`, c.mpos(), first, 0.5);
  return c.mpos();
}

// Idle for `settle` ms with an unchanged position (one status report is not enough: a move
// queued a moment ago may not have started).
async function waitIdle(c, what, ms = 60000, settle = 600) {
  let since = 0;
  let last = null;
  await until(`${what}: Idle (state now ${c.active || 'unknown'})`, ms, () => {
    const p = c.mpos();
    if (c.active === 'Idle' && last && dist(p, last) < 1e-6) {
      if (!since) since = Date.now();
      if (Date.now() - since >= settle) return true;
    } else {
      since = 0;
    }
    last = p;
    return undefined;
  }, 50);
}

// Lines through cncjs's feeder (its MDI / jog path: one line at a time, each after the
// previous answer); resolves with the answer (`ok` or `error:...`) to the last one.
async function feed(c, ...lines) {
  const from = c.reads.length;
  for (const l of lines) c.command('gcode', l);
  const answers = () => c.reads.slice(from).filter((l) => /^(ok|error:)/.test(l));
  await until(`the answers to ${lines.join(' / ')}`, 60000, () => (answers().length >= lines.length ? true : undefined));
  return answers()[lines.length - 1];
}

// Errors that follow cncjs's extended realtime bytes (sent as UTF-8: C2 85, C2 90..): a
// firmware that keeps the 0xC2 in the next line answers that line (often cncjs's own $G
// poll) with an error. Recorded as a gap; the scenario goes on.
function utf8Gap(c, from, what) {
  const e = c.errors.slice(from);
  if (e.length) {
    gaps.push(`${what}: cncjs sends it UTF-8 encoded (0xC2 first) and the firmware answered ${e.join(' | ')} ` +
              '(the 0xC2 went into the next line; GRBL drops bytes >= 0x80 that are not realtime commands)');
  }
  return c.errors.length;
}

function noNewErrors(c, from, what) {
  const e = c.errors.slice(from);
  if (e.length) throw new Error(`${what}: the firmware answered ${e.join(' | ')}`);
}

// 50 lines: setup, a closed polygon around the start point in three heights, and a last
// absolute line to `end`. Every line is a plain GRBL line cncjs's sender streams as is.
function makeProgram(start, end) {
  const lines = ['(servoarm: cncjs sender test, 50 lines)', 'G21 G90', 'G1 F3000'];
  const n = 50 - lines.length - 1;
  for (let i = 0; i < n; ++i) {
    const a = (2 * Math.PI * (i + 1)) / 16;
    const r = 20 + 5 * Math.sin(i / 5);
    const x = start[0] + r * Math.cos(a) - 20;
    const y = start[1] + r * Math.sin(a);
    const z = start[2] + 4 * Math.sin(i / 7);
    lines.push(`G1 X${x.toFixed(3)} Y${y.toFixed(3)} Z${z.toFixed(3)}`);
  }
  lines.push(`G1 X${end[0].toFixed(3)} Y${end[1].toFixed(3)} Z${end[2].toFixed(3)}`);
  return lines;
}

// Joints from armfw's native `status`, then their tool point from `armctl kin fk`.
async function fkOfCurrentJoints(args, armfw) {
  const st = await armfw.native('status');
  const m = /joints=\[([^\]]*)\]/.exec(st);
  if (!m) throw new Error(`armfw's 'status' answer has no joints=[...]: ${st}`);
  const joints = m[1].split(/[\s,]+/).filter((s) => s.length).map(Number);
  const r = childProcess.spawnSync(args.armctl, ['kin', 'fk', '--robot', args.robot, ...joints.map(String)],
    { encoding: 'utf8', timeout: 20000 });
  const p = /position \[mm\]:\s+x\s+(\S+)\s+y\s+(\S+)\s+z\s+(\S+)/.exec(r.stdout || '');
  if (r.status !== 0 || !p) throw new Error(`armctl kin fk ${joints.join(' ')} failed: ${r.stdout}${r.stderr}`);
  return { joints, pos: [Number(p[1]), Number(p[2]), Number(p[3])] };
}

// ---- the scenario -----------------------------------------------------------------------

const gaps = [];  // what cncjs needs and did not get, where the scenario could go on anyway

async function run(args) {
  const { io, cncjsBin } = requireInstalled();
  const work = args.workdir || fs.mkdtempSync(path.join(os.tmpdir(), 'servoarm-grbl-'));
  fs.rmSync(work, { recursive: true, force: true });
  fs.mkdirSync(work, { recursive: true });
  traffic = fs.createWriteStream(path.join(work, 'traffic.log'));
  step(`work dir ${work} (armfw.log, cncjs.log, traffic.log)`);

  let armfw = null;
  let port = args.port;
  if (!port) {
    armfw = await startArmfw(args, work);
    port = armfw.pty;
    step(`armfw --sim --dialect grbl: pty ${port}`);
  }
  const cncjs = await startCncjs(cncjsBin, work, port);
  step(`cncjs 1.11.5 listening on ${cncjs.url}`);

  const c = new CncjsClient(io, cncjs.url, signToken(cncjs.secret, { id: 'servoarm-ci', name: 'servoarm-ci' }));
  const startup = await c.connected();
  if (!startup.loadedControllers.includes('Grbl')) throw new Error(`cncjs loaded ${startup.loadedControllers}, no Grbl`);
  step('socket.io: authenticated (JWT signed with the secret of its config)');

  // the port list cncjs's Connection widget shows: the pty, named in its configuration
  const list = await new Promise((resolve) => {
    c.socket.once('serialport:list', resolve);
    c.socket.emit('list');
  });
  if (!list.some((e) => e.port === port)) throw new Error(`cncjs's port list ${JSON.stringify(list)} has no ${port}`);
  step(`port list has ${port} (from the config's "ports")`);

  // -- detection: banner, $$ (sent by cncjs itself), ? and $G polling
  await c.open(port);
  step(`opened ${port} as a Grbl controller`);
  // The banner must come after cncjs opened the port (a line written to the pty before is
  // lost). Without it cncjs sends ? after 2 s and goes on without a version: the rest of the
  // scenario still runs, and the test fails at the end naming the gap.
  try {
    await until('the startup banner', 6000, () => (c.settings.version ? true : undefined));
  } catch (e) {
    gaps.push('no banner "Grbl 1.1h [\'$\' for help]" after cncjs opened the port (cncjs detected the ' +
              'controller through its ? fallback 2 s later, without a version)');
  }
  if (c.settings.version && c.settings.version !== '1.1h') gaps.push(`banner version '${c.settings.version}', expected 1.1h`);
  await until('the $$ settings cncjs asks for at connect', 15000,
    () => (Object.keys(c.settings.settings || {}).some((k) => /^\$\d+$/.test(k)) ? true : undefined));
  await until('a status report (cncjs polls ? every 250 ms)', 15000, () => (c.active ? true : undefined));
  await until('the $G parser state (cncjs polls $G)', 15000,
    () => (((c.state.parserstate || {}).modal || {}).units ? true : undefined));
  step(`detected: version ${c.settings.version || '(none)'}, ${Object.keys(c.settings.settings).length} $$ settings, ` +
       `state ${c.active}, modal ${JSON.stringify(c.state.parserstate.modal)}`);

  // $# and $I as a user types them in cncjs's console
  let from = c.reads.length;
  c.writeln('$#');
  await until('$# parameters ([G54:...])', 10000, () => (c.reads.slice(from).some((l) => /^\[G54:/.test(l)) ? true : undefined));
  await until('$# parameters in cncjs\'s settings', 10000, () => ((c.settings.parameters || {}).G54 ? true : undefined));
  from = c.reads.length;
  c.writeln('$I');
  await until('$I build info ([VER:...] and ok)', 10000,
    () => (c.reads.slice(from).some((l) => /^\[VER:/.test(l)) && c.reads.slice(from).includes('ok') ? true : undefined));
  step('$# and $I answered');

  // -- a working pose: $H (cncjs's Homing button); $X first if the firmware starts in Alarm
  let errs = c.errors.length;
  if (c.active === 'Alarm') {
    c.command('unlock');
    await until('$X to leave Alarm', 15000, () => (c.active !== 'Alarm' ? true : undefined));
  }
  from = c.reads.length;
  c.command('homing');
  const homed = await until('the answer to $H', 120000, () => c.reads.slice(from).find((l) => /^(ok|error:)/.test(l)));
  let how = '$H';
  if (/^error:5\b/.test(homed)) {
    // GRBL's "homing not enabled": a firmware without a homing cycle may say so.
    step(`$H answered ${homed} (homing not enabled)`);
    errs = c.errors.length;
  } else {
    await waitIdle(c, how, 120000);
  }
  // $H establishes the joints' zeros (it does not go anywhere: armfw --sim's joints are
  // absolute); G28 goes to the park pose (motion.home_deg) as cncjs's Go To G28 would.
  await feed(c, 'G28');
  how = `${how}, G28`;
  await waitIdle(c, how, 120000);
  noNewErrors(c, errs, how);
  const home = c.mpos();
  if (!home.every(Number.isFinite)) throw new Error(`MPos after ${how} is not three numbers: ${JSON.stringify(c.state.status)}`);
  step(`${how}: Idle at MPos ${fmt(home)}`);

  // -- jog: cncjs's Axes widget (its jog buttons send G91, G0 <axis><step>, G90 as three lines)
  errs = c.errors.length;
  await feed(c, 'G91', 'G0 X10', 'G90');
  await waitIdle(c, 'widget jog X+10');
  noNewErrors(c, errs, 'widget jog (G91 / G0 X10 / G90)');
  let p = c.mpos();
  let off = expectNear('after the widget jog X+10', p, [home[0] + 10, home[1], home[2]], POS_TOL);
  step(`widget jog X+10: MPos ${fmt(p)} (${off.toFixed(3)} mm from the target)`);

  // -- GRBL jogging: $J= lines (cncjs's MDI / pendants), a jog cancel (cncjs's jogCancel: 0x85)
  let before = p;
  await feed(c, '$J=G91 G21 X-10 Y5 F600');
  await until('state Jog for $J=', 10000, () => (c.active === 'Jog' ? true : undefined));
  await waitIdle(c, '$J= jog');
  noNewErrors(c, errs, '$J=G91 G21 X-10 Y5 F600');
  p = c.mpos();
  off = expectNear('after $J=G91 X-10 Y5', p, [before[0] - 10, before[1] + 5, before[2]], POS_TOL);
  step(`$J=G91 X-10 Y5 F600: Jog, then Idle at ${fmt(p)} (${off.toFixed(3)} mm from the target)`);

  before = p;
  await feed(c, '$J=G91 G21 Y-60 F600');  // 6 s at 600 mm/min
  await until('state Jog for the long $J=', 10000, () => (c.active === 'Jog' ? true : undefined));
  await sleep(1000);
  c.command('jogCancel');
  const cancelAt = Date.now();
  await waitIdle(c, 'jog cancel', 10000, 300);
  const cancelled = c.mpos();
  const travelled = before[1] - cancelled[1];
  if (!(travelled > 2 && travelled < 40)) {
    throw new Error(`jog cancel: travelled ${travelled.toFixed(3)} mm of 60 (expected stopped early, after ~10 mm)`);
  }
  errs = utf8Gap(c, errs, 'jogCancel (0x85)');
  step(`jogCancel (0x85) after 1 s: Idle ${((Date.now() - cancelAt) / 1000).toFixed(2)} s later, travelled ${travelled.toFixed(2)} of 60 mm`);
  // back to the start of the program (an absolute jog)
  await feed(c, `$J=G90 G21 X${home[0].toFixed(3)} Y${home[1].toFixed(3)} Z${home[2].toFixed(3)} F3000`);
  await until('the absolute jog to start', 10000, () => (c.active === 'Jog' ? true : undefined));
  await waitIdle(c, '$J=G90 back to the home pose');
  expectNear('after $J=G90 to the home pose', c.mpos(), home, POS_TOL);
  noNewErrors(c, errs, '$J=G90');
  step('$J=G90 X.. Y.. Z..: back at the home pose');

  // -- a 50-line program through cncjs's sender (character counting), feed hold and resume
  const end = [home[0] + 15, home[1] - 10, home[2] + 5];
  const program = makeProgram(home, end);
  if (program.length !== 50) throw new Error(`program has ${program.length} lines`);
  fs.writeFileSync(path.join(work, 'program.nc'), `${program.join('\n')}\n`);
  const loaded = await c.commandCb('gcode:load', 'servoarm-test.nc', program.join('\n'));
  step(`gcode:load: ${loaded.total} lines (cncjs appends %wait, sent as G4 P0.5)`);
  errs = c.errors.length;
  // an error during the program pauses cncjs's workflow: say which line and why, at once
  const progErrs = errs;
  failFast = () => (c.errors.length > progErrs ? `the firmware answered, during the program: ${c.errors.slice(progErrs).join(' | ')}` : null);
  c.command('gcode:start');
  await until('the program to run (Run)', 10000, () => (c.active === 'Run' ? true : undefined));

  // pause (cncjs's Pause button: ! and the sender holds) at a third of the program
  await until('a third of the program acknowledged', 120000, () => (c.sender.received >= 16 ? true : undefined));
  c.command('gcode:pause');
  await until('Hold:0 after gcode:pause (!)', 10000, () => (c.active === 'Hold' && c.subState === 0 ? true : undefined));
  const held = await settledHold(c, 'in Hold:0 (the arm must stand still)');
  await sleep(1500);
  expectNear('in Hold:0 (the arm must stand still)', c.mpos(), held, 0.01);
  step(`gcode:pause (!): Hold:0 at ${fmt(held)}, still after 1.5 s; sender ${c.sender.received}/${c.sender.total}`);
  c.command('gcode:resume');
  await until('Run after gcode:resume (~)', 10000, () => (c.active === 'Run' ? true : undefined));
  step('gcode:resume (~): Run');

  // feed override buttons: -10 % (0x92) twice, then 100 % (0x90); cncjs sends them UTF-8 encoded
  const ov = () => ((c.state.status || {}).ov || [])[0];
  c.command('feedOverride', -10);
  c.command('feedOverride', -10);
  await until(`Ov: 80 after two feed override -10 % (Ov now ${ov()})`, 5000, () => (ov() === 80 ? true : undefined));
  c.command('feedOverride', 0);
  await until(`Ov: 100 after feed override reset (Ov now ${ov()})`, 5000, () => (ov() === 100 ? true : undefined));
  await sleep(600);  // the next $G poll carries a stray 0xC2, if any
  errs = utf8Gap(c, errs, 'feedOverride (0x92, 0x90)');
  step('feedOverride -10, -10, 0 (0x92 0x92 0x90): Ov 80, then 100');

  // feed hold / cycle start (cncjs's Feedhold and Cycle Start buttons: ! and ~ only)
  await until('two thirds of the program acknowledged', 120000, () => (c.sender.received >= 33 ? true : undefined));
  c.command('feedhold');
  await until('Hold:0 after feedhold', 10000, () => (c.active === 'Hold' && c.subState === 0 ? true : undefined));
  const held2 = await settledHold(c, 'in Hold:0 after feedhold');
  await sleep(1000);
  expectNear('in Hold:0 after feedhold', c.mpos(), held2, 0.01);
  c.command('cyclestart');
  await until('Run after cyclestart', 10000, () => (c.active === 'Run' ? true : undefined));
  step(`feedhold (!) / cyclestart (~): held at ${fmt(held2)}, running again`);

  await until('the sender to finish and cncjs to end the workflow (workflow idle)', 180000,
    () => (c.senderMax.received === loaded.total && c.workflow === 'idle' ? true : undefined), 100);
  await waitIdle(c, 'program end');
  failFast = null;
  noNewErrors(c, errs, 'the program');
  p = c.mpos();
  off = expectNear('at the end of the program', p, end, POS_TOL);
  step(`program done: ${c.senderMax.received}/${loaded.total} lines acknowledged, no error, MPos ${fmt(p)} (${off.toFixed(3)} mm from its last point)`);

  // -- the end position against the kinematics: FK of the joints armfw reports
  if (armfw) {
    const fk = await fkOfCurrentJoints(args, armfw);
    off = expectNear(`cncjs's MPos against armctl kin fk of joints [${fk.joints.join(', ')}]`, p, fk.pos, FK_TOL);
    step(`armctl kin fk of the joints [${fk.joints.map((j) => j.toFixed(3)).join(', ')}] = ${fmt(fk.pos)}: ${off.toFixed(3)} mm from MPos`);
  }

  // a state walk the report must have shown
  const seen = new Set(c.states.map((s) => s.name.split(':')[0]));
  for (const s of ['Idle', 'Jog', 'Run', 'Hold']) if (!seen.has(s)) throw new Error(`state ${s} never reported`);
  c.close();
  step(`states seen: ${[...new Set(c.states.map((s) => s.name))].join(' ')}`);
  if (gaps.length) throw new Error(`the scenario ran, but:\n  - ${gaps.join('\n  - ')}`);
}

async function main() {
  let args;
  try {
    args = parseArgs(process.argv);
  } catch (e) {
    process.stderr.write(`grbl_cncjs: ${e.message}\n`);
    process.exit(2);
  }
  const timer = setTimeout(() => {
    process.stderr.write('grbl_cncjs: FAILED: overall timeout (600 s)\n');
    killChildren();
    process.exit(1);
  }, 600000);
  let rc = 0;
  try {
    await run(args);
    step('PASSED');
  } catch (e) {
    process.stderr.write(`grbl_cncjs: FAILED: ${e.message}\n`);
    if (gaps.length && !/the scenario ran, but/.test(e.message)) process.stderr.write(`  and before that:\n  - ${gaps.join('\n  - ')}\n`);
    for (const p of children) process.stderr.write(`  (${path.basename(p.logPath)}: ${p.logPath})\n`);
    rc = 1;
  }
  clearTimeout(timer);
  killChildren();
  if (traffic) traffic.end();
  await sleep(200);
  process.exit(rc);
}

process.on('SIGTERM', () => { killChildren(); process.exit(1); });
process.on('SIGINT', () => { killChildren(); process.exit(1); });
main();
