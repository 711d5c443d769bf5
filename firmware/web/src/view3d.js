// SPDX-License-Identifier: Apache-2.0
// The live 3D view: the links drawn between the frame origins the state stream carries
// (`frames`: base, each DH row, flange), the active tool (to the state's `tcp`), the planned path of the running move (from
// `planned_path`), the taught points (their tool points, from `points`) and the user frames
// (from `tools`); the page computes no kinematics.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

export class ArmView {
  constructor(el) {
    this.el = el;
    this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    el.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0xe5e7eb);
    this.camera = new THREE.PerspectiveCamera(45, 1, 0.01, 100);
    this.camera.up.set(0, 0, 1);
    this.camera.position.set(1.6, -1.6, 1.2);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.target.set(0, 0, 0.3);
    this.controls.update();
    const grid = new THREE.GridHelper(2, 20, 0x9ca3af, 0xd1d5db);
    grid.rotation.x = Math.PI / 2;  // the base's x-y plane (z up)
    this.scene.add(grid);
    this.scene.add(new THREE.AxesHelper(0.2));
    this.scene.add(new THREE.AmbientLight(0xffffff, 0.7));
    const sun = new THREE.DirectionalLight(0xffffff, 0.9);
    sun.position.set(2, -1, 3);
    this.scene.add(sun);
    this.links = new THREE.Group();
    this.scene.add(this.links);
    this.jointMat = new THREE.MeshStandardMaterial({ color: 0x2563eb });
    this.linkMat = new THREE.MeshStandardMaterial({ color: 0x6b7280 });
    this.toolMat = new THREE.MeshStandardMaterial({ color: 0xf59e0b });
    this.count = -1;
    this.dirty = true;
    this.drawn = {};  // what update() and tool() last drew, flat, for changed()
    new ResizeObserver(() => this.resize()).observe(el);
    this.resize();
    this.controls.addEventListener('change', () => { this.dirty = true; });
    // at most 20 frames a second: drawing shares the page's thread with the jog keep-alives
    let last = 0;
    const loop = (t) => {
      if (this.dirty && t - last >= 50) { this.renderer.render(this.scene, this.camera); this.dirty = false; last = t; }
      requestAnimationFrame(loop);
    };
    requestAnimationFrame(loop);
  }

  /** Whether `values` (numbers, m) differ by 10 um or more from what `key` last drew; if so they
   *  are what it draws now. The state stream (30 Hz) repeats an arm at rest: drawn
   *  again each time, SwiftShader's WebGL kept half a core busy on a page nobody touched. */
  changed(key, values) {
    const prev = this.drawn[key];
    if (prev && prev.length === values.length && values.every((v, i) => Math.abs(v - prev[i]) < 1e-5)) return false;
    this.drawn[key] = values;
    return true;
  }

  /** The taught points: a marker at each tool point (positions [x, y, z] in m, base frame). */
  points(list) {
    if (!this.pointGroup) {
      this.pointGroup = new THREE.Group();
      this.scene.add(this.pointGroup);
      this.pointMat = new THREE.MeshStandardMaterial({ color: 0x16a34a });
    }
    this.pointGroup.clear();
    for (const p of list) {
      const m = new THREE.Mesh(new THREE.OctahedronGeometry(0.018), this.pointMat);
      m.position.set(p[0], p[1], p[2]);
      this.pointGroup.add(m);
    }
    this.dirty = true;
  }

  /** The planned path of the running move: a line through its tool points ([x, y, z] in m, base
   *  frame, from the API's planned_path), its goal marked; an empty list removes it. */
  path(points) {
    if (!this.pathLine) {
      this.pathLine = new THREE.Line(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: 0xdb2777 }));
      this.pathDots = new THREE.Points(new THREE.BufferGeometry(), new THREE.PointsMaterial({ color: 0xdb2777, size: 5, sizeAttenuation: false }));
      this.pathGoal = new THREE.Mesh(new THREE.SphereGeometry(0.012, 12, 8), new THREE.MeshStandardMaterial({ color: 0xdb2777 }));
      this.scene.add(this.pathLine, this.pathDots, this.pathGoal);
    }
    const ok = Array.isArray(points) && points.length >= 2;
    this.pathLine.geometry.dispose();
    this.pathLine.geometry = new THREE.BufferGeometry().setAttribute('position', new THREE.Float32BufferAttribute(ok ? points.flat() : [], 3));
    this.pathDots.geometry = this.pathLine.geometry;  // the samples themselves, a dot each
    this.pathLine.visible = this.pathDots.visible = this.pathGoal.visible = ok;
    if (ok) this.pathGoal.position.set(...points[points.length - 1]);
    this.dirty = true;
  }

  /** The user frames: axes at each frame's origin, turned by its roll, pitch, yaw (base frame). */
  frames(list) {
    if (!this.frameGroup) {
      this.frameGroup = new THREE.Group();
      this.scene.add(this.frameGroup);
    }
    this.frameGroup.clear();
    for (const f of list) {
      if (f.name === 'base') continue;  // the base's axes are drawn already
      const a = new THREE.AxesHelper(0.15);
      a.position.set(f.position[0], f.position[1], f.position[2]);
      a.rotation.set(f.rpy[0], f.rpy[1], f.rpy[2], 'ZYX');  // R = Rz(yaw) Ry(pitch) Rx(roll)
      this.frameGroup.add(a);
    }
    this.dirty = true;
  }

  resize() {
    const w = this.el.clientWidth || 300, h = this.el.clientHeight || 300;
    this.renderer.setSize(w, h, false);
    this.renderer.domElement.style.width = '100%';
    this.renderer.domElement.style.height = '100%';
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.dirty = true;
  }

  build(n, scale) {
    this.links.clear();
    this.spheres = [];
    this.rods = [];
    const r = Math.max(0.01, 0.025 * scale);
    for (let i = 0; i < n; ++i) {
      const s = new THREE.Mesh(new THREE.SphereGeometry(i === n - 1 ? r * 0.8 : r, 16, 12), i === n - 1 ? this.toolMat : this.jointMat);
      this.links.add(s);
      this.spheres.push(s);
      if (i > 0) {
        const c = new THREE.Mesh(new THREE.CylinderGeometry(r * 0.55, r * 0.55, 1, 12), this.linkMat);
        this.links.add(c);
        this.rods.push(c);
      }
    }
    this.count = n;
  }

  /** The active tool: a rod from the flange (the last frame) to its point `tcp` ([x, y, z] in m,
   *  the state's `tcp`), hidden when the tool is the flange itself (tool0). */
  tool(flange, tcp) {
    if (!this.changed('tool', [...flange, ...tcp])) return;
    if (!this.toolRod) {
      this.toolRod = new THREE.Mesh(new THREE.CylinderGeometry(0.006, 0.006, 1, 8), this.toolMat);
      this.toolTip = new THREE.Mesh(new THREE.ConeGeometry(0.012, 0.03, 12), this.toolMat);
      this.scene.add(this.toolRod, this.toolTip);
    }
    const a = new THREE.Vector3(...flange), b = new THREE.Vector3(...tcp);
    const dir = b.clone().sub(a);
    const len = dir.length();
    this.toolRod.visible = this.toolTip.visible = len > 1e-4;
    if (len > 1e-4) {
      const q = new THREE.Quaternion().setFromUnitVectors(new THREE.Vector3(0, 1, 0), dir.clone().normalize());
      this.toolRod.position.copy(a).addScaledVector(dir, 0.5);
      this.toolRod.scale.set(1, len, 1);
      this.toolRod.quaternion.copy(q);
      this.toolTip.position.copy(b).addScaledVector(dir, -0.015 / len);  // its apex at the tool point
      this.toolTip.quaternion.copy(q);
    }
    this.dirty = true;
  }

  /** frames: [[x, y, z], ...] in m, base first, tool last. */
  update(frames) {
    if (!Array.isArray(frames) || frames.length < 2 || !this.changed('frames', frames.flat())) return;
    if (frames.length !== this.count) {
      let reach = 0;
      for (const f of frames) reach = Math.max(reach, Math.hypot(f[0], f[1], f[2]));
      this.build(frames.length, Math.max(reach, 0.2));
      const d = Math.max(reach, 0.3) * 1.5;
      this.camera.position.set(d, -d, d * 0.75);
      this.controls.target.set(0, 0, reach * 0.35);
      this.controls.update();
    }
    const up = new THREE.Vector3(0, 1, 0);
    for (let i = 0; i < frames.length; ++i) {
      const p = new THREE.Vector3(frames[i][0], frames[i][1], frames[i][2]);
      this.spheres[i].position.copy(p);
      if (i > 0) {
        const a = this.spheres[i - 1].position;
        const rod = this.rods[i - 1];
        const dir = p.clone().sub(a);
        const len = dir.length();
        rod.visible = len > 1e-6;
        if (rod.visible) {
          rod.position.copy(a).addScaledVector(dir, 0.5);
          rod.scale.set(1, len, 1);
          rod.quaternion.setFromUnitVectors(up, dir.normalize());
        }
      }
    }
    this.dirty = true;
  }
}
