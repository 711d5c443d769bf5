// SPDX-License-Identifier: Apache-2.0
// The browser pendant (docs/pendant.md): state bar and stop, arm commands, hold-to-run joint and
// Cartesian jog, feed override, program editor (checked as typed by the arm's dry run, saved to
// the controller), teach points, tools and frames, live 3D view with the running move's planned
// path, and plots, outputs, over armfw's network API on the
// port that served the page.
import './pendant.css';
import { ApiClient } from './api.js';
import { ArmView } from './view3d.js';
import { Plots } from './plots.js';

const $ = (id) => document.getElementById(id);
const wsUrl = (location.protocol === 'https:' ? 'wss://' : 'ws://') + location.host + '/';
const api = new ApiClient(wsUrl);
// What the page knows, for people and for the tests that read it.
const P = (window.pendant = { hello: null, role: null, client: 0, controller: 0, state: null, results: [], jogging: null,
                              check: null, points: [], tools: null, path: null });

// Keep-alive period of a held jog: well inside the firmware's jog deadman (console.jog_deadman_ms,
// 250 ms by default), so one late message does not stop the arm, while a released button, a
// hidden tab or a lost connection stops it within the deadman.
const JOG_KEEPALIVE_MS = 60;

function say(text) { $('msg').textContent = text; }

function report(cmd, r) {
  P.results.push({ cmd, ...r });
  if (P.results.length > 50) P.results.shift();
  if (r.error) say(cmd + ': ' + r.error + (r.message ? ': ' + r.message : ''));
  else if (cmd !== 'jog') say(cmd + ': ok');
  return r;
}

async function command(cmd, args = {}) { return report(cmd, await api.request(cmd, args)); }

// ---- stop: the button, the space bar; any client may stop (observers too) -------------------
function stopNow() {
  endJog(false);
  api.send('stop');
  say('stop sent');
}
$('stop').addEventListener('pointerdown', (e) => { e.preventDefault(); stopNow(); });
$('stop').addEventListener('click', (e) => e.preventDefault());
document.addEventListener('keydown', (e) => {
  if (e.code !== 'Space' && e.key !== ' ') return;
  const t = e.target;
  const typing = t && (t.tagName === 'TEXTAREA' || (t.tagName === 'INPUT' && ['text', 'password', 'number'].includes(t.type)));
  if (typing) return;  // a space typed into a field is text; the stop button is still one tap away
  e.preventDefault();
  stopNow();
});

// ---- connection, token, role, control -------------------------------------------------------
function canOperate() { return P.role === 'operator' && api.open; }

function refreshRole() {
  $('role').textContent = 'role: ' + (P.role || '-');
  const inControl = P.controller !== 0 && P.controller === P.client;
  $('control').textContent = 'control: ' + (P.controller === 0 ? 'nobody' : inControl ? 'this pendant' : 'client ' + P.controller);
  for (const b of document.querySelectorAll('button.op, button.jog, #take, #release, .op-input')) b.disabled = !canOperate();
  // hold and e-stop, like stop, are any authenticated client's (docs/api.md); so are a program's
  // pause and abort
  for (const b of document.querySelectorAll('button.any, button.stopper')) b.disabled = !P.role || !api.open;
  document.body.dataset.role = P.role || '';
}

// Whether a lost connection is tried again (every 2 s): once armfw has accepted the page, or
// has closed a connection before answering its hello (armfw stopping for a restart, too many
// clients: no answer is no refusal); not after a refusal (hello answered with an error: wrong
// token, protocol), nor before any connection opened (the page's first, armfw not running).
let reconnect = false;
let retry = null;
let attempt = 0;  // the newest connect(): a continuation of an older one, replaced, does nothing

function connectLater() {
  if (reconnect && retry === null) retry = setTimeout(() => { retry = null; connect(); }, 2000);
}

