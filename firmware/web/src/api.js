// SPDX-License-Identifier: Apache-2.0
// The pendant's client of armfw's network API (docs/api.md): one WebSocket to the port that
// served the page, requests with ids answered by promises, the state, event and control
// streams handed to listeners.

export class ApiClient {
  constructor(url) {
    this.url = url;
    this.ws = null;
    this.nextId = 1;
    this.pending = new Map();
    this.listeners = { state: [], event: [], control: [], open: [], close: [] };
  }

  on(topic, fn) { this.listeners[topic].push(fn); }

  emit(topic, msg) { for (const fn of this.listeners[topic]) fn(msg); }

  get open() { return this.ws !== null && this.ws.readyState === WebSocket.OPEN; }

  connect() {
    this.close();
    return new Promise((resolve, reject) => {
      const ws = new WebSocket(this.url);
      this.ws = ws;
      let opened = false;
      ws.onopen = () => { opened = true; this.emit('open', {}); resolve(); };
      ws.onerror = () => { if (!opened) reject(new Error('cannot connect to ' + this.url)); };
      ws.onclose = () => {
        // the requests sent on this socket get an answer: error 'closed', this client's own
        // code (armfw has none by that name) for "no answer came"; a socket replaced by
        // connect() or closed by close() is not reported as a lost connection
        for (const [id, p] of this.pending) {
          if (p.ws !== ws) continue;
          p.resolve({ error: 'closed', message: 'the connection closed' });
          this.pending.delete(id);
        }
        if (!opened) reject(new Error('cannot connect to ' + this.url));
        if (this.ws !== ws) return;
        this.ws = null;
        this.emit('close', {});
      };
      ws.onmessage = (ev) => {
        let m;
        try { m = JSON.parse(ev.data); } catch { return; }
        if (m.topic === 'state' || m.topic === 'event' || m.topic === 'control') {
          this.emit(m.topic, m);
        } else if (m.id !== undefined && this.pending.has(m.id)) {
          this.pending.get(m.id).resolve(m);
          this.pending.delete(m.id);
        }
      };
    });
  }

  close() {
    if (this.ws) {
      const ws = this.ws;
      this.ws = null;
      ws.close();
    }
  }

  /** Send a request; resolves with its result (ok or error; error 'closed' when the connection
   *  closed before an answer, or was not open), never rejects. */
  request(cmd, args = {}) {
    if (!this.open) return Promise.resolve({ error: 'closed', message: 'not connected' });
    const id = this.nextId++;
    return new Promise((resolve) => {
      this.pending.set(id, { resolve, ws: this.ws });
      this.ws.send(JSON.stringify({ id, cmd, ...args }));
    });
  }

  /** Fire and forget (keep-alives, stops on the way out). */
  send(cmd, args = {}) {
    if (this.open) this.ws.send(JSON.stringify({ id: this.nextId++, cmd, ...args }));
  }
}
