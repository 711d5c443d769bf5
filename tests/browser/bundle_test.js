#!/usr/bin/env node
// SPDX-License-Identifier: Apache-2.0
// The pendant's built page (firmware/web/dist, committed so that armfw serves it without npm)
// against its sources: dist/ is rebuilt with the esbuild of firmware/web/package-lock.json into a
// temporary folder and every file must be byte for byte the committed one; and the page keeps
// its size budget (1 MB compressed, gzip -9 of every file).
// usage: node bundle_test.js [--web DIR]      (DIR: firmware/web)
// Exit status: 0 passed, 1 failed, 77 skipped (firmware/web/node_modules not installed: bash .ci/npm).
'use strict';

const fs = require('fs');
const os = require('os');
const path = require('path');
const zlib = require('zlib');
const childProcess = require('child_process');

const web = process.argv[2] === '--web' ? process.argv[3] : path.join(__dirname, '../../firmware/web');
const dist = path.join(web, 'dist');
const BUDGET = 1000 * 1000;

let gz = 0;
const files = fs.readdirSync(dist).sort();
for (const f of files) {
  const n = zlib.gzipSync(fs.readFileSync(path.join(dist, f)), { level: 9 }).length;
  gz += n;
  console.log(`${f}: ${fs.statSync(path.join(dist, f)).size} bytes, ${n} gzipped`);
}
console.log(`the page: ${gz} bytes gzipped (budget ${BUDGET})`);
if (gz > BUDGET) {
  console.error(`pendant_bundle: the page is ${gz} bytes compressed, over its budget of ${BUDGET}`);
  process.exit(1);
}
if (!fs.existsSync(path.join(web, 'node_modules', 'esbuild', 'package.json'))) {
  console.error(`pendant_bundle: SKIPPED: ${path.join(web, 'node_modules')} is not installed (run: bash .ci/npm); the size was checked`);
  process.exit(77);
}
const tmp = fs.mkdtempSync(path.join(os.tmpdir(), 'servoarm-pendant-'));
try {
  childProcess.execFileSync(process.execPath, [path.join(web, 'build.mjs'), tmp], { stdio: 'inherit' });
  const built = fs.readdirSync(tmp).sort();
  let bad = 0;
  if (built.join(' ') !== files.join(' ')) {
    console.error(`pendant_bundle: dist/ holds ${files.join(' ')}, the build makes ${built.join(' ')}`);
    bad++;
  }
  for (const f of built) {
    const a = path.join(tmp, f), b = path.join(dist, f);
    if (!fs.existsSync(b) || !fs.readFileSync(a).equals(fs.readFileSync(b))) {
      console.error(`pendant_bundle: firmware/web/dist/${f} differs from what its sources build: run (cd firmware/web && npm run build) and commit dist/`);
      bad++;
    }
  }
  if (bad) process.exit(1);
  console.log('firmware/web/dist matches its sources');
} finally {
  fs.rmSync(tmp, { recursive: true, force: true });
}
