// The orbitable 3D view (three.js, built into voxeld): meshes (OBJ, PLY)
// and voxel grids (binvox, raw8, raw1) as instanced cubes of their surface.
import * as THREE from 'three';
import { OrbitControls } from '/ui/OrbitControls.js';
import { OBJLoader } from '/ui/OBJLoader.js';
import { PLYLoader } from '/ui/PLYLoader.js';

export const BACKGROUND = 0x20242a;
// Instances drawn at most: beyond it every n-th surface voxel is drawn.
const MAX_CUBES = 400000;

export class View3D {
  constructor(canvas) {
    this.canvas = canvas;
    // preserveDrawingBuffer: the picture can be read back (the browser test).
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(1);
    this.renderer.setClearColor(BACKGROUND, 1);
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(40, 4 / 3, 0.01, 1000);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x404050, 1.2));
    const sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(1, 1.5, 2);
    this.camera.add(sun);
    this.scene.add(this.camera);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.addEventListener('change', () => this.render());
    this.object = null;
    new ResizeObserver(() => this.resize()).observe(canvas);
    this.resize();
  }

  resize() {
    const w = Math.max(1, this.canvas.clientWidth), h = Math.max(1, this.canvas.clientHeight);
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.render();
  }

  render() { this.renderer.render(this.scene, this.camera); }

  clear() {
    if (this.object) this.scene.remove(this.object);
    for (const obj of this.owned || []) obj.traverse(o => { o.geometry?.dispose(); o.material?.dispose?.(); });
    this.owned = [];
    this.object = null;
    this.render();
  }

  // Shows object in place of the one shown, keeping the camera (a frame of
  // the same mesh); show() must have been called with the first one.
  swap(object) {
    if (this.object) this.scene.remove(this.object);
    if (!this.owned.includes(object)) this.owned.push(object);
    this.object = object;
    this.scene.add(object);
    this.render();
  }

  show(object) {
    this.clear();
    this.owned = [object];
    this.object = object;
    this.scene.add(object);
    const box = new THREE.Box3().setFromObject(object);
    const sphere = box.getBoundingSphere(new THREE.Sphere());
    const r = sphere.radius || 1;
    const d = r / Math.sin(THREE.MathUtils.degToRad(this.camera.fov / 2));
    this.camera.near = d / 100;
    this.camera.far = d * 10;
    this.camera.position.copy(sphere.center).add(new THREE.Vector3(0.6, 0.5, 1).normalize().multiplyScalar(d));
    this.camera.updateProjectionMatrix();
    this.controls.target.copy(sphere.center);
    this.controls.update();
    this.render();
  }

  // format: "obj" (text) or "ply" (ArrayBuffer). Returns the triangles.
  showMesh(data, format) {
    const object = this.parseMesh(data, format);
    this.show(object);
    return countTriangles(object);
  }

  // A mesh file as a three.js object, not shown.
  parseMesh(data, format) {
    const material = new THREE.MeshStandardMaterial({ color: 0xc8b48c, roughness: 0.6, metalness: 0.05, side: THREE.DoubleSide });
    let object;
    if (format === 'ply') {
      const g = new PLYLoader().parse(data);
      if (!g.getAttribute('normal')) g.computeVertexNormals();
      object = new THREE.Mesh(g, material);
    } else {
      object = new OBJLoader().parse(typeof data === 'string' ? data : new TextDecoder().decode(data));
      object.traverse(o => {
        if (!o.isMesh) return;
        if (!o.geometry.getAttribute('normal')) o.geometry.computeVertexNormals();
        o.material = material;
      });
    }
    return object;
  }

  // grid: {dims: [nx, ny, nz], at(i, j, k) -> bool, origin: [x, y, z], h}.
  showVoxels(grid) {
    const [nx, ny, nz] = grid.dims;
    const surface = [];
    const on = (i, j, k) => i >= 0 && j >= 0 && k >= 0 && i < nx && j < ny && k < nz && grid.at(i, j, k);
    let inside = 0;
    for (let k = 0; k < nz; k++)
      for (let j = 0; j < ny; j++)
        for (let i = 0; i < nx; i++) {
          if (!grid.at(i, j, k)) continue;
          inside++;
          if (!on(i - 1, j, k) || !on(i + 1, j, k) || !on(i, j - 1, k) || !on(i, j + 1, k) || !on(i, j, k - 1) || !on(i, j, k + 1))
            surface.push(i, j, k);
        }
    const n = surface.length / 3, step = Math.max(1, Math.ceil(n / MAX_CUBES));
    const count = Math.ceil(n / step), h = grid.h, o = grid.origin;
    const cube = new THREE.BoxGeometry(h * 0.95, h * 0.95, h * 0.95);
    const mesh = new THREE.InstancedMesh(cube, new THREE.MeshStandardMaterial({ roughness: 0.7 }), Math.max(1, count));
    const m = new THREE.Matrix4(), c = new THREE.Color();
    let at = 0;
    for (let v = 0; v < n; v += step, at++) {
      const i = surface[3 * v], j = surface[3 * v + 1], k = surface[3 * v + 2];
      m.makeTranslation(o[0] + (i + 0.5) * h, o[1] + (j + 0.5) * h, o[2] + (k + 0.5) * h);
      mesh.setMatrixAt(at, m);
      mesh.setColorAt(at, c.setHSL(0.6 - 0.6 * (ny > 1 ? j / (ny - 1) : 0), 0.55, 0.55));
    }
    mesh.count = count;
    this.show(mesh);
    return { inside, surface: n, drawn: count };
  }
}

function countTriangles(object) {
  let t = 0;
  object.traverse(o => {
    if (!o.isMesh) return;
    const g = o.geometry;
    t += (g.index ? g.index.count : g.getAttribute('position').count) / 3;
  });
  return t;
}

// binvox 1 (api/openapi.yaml, VoxelizeParams): header, then (value, count)
// byte pairs; index = i*d*d + k*d + j.
export function parseBinvox(buf) {
  const bytes = new Uint8Array(buf);
  let p = 0, header = {};
  const line = () => {
    const e = bytes.indexOf(10, p);
    if (e < 0) throw new Error('binvox: truncated header');
    const s = new TextDecoder().decode(bytes.subarray(p, e)).trim();
    p = e + 1;
    return s;
  };
  if (!line().startsWith('#binvox')) throw new Error('not a binvox file');
  for (let s = line(); s !== 'data'; s = line()) {
    const [k, ...v] = s.split(/\s+/);
    header[k] = v.map(Number);
  }
  const [d] = header.dim, vox = new Uint8Array(d * d * d);
  for (let idx = 0; p + 1 < bytes.length && idx < vox.length; p += 2) {
    const v = bytes[p], n = bytes[p + 1];
    if (v) vox.fill(1, idx, Math.min(vox.length, idx + n));
    idx += n;
  }
  return { dims: [d, d, d], origin: header.translate, h: header.scale[0] / d, at: (i, j, k) => vox[i * d * d + k * d + j] };
}

// raw8 / raw1: x fastest, then y, then z; the grid from the job's stats.
export function parseRaw(buf, bits, stats) {
  const [nx, ny, nz] = stats.dims, b = new Uint8Array(buf);
  const at = bits
    ? (i, j, k) => { const n = i + nx * (j + ny * k); return (b[n >> 3] >> (n & 7)) & 1; }
    : (i, j, k) => b[i + nx * (j + ny * k)];
  return { dims: [nx, ny, nz], origin: stats.origin, h: stats.voxel_size, at };
}
