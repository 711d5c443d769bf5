#!/usr/bin/env node
// SPDX-License-Identifier: Apache-2.0
// The browser pendant (firmware/web, docs/pendant.md) in a real browser: Debian's chromium,
// headless, driven by puppeteer-core (package-lock.json beside this file; no browser download)
// against armfw --sim serving the page and the API on free loopback ports. An independent
// client on the API's TCP port reads the arm's state, so what the page shows is never what
// the test checks the arm against.
//
// usage: node pendant_test.js --armfw PATH [--workdir DIR] [--chromium PATH] [--screenshots]
// Exit status: 0 passed, 1 failed, 77 skipped (chromium not found; the reason on stderr).
// Measured times are printed as "figure:" lines (and written to DIR/figures.txt). A failed case
// saves a screenshot of each open page to DIR/screenshots/FAILED-*.png; --screenshots saves one
// of each view there too (each costs a PNG encode of the page: left out of the ordinary run).
'use strict';

const childProcess = require('child_process');
const crypto = require('crypto');
const fs = require('fs');
const http = require('http');
const net = require('net');
const path = require('path');

const SKIP = 77;
const here = __dirname;
// Generous limits: the machine may be busy; every wait polls for its condition.
const WAIT_S = 30;

function parseArgs(argv) {
  const a = { workdir: path.join(process.cwd(), 'pendant-test'), chromium: process.env.CHROMIUM || '', screenshots: false };
  for (let i = 2; i < argv.length; ++i) {
    const k = argv[i];
    const v = () => {
      if (i + 1 >= argv.length) throw new Error(`${k} needs a value`);
      return argv[++i];
    };
    if (k === '--armfw') a.armfw = v();
    else if (k === '--workdir') a.workdir = v();
    else if (k === '--chromium') a.chromium = v();
    else if (k === '--screenshots') a.screenshots = true;
    else throw new Error(`unknown argument '${k}'`);
  }
  if (!a.armfw) throw new Error('--armfw is required');
  return a;
}

function findChromium(given) {
  const candidates = given ? [given] : ['/usr/bin/chromium', '/usr/bin/chromium-browser'];
  for (const c of candidates) if (fs.existsSync(c)) return c;
  process.stderr.write(`pendant_browser: SKIPPED: chromium not found (${candidates.join(', ')}); ` +
                       'install Debian\'s chromium (bash .ci/deps) or pass --chromium PATH\n');
  process.exit(SKIP);
}

function puppeteer() {
  const p = path.join(here, 'node_modules', 'puppeteer-core');
  try {
    return require(p);
  } catch (e) {
    if (e.code === 'MODULE_NOT_FOUND') throw new Error(`${p} is not installed (run: bash .ci/npm)`);
    // installed but not loadable (puppeteer-core 24, a CommonJS package, asks for Node.js 18 or later)
    throw new Error(`${p} does not load in Node.js ${process.version} (it needs 18 or later): ${e.message}`);
  }
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
const now = () => Number(process.hrtime.bigint()) / 1e9;

async function until(what, fn, timeoutS = WAIT_S, periodMs = 10) {
  const end = now() + timeoutS;
  for (;;) {
    const v = await fn();
    if (v) return v;
    if (now() > end) throw new Error(`timed out after ${timeoutS} s waiting for ${what}`);
    await sleep(periodMs);
  }
}

// ---- armfw --sim ------------------------------------------------------------------------------
function startArmfw(exe, extra = [], wsPort = 0) {
  const args = ['--sim', '--no-stdin', '--priority', '0', '--api-ws', String(wsPort), '--api-tcp', '0', ...extra];
  const p = childProcess.spawn(exe, args, { stdio: ['ignore', 'ignore', 'pipe'] });
  const lines = [];
  let buf = '';
  return new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error('armfw did not print the pendant URL:\n' + lines.join('\n'))), WAIT_S * 1000);
    const info = {};
    p.stderr.on('data', (d) => {
      buf += d.toString();
      let nl;
      while ((nl = buf.indexOf('\n')) >= 0) {
        const l = buf.slice(0, nl);
        buf = buf.slice(nl + 1);
        lines.push(l);
        let m = /TCP port (\d+)/.exec(l);
        if (m) info.tcp = Number(m[1]);
        m = /armfw: pendant: (http:\/\/\S+)/.exec(l);
        if (m) info.url = m[1];
        if (/pendant: not served/.test(l)) { clearTimeout(timer); reject(new Error(l)); }
        if (info.url && info.tcp && !info.done) {
          info.done = true;
          clearTimeout(timer);
          resolve({ proc: p, url: info.url, tcp: info.tcp, lines });
        }
      }
    });
    p.on('exit', (code) => { clearTimeout(timer); reject(new Error(`armfw exited (${code}):\n${lines.join('\n')}`)); });
  });
}

function stopArmfw(a) {
  if (!a) return Promise.resolve();
  a.proc.removeAllListeners('exit');
  return new Promise((resolve) => {
    const t = setTimeout(() => { a.proc.kill('SIGKILL'); resolve(); }, 10000);
    a.proc.on('exit', () => { clearTimeout(t); resolve(); });
    a.proc.kill('SIGTERM');
  });
}

// ---- an armfw that is going away: accepts the WebSocket, closes it at the first message ----------
/** A WebSocket server on `port` that completes each handshake and closes the connection without
 *  an answer when the first message (the page's hello) arrives, as an armfw shutting down may.
 *  `hellos` counts them; close() stops listening and drops its connections. */
function closingServer(host, port) {
  const srv = { hellos: 0, sockets: new Set() };
  const server = http.createServer((req, res) => { res.writeHead(503); res.end(); });
  server.on('upgrade', (req, socket) => {
    srv.sockets.add(socket);
    socket.on('close', () => srv.sockets.delete(socket));
    socket.on('error', () => {});
    const accept = crypto.createHash('sha1').update(req.headers['sec-websocket-key'] + '258EAFA5-E914-47DA-95CA-C5AB0DC85B11').digest('base64');
    socket.write('HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n' +
                 `Sec-WebSocket-Accept: ${accept}\r\n\r\n`);
    socket.once('data', () => { ++srv.hellos; socket.destroy(); });
  });
  srv.close = () => new Promise((resolve) => {
    for (const s of srv.sockets) s.destroy();
    server.close(() => resolve());
  });
  return new Promise((resolve, reject) => {
    server.once('error', reject);
    server.listen(port, host, () => resolve(srv));
  });
}

// ---- the independent client: newline-delimited JSON on the API's TCP port ---------------------------
class Tcp {
  constructor(port) {
    this.port = port;
    this.id = 1;
    this.pending = new Map();
    this.buf = '';
  }
  connect() {
    return new Promise((resolve, reject) => {
      this.s = net.connect(this.port, '127.0.0.1', resolve);
      this.s.on('error', reject);
      this.s.on('data', (d) => {
        this.buf += d.toString();
        let nl;
        while ((nl = this.buf.indexOf('\n')) >= 0) {
          const l = this.buf.slice(0, nl);
          this.buf = this.buf.slice(nl + 1);
          let m;
          try { m = JSON.parse(l); } catch { continue; }
          if (m.id !== undefined && this.pending.has(m.id)) {
            this.pending.get(m.id)(m);
            this.pending.delete(m.id);
          }
        }
      });
    });
  }
  ask(cmd, args = {}) {
    const id = this.id++;
    return new Promise((resolve, reject) => {
      const t = setTimeout(() => reject(new Error(`no answer to ${cmd} within ${WAIT_S} s`)), WAIT_S * 1000);
      this.pending.set(id, (m) => { clearTimeout(t); resolve(m); });
      this.s.write(JSON.stringify({ id, cmd, ...args }) + '\n');
    });
  }
  async state() {
    const s = await this.ask('state');
    if (s.error) throw new Error('state: ' + JSON.stringify(s));
    return s;
  }
  close() { if (this.s) this.s.destroy(); }
}

/** Waits for standstill after a stop; the time from the first sample below the speed the move
 *  had to the first at rest, on the arm's clock (the state's t), in ms. */