async function connect() {
  const mine = ++attempt;
  if (retry !== null) { clearTimeout(retry); retry = null; }
  const token = $('token').value.trim();
  if (token) sessionStorage.setItem('servoarm-token', token);
  P.role = null;
  refreshRole();
  try {
    await api.connect();
  } catch (e) {
    if (mine !== attempt) return;
    say(String(e.message || e));
    return;  // the close handler tries again when armfw accepted the page before
  }
  const h = await api.request('hello', token ? { token } : {});
  if (mine !== attempt) return;
  if (h.error === 'closed') {
    // the connection closed before armfw answered (api.js's own code, never armfw's): not a refusal
    reconnect = true;
    say('the connection closed before armfw answered: connecting again');
    connectLater();
    return;
  }
  if (h.error) {
    reconnect = false;
    report('hello', h);
    say('refused: ' + (h.error === 'unauthenticated' ? 'wrong token' : h.error) + (h.message ? ' (' + h.message + ')' : ''));
    document.body.dataset.auth = 'refused';
    api.close();
    $('conn').textContent = 'refused';
    return;
  }
  reconnect = true;
  document.body.dataset.auth = 'ok';
  P.hello = h;
  P.role = h.role;
  P.client = h.client;
  P.controller = h.controller;
  buildJoints(h.joints || []);
  buildCartesian();
  refreshRole();
  const s = await api.request('subscribe', { topic: 'state', rate_hz: 30 });
  if (s.error) report('subscribe', s);
  await api.request('subscribe', { topic: 'events' });
  say('connected to ' + (h.robot || 'the arm') + ' as ' + h.role);
  loadPoints();
  loadTools();
  scheduleCheck(0);
}

api.on('open', () => { $('conn').textContent = 'online'; });
api.on('close', () => {
  endJog(false);
  pathFor = 0;  // motions are numbered again by an armfw started again
  P.path = null;
  view.path?.([]);
  $('conn').textContent = 'offline';
  P.controller = 0;
  refreshRole();
  // a connection that is lost (armfw restarted, network gone): connect again every 2 s;
  // control is not taken again by itself
  if (reconnect && retry === null) {
    say('connection lost: connecting again');
    connectLater();
  }
});
api.on('control', (m) => { P.controller = m.holder; refreshRole(); });
$('login').addEventListener('submit', (e) => { e.preventDefault(); connect(); });
$('take').addEventListener('click', () => command('take_control').then(refreshRole));
$('release').addEventListener('click', () => command('release_control').then(refreshRole));

// ---- arm commands -------------------------------------------------------------------------------
for (const b of document.querySelectorAll('#arm button[data-cmd]')) b.addEventListener('click', () => command(b.dataset.cmd));
const speed = () => Number($('speed').value);
$('speed').addEventListener('input', () => { $('speed-out').textContent = $('speed').value; $('st-speed').textContent = 'speed: ' + speed() + ' %'; });
$('freedrive').addEventListener('click', () => command('freedrive', { on: !(P.state && P.state.freedrive) }));
$('movej-form').addEventListener('submit', (e) => {
  e.preventDefault();
  const q = $('movej-q').value.split(/[\s,]+/).filter((x) => x !== '').map(Number);
  command('movej', { q, speed_pct: speed() });
});

// ---- hold-to-run joint jog ------------------------------------------------------------------------
let jogTimer = null;

function jogKeepAlive() {
  const j = P.jogging;
  if (!j) return;
  api.request(j.cmd, { ...j.args, direction: j.direction, speed_pct: speed() }).then((r) => {
    if (r.error && P.jogging === j) { report(j.cmd, r); endJog(true); }
  });
}

/** A joint jog (`jog`, args {joint}) or a Cartesian one (`jog_cartesian`, args {axis, frame}). */
function startJog(cmd, args, direction, button) {
  if (!canOperate()) return;
  endJog(true);
  P.jogging = { cmd, args, joint: args.joint, direction, button, t0: P.state ? P.state.t : 0 };
  button.classList.add('active');
  jogKeepAlive();
  jogTimer = setInterval(jogKeepAlive, JOG_KEEPALIVE_MS);
}

