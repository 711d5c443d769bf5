#!/usr/bin/env node
// SPDX-License-Identifier: Apache-2.0
// armfw's Foxglove WebSocket server and MCAP recordings against independent clients:
// @foxglove/ws-protocol's FoxgloveClient (live data) and @mcap/core's readers (recordings),
// both from npm (package-lock.json beside this file; installed by bash .ci/npm).
//
// Against `armfw --sim --foxglove-port 0 --record-dir DIR` (its console on stdin):
//  live:  serverInfo; the four channels advertised with their JSON schemas; every message of a
//         subscription decodes (JSON) and has its schema's fields; /tf holds every link's
//         transform, chained from world to tool; the rates measured over a window are within
//         [0.5, 1.15] x the configured rates (low bound loose: a busy machine delays the
//         publisher, never speeds it up) while another client subscribed to everything does not
//         read; faults and events arrive as foxglove.Log.
//  MCAP:  `record mcap rate=1000` for RECORD_S seconds (a few seconds here, not the
//         10 minutes of a soak run: pass --record-s 600 for that) then at 100 Hz: the indexed
//         reader reads the summary; every message decodes; log times increase on every channel;
//         state frames are consecutive cycles (step 1 at 1 kHz, 10 at 100 Hz) with none missed
//         (the control thread keeps 2 s of cycles for the recorder), and any missed cycle would
//         be reported (counted, never silent: frames + missed = the span); the
//         robot description and events are in; a copy cut in the middle of a chunk reads in
//         the streaming reader up to its last whole chunk.
// Exit 0 pass, 1 fail, 77 skipped (node_modules missing).
"use strict";
const { spawn } = require("child_process");
const fs = require("fs");
const path = require("path");
const os = require("os");

const args = process.argv.slice(2);
const opt = (name, def) => {
  const i = args.indexOf(name);
  return i >= 0 ? args[i + 1] : def;
};
const armfw = opt("--armfw");
const recordS = Number(opt("--record-s", "4"));
let ws, FoxgloveClient, mcap;
try {
  ws = require("ws");
  ({ FoxgloveClient } = require("@foxglove/ws-protocol"));
  mcap = require("@mcap/core");
} catch (e) {
  console.error(`foxglove_test: SKIPPED: npm packages missing (${e.message.split("\n")[0]}): run bash .ci/npm`);
  process.exit(77);
}

let failures = 0;
const check = (ok, what) => {
  console.log(`${ok ? "ok  " : "FAIL"} ${what}`);
  if (!ok) failures++;
};
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