async function brakeTimes(tcp, j, speed) {
  let tBrake = null;
  let tRest = null;
  await until('standstill after the stop', async () => {
    const s = await tcp.state();
    if (tBrake === null && Math.abs(s.qd_cmd[j]) < Math.abs(speed) * 0.98) tBrake = s.t;
    if (allStill(s)) { tRest = s.t; return true; }
    return false;
  });
  return tBrake === null ? 'n/a' : ((tRest - tBrake) * 1000).toFixed(0);
}

const still = (s, j) => Math.abs(s.qd_cmd[j]) < 1e-6;
const allStill = (s) => s.qd_cmd.every((v) => Math.abs(v) < 1e-6) && s.running === 0;

// ---- the browser ----------------------------------------------------------------------------------
// the pages open now: a failed case saves a screenshot of each
const openPages = new Set();
let shotsDir = '';
let shotsWanted = false;

/** A screenshot of a view, saved with --screenshots only; opts as page.screenshot's, or an
 *  element handle to take that element alone. */
async function shot(page, name, opts = {}) {
  if (!shotsWanted) return;
  const file = path.join(shotsDir, name + '.png');
  if (opts.element) await opts.element.screenshot({ path: file });
  else await page.screenshot({ path: file, ...opts });
}

/** After a failed case: a screenshot of each open page, each given 10 s (a page may hang). */
async function failureShots(n) {
  let k = 0;
  for (const p of openPages) {
    const file = path.join(shotsDir, `FAILED-${n}-${++k}.png`);
    const t = new Promise((resolve) => setTimeout(() => resolve('timed out'), 10000));
    const r = await Promise.race([p.screenshot({ path: file }).then(() => file, (e) => `failed: ${e.message}`), t]);
    console.log(`     screenshot of ${p.url()}: ${r}`);
  }
}

async function openPage(browser, url, viewport = { width: 1280, height: 900 }) {
  const page = await browser.newPage();
  openPages.add(page);
  page.on('close', () => openPages.delete(page));
  await page.setViewport(viewport);
  const errors = [];
  page.on('pageerror', (e) => errors.push(String(e)));
  page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  await page.goto(url, { waitUntil: 'load', timeout: WAIT_S * 1000 });
  page.errors = errors;
  return page;
}

async function waitAuth(page, want) {
  await page.waitForFunction((w) => document.body.dataset.auth === w, { timeout: WAIT_S * 1000 }, want);
}

/** The page's speed slider, as a person sets it. */
async function setSpeed(page, pct) {
  await page.$eval('#speed', (e, v) => { e.value = String(v); e.dispatchEvent(new Event('input')); }, pct);
}

/** Submits the page's movej form at 100 %: for the moves that only bring the arm to where a
 *  check starts (the simulated arm; no check depends on their speed). */
async function moveAtFullSpeed(page) {
  await setSpeed(page, 100);
  await page.click('#movej-form button[type=submit]');
}

async function takeControl(page) {
  await page.click('#take');
  await page.waitForFunction(() => /this pendant/.test(document.getElementById('control').textContent), { timeout: WAIT_S * 1000 });
}

async function pressHold(page, selector) {
  const b = await page.$(selector);
  if (!b) throw new Error(`no ${selector} on the page`);
  const box = await b.boundingBox();
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.down();
}

/** Hold `selector` until cond() holds, then release. On a loaded machine the browser may stall
 *  past the jog deadman: the firmware ends the jog and the page waits for a new press; it is
 *  pressed again and counted (a figure line). */
async function holdUntil(page, selector, what, cond) {
  let lapses = 0;
  await pressHold(page, selector);
  try {
    await until(what, async () => {
      if (await page.evaluate(() => window.pendant.jogging === null)) {
        ++lapses;
        await page.mouse.up();
        await pressHold(page, selector);
      }
      return cond();
    });
  } finally {
    await page.mouse.up();
  }
  if (lapses) figure(`${what}: the held jog lapsed ${lapses} time(s) (keep-alives later than the deadman: a busy machine)`);
}

// ---- the cases ------------------------------------------------------------------------------------
const results = [];
const figures = [];
async function check(name, fn) {
  const t0 = now();
  try {
    await fn();
    results.push([name, 'ok']);
    console.log(`ok   ${name} (${(now() - t0).toFixed(1)} s)`);
  } catch (e) {
    results.push([name, 'FAILED']);
    console.log(`FAIL ${name} (${(now() - t0).toFixed(1)} s): ${e.stack || e}`);
    await failureShots(results.length);
  }
}
function figure(text) {
  figures.push(text);
  console.log('figure: ' + text);
}
function assert(cond, text) { if (!cond) throw new Error(text); }