/** Release: no more keep-alives, and (connected) the jog is ended at once, not at its deadman. */
function endJog(cancel) {
  if (jogTimer !== null) clearInterval(jogTimer);
  jogTimer = null;
  if (!P.jogging) return;
  P.jogging.button.classList.remove('active');
  P.jogging = null;
  if (cancel) api.send('jog_cancel');
}

const release = () => endJog(true);
window.addEventListener('pointerup', release);
window.addEventListener('pointercancel', release);
window.addEventListener('blur', release);
window.addEventListener('pagehide', release);
document.addEventListener('visibilitychange', () => { if (document.hidden) release(); });

function buildJoints(joints) {
  const tb = $('joints').querySelector('tbody');
  tb.textContent = '';
  const unit = (P.hello && P.hello.units) || { angle: 'rad', length: 'm' };
  joints.forEach((jt, j) => {
    const tr = document.createElement('tr');
    tr.dataset.joint = String(j);
    const name = document.createElement('td');
    name.textContent = 'J' + (j + 1);
    const val = document.createElement('td');
    val.className = 'val';
    val.dataset.unit = jt.type === 'prismatic' ? unit.length : unit.angle;
    val.textContent = '-';
    const temp = document.createElement('td');  // the drive's temperature, empty when it reports none
    temp.className = 'temp';
    tr.append(name, val, temp);
    for (const dir of [-1, 1]) {
      const td = document.createElement('td');
      const b = document.createElement('button');
      b.className = 'jog';
      b.textContent = dir < 0 ? '−' : '+';
      b.dataset.joint = String(j);
      b.dataset.dir = String(dir);
      b.title = 'hold to jog J' + (j + 1) + (dir < 0 ? ' negative' : ' positive');
      holdToRun(b, () => startJog('jog', { joint: j }, dir, b));
      td.append(b);
      tr.append(td);
    }
    tb.append(tr);
  });
  refreshRole();
}

function holdToRun(b, start) {
  b.addEventListener('pointerdown', (e) => { e.preventDefault(); b.setPointerCapture?.(e.pointerId); start(); });
  b.addEventListener('pointerup', release);
  b.addEventListener('lostpointercapture', release);
  b.addEventListener('contextmenu', (e) => e.preventDefault());
}

// ---- hold-to-run Cartesian jog: along / about the axes of the base, the tool or the user frame ------
function buildCartesian() {
  const tb = $('cjog-axes').querySelector('tbody');
  tb.textContent = '';
  ['x', 'y', 'z', 'rx', 'ry', 'rz'].forEach((name, axis) => {
    const tr = document.createElement('tr');
    const td0 = document.createElement('td');
    td0.textContent = name + (axis < 3 ? ' (m)' : ' (rad)');
    tr.append(td0);
    for (const dir of [-1, 1]) {
      const td = document.createElement('td');
      const b = document.createElement('button');
      b.className = 'jog cjog';
      b.textContent = dir < 0 ? '−' : '+';
      b.dataset.axis = String(axis);
      b.dataset.dir = String(dir);
      b.title = 'hold to jog ' + name + (dir < 0 ? ' negative' : ' positive');
      holdToRun(b, () => startJog('jog_cartesian', { axis, frame: $('cjog-frame').value }, dir, b));
      td.append(b);
      tr.append(td);
    }
    tb.append(tr);
  });
  refreshRole();
}

// ---- feed override: the arm's, bound both ways (the state stream's feed_pct) ---------------------
let overrideTimer = null;
$('override').addEventListener('input', () => {
  $('override-out').textContent = $('override').value;
  clearTimeout(overrideTimer);
  overrideTimer = setTimeout(async () => {
    await command('feed_override', { pct: Number($('override').value) });
    overrideTimer = null;  // the state stream shows the arm's value again
  }, 120);
});