async function main() {
  const dir = fs.mkdtempSync(path.join(os.tmpdir(), "servoarm_fox_"));
  // the virtual drives answer bring-up's SDOs from a thread of armfw: on a loaded machine (the
  // sanitizer tree beside a browser test) that took longer than the default 100 ms, so 1 s here
  const cfg = path.join(dir, "armfw.toml");
  fs.writeFileSync(cfg, "[bus]\nsdo_timeout_ms = 1000\n");
  const fw = spawn(armfw, ["--sim", "--config", cfg, "--foxglove-port", "0", "--record-dir", dir, "--api-tcp", "0"],
                   { stdio: ["pipe", "pipe", "pipe"] });
  let out = "", err = "";
  fw.stdout.on("data", (d) => (out += d));
  fw.stderr.on("data", (d) => (err += d));
  const send = (line) => fw.stdin.write(line + "\n");
  const answer = async (line, pattern, ms = 20000) => {
    const from = out.length;
    send(line);
    for (let t = 0; t < ms; t += 20) {
      const m = out.slice(from).match(pattern);
      if (m) return m;
      await sleep(20);
    }
    throw new Error(`no answer to '${line}' matching ${pattern}: ${out.slice(from)}`);
  };
  let port;
  for (let t = 0; t < 30000 && !port; t += 50) {
    const m = err.match(/foxglove: ws:\/\/127\.0\.0\.1:(\d+)/);
    if (m) port = Number(m[1]);
    else await sleep(50);
  }
  check(port > 0, `armfw prints where the Foxglove server listens (port ${port})`);
  if (!port) throw new Error(err);

  // ---------------- live data ----------------
  const client = new FoxgloveClient({ ws: new ws.WebSocket(`ws://127.0.0.1:${port}`, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]) });
  const advertised = new Promise((res) => client.on("advertise", res));
  const info = await new Promise((res, rej) => {
    client.on("serverInfo", res);
    client.on("error", rej);
  });
  check(typeof info.name === "string" && info.name.startsWith("servoarm"), `serverInfo names the server (${info.name})`);
  const channels = await advertised;
  const byTopic = Object.fromEntries(channels.map((c) => [c.topic, c]));
  const want = { "/arm/state": "servoarm.State", "/tf": "foxglove.FrameTransforms", "/tool_pose": "foxglove.PoseInFrame", "/events": "foxglove.Log" };
  for (const [topic, schema] of Object.entries(want)) {
    const c = byTopic[topic];
    check(c && c.schemaName === schema && c.encoding === "json" && c.schemaEncoding === "jsonschema" && JSON.parse(c.schema).type === "object",
          `${topic} advertised as ${schema}, JSON, with a JSON schema`);
  }
  const got = {};
  const decodeErrors = [];
  const subTopic = {};
  client.on("message", ({ subscriptionId, data }) => {
    const topic = subTopic[subscriptionId];
    try {
      const m = JSON.parse(new TextDecoder().decode(data));
      (got[topic] = got[topic] || []).push({ at: Date.now(), m });
    } catch (e) {
      decodeErrors.push(`${topic}: ${e.message}`);
    }
  });
  for (const topic of Object.keys(want)) subTopic[client.subscribe(byTopic[topic].id)] = topic;
  // A client that subscribes to everything and never reads: it loses its own messages; the
  // rates measured below on the reading client are its rates with this one connected.
  const slow = new ws.WebSocket(`ws://127.0.0.1:${port}`, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
  await new Promise((res) => slow.on("open", res));
  slow.send(JSON.stringify({ op: "subscribe", subscriptions: channels.map((c, i) => ({ id: i, channelId: c.id })) }));
  slow._socket.pause();
  await sleep(500);  // settle
  for (const k of Object.keys(got)) got[k] = [];
  const window = 3000;
  const t0 = Date.now();
  await sleep(window);
  const counts = Object.fromEntries(Object.keys(want).map((k) => [k, (got[k] || []).filter((x) => x.at - t0 <= window).length]));
  const rate = (k) => counts[k] / (window / 1000);
  check(decodeErrors.length === 0, `every message decodes as JSON (${decodeErrors.length} did not${decodeErrors.length ? ": " + decodeErrors[0] : ""})`);
  for (const [k, hz] of [["/arm/state", 50], ["/tool_pose", 50], ["/tf", 30]])
    check(rate(k) >= 0.5 * hz && rate(k) <= 1.15 * hz, `${k}: ${rate(k).toFixed(1)} messages/s, configured ${hz} (foxglove defaults)`);
  const st = got["/arm/state"].at(-1).m;
  check(Array.isArray(st.q) && st.q.length === 6 && Number.isInteger(st.cycle), `/arm/state has the joints (${st.q.length}) and the cycle`);
  const tf = got["/tf"].at(-1).m.transforms;
  // world -> base -> link1..link6 -> tool: a chain (each parent is the child before it)
  const chained = tf.every((t, i) => i === 0 ? t.parent_frame_id === "world" : t.parent_frame_id === tf[i - 1].child_frame_id);
  check(tf.length === 8 && chained && tf.at(-1).child_frame_id === "tool", `/tf: ${tf.length} transforms chained world -> ${tf.map((t) => t.child_frame_id).join(" -> ")}`);
  const unit = tf.every((t) => Math.abs(Math.hypot(t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w) - 1) < 1e-9);
  check(unit, "/tf rotations are unit quaternions");
  // the tool pose = the chained transforms' product
  const mul = (a, b) => ({  // (q, p) composition
    q: { w: a.q.w * b.q.w - a.q.x * b.q.x - a.q.y * b.q.y - a.q.z * b.q.z, x: a.q.w * b.q.x + a.q.x * b.q.w + a.q.y * b.q.z - a.q.z * b.q.y,
         y: a.q.w * b.q.y - a.q.x * b.q.z + a.q.y * b.q.w + a.q.z * b.q.x, z: a.q.w * b.q.z + a.q.x * b.q.y - a.q.y * b.q.x + a.q.z * b.q.w },
    p: (() => {  // a.p + R(a.q) b.p
      const { w, x, y, z } = a.q, v = b.p;
      const r = [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y), 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)];
      return { x: a.p.x + r[0] * v.x + r[1] * v.y + r[2] * v.z, y: a.p.y + r[3] * v.x + r[4] * v.y + r[5] * v.z, z: a.p.z + r[6] * v.x + r[7] * v.y + r[8] * v.z };
    })(),
  });
  let acc = { q: { w: 1, x: 0, y: 0, z: 0 }, p: { x: 0, y: 0, z: 0 } };
  for (const t of tf) acc = mul(acc, { q: t.rotation, p: t.translation });
  const pose = got["/tool_pose"].at(-1).m.pose.position;
  check(Math.hypot(acc.p.x - pose.x, acc.p.y - pose.y, acc.p.z - pose.z) < 1e-6,
        `the transforms' product is /tool_pose (${pose.x.toFixed(4)} ${pose.y.toFixed(4)} ${pose.z.toFixed(4)} m)`);
  check(Math.hypot(pose.x - st.tool.position[0], pose.y - st.tool.position[1], pose.z - st.tool.position[2]) < 1e-3,
        "/tool_pose agrees with /arm/state's tool position");

  // ---------------- MCAP at 1 kHz, with events ----------------
  const rec1 = await answer("record mcap rate=1000", /ok recording MCAP at (\S+) Hz to (\S+)/);
  await answer("enable", /\nok[^\n]*\n|^ok[^\n]*\n/);
  await answer("home", /homing done/);
  await answer("movej 10 -40 170 0 40 0", /\nok[^\n]*\n|^ok[^\n]*\n/);
  await sleep(recordS * 1000);
  const stop1 = await answer("record mcap stop", /ok recorded MCAP (\S+): (\d+) files, (\d+) frames at (\S+) Hz, (\d+) missed, (\d+) events/);
  const logs = got["/events"] || [];
  check(logs.length > 0 && logs.every((x) => [1, 2, 3, 4, 5].includes(x.m.level) && typeof x.m.message === "string" && x.m.timestamp.sec > 0),
        `/events: ${logs.length} foxglove.Log messages (enable, homing, the move): ${logs.length ? logs[0].m.message : ""}`);
  await verify(rec1[2], 1, stop1, true);
  // ---------------- MCAP at 100 Hz ----------------
  const rec2 = await answer("record mcap rate=100", /ok recording MCAP at (\S+) Hz to (\S+)/);
  await sleep(2000);
  const stop2 = await answer("record mcap stop", /ok recorded MCAP (\S+): (\d+) files, (\d+) frames at (\S+) Hz, (\d+) missed, (\d+) events/);
  check(rec2[2] !== rec1[2], `a second recording is a new file (${path.basename(rec2[2])})`);
  await verify(rec2[2], 10, stop2, false);
  // ---------------- the same through the network API ----------------
  const apiPort = Number(err.match(/api: WebSocket port -?\d+, TCP port (\d+)/)[1]);
  const sock = require("net").connect(apiPort, "127.0.0.1");
  let apiIn = "";
  sock.on("data", (d) => (apiIn += d));
  const api = async (msg) => {
    sock.write(JSON.stringify(msg) + "\n");
    for (let t = 0; t < 10000; t += 20) {
      const line = apiIn.split("\n").find((l) => l.includes(`"id":${msg.id}`));
      if (line) return JSON.parse(line);
      await sleep(20);
    }
    throw new Error(`no API answer to ${JSON.stringify(msg)}`);
  };
  await api({ id: 1, cmd: "hello" });
  const a1 = await api({ id: 2, cmd: "record_mcap", rate_hz: 500 });
  check(a1.ok === true && typeof a1.file === "string" && a1.rate_hz === 500, `API record_mcap starts: ${JSON.stringify(a1)}`);
  await sleep(1000);
  const a2 = await api({ id: 3, cmd: "record_mcap", stop: true });
  check(a2.ok === true && a2.file === a1.file && a2.frames > 300 && a2.frames + a2.missed >= 450,
        `API record_mcap stop: ${a2.frames} frames, ${a2.missed} missed`);
  await verify(a1.file, 2, [null, null, String(a2.files), String(a2.frames), null, String(a2.missed)], false);
  sock.destroy();
  const refused = await answer("record mcap rate=5000", /\n?(error[^\n]*)\n/);
  check(/rate .*outside/.test(refused[1]), `a rate above the control rate is refused: ${refused[1]}`);

  client.close();
  slow.terminate();
  send("quit");
  fw.stdin.end();
  await new Promise((r) => { fw.on("exit", r); setTimeout(() => { fw.kill("SIGTERM"); }, 5000); });
  fs.rmSync(dir, { recursive: true, force: true });
}