async function main() {
  const args = parseArgs(process.argv);
  const chromium = findChromium(args.chromium);
  const pptr = puppeteer();
  const shots = path.join(args.workdir, 'screenshots');
  // emptied: a file there is this run's
  fs.rmSync(shots, { recursive: true, force: true });
  fs.mkdirSync(shots, { recursive: true });
  shotsDir = shots;
  shotsWanted = args.screenshots;
  // WebGL in SwiftShader (software); the page composited in software too: composited through
  // SwiftShader the GPU process spent a core on a page at rest (15.5 CPU-s in 15 s, 10 without)
  const browser = await pptr.launch({
    executablePath: chromium,
    headless: true,
    args: ['--no-sandbox', '--disable-dev-shm-usage', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
           '--disable-gpu-compositing', '--disable-background-timer-throttling', '--disable-renderer-backgrounding'],
    protocolTimeout: WAIT_S * 4000,
  });
  console.log(`chromium: ${await browser.version()}, puppeteer-core ${require(path.join(here, 'node_modules/puppeteer-core/package.json')).version}`);
  let armfw = null;
  let tcp = null;
  try {
    // ------------------------------------------------------------ no token file: loopback operators
    // a programs folder for the editor's save (emptied: a file there is this run's)
    const progDir = path.join(args.workdir, 'programs');
    fs.rmSync(progDir, { recursive: true, force: true });
    fs.mkdirSync(progDir, { recursive: true });
    // two digital outputs; tools, frames and points kept in memory only (as without --config)
    const simToml = path.join(args.workdir, 'sim.toml');
    fs.writeFileSync(simToml, '[console]\nframes_file = ""\n\n[programs]\npoints_file = ""\n\n' +
                     '[[output]]\nname = "gripper"\nnode = 1\nbit = 16\n\n[[output]]\nname = "lamp"\nnode = 2\nbit = 17\n');
    armfw = await startArmfw(args.armfw, ['--config', simToml, '--programs', progDir]);
    console.log(`armfw: pendant at ${armfw.url}, API TCP port ${armfw.tcp}`);
    tcp = new Tcp(armfw.tcp);
    await tcp.connect();
    let page = null;

    await check('the page loads and shows the joints', async () => {
      page = await openPage(browser, armfw.url);
      await waitAuth(page, 'ok');
      await page.waitForFunction(() => {
        const v = [...document.querySelectorAll('#joints td.val')];
        return v.length === 6 && v.every((td) => /^-?\d+\.\d+ rad$/.test(td.textContent));
      }, { timeout: WAIT_S * 1000 });
      const s = await tcp.state();
      const shown = await page.$$eval('#joints td.val', (tds) => tds.map((td) => parseFloat(td.textContent)));
      shown.forEach((v, j) => assert(Math.abs(v - s.q[j]) < 1e-3, `J${j + 1} shows ${v}, the arm is at ${s.q[j]}`));
      const role = await page.$eval('#role', (e) => e.textContent);
      assert(role === 'role: operator', `role shown: ${role}`);
      const safety = await page.$eval('#st-safety', (e) => e.textContent);
      assert(safety === 'safety: off', `safety shown without an envelope: ${safety}`);
      // CiA 402 drives report no temperature: no warning, empty temperature cells
      assert(await page.$eval('#st-temp', (e) => e.hidden), 'a temperature warning without a temperature');
      const temps = await page.$$eval('#joints td.temp', (tds) => tds.map((td) => td.textContent));
      assert(temps.length === 6 && temps.every((t) => t === ''), `temperatures shown for CiA 402 drives: ${temps}`);
      assert(await page.$('#stop') !== null, 'no stop button');
      // the 3D view drew the arm from the state's frames
      await page.waitForFunction(() => window.pendant.state && Array.isArray(window.pendant.state.frames), { timeout: WAIT_S * 1000 });
      const nFrames = await page.evaluate(() => window.pendant.state.frames.length);
      assert(nFrames === s.frames.length && nFrames >= 7, `the page has ${nFrames} frames, the API ${s.frames.length}`);
      assert(await page.$('#three canvas') !== null, 'no 3D view (WebGL canvas)');
      // the three live plots (following error, speed, torque), one series per joint
      await page.waitForFunction(() => document.querySelectorAll('#plots .uplot').length === 3, { timeout: WAIT_S * 1000 });
      const legends = await page.$$eval('#plot-fe .u-legend .u-series', (e) => e.length);
      assert(legends === 6, `following-error plot: ${legends} legend rows, expected one per joint (6)`);
      assert(page.errors.length === 0, 'errors in the page: ' + page.errors.join('; '));
      await shot(page, 'pendant-overview');
    });

    await check('hold a jog button: the joint moves; release: it stops', async () => {
      await takeControl(page);
      await page.click('#arm button[data-cmd="enable"]');
      await until('the arm idle', async () => (await tcp.state()).state === 'idle');
      const q0 = (await tcp.state()).q[0];
      const sel = '#joints button.jog[data-joint="0"][data-dir="1"]';
      await pressHold(page, sel);
      await until('J1 moving', async () => (await tcp.state()).q[0] > q0 + 0.01);
      await shot(page, 'pendant-jog');
      // held for a while: the keep-alives keep it moving past several deadman periods. On a
      // loaded machine the browser may stall past the deadman; the firmware then stops the jog
      // and the page waits for a new press: the test presses again and counts it.
      let lapses = 0;
      const qa = (await tcp.state()).q[0];
      await until('J1 still moving 1 s on', async () => {
        if (await page.evaluate(() => window.pendant.jogging === null)) {
          ++lapses;
          await page.mouse.up();
          await pressHold(page, sel);
        }
        return (await tcp.state()).q[0] > qa + 0.02;
      });
      if (lapses) figure(`the held jog lapsed ${lapses} time(s) (keep-alives later than the deadman: a busy machine)`);
      await page.mouse.up();
      const t0 = now();
      await until('J1 at rest after the release', async () => still(await tcp.state(), 0));
      figure(`jog release -> J1 commanded at rest: ${((now() - t0) * 1000).toFixed(0)} ms (the page ends the jog at once)`);
      const qr = (await tcp.state()).q[0];
      await sleep(300);
      const qr2 = (await tcp.state()).q[0];
      assert(Math.abs(qr2 - qr) < 1e-3, `J1 moved on after the release: ${qr} -> ${qr2}`);
      await shot(page, 'pendant-full', { fullPage: true });  // the plots of the jog
    });

    await check('close the tab while holding: the arm stops within the jog deadman', async () => {
      const q0 = (await tcp.state()).q[1];
      await pressHold(page, '#joints button.jog[data-joint="1"][data-dir="1"]');
      await until('J2 moving', async () => (await tcp.state()).q[1] > q0 + 0.01);
      const speed = (await tcp.state()).qd_cmd[1];
      const t0 = now();
      await page.close({ runBeforeUnload: false });
      page = null;
      let tBrake = null;
      await until('J2 at rest after the tab closed', async () => {
        const s = await tcp.state();
        if (tBrake === null && Math.abs(s.qd_cmd[1]) < Math.abs(speed) * 0.98) tBrake = now();
        return still(s, 1);
      });
      const tRest = now();
      figure(`tab closed while jogging J2 at ${speed.toFixed(3)} rad/s -> braking begins ${((tBrake - t0) * 1000).toFixed(0)} ms, at rest ${((tRest - t0) * 1000).toFixed(0)} ms (console.jog_deadman_ms = 250)`);
      // generous on a busy machine: the deadman (250 ms) plus braking plus scheduling
      assert(tBrake - t0 < 2.0, `braking began ${(tBrake - t0).toFixed(3)} s after the tab closed`);
    });

    await check('a hung page while holding: the firmware\'s jog deadman stops the arm', async () => {
      // the page's script frozen (paused in the debugger, so it stays frozen until the arm is at
      // rest however long that takes): no keep-alive and no jog_cancel, the connection stays open
      page = await openPage(browser, armfw.url);
      await waitAuth(page, 'ok');
      await takeControl(page);
      const q0 = (await tcp.state()).q[2];
      await pressHold(page, '#joints button.jog[data-joint="2"][data-dir="1"]');
      await until('J3 moving', async () => (await tcp.state()).q[2] > q0 + 0.01);
      const speed = (await tcp.state()).qd_cmd[2];
      // the debugger stops the page's script at its next statement: the view's animation frame
      // or the jog keep-alive's timer, whichever comes first (both within a frame or a period)
      const dbg = await page.createCDPSession();
      await dbg.send('Debugger.enable');
      await dbg.send('Debugger.pause');
      const t0 = now();
      let tBrake = null;
      try {
        await until('J3 at rest with the page hung', async () => {
          const s = await tcp.state();
          if (tBrake === null && Math.abs(s.qd_cmd[2]) < Math.abs(speed) * 0.98) tBrake = now();
          return still(s, 2);
        });
      } finally {
        await dbg.send('Debugger.resume').catch(() => {});
        await dbg.send('Debugger.disable').catch(() => {});
        await dbg.detach().catch(() => {});
        await page.mouse.up();
      }
      const tRest = now();
      figure(`page hung while jogging J3 at ${speed.toFixed(3)} rad/s -> braking begins ${((tBrake - t0) * 1000).toFixed(0)} ms, at rest ${((tRest - t0) * 1000).toFixed(0)} ms (console.jog_deadman_ms = 250)`);
      assert(tBrake - t0 < 2.0, `braking began ${(tBrake - t0).toFixed(3)} s after the page hung`);
      // running again, the page ends its jog (it was ended by the firmware): the next check uses it
      await page.waitForFunction(() => window.pendant.jogging === null, { timeout: WAIT_S * 1000 });
    });

    await check('the stop button stops a running movej', async () => {
      if (!page) {
        page = await openPage(browser, armfw.url);
        await waitAuth(page, 'ok');
      }
      await takeControl(page);
      await until('the arm idle', async () => (await tcp.state()).state === 'idle');
      const s0 = await tcp.state();
      // a long, slow move (2 rad at 8 %: 12 s, 4 s of it speeding up), stopped once it is
      // under way (0.15 rad, 2.5 s in): the stop comes nearly 10 s before its end however busy
      // the machine is
      const goal = s0.q.map((v, j) => (j === 0 ? v - 2.0 : v));
      await page.$eval('#movej-q', (e, g) => { e.value = g; }, goal.map((v) => v.toFixed(4)).join(', '));
      await page.$eval('#speed', (e) => { e.value = '8'; e.dispatchEvent(new Event('input')); });
      await page.click('#movej-form button[type=submit]');
      const moving = await until('the movej under way', async () => {
        const s = await tcp.state();
        return Math.abs(s.q[0] - s0.q[0]) > 0.15 ? s : null;
      });
      const t0 = now();
      await page.click('#stop');
      const b1 = await brakeTimes(tcp, 0, moving.qd_cmd[0]);
      figure(`stop button during a movej at ${moving.qd_cmd[0].toFixed(3)} rad/s -> standstill (every joint commanded at rest, nothing running) ${((now() - t0) * 1000).toFixed(0)} ms after the click began; braking to rest ${b1} ms of the arm's clock`);
      const s1 = await tcp.state();
      assert(Math.abs(s1.q[0] - goal[0]) > 0.05, `the movej reached its goal (${s1.q[0]}): the stop did not stop it`);
      await shot(page, 'pendant-stopped');
      // the space bar stops too: a second long move, from where the first stopped the other way
      // (2 rad), so the key comes long before its end however slow the machine is
      const goal2 = s1.q.map((v, j) => (j === 0 ? v + 2.0 : v));
      await page.$eval('#movej-q', (e, g) => { e.value = g; }, goal2.map((v) => v.toFixed(4)).join(', '));
      await page.click('#movej-form button[type=submit]');
      const moving2 = await until('the movej running again', async () => {
        const s = await tcp.state();
        return Math.abs(s.q[0] - s1.q[0]) > 0.15 ? s : null;
      });
      await page.focus('#stop');
      const t1 = now();
      await page.keyboard.press('Space');
      const b2 = await brakeTimes(tcp, 0, moving2.qd_cmd[0]);
      figure(`space bar during a movej at ${moving2.qd_cmd[0].toFixed(3)} rad/s -> standstill ${((now() - t1) * 1000).toFixed(0)} ms after the key press began; braking to rest ${b2} ms of the arm's clock`);
      assert(Math.abs((await tcp.state()).q[0] - goal2[0]) > 0.05, 'the movej reached its goal: the space bar did not stop it');
    });

    await check('the 3D view draws the running move\'s planned path, the firmware\'s, ending where the arm stops', async () => {
      await until('the arm idle and at rest', async () => { const s = await tcp.state(); return s.state === 'idle' && allStill(s); });
      const s0 = await tcp.state();
      // a joint move whose tool point sweeps a wide arc (J1 turns, the arm leans out); at 12 %
      // it lasts 5.6 s, for the page to fetch and draw its path while it runs on a busy machine
      const goal = s0.q.map((v, j) => (j === 0 ? v + 1.0 : j === 1 ? 0.5 : j === 2 ? -0.3 : v));
      await page.$eval('#movej-q', (e, g) => { e.value = g; }, goal.map((v) => v.toFixed(4)).join(', '));
      await page.$eval('#speed', (e) => { e.value = '12'; e.dispatchEvent(new Event('input')); });
      await page.click('#movej-form button[type=submit]');
      const run = await until('the movej running', async () => { const s = await tcp.state(); return s.running ? s : null; });
      // the firmware's planned path of that motion, asked by the independent client
      const ref = await tcp.ask('planned_path', { motion: run.running });
      assert(ref.ok && ref.motion === run.running && ref.points.length >= 24, 'planned_path over TCP: ' + JSON.stringify(ref).slice(0, 300));
      const drawn = await (await page.waitForFunction((id) => {
        const v = window.pendant.view, p = window.pendant.path;
        if (!p || p.motion !== id || !v.pathLine || !v.pathLine.visible) return null;
        return Array.from(v.pathLine.geometry.attributes.position.array);
      }, { timeout: WAIT_S * 1000 }, run.running)).jsonValue();
      assert(drawn.length === 3 * ref.points.length, `the view draws ${drawn.length / 3} points, the firmware planned ${ref.points.length}`);
      ref.points.forEach((p, k) => p.forEach((v, i) => assert(Math.abs(drawn[3 * k + i] - v) < 1e-5, `drawn point ${k} differs from the plan: ${drawn.slice(3 * k, 3 * k + 3)} vs ${p}`)));
      if (shotsWanted) {
        await page.$eval('#view', (e) => e.scrollIntoView({ block: 'center' }));
        await sleep(150);  // a frame drawn (the view draws at most every 50 ms)
        await shot(page, 'pendant-path');
      }
      const drawsMoving = await page.evaluate(() => window.pendant.view.renderer.info.render.frame);
      await until('the move done and the arm at rest', async () => { const s = await tcp.state(); return s.done >= run.running && allStill(s); });
      const drawsDone = await page.evaluate(() => window.pendant.view.renderer.info.render.frame);
      assert(drawsDone > drawsMoving, `the view was not drawn again while the arm moved (${drawsMoving} draws, then ${drawsDone})`);
      // where the arm stopped (its tool point, measured) is where the drawn path ends; 1 mm
      // covers the float32 of the drawing and the simulated drives' settling
      const tool = (await tcp.state()).tool.position;
      const end = drawn.slice(-3);
      const miss = Math.hypot(end[0] - tool[0], end[1] - tool[1], end[2] - tool[2]);
      figure(`planned path drawn: ${ref.points.length} points over ${ref.duration.toFixed(2)} s; its end ${(miss * 1000).toFixed(3)} mm from the tool point the arm stopped at`);
      assert(miss < 1e-3, `the drawn path ends ${miss} m from where the arm stopped (${end} vs ${tool})`);
      // nothing runs: the path goes
      await page.waitForFunction(() => window.pendant.path === null && !window.pendant.view.pathLine.visible, { timeout: WAIT_S * 1000 });
      // back where it started: the checks after this one start from the pose the stop left
      await page.$eval('#movej-q', (e, g) => { e.value = g; }, s0.q.map((v) => v.toFixed(6)).join(', '));
      await moveAtFullSpeed(page);
      await until('the arm back at the start', async () => { const s = await tcp.state(); return allStill(s) && s.q.every((v, j) => Math.abs(v - s0.q[j]) < 1e-3); });
      // at rest the state stream goes on (30 Hz) but nothing in the view changes: it is not drawn
      await sleep(300);  // the last change drawn (at most every 50 ms)
      const drawsAtRest = await page.evaluate(() => window.pendant.view.renderer.info.render.frame);
      await sleep(1500);
      const drawsLater = await page.evaluate(() => window.pendant.view.renderer.info.render.frame);
      figure(`3D view: ${drawsDone - drawsMoving} draws for the rest of the planned-path move, ${drawsLater - drawsAtRest} in 1.5 s at rest`);
      assert(drawsLater === drawsAtRest, `the view was drawn ${drawsLater - drawsAtRest} times in 1.5 s with the arm at rest`);
      await setSpeed(page, 30);
    });

    await check('a program with an unreachable line 3 shows the error on line 3 and does not run', async () => {
      await until('the arm idle', async () => (await tcp.state()).state === 'idle');
      const s0 = await tcp.state();
      // typed as a person types it: checked as typed (debounced), the space bar types a space there
      await page.click('#prog-text');
      await page.type('#prog-text', 'movej 0 0 0 0 0 0\nmovej 10 0 0 0 0 0\nmovel 5000 0 500 0 0 0\nmovej 0 0 0 0 0 0');
      await page.waitForFunction(() => document.getElementById('prog-check').dataset.line === '3', { timeout: WAIT_S * 1000 });
      const marked = await page.$$eval('#prog-gutter div', (d) => d.map((e, i) => (e.classList.contains('error') ? i + 1 : 0)).filter((x) => x));
      assert(marked.length === 1 && marked[0] === 3, `lines marked as errors: ${JSON.stringify(marked)}`);
      const msg = await page.$eval('#prog-check', (e) => e.textContent);
      assert(/^line 3: /.test(msg), `the check shows: ${msg}`);
      // the independent client: the same program refused at line 3 by the API's own check
      const ind = await tcp.ask('program_check', { text: await page.$eval('#prog-text', (e) => e.value), name: 'editor' });
      assert(ind.error && ind.line === 3, `program_check over TCP: ${JSON.stringify(ind)}`);
      await shot(page, 'pendant-program-error');
      await page.click('#prog-run');
      await page.waitForFunction(() => window.pendant.results.some((r) => r.cmd === 'program_run'), { timeout: WAIT_S * 1000 });
      const run = await page.evaluate(() => window.pendant.results.filter((r) => r.cmd === 'program_run').pop());
      assert(run.error && run.line === 3, `run answered: ${JSON.stringify(run)}`);
      await sleep(500);  // a window for a motion that must not come
      const s1 = await tcp.state();
      assert(s1.done === s0.done && s1.queued === 0 && s1.running === 0, `the arm ran motions: ${s0.done} -> ${s1.done}, ${s1.queued} queued`);
      s1.q_cmd.forEach((v, j) => assert(Math.abs(v - s0.q_cmd[j]) < 1e-9, `J${j + 1} moved: ${s0.q_cmd[j]} -> ${v}`));
      assert(s1.program.state === 'idle', `a program runs: ${JSON.stringify(s1.program)}`);
    });

    await check('a good program runs with its current line highlighted; pause, resume, abort', async () => {
      // nine lines: a pause lands once the running motion and the one queued behind it are done,
      // so it is pressed while more than two motions are left (else the program simply ends)
      const text = 'movej 0 0 0 0 0 0\n' + 'movej 60 0 0 0 0 0\nmovej -60 0 0 0 0 0\n'.repeat(4) + 'movej 0 0 0 0 0 0';
      await page.$eval('#prog-text', (e, t) => { e.value = t; e.dispatchEvent(new Event('input')); }, text);
      await page.waitForFunction(() => /^checked: /.test(document.getElementById('prog-check').textContent), { timeout: WAIT_S * 1000 });
      await page.$eval('#speed', (e) => { e.value = '10'; e.dispatchEvent(new Event('input')); });
      await page.click('#prog-run');
      await until('the program running (independent client)', async () => (await tcp.state()).program.state === 'running');
      const line = await page.waitForFunction(() => {
        const d = [...document.querySelectorAll('#prog-gutter div.current')];
        return d.length === 1 ? Number(d[0].textContent) : 0;
      }, { timeout: WAIT_S * 1000 });
      const shown = await line.jsonValue();
      assert(shown >= 1 && shown <= 10, `current line shown: ${shown}`);
      await page.click('#prog-pause');
      await shot(page, 'pendant-program-running');
      await until('the program paused', async () => (await tcp.state()).program.state === 'paused');
      await page.click('#prog-resume');
      await until('the program running again', async () => (await tcp.state()).program.state === 'running');
      await page.click('#prog-abort');
      await until('the program ended and the arm at rest', async () => {
        const s = await tcp.state();
        return s.program.state === 'idle' && allStill(s);
      });
      await page.waitForFunction(() => document.querySelectorAll('#prog-gutter div.current').length === 0, { timeout: WAIT_S * 1000 });
    });

    await check('save the program from the editor: written to the programs folder; a line the loader refuses is marked, nothing written', async () => {
      const text = 'movej 0 0 0 0 0 0\nmovej 10 0 0 0 0 0\n';
      await page.$eval('#prog-name', (e) => { e.value = 'saved1'; e.dispatchEvent(new Event('input')); });
      await page.$eval('#prog-text', (e, t) => { e.value = t; e.dispatchEvent(new Event('input')); }, text);
      await page.click('#prog-save');
      const file = path.join(progDir, 'saved1.arm');
      await until('saved1.arm in the programs folder', async () => fs.existsSync(file));
      assert(fs.readFileSync(file, 'utf8') === text, `saved1.arm holds: ${JSON.stringify(fs.readFileSync(file, 'utf8'))}`);
      // the arm runs it by name from the folder (the independent client)
      const chk = await tcp.ask('program_check', { name: 'saved1' });
      assert(chk.ok && chk.steps === 2, 'program_check of the saved file: ' + JSON.stringify(chk));
      await page.$eval('#prog-name', (e) => { e.value = 'bad1'; e.dispatchEvent(new Event('input')); });
      await page.$eval('#prog-text', (e) => { e.value = 'movej 0 0 0 0 0 0\nfrobnicate 1 2\n'; e.dispatchEvent(new Event('input')); });
      await page.click('#prog-save');
      await page.waitForFunction(() => window.pendant.results.some((r) => r.cmd === 'program_save' && r.error), { timeout: WAIT_S * 1000 });
      await page.waitForFunction(() => document.getElementById('prog-check').dataset.line === '2', { timeout: WAIT_S * 1000 });
      assert(!fs.existsSync(path.join(progDir, 'bad1.arm')), 'a program the loader refuses was saved');
      await page.$eval('#prog-name', (e) => { e.value = 'editor'; e.dispatchEvent(new Event('input')); });
      await page.$eval('#prog-text', (e) => { e.value = ''; e.dispatchEvent(new Event('input')); });
    });

    await check('Cartesian jog: hold x+ in the base frame, the tool moves along x; the override slider sets the arm\'s', async () => {
      await until('the arm idle', async () => (await tcp.state()).state === 'idle');
      // away from the zero pose's singularity first
      await page.$eval('#movej-q', (e) => { e.value = '0, 0.3, -0.6, 0, 0.6, 0'; });
      await moveAtFullSpeed(page);
      await until('the arm at the start pose', async () => { const s = await tcp.state(); return Math.abs(s.q[1] - 0.3) < 1e-3 && allStill(s); });
      await setSpeed(page, 30);  // the jog's speed
      const p0 = (await tcp.state()).tool.position;
      await page.select('#cjog-frame', 'base');
      const sel = '#cjog-axes button.cjog[data-axis="0"][data-dir="1"]';
      await page.$eval(sel, (e) => e.scrollIntoView({ block: 'center' }));
      await holdUntil(page, sel, 'the tool moving along x', async () => (await tcp.state()).tool.position[0] > p0[0] + 0.005);
      await until('at rest after the release', async () => allStill(await tcp.state()));
      const p1 = (await tcp.state()).tool.position;
      assert(Math.abs(p1[1] - p0[1]) < 2e-3 && Math.abs(p1[2] - p0[2]) < 2e-3, `the tool left its line: ${p0} -> ${p1}`);
      await page.$eval('#override', (e) => { e.value = '55'; e.dispatchEvent(new Event('input')); });
      await until('the arm\'s feed override at 55 %', async () => (await tcp.state()).feed_pct === 55);
      // the state bar shows the arm's override (from the state stream)
      await page.waitForFunction(() => document.getElementById('st-override').textContent === 'override: 55 %', { timeout: WAIT_S * 1000 });
      await page.$eval('#override', (e) => { e.value = '100'; e.dispatchEvent(new Event('input')); });
      await until('the arm\'s feed override at 100 %', async () => (await tcp.state()).feed_pct === 100);
    });

    await check('teach a point: listed, drawn, gone to, deleted', async () => {
      await page.$eval('#teach-name', (e) => { e.value = 'here1'; });
      await page.click('#teach-form button[type=submit]');
      await page.waitForSelector('#points tr[data-point="here1"]', { timeout: WAIT_S * 1000 });
      const pts = await tcp.ask('points');
      const pt = (pts.points || []).find((x) => x.name === 'here1');
      assert(pt, `points over TCP: ${JSON.stringify(pts)}`);
      const s = await tcp.state();
      pt.q.forEach((v, j) => assert(Math.abs(v - s.q[j]) < 1e-3, `the point's J${j + 1} ${v}, the arm ${s.q[j]}`));
      const drawn = await page.evaluate(() => window.pendant.points.length);
      assert(drawn === pts.points.length, `the page has ${drawn} points`);
      await shot(page, 'pendant-teach');
      // away from it, then back with its go button
      await page.$eval('#movej-q', (e, q) => { e.value = q.map((v, j) => (j === 0 ? v + 0.3 : v).toFixed(4)).join(', '); }, pt.q);
      await moveAtFullSpeed(page);
      await until('the arm away from the point', async () => { const a = await tcp.state(); return Math.abs(a.q[0] - pt.q[0]) > 0.29 && allStill(a); });
      await page.click('#points tr[data-point="here1"] button[data-action="go"]');
      await until('the arm back at the point', async () => {
        const a = await tcp.state();
        return allStill(a) && a.q.every((v, j) => Math.abs(v - pt.q[j]) < 1e-3);
      });
      await setSpeed(page, 30);
      await page.click('#points tr[data-point="here1"] button[data-action="delete"]');
      await page.waitForFunction(() => !document.querySelector('#points tr[data-point="here1"]'), { timeout: WAIT_S * 1000 });
      assert(!((await tcp.ask('points')).points || []).some((x) => x.name === 'here1'), 'the point is still there');
    });

    await check('tools and user frames defined from the page: in the API\'s lists, drawn, jogged in, deleted', async () => {
      await until('the arm idle and at rest', async () => { const s = await tcp.state(); return s.state === 'idle' && allStill(s); });
      const define = async (kind, name, pos, rpy) => {
        await page.select('#def-kind', kind);
        await page.$eval('#def-name', (e, v) => { e.value = v; }, name);
        await page.$eval('#def-pos', (e, v) => { e.value = v; }, pos.join(', '));
        await page.$eval('#def-rpy', (e, v) => { e.value = v; }, rpy.join(', '));
        await page.click('#define-form button[type=submit]');
        await page.waitForSelector(`#tf-list tr[data-${kind}="${name}"]`, { timeout: WAIT_S * 1000 });
      };
      const near = (a, b, tol = 1e-9) => a.length === b.length && a.every((v, i) => Math.abs(v - b[i]) < tol);
      await define('tool', 'pen', [0, 0, 0.1], [0, 0, 0]);
      await define('frame', 'table', [0.3, 0.4, 0.05], [0, 0, 0.5]);
      const tf = await tcp.ask('tools');
      const pen = tf.tools.find((t) => t.name === 'pen');
      const table = tf.frames.find((f) => f.name === 'table');
      assert(pen && near(pen.position, [0, 0, 0.1]) && near(pen.rpy, [0, 0, 0]), 'tools over TCP: ' + JSON.stringify(tf.tools));
      assert(table && near(table.position, [0.3, 0.4, 0.05]) && near(table.rpy, [0, 0, 0.5]), 'frames over TCP: ' + JSON.stringify(tf.frames));
      const opts = await page.$$eval('#tool-sel option, #frame-sel option', (o) => o.map((x) => x.value));
      assert(opts.includes('pen') && opts.includes('table'), `the selectors offer ${opts}`);
      // the frame drawn in the 3D view: axes at its origin, with the taught points
      const axes = await page.evaluate(() => window.pendant.view.frameGroup.children.map((c) => [c.position.x, c.position.y, c.position.z, c.rotation.z]));
      assert(axes.some((a) => near(a, [0.3, 0.4, 0.05, 0.5], 1e-6)), `frames drawn: ${JSON.stringify(axes)}`);
      // a bad definition is refused in one line and adds nothing
      await page.select('#def-kind', 'tool');
      await page.$eval('#def-name', (e) => { e.value = 'bad name'; });
      await page.click('#define-form button[type=submit]');
      await page.waitForFunction(() => /^tool_define: bad_option/.test(document.getElementById('msg').textContent), { timeout: WAIT_S * 1000 });
      assert((await tcp.ask('tools')).tools.length === tf.tools.length, 'a refused tool was added');
      // active from the selectors, then jog along the table's x axis (Cartesian jog, user frame)
      await page.select('#tool-sel', 'pen');
      await page.select('#frame-sel', 'table');
      await until('pen and table active', async () => { const a = await tcp.ask('tools'); return a.tool === 'pen' && a.frame === 'table'; });
      // the active tool drawn: a rod from the flange to the tool point the API's state gives (tcp)
      const st = await tcp.state();
      const off = Math.hypot(...st.tcp.position.map((v, i) => v - st.tool.position[i]));
      assert(Math.abs(off - 0.1) < 1e-6, `the state's tcp is ${off} m from the flange, the pen is 0.1 m long`);
      await page.waitForFunction((want) => {
        const r = window.pendant.view.toolRod;
        if (!r || !r.visible) return false;
        r.updateMatrixWorld();
        const e = r.localToWorld(new r.position.constructor(0, 0.5, 0));
        return Math.hypot(e.x - want[0], e.y - want[1], e.z - want[2]) < 1e-4;
      }, { timeout: WAIT_S * 1000 }, st.tcp.position);
      await page.$eval('#frames', (e) => e.scrollIntoView({ block: 'center' }));
      await shot(page, 'pendant-tools-frames');
      await shot(page, 'pendant-frame-view', { element: await page.$('#view') });
      const pose0 = (await tcp.state()).tool.position;
      await page.select('#cjog-frame', 'user');
      const sel = '#cjog-axes button.cjog[data-axis="0"][data-dir="1"]';
      await page.$eval(sel, (e) => e.scrollIntoView({ block: 'center' }));
      await holdUntil(page, sel, 'the tool moving in the table frame', async () => {
        const p = (await tcp.state()).tool.position;
        return Math.hypot(p[0] - pose0[0], p[1] - pose0[1]) > 0.01;
      });
      await until('at rest after the release', async () => allStill(await tcp.state()));
      const pose1 = (await tcp.state()).tool.position;
      // the flange (the state's tool point) moves as the pen does in a pure translation: along the table's x = (cos 0.5, sin 0.5, 0)
      const d = [pose1[0] - pose0[0], pose1[1] - pose0[1], pose1[2] - pose0[2]];
      const len = Math.hypot(...d);
      const along = (d[0] * Math.cos(0.5) + d[1] * Math.sin(0.5)) / len;
      assert(along > 0.99, `jogged x+ in the table frame, the tool went ${d} (cos to the frame's x ${along})`);
      // back to tool0 / base; then both deleted from their rows
      await page.select('#cjog-frame', 'base');
      await page.select('#tool-sel', 'tool0');
      await page.select('#frame-sel', 'base');
      await until('tool0 and base active', async () => { const a = await tcp.ask('tools'); return a.tool === 'tool0' && a.frame === 'base'; });
      await page.waitForFunction(() => !window.pendant.view.toolRod.visible, { timeout: WAIT_S * 1000 });
      // (clicked in the page: the list is drawn again after each answer)
      await page.$eval('#tf-list tr[data-tool="pen"] button[data-action="delete"]', (b) => b.click());
      await page.waitForFunction(() => !document.querySelector('#tf-list tr[data-tool="pen"]'), { timeout: WAIT_S * 1000 });
      await page.$eval('#tf-list tr[data-frame="table"] button[data-action="delete"]', (b) => b.click());
      await page.waitForFunction(() => !document.querySelector('#tf-list tr'), { timeout: WAIT_S * 1000 });
      const after = await tcp.ask('tools');
      assert(!after.tools.some((t) => t.name === 'pen') && !after.frames.some((f) => f.name === 'table'), 'still defined: ' + JSON.stringify(after));
      const left = await page.evaluate(() => window.pendant.view.frameGroup.children.length);
      assert(left === 0, `${left} user frames still drawn`);
    });

    await check('digital outputs: one row each from the state, switched on and off from the page', async () => {
      await page.waitForFunction(() => document.querySelectorAll('#outputs tr').length === 2, { timeout: WAIT_S * 1000 });
      const names = await page.$$eval('#outputs tr td:first-child', (t) => t.map((e) => e.textContent));
      assert(names.join('|') === '0 gripper|1 lamp', `output rows: ${names}`);
      await page.$eval('#outputs tr[data-output="1"] button[data-on="true"]', (b) => b.click());
      await until('lamp on (independent client)', async () => { const o = (await tcp.state()).outputs; return o[1].on && !o[0].on; });
      await page.waitForFunction(() => document.querySelector('#outputs tr[data-output="1"] .val').textContent === 'on', { timeout: WAIT_S * 1000 });
      await page.$eval('#io', (e) => e.scrollIntoView({ block: 'center' }));
      await shot(page, 'pendant-outputs');
      await page.$eval('#outputs tr[data-output="1"] button[data-on="false"]', (b) => b.click());
      await until('lamp off', async () => !(await tcp.state()).outputs[1].on);
      await page.waitForFunction(() => document.querySelector('#outputs tr[data-output="1"] .val').textContent === 'off', { timeout: WAIT_S * 1000 });
    });

    await check('park: the arm goes to its park pose', async () => {
      await until('the arm idle and at rest', async () => { const s = await tcp.state(); return s.state === 'idle' && allStill(s); });
      const q0 = (await tcp.state()).q;
      await page.click('#arm button[data-cmd="park"]');
      await page.waitForFunction(() => window.pendant.results.some((r) => r.cmd === 'park'), { timeout: WAIT_S * 1000 });
      const r = await page.evaluate(() => window.pendant.results.filter((x) => x.cmd === 'park').pop());
      assert(r.ok && Array.isArray(r.goal), 'park answered: ' + JSON.stringify(r));
      // motion.home_deg left out: the park pose is every joint at 0 (clamped into its limits)
      assert(r.goal.every((v) => Math.abs(v) < 1e-9), `park goal ${r.goal}`);
      assert(q0.some((v) => Math.abs(v) > 0.05), 'the arm was at the park pose already: nothing tested');
      await until('the arm at rest at the park pose', async () => { const s = await tcp.state(); return allStill(s) && s.q.every((v) => Math.abs(v) < 1e-3); });
    });

    await check('Cartesian jog in the tool frame: z+ moves the tool along its own z axis', async () => {
      await page.$eval('#movej-q', (e) => { e.value = '0.2, 0.3, -0.6, 0, 0.9, 0.4'; });
      await moveAtFullSpeed(page);
      await until('the arm at the start pose', async () => { const s = await tcp.state(); return Math.abs(s.q[4] - 0.9) < 1e-3 && allStill(s); });
      await setSpeed(page, 30);  // the jog's speed
      const s0 = await tcp.state();
      const [r, p, y] = s0.tool.rpy;  // R = Rz(y) Ry(p) Rx(r): its z column is the tool's z axis in the base
      const zAxis = [Math.cos(y) * Math.sin(p) * Math.cos(r) + Math.sin(y) * Math.sin(r),
                     Math.sin(y) * Math.sin(p) * Math.cos(r) - Math.cos(y) * Math.sin(r),
                     Math.cos(p) * Math.cos(r)];
      await page.select('#cjog-frame', 'tool');
      const sel = '#cjog-axes button.cjog[data-axis="2"][data-dir="1"]';
      await page.$eval(sel, (e) => e.scrollIntoView({ block: 'center' }));
      const p0 = s0.tool.position;
      await holdUntil(page, sel, 'the tool moving along its z axis', async () => {
        const q = (await tcp.state()).tool.position;
        return Math.hypot(q[0] - p0[0], q[1] - p0[1], q[2] - p0[2]) > 0.01;
      });
      await until('at rest after the release', async () => allStill(await tcp.state()));
      const p1 = (await tcp.state()).tool.position;
      const d = [0, 1, 2].map((i) => p1[i] - p0[i]);
      const cos = (d[0] * zAxis[0] + d[1] * zAxis[1] + d[2] * zAxis[2]) / Math.hypot(...d);
      assert(cos > 0.99, `jogged z+ in the tool frame, the tool went ${d}, its z axis is ${zAxis} (cos ${cos})`);
      await page.select('#cjog-frame', 'base');
    });

    await check('step: a paused program runs one motion, then pauses again', async () => {
      const text = 'movej 0 0 0 0 0 0\nmovej 20 0 0 0 0 0\nmovej 0 0 0 0 0 0\nmovej 20 0 0 0 0 0\nmovej 0 0 0 0 0 0';
      await page.$eval('#prog-text', (e, t) => { e.value = t; e.dispatchEvent(new Event('input')); }, text);
      await page.waitForFunction(() => /^checked: /.test(document.getElementById('prog-check').textContent), { timeout: WAIT_S * 1000 });
      await page.click('#prog-run');
      await until('the program running', async () => (await tcp.state()).program.state === 'running');
      await page.click('#prog-pause');
      await until('the program paused and the arm at rest', async () => { const s = await tcp.state(); return s.program.state === 'paused' && allStill(s); });
      const d0 = (await tcp.state()).done;
      await sleep(300);
      assert((await tcp.state()).done === d0, 'a paused program ran a motion');
      await page.click('#prog-step');
      await until('one motion done, paused again', async () => { const s = await tcp.state(); return s.done === d0 + 1 && s.program.state === 'paused' && allStill(s); });
      await sleep(300);
      assert((await tcp.state()).done === d0 + 1, 'the step ran more than one motion');
      await page.click('#prog-abort');
      await until('the program ended', async () => (await tcp.state()).program.state === 'idle');
      await page.$eval('#prog-text', (e) => { e.value = ''; e.dispatchEvent(new Event('input')); });
    });

    await check('free-drive: the button asks the firmware, which names why the simulated drives cannot', async () => {
      await page.click('#freedrive');
      await page.waitForFunction(() => window.pendant.results.some((r) => r.cmd === 'freedrive'), { timeout: WAIT_S * 1000 });
      const r = await page.evaluate(() => window.pendant.results.filter((x) => x.cmd === 'freedrive').pop());
      // armfw --sim's drives have no cyclic synchronous torque mode: refused in one line, shown
      assert(r.error === 'bad_state' && /free-drive needs it/.test(r.message), 'freedrive answered: ' + JSON.stringify(r));
      const msg = await page.$eval('#msg', (e) => e.textContent);
      assert(/^freedrive: bad_state: /.test(msg), `message shown: ${msg}`);
      assert(!(await tcp.state()).freedrive, 'the arm is in free-drive');
    });

    await check('e-stop, reset, disable, enable and home from the page: the arm follows', async () => {
      const arm = (cmd) => page.$eval(`#arm button[data-cmd="${cmd}"]`, (b) => b.click());
      await until('the arm idle and at rest', async () => { const s = await tcp.state(); return s.state === 'idle' && allStill(s); });
      await arm('estop');
      await until('the arm in e-stop', async () => (await tcp.state()).state === 'estop');
      await page.waitForFunction(() => document.body.dataset.state === 'estop', { timeout: WAIT_S * 1000 });
      await arm('reset');
      await until('the e-stop reset', async () => (await tcp.state()).state !== 'estop');
      await arm('enable');
      await until('the arm idle again', async () => (await tcp.state()).state === 'idle');
      await arm('disable');
      await until('the arm disabled', async () => (await tcp.state()).state === 'disabled');
      await arm('enable');
      await until('the arm idle again', async () => (await tcp.state()).state === 'idle');
      // armfw --sim's joints home by method none (at once): the homing cycle's events say it ran
      const seq0 = Math.max(0, ...((await tcp.ask('events')).events || []).map((e) => e.seq));
      await arm('home');
      await until('the homing cycle\'s events', async () => ((await tcp.ask('events', { since: seq0 })).events || []).some((e) => e.kind === 'homing'));
      await until('every joint homed, homing over', async () => { const s = await tcp.state(); return s.homing === 0 && s.homed === 63 && s.state === 'idle'; }, 120);
      const bar = await page.$eval('#st-homed', (e) => e.textContent);
      assert(bar === 'homed: 6/6', `the bar shows ${bar}`);
    });

    await check('tablet and phone layouts keep the stop button in view', async () => {
      for (const [name, vp] of [['pendant-tablet', { width: 1280, height: 800 }], ['pendant-phone', { width: 390, height: 844, isMobile: true, hasTouch: true }]]) {
        await page.setViewport(vp);
        await page.evaluate(() => window.scrollTo(0, document.body.scrollHeight));
        const box = await page.$eval('#stop', (e) => { const r = e.getBoundingClientRect(); return { top: r.top, bottom: r.bottom, left: r.left, right: r.right }; });
        assert(box.top >= 0 && box.bottom <= vp.height && box.left >= 0 && box.right <= vp.width, `${name}: the stop button is off screen: ${JSON.stringify(box)}`);
        const overflow = await page.evaluate(() => document.documentElement.scrollWidth - window.innerWidth);
        assert(overflow <= 1, `${name}: the page is ${overflow} px wider than the screen`);
        await page.evaluate(() => window.scrollTo(0, 0));
        await shot(page, name);
      }
    });
    await check('armfw restarted: the page connects again by itself', async () => {
      const wsPort = Number(new URL(armfw.url).port);
      tcp.close();
      await stopArmfw(armfw);
      armfw = null;
      await page.waitForFunction(() => document.getElementById('conn').textContent === 'offline', { timeout: WAIT_S * 1000 });
      armfw = await startArmfw(args.armfw, [], wsPort);
      tcp = new Tcp(armfw.tcp);
      await tcp.connect();
      await page.waitForFunction(() => document.getElementById('conn').textContent === 'online' && window.pendant.role === 'operator' &&
                                 window.pendant.state !== null, { timeout: WAIT_S * 1000 });
      const ctl = await page.$eval('#control', (e) => e.textContent);
      assert(ctl === 'control: nobody', `after the reconnection: ${ctl} (control is not taken again by itself)`);
    });
    await check('a connection closed before hello is answered: the page connects again by itself', async () => {
      const u = new URL(armfw.url);
      const wsPort = Number(u.port);
      tcp.close();
      await stopArmfw(armfw);
      armfw = null;
      await page.waitForFunction(() => document.getElementById('conn').textContent === 'offline', { timeout: WAIT_S * 1000 });
      // in armfw's place, one that accepts each connection and closes it at the page's hello:
      // twice, so that a page that took the first for a refusal has stopped by the second
      const closing = await closingServer(u.hostname, wsPort);
      try {
        await until('two hellos closed unanswered', async () => closing.hellos >= 2);
      } finally {
        await closing.close();
      }
      const shown = await page.$eval('#msg', (e) => e.textContent);
      armfw = await startArmfw(args.armfw, [], wsPort);
      tcp = new Tcp(armfw.tcp);
      await tcp.connect();
      try {
        await page.waitForFunction(() => document.getElementById('conn').textContent === 'online' && window.pendant.role === 'operator' &&
                                   window.pendant.state !== null, { timeout: WAIT_S * 1000 });
      } catch (e) {
        const later = await page.$eval('#msg', (el) => el.textContent);
        throw new Error(`the page did not connect to armfw again in ${WAIT_S} s; it said '${shown}' after the unanswered hellos, '${later}' at the end`);
      }
    });
    if (page) await page.close();
    tcp.close();
    await stopArmfw(armfw);
    armfw = null;

    // ------------------------------------------------------------ a token file: observer, operator
    const opTok = 'operator-token-0123456789abcdef';
    const obsTok = 'observer-token-0123456789abcdef';
    const tokens = path.join(args.workdir, 'tokens');
    fs.writeFileSync(tokens, `operator ${opTok}\nobserver ${obsTok}\n`, { mode: 0o600 });
    fs.chmodSync(tokens, 0o600);
    // and a safety envelope far from the arm (a floor 2 m below the base): the page shows its checksum
    const armToml = path.join(args.workdir, 'armfw.toml');
    fs.writeFileSync(armToml, '[safety]\nplanes = [0, 0, 1, -2000]\n');
    armfw = await startArmfw(args.armfw, ['--api-tokens', tokens, '--config', armToml]);
    tcp = new Tcp(armfw.tcp);
    await tcp.connect();
    const hello = await tcp.ask('hello', { token: opTok });
    assert(hello.ok, 'the test\'s operator client: ' + JSON.stringify(hello));

    await check('a wrong token is refused', async () => {
      const p = await openPage(browser, armfw.url + '#token=wrong-token-0000000000000');
      await waitAuth(p, 'refused');
      const msg = await p.$eval('#msg', (e) => e.textContent);
      assert(/wrong token/.test(msg), `message shown: ${msg}`);
      const jogs = await p.$$eval('button.jog', (b) => b.length);
      assert(jogs === 0, 'a refused page shows jog buttons');
      await shot(p, 'pendant-refused');
      await p.close();
    });

    await check('an observer cannot jog', async () => {
      assert((await tcp.ask('take_control')).ok, 'take_control');
      assert((await tcp.ask('enable')).ok, 'enable');
      await until('the arm idle', async () => (await tcp.state()).state === 'idle');
      assert((await tcp.ask('release_control')).ok, 'release_control');
      const p = await openPage(browser, armfw.url + '#token=' + obsTok);
      await waitAuth(p, 'ok');
      const role = await p.$eval('#role', (e) => e.textContent);
      assert(role === 'role: observer', `role shown: ${role}`);
      const env = hello.safety;
      assert(env && env.enabled && /^[0-9A-F]{8}$/.test(env.checksum), 'hello\'s safety: ' + JSON.stringify(env));
      await p.waitForFunction((want) => document.querySelector('#st-safety').textContent === want,
                              { timeout: WAIT_S * 1000 }, 'safety: normal ' + env.checksum);
      const disabled = await p.$$eval('button.jog, #take, button.op', (bs) => bs.length > 0 && bs.every((b) => b.disabled));
      assert(disabled, 'an observer\'s page has enabled command buttons');
      const stops = await p.$$eval('#stop, button.any', (bs) => bs.length === 3 && bs.every((b) => !b.disabled));
      assert(stops, 'an observer\'s page cannot stop, hold or e-stop');
      const q0 = (await tcp.state()).q[0];
      await pressHold(p, '#joints button.jog[data-joint="0"][data-dir="1"]');
      await sleep(1000);  // a window for a motion that must not come
      await p.mouse.up();
      const q1 = (await tcp.state()).q[0];
      assert(Math.abs(q1 - q0) < 1e-4, `J1 moved for an observer: ${q0} -> ${q1}`);
      // and the server refuses it whatever the page does: a jog sent on the page's own connection
      const r = await p.evaluate(async (tok) => new Promise((resolve) => {
        const ws = new WebSocket('ws://' + location.host + '/');
        ws.onopen = () => {
          ws.send(JSON.stringify({ id: 1, cmd: 'hello', token: tok }));
          ws.send(JSON.stringify({ id: 2, cmd: 'take_control' }));
          ws.send(JSON.stringify({ id: 3, cmd: 'jog', joint: 0, direction: 1 }));
        };
        const got = {};
        ws.onmessage = (e) => { const m = JSON.parse(e.data); if (m.id) got[m.id] = m; if (got[3]) { ws.close(); resolve(got); } };
      }), obsTok);
      assert(r[2].error === 'forbidden' && r[3].error, `observer's take_control / jog: ${JSON.stringify(r)}`);
      await shot(p, 'pendant-observer');
      await p.close();
    });
    tcp.close();
    await stopArmfw(armfw);
    armfw = null;

    // ------------------------------------------------------------ MIT motors: temperatures
    // six virtual Damiao DM-J4340 (warning from 85 deg C, fault at 95), joint 3's standing at 88
    const mitToml = path.join(args.workdir, 'mit.toml');
    // the virtual motors' answers and watchdog given 1-2 s: they run on a thread of armfw (a loaded machine)
    let mit = 'robot = "puma560"\n[bus]\ncan = "sim"\nheartbeat_timeout_ms = 2000\nsdo_timeout_ms = 1000\n' +
              '[safety]\nfeedback_timeout_ms = 2000\n';
    for (let j = 0; j < 6; ++j) mit += `[[drive]]\nnode = ${j + 1}\nfamily = "damiao"\nmotor = "DM-J4340"\nmit_kp = 60\nmit_kd = 2\n`;
    fs.writeFileSync(mitToml, mit);
    armfw = await startArmfw(args.armfw, ['--config', mitToml, '--motor-temperature', '3:88']);
    tcp = new Tcp(armfw.tcp);
    await tcp.connect();

    await check('a joint at its warning temperature is named in the state bar', async () => {
      const s = await until('the state\'s temperatures', async () => {
        const st = await tcp.state();
        return st.temperature_warning ? st : null;
      });
      assert(s.temperature_warning === 4, `temperature_warning ${s.temperature_warning}, joint 3 is hot (4)`);
      const p = await openPage(browser, armfw.url);
      await waitAuth(p, 'ok');
      await p.waitForFunction(() => !document.querySelector('#st-temp').hidden, { timeout: WAIT_S * 1000 });
      const bar = await p.$eval('#st-temp', (e) => e.textContent);
      assert(bar === `hot: J3 ${s.temperature[2].toFixed(0)} °C`, `state bar: '${bar}', the API: J3 ${s.temperature[2]}`);
      assert(Math.abs(s.temperature[2] - 88) < 1, `J3's temperature ${s.temperature[2]}, stood at 88`);
      const cells = await p.$$eval('#joints td.temp', (tds) => tds.map((td) => [td.textContent, td.classList.contains('hot')]));
      cells.forEach(([text, hot], j) => {
        assert(text === s.temperature[j].toFixed(0) + ' °C', `J${j + 1} shows '${text}', the API ${s.temperature[j]}`);
        assert(hot === (j === 2), `J${j + 1} ${hot ? 'marked' : 'not marked'} hot`);
      });
      await shot(p, 'pendant-temperature');
      await p.close();
    });
  } finally {
    if (tcp) tcp.close();
    await browser.close();
    await stopArmfw(armfw);
  }
  const failed = results.filter((r) => r[1] !== 'ok').length;
  fs.writeFileSync(path.join(args.workdir, 'figures.txt'), figures.join('\n') + '\n');
  console.log(`${results.length - failed} of ${results.length} passed` + (shotsWanted || failed ? `; screenshots in ${shots}` : ''));
  return failed === 0 ? 0 : 1;
}

main().then((c) => process.exit(c), (e) => { console.error(e.stack || String(e)); process.exit(1); });