// ---- program editor: checked as typed by the arm's dry run, the error shown on its line ----------
const progName = () => $('prog-name').value.trim() || 'editor';
const progArgs = () => ({ text: $('prog-text').value, gcode: $('prog-gcode').checked, name: progName() });
let errorLine = 0;
let currentLine = 0;
let checkTimer = null;
let checkSeq = 0;

function drawGutter() {
  const g = $('prog-gutter');
  const n = Math.max(1, $('prog-text').value.split('\n').length);
  while (g.children.length < n) {
    const d = document.createElement('div');
    d.textContent = String(g.children.length + 1);
    g.append(d);
  }
  while (g.children.length > n) g.lastChild.remove();
  for (let i = 0; i < n; ++i) {
    const d = g.children[i];
    d.classList.toggle('error', i + 1 === errorLine);
    d.classList.toggle('current', i + 1 === currentLine);
  }
  g.scrollTop = $('prog-text').scrollTop;
}

/** Show a check's or a run's answer: ok with its counts, or the error on its line. */
function showCheck(r) {
  P.check = r;
  const p = $('prog-check');
  const ours = r.file === undefined || r.file === progName() || r.file === progName() + '.arm' || r.file === progName() + '.gcode';
  errorLine = r.error && r.line && ours ? r.line : 0;
  p.dataset.line = String(errorLine);
  p.className = 'check ' + (r.error ? 'bad' : 'good');
  p.textContent = r.error ? (r.line ? 'line ' + r.line + ': ' : '') + r.error + ': ' + r.message
                          : 'checked: ' + r.summary + ', ' + Number(r.duration).toFixed(2) + ' s planned' +
                            (r.planned_steps < r.steps ? ' (the moves after step ' + r.planned_steps + ', a tool or frame definition, are planned when they run)' : '');
  const g = $('prog-gutter').children[errorLine - 1];
  if (g) g.title = p.textContent;
  drawGutter();
}

function scheduleCheck(ms = 300) {
  clearTimeout(checkTimer);
  checkTimer = setTimeout(async () => {
    if (!api.open || !P.role) return;
    if ($('prog-text').value.trim() === '') {
      errorLine = 0;
      $('prog-check').textContent = '';
      $('prog-check').dataset.line = '0';
      drawGutter();
      return;
    }
    const seq = ++checkSeq;
    const r = await api.request('program_check', progArgs());
    if (seq === checkSeq) showCheck(r);  // an older answer to an older text is not shown
  }, ms);
}
$('prog-text').addEventListener('input', () => { drawGutter(); scheduleCheck(); });
$('prog-text').addEventListener('scroll', drawGutter);
$('prog-gcode').addEventListener('change', () => scheduleCheck(0));
$('prog-name').addEventListener('input', () => scheduleCheck());
$('prog-run').addEventListener('click', async () => {
  ++checkSeq;  // the run's own check answers now
  const r = await command('program_run', progArgs());
  showCheck(r);
});
$('prog-pause').addEventListener('click', () => command('program_pause'));
$('prog-resume').addEventListener('click', () => command('resume'));
$('prog-step').addEventListener('click', () => command('program_step'));
$('prog-abort').addEventListener('click', () => command('program_abort'));
// save: into the controller's programs folder (program_save loads it first: a line it refuses is marked, nothing written)
$('prog-save').addEventListener('click', async () => {
  const r = await command('program_save', progArgs());
  if (r.error) showCheck(r);
  else say('saved as ' + r.file + ' in the programs folder');
});
drawGutter();

function showProgram(pr) {
  if (!pr) return;
  const on = pr.state !== 'idle';
  $('prog-status').textContent = on ? pr.name + ': ' + pr.state + ' at ' + pr.file + ':' + (pr.running_line || pr.line) +
                                      ' (step ' + (pr.step + 1) + ' of ' + pr.steps + ')' : 'no program runs';
  const line = on && (pr.name === progName()) ? (pr.running_line || pr.line) : 0;
  if (line !== currentLine) {
    currentLine = line;
    drawGutter();
  }
}

