// SPDX-License-Identifier: Apache-2.0
// Live plots of the state stream, one per quantity, one series per joint: following error,
// measured joint speed and measured torque, the last `seconds` of samples in the API's units.
import uPlot from 'uplot';
import 'uplot/dist/uPlot.min.css';

const COLORS = ['#2563eb', '#dc2626', '#16a34a', '#9333ea', '#ea580c', '#0891b2', '#4b5563', '#ca8a04'];

export class Plots {
  constructor(specs, seconds = 10) {
    this.specs = specs;  // [{el, title, field, unit}]
    this.seconds = seconds;
    this.plots = [];
    this.data = [];
    this.n = 0;
    this.last = 0;
  }

  setup(n) {
    this.n = n;
    for (const p of this.plots) p.destroy();
    this.plots = [];
    this.data = [];
    for (const s of this.specs) {
      const series = [{}];
      for (let j = 0; j < n; ++j) series.push({ label: 'J' + (j + 1), stroke: COLORS[j % COLORS.length], width: 1.5 });
      const width = Math.max(260, s.el.parentElement.clientWidth - 16);
      const opts = { title: s.title + ' (' + s.unit + ')', width, height: 170, series,
                     scales: { x: { time: false } }, axes: [{ label: 's' }, {}], legend: { live: false } };
      const d = [[]];
      for (let j = 0; j < n; ++j) d.push([]);
      this.data.push(d);
      this.plots.push(new uPlot(opts, d, s.el));
    }
  }

  push(st) {
    if (!Array.isArray(st.q)) return;
    if (st.q.length !== this.n) this.setup(st.q.length);
    this.specs.forEach((s, k) => {
      const d = this.data[k];
      d[0].push(st.t);
      const v = st[s.field] || [];
      for (let j = 0; j < this.n; ++j) d[j + 1].push(v[j] ?? null);
      while (d[0].length > 2 && d[0][d[0].length - 1] - d[0][0] > this.seconds) for (const a of d) a.shift();
    });
    const now = performance.now();
    if (now - this.last > 100) {  // redraw at 10 Hz whatever the stream's rate
      this.last = now;
      this.plots.forEach((p, k) => p.setData(this.data[k]));
    }
  }
}
