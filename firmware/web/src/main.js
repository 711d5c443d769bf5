// SPDX-License-Identifier: Apache-2.0
// The browser pendant (docs/pendant.md): state bar and stop, arm commands, hold-to-run jog,
// live 3D view and plots, outputs, over armfw's network API on the port that served the page.
import './pendant.css';
import { ApiClient } from './api.js';
import { ArmView } from './view3d.js';
import { Plots } from './plots.js';

const $ = (id) => document.getElementById(id);
const wsUrl = (location.protocol === 'https:' ? 'wss://' : 'ws://') + location.host + '/';
const api = new ApiClient(wsUrl);
// What the page knows, for people and for the tests that read it.
const P = (window.pendant = { hello: null, role: null, client: 0, controller: 0, state: null, results: [], jogging: null });

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
  for (const b of document.querySelectorAll('button.op, button.jog, #take, #release')) b.disabled = !canOperate();
  // hold and e-stop, like stop, are any authenticated client's (docs/api.md)
  for (const b of document.querySelectorAll('button.any')) b.disabled = !P.role || !api.open;
  document.body.dataset.role = P.role || '';
}

async function connect() {
  const token = $('token').value.trim();
  if (token) sessionStorage.setItem('servoarm-token', token);
  P.role = null;
  refreshRole();
  try {
    await api.connect();
  } catch (e) {
    say(String(e.message || e));
    return;  // the close handler tries again when the page was connected before
  }
  const h = await api.request('hello', token ? { token } : {});
  if (h.error) {
    report('hello', h);
    say('refused: ' + (h.error === 'unauthenticated' ? 'wrong token' : h.error) + (h.message ? ' (' + h.message + ')' : ''));
    document.body.dataset.auth = 'refused';
    api.close();
    $('conn').textContent = 'refused';
    return;
  }
  document.body.dataset.auth = 'ok';
  P.hello = h;
  P.role = h.role;
  P.client = h.client;
  P.controller = h.controller;
  buildJoints(h.joints || []);
  refreshRole();
  const s = await api.request('subscribe', { topic: 'state', rate_hz: 30 });
  if (s.error) report('subscribe', s);
  await api.request('subscribe', { topic: 'events' });
  say('connected to ' + (h.robot || 'the arm') + ' as ' + h.role);
}

api.on('open', () => { $('conn').textContent = 'online'; });
let retry = null;
api.on('close', () => {
  endJog(false);
  $('conn').textContent = 'offline';
  P.controller = 0;
  refreshRole();
  // a connection that was accepted and is lost (armfw restarted, network gone): connect again
  // every 2 s; control is not taken again by itself
  if (document.body.dataset.auth === 'ok' && retry === null) {
    say('connection lost: connecting again');
    retry = setTimeout(() => { retry = null; connect(); }, 2000);
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
for (const b of document.querySelectorAll('#out-form button[data-out]'))
  b.addEventListener('click', () => command('output', { index: Number($('out-index').value), on: b.dataset.out === '1' }));

// ---- hold-to-run joint jog ------------------------------------------------------------------------
let jogTimer = null;

function jogKeepAlive() {
  const j = P.jogging;
  if (!j) return;
  api.request('jog', { joint: j.joint, direction: j.direction, speed_pct: speed() }).then((r) => {
    if (r.error && P.jogging === j) { report('jog', r); endJog(true); }
  });
}

function startJog(joint, direction, button) {
  if (!canOperate()) return;
  endJog(true);
  P.jogging = { joint, direction, button, t0: P.state ? P.state.t : 0 };
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
    tr.append(name, val);
    for (const dir of [-1, 1]) {
      const td = document.createElement('td');
      const b = document.createElement('button');
      b.className = 'jog';
      b.textContent = dir < 0 ? '−' : '+';
      b.dataset.joint = String(j);
      b.dataset.dir = String(dir);
      b.title = 'hold to jog J' + (j + 1) + (dir < 0 ? ' negative' : ' positive');
      b.addEventListener('pointerdown', (e) => { e.preventDefault(); b.setPointerCapture?.(e.pointerId); startJog(j, dir, b); });
      b.addEventListener('pointerup', release);
      b.addEventListener('lostpointercapture', release);
      b.addEventListener('contextmenu', (e) => e.preventDefault());
      td.append(b);
      tr.append(td);
    }
    tb.append(tr);
  });
  refreshRole();
}

// ---- state bar, joints, view, plots ---------------------------------------------------------------
let view = { update() {} };
try {
  view = new ArmView($('three'));
} catch (e) {  // no WebGL here: everything but the 3D view still works
  $('three').textContent = '3D view unavailable: ' + (e.message || e);
}
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
  const f = st.fault || {};
  $('st-fault').textContent = f.cause && f.cause !== 'none' ? 'fault: ' + f.cause + (f.joint >= 0 ? ' J' + (f.joint + 1) : '') + (f.text ? ': ' + f.text : '') : '';
  $('freedrive').textContent = st.freedrive ? 'free-drive off' : 'free-drive on';
  document.body.dataset.state = st.state;
  for (const tr of $('joints').querySelectorAll('tr')) {
    const j = Number(tr.dataset.joint);
    const td = tr.querySelector('.val');
    if (j < n) td.textContent = st.q[j].toFixed(4) + ' ' + td.dataset.unit;
  }
  view.update(st.frames);
  plots.push(st);
});

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