// ---- teach points ---------------------------------------------------------------------------------
async function loadPoints() {
  const r = await api.request('points');
  if (r.error) return;
  P.points = r.points;
  const tb = $('points').querySelector('tbody');
  tb.textContent = '';
  for (const pt of r.points) {
    const tr = document.createElement('tr');
    tr.dataset.point = pt.name;
    const name = document.createElement('td');
    name.textContent = pt.name;
    name.title = 'joints ' + pt.q.map((v) => v.toFixed(4)).join(', ') + '; tool ' + pt.tool + ', frame ' + pt.frame;
    tr.append(name);
    for (const [label, fn] of [['go', () => command('point_go', { name: pt.name, speed: speed() })],
                               ['line', () => command('point_go', { name: pt.name, line: true })],
                               ['delete', () => command('point_delete', { name: pt.name }).then(loadPoints)]]) {
      const td = document.createElement('td');
      const b = document.createElement('button');
      b.className = 'op';
      b.textContent = label;
      b.dataset.action = label;
      b.addEventListener('click', fn);
      td.append(b);
      tr.append(td);
    }
    tb.append(tr);
  }
  view.points?.(r.points.map((pt) => pt.pose.position));
  refreshRole();
}
$('teach-form').addEventListener('submit', async (e) => {
  e.preventDefault();
  const name = $('teach-name').value.trim();
  if (!name) return say('teach: give the point a name');
  const r = await command('teach', { name });
  if (!r.error) loadPoints();
});

// ---- tools and frames -------------------------------------------------------------------------------
function fillSelect(sel, list, active) {
  sel.textContent = '';
  for (const t of list) {
    const o = document.createElement('option');
    o.value = o.textContent = t.name;
    sel.append(o);
  }
  sel.value = active;
}
async function loadTools() {
  const r = await api.request('tools');
  if (r.error) return;
  P.tools = r;
  fillSelect($('tool-sel'), r.tools, r.tool);
  fillSelect($('frame-sel'), r.frames, r.frame);
  // the defined ones, each with its pose and a delete button (tool0 and base are always there)
  const tb = $('tf-list').querySelector('tbody');
  tb.textContent = '';
  for (const [kind, list] of [['tool', r.tools], ['frame', r.frames]]) {
    for (const t of list) {
      if (t.name === 'tool0' || t.name === 'base') continue;
      const tr = document.createElement('tr');
      tr.dataset[kind] = t.name;
      const name = document.createElement('td');
      name.textContent = (kind === 'tool' ? 'tool ' : 'frame ') + t.name;
      const pose = document.createElement('td');
      pose.className = 'pose';
      pose.textContent = t.position.map((v) => v.toFixed(3)).join(' ') + ' m, ' + t.rpy.map((v) => v.toFixed(3)).join(' ') + ' rad';
      const td = document.createElement('td');
      const b = document.createElement('button');
      b.className = 'op';
      b.textContent = 'delete';
      b.dataset.action = 'delete';
      b.title = 'deletes it (not the active one, not while the arm moves)';
      b.addEventListener('click', async () => { if (!(await command(kind + '_delete', { name: t.name })).error) loadTools(); });
      td.append(b);
      tr.append(name, pose, td);
      tb.append(tr);
    }
  }
  view.frames?.(r.frames);
  refreshRole();
}
// define a tool (its pose in the flange frame) or a user frame (its pose in the base frame);
// delete the selected one (the controller refuses the active one, and any change while the arm moves)
const triple = (id) => $(id).value.split(/[\s,]+/).filter((x) => x !== '').map(Number);
$('define-form').addEventListener('submit', async (e) => {
  e.preventDefault();
  const kind = $('def-kind').value;
  const r = await command(kind + '_define', { name: $('def-name').value.trim(), position: triple('def-pos'), rpy: triple('def-rpy') });
  if (!r.error) loadTools();
});
$('def-here').addEventListener('click', () => {
  const t = P.state && P.state.tool;
  if (!t) return say('no tool pose in the state yet');
  $('def-kind').value = 'frame';
  $('def-pos').value = t.position.map((v) => v.toFixed(4)).join(', ');
  $('def-rpy').value = t.rpy.map((v) => v.toFixed(4)).join(', ');
});
$('tool-sel').addEventListener('change', async () => { await command('tool_select', { name: $('tool-sel').value }); loadTools(); });
$('frame-sel').addEventListener('change', async () => { await command('frame_select', { name: $('frame-sel').value }); loadTools(); });

