// SPDX-License-Identifier: Apache-2.0
// Builds the pendant: src/ -> dist/ (index.html, pendant.js, pendant.css), with the esbuild of
// package-lock.json. `node build.mjs [OUTDIR]`: the page's test builds into a temporary folder and
// compares it with the committed dist/ (tests/browser/CMakeLists.txt).
import { build } from 'esbuild';
import { copyFileSync, mkdirSync } from 'node:fs';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const out = process.argv[2] || join(here, 'dist');
mkdirSync(out, { recursive: true });
await build({
  entryPoints: { pendant: join(here, 'src/main.js') },
  bundle: true,
  minify: true,
  format: 'esm',
  target: ['es2020'],
  outdir: out,
  legalComments: 'eof',
  lineLimit: 500,  // short lines: readable diffs, and line tools (head, grep) on the bundle
  // the bundle holds three.js (MIT, Three.js Authors) and uPlot (MIT, Leon Sorokin) beside the pendant's code
  banner: {
    js: '// SPDX-License-Identifier: Apache-2.0 AND MIT\n// The servoarm pendant, built by firmware/web/build.mjs from src/ with three.js (MIT, Three.js Authors) and uPlot (MIT, Leon Sorokin); do not edit (docs/pendant.md)',
    css: '/* SPDX-License-Identifier: Apache-2.0 AND MIT */',
  },
  logLevel: 'warning',
});
copyFileSync(join(here, 'src/index.html'), join(out, 'index.html'));