// The files of one recording (`record mcap stop` said how many: a new file begins at
// record.max_file_mb): the first one and the ones after it by name.
function recordingFiles(first, count) {
  const dir = path.dirname(first);
  const all = fs.readdirSync(dir).filter((f) => f.endsWith(".mcap")).sort();
  const i = all.indexOf(path.basename(first));
  return all.slice(i, i + count).map((f) => path.join(dir, f));
}

async function verify(first, step, stop, cut) {
  const files = recordingFiles(first, Number(stop[2] || 1));
  const per = {};
  let bad = 0, nonMono = 0, r = null, bytes = null, described = 0;
  const lastT = {};
  for (const file of files) {
    const fileBytes = fs.readFileSync(file);
    const readable = { size: async () => BigInt(fileBytes.length), read: async (o, n) => fileBytes.subarray(Number(o), Number(o + n)) };
    const fr = await mcap.McapIndexedReader.Initialize({ readable });
    if (r === null) { r = fr; bytes = fileBytes; }
    const topics = new Map([...fr.channelsById.values()].map((c) => [c.id, c.topic]));
    const schemas = [...fr.schemasById.values()];
    check(schemas.every((s) => s.encoding === "jsonschema" && JSON.parse(new TextDecoder().decode(s.data)).type === "object"),
          `${path.basename(file)}: ${schemas.length} JSON schemas`);
    let inFile = 0;
    for await (const m of fr.readMessages()) {
      const topic = topics.get(m.channelId);
      let j;
      try { j = JSON.parse(new TextDecoder().decode(m.data)); } catch (e) { bad++; continue; }
      if (lastT[topic] !== undefined && m.logTime < lastT[topic]) nonMono++;  // events of one cycle share its time
      lastT[topic] = m.logTime;
      if (topic === "/robot_description") {
        described++;
        if (j.rows.length >= 6) continue;
      }
      (per[topic] = per[topic] || []).push(j);
      ++inFile;
    }
    check(fr.statistics && Number(fr.statistics.messageCount) === inFile + 1,
          `${path.basename(file)}: the summary's statistics count every message (${fr.statistics && fr.statistics.messageCount})`);
  }
  const states = per["/arm/state"] || [];
  check(bad === 0, `every message of ${files.length} file(s) decodes (${Object.entries(per).map(([k, v]) => `${k} ${v.length}`).join(", ")})`);
  check(nonMono === 0, `log times never decrease on any channel (${nonMono} did)`);
  check(described === files.length && !per["/robot_description"], `the robot description (its DH rows) in each of the ${files.length} file(s)`);
  let gaps = 0, wrongStep = 0;
  for (let i = 1; i < states.length; i++) {
    const d = states[i].cycle - states[i - 1].cycle;
    if (d % step !== 0 || d <= 0) wrongStep++;
    else gaps += d / step - 1;
  }
  const frames = Number(stop[3]), missed = Number(stop[5]);
  check(states.length === frames && wrongStep === 0, `${states.length} state frames (record mcap stop said ${frames}), every one a multiple of ${step} cycles apart`);
  const span = (states.at(-1).cycle - states[0].cycle) / step + 1;
  // every cycle due is written or reported missed: nothing is lost silently; and the control
  // thread's sample ring (2 s at 1 kHz) keeps every cycle for a recorder kept off the CPU
  check(gaps <= missed && states.length + gaps === span, `frames ${states.length} + gaps ${gaps} = span ${span} cycles; missed reported ${missed}`);
  check(missed === 0 && gaps === 0, `every cycle due is in the file (${missed} missed, ${gaps} gaps)`);
  console.log(`     ${path.basename(first)} (${files.length} file(s)): ${states.length} of ${span} due cycles written (${(100 * states.length / span).toFixed(2)} %), ${missed} missed`);
  check((per["/arm/setpoint"] || []).length === states.length, "a setpoint message per state frame");
  if (step === 1) check((per["/arm/events"] || []).length > 0, `events recorded (${(per["/arm/events"] || []).length})`);
  if (!cut) return;
  // A copy cut in the middle of its second-last chunk: the streaming reader reads up to the last whole chunk.
  const chunks = r.chunkIndexes;
  check(chunks.length >= 3, `${chunks.length} chunks`);
  const c = chunks[chunks.length - 2];
  const cutAt = Number(c.chunkStartOffset + c.chunkLength / 2n);
  const sr = new mcap.McapStreamReader();
  sr.append(bytes.subarray(0, cutAt));
  let n = 0, rec, threw = "";
  try {
    while ((rec = sr.nextRecord())) if (rec.type === "Message") n++;
  } catch (e) { threw = e.message; }
  // the messages of the chunks wholly before the cut (the whole file streamed, chunks counted)
  const full = new mcap.McapStreamReader({ includeChunks: true });
  full.append(bytes);
  let expect = 0, seen = 0;
  for (let x; (x = full.nextRecord()); ) {
    if (x.type === "Chunk") seen++;
    else if (x.type === "Message" && seen <= chunks.length - 2) expect++;
  }
  check(threw === "" && n === expect && n > 0 && !sr.done(), `cut mid-chunk at byte ${cutAt} of ${bytes.length}: ${n} messages read (the whole chunks before it hold ${expect})${threw ? ": " + threw : ""}`);
}

main().then(
  () => {
    console.log(failures ? `foxglove_test: ${failures} FAILED` : "foxglove_test: all passed");
    process.exit(failures ? 1 : 0);
  },
  (e) => {
    console.error("foxglove_test: FAILED:", e.stack || e);
    process.exit(1);
  },
);