// ---- state bar, joints, view, plots ---------------------------------------------------------------
let view = { update() {} };
try {
  view = new ArmView($('three'));
} catch (e) {  // no WebGL here: everything but the 3D view still works
  $('three').textContent = '3D view unavailable: ' + (e.message || e);
}
P.view = view;
const plots = new Plots([
  { el: $('plot-fe'), title: 'following error', field: 'following_error', unit: 'rad / m' },
  { el: $('plot-qd'), title: 'speed', field: 'qd', unit: 'rad/s / m/s' },
  { el: $('plot-tau'), title: 'torque', field: 'torque', unit: 'N m / N' },
]);

function bits(mask, n) {
  let k = 0;
  for (let j = 0; j < n; ++j) if ((mask >> j) & 1) ++k;
  return k;
}

api.on('state', (st) => {
  P.state = st;
  const n = st.q.length;
  $('st-state').textContent = 'state: ' + st.state + (st.holding ? ' (holding)' : '');
  $('st-mode').textContent = 'mode: ' + st.mode + (st.freedrive ? ', free-drive' : '');
  $('st-homed').textContent = 'homed: ' + bits(st.homed, n) + '/' + n + (st.homing ? ' (homing)' : '');
  $('st-speed').textContent = 'speed: ' + speed() + ' %';
  if (st.feed_pct !== undefined) $('st-override').textContent = 'override: ' + st.feed_pct + ' %';
  // the envelope the arm runs with: its mode now and the checksum of [safety] hello told
  const env = (P.hello && P.hello.safety) || {};
  $('st-safety').textContent = env.enabled ? 'safety: ' + st.safety_mode + ' ' + env.checksum + (st.safety_stops ? ', ' + st.safety_stops + ' stops' : '') : 'safety: off';
  const f = st.fault || {};
  $('st-fault').textContent = f.cause && f.cause !== 'none' ? 'fault: ' + f.cause + (f.joint >= 0 ? ' J' + (f.joint + 1) : '') + (f.text ? ': ' + f.text : '') : '';
  showTemperatures(st.temperature, st.temperature_warning || 0, n);
  $('freedrive').textContent = st.freedrive ? 'free-drive off' : 'free-drive on';
  document.body.dataset.state = st.state;
  for (const tr of $('joints').querySelectorAll('tr')) {
    const j = Number(tr.dataset.joint);
    const td = tr.querySelector('.val');
    if (j < n) td.textContent = st.q[j].toFixed(4) + ' ' + td.dataset.unit;
  }
  view.update(st.frames);
  if (st.tcp && Array.isArray(st.frames) && st.frames.length) view.tool?.(st.frames[st.frames.length - 1], st.tcp.position);
  showPath(st.running);
  showOutputs(st.outputs);
  plots.push(st);
  showProgram(st.program);
  if (st.feed_pct !== undefined && document.activeElement !== $('override') && overrideTimer === null) {
    $('override').value = String(st.feed_pct);
    $('override-out').textContent = String(st.feed_pct);
  }
  if (st.active_tool !== undefined && document.activeElement !== $('tool-sel') && $('tool-sel').value !== st.active_tool &&
      P.tools && P.tools.tools.some((t) => t.name === st.active_tool)) $('tool-sel').value = st.active_tool;
  if (st.active_frame !== undefined && document.activeElement !== $('frame-sel') && $('frame-sel').value !== st.active_frame &&
      P.tools && P.tools.frames.some((t) => t.name === st.active_frame)) $('frame-sel').value = st.active_frame;
});

// ---- temperatures: each joint's in its row (deg C; null: the drive reports none); the joints at or
// above their warning temperature (the state's temperature_warning bits) named in the state bar
function showTemperatures(temps, hot, n) {
  if (!Array.isArray(temps)) return;
  const names = [];
  for (let j = 0; j < n; ++j) {
    const isHot = ((hot >> j) & 1) === 1;
    if (isHot) names.push('J' + (j + 1) + (temps[j] === null ? '' : ' ' + temps[j].toFixed(0) + ' °C'));
    const td = $('joints').querySelector(`tr[data-joint="${j}"] .temp`);
    if (!td) continue;
    td.textContent = temps[j] === null ? '' : temps[j].toFixed(0) + ' °C';
    td.classList.toggle('hot', isHot);
  }
  $('st-temp').hidden = names.length === 0;
  $('st-temp').textContent = names.length ? 'hot: ' + names.join(', ') : '';
}

// ---- digital outputs: one row each from the state's `outputs` ([[output]] order: the index `output` takes)
function showOutputs(outs) {
  if (!Array.isArray(outs)) return;
  const tb = $('outputs').querySelector('tbody');
  if (tb.children.length !== outs.length) {
    tb.textContent = '';
    outs.forEach((o, i) => {
      const tr = document.createElement('tr');
      tr.dataset.output = String(i);
      const name = document.createElement('td');
      name.textContent = i + ' ' + o.name;
      const val = document.createElement('td');
      val.className = 'val';
      tr.append(name, val);
      for (const on of [true, false]) {
        const td = document.createElement('td');
        const b = document.createElement('button');
        b.className = 'op';
        b.textContent = on ? 'on' : 'off';
        b.dataset.on = String(on);
        b.addEventListener('click', () => command('output', { index: i, on }));
        td.append(b);
        tr.append(td);
      }
      tb.append(tr);
    });
    $('no-outputs').hidden = outs.length > 0;
    refreshRole();
  }
  outs.forEach((o, i) => {
    const td = tb.children[i].querySelector('.val');
    td.textContent = o.on ? 'on' : 'off';
    td.classList.toggle('on', o.on);
  });
}

// ---- the planned path of the running move: the firmware's own, asked once when a motion starts --
let pathFor = 0;
async function showPath(running) {
  if (running === pathFor) return;
  pathFor = running;
  if (!running) {  // nothing runs: the path goes
    P.path = null;
    view.path?.([]);
    return;
  }
  const r = await api.request('planned_path', { motion: running });
  if (pathFor !== running) return;  // another motion started meanwhile
  P.path = r.error ? null : r;
  view.path?.(r.error ? [] : r.points);  // a dwell has none
}

api.on('event', (ev) => {
  // The firmware ended the jog while the button is still held (keep-alives late: a stalled
  // browser or network, or a joint at its limit): the page does not start it again by itself;
  // the operator releases and presses again.
  if (ev.kind === 'jog_stopped' && P.jogging && ev.t >= P.jogging.t0) {
    endJog(true);
    say(ev.detail + ': release and press again');
  }
  const li = document.createElement('li');
  li.textContent = ev.t.toFixed(3) + ' s ' + ev.kind + ' ' + ev.state + (ev.detail ? ': ' + ev.detail : '');
  const ol = $('event-list');
  ol.prepend(li);
  while (ol.children.length > 100) ol.lastChild.remove();
});

$('token').value = sessionStorage.getItem('servoarm-token') || new URLSearchParams(location.hash.slice(1)).get('token') || '';
refreshRole();
connect();
