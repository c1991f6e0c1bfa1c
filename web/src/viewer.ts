// The right pane: the reconstructed mesh in three.js. The page keeps the camera, its controls and
// what it asks of the view (where a point is drawn, the depth under a pixel); the drawing is done
// in a render worker on the canvas handed over as an OffscreenCanvas (renderScene.ts says why).
// Each change is sent to it; each frame asked for carries the camera's pose.
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import type { DecodedMesh } from './api';
import { meshBounds, meshBuffers, meshCopy, type MeshBounds } from './meshWorker';
import type { RenderMessage, RenderReply, RenderScene, ViewOptions } from './renderScene';

export type { ViewOptions } from './renderScene';

export class Viewer {
  private readonly canvas: HTMLCanvasElement;
  private readonly send: (message: RenderMessage, transfer?: Transferable[]) => void;
  private readonly camera = new THREE.PerspectiveCamera(32, 1, 0.1, 1e5);
  private readonly controls: OrbitControls;
  private readonly modelPosition = new THREE.Vector3(); // the mesh's centre at the origin
  private readonly halfBox = new THREE.Vector3(0.5, 0.5, 0.5); // the mesh's half extents about its centre
  private centred = false;
  private positions: Float32Array | null = null;
  private size = 1;
  private options: ViewOptions = { wireframe: false, normalColours: false, texture: false, lightArrow: true };
  private partCount = 0;
  private partsOn = true;
  private hasGuides = false;
  private frame = 0; // the page's animation frame asked for
  private sent = 0; // the id of the last frame asked of the renderer
  private renderWaiters: Array<{ id: number; resolve: (t: number) => void }> = [];
  // what the mesh's coordinates are ("model": pixels; "solid": a print in mm); a mesh in another
  // frame than the last one is always fitted anew (a solid of 80 mm after a model of 1000 px)
  private meshFrame = 'none';
  private readonly renderListeners: Array<() => void> = [];

  constructor(private readonly host: HTMLElement) {
    this.canvas = document.createElement('canvas');
    this.canvas.className = 'viewer-canvas';
    this.canvas.tabIndex = 0;
    this.canvas.setAttribute('aria-label', '3D view: drag to rotate, wheel to zoom, right-drag to pan');
    Object.assign(this.canvas.style, { width: '100%', height: '100%' });
    host.append(this.canvas);
    this.send = connectRenderer(this.canvas, (reply) => this.rendered_(reply));

    this.camera.up.set(0, 1, 0);
    this.controls = new OrbitControls(this.camera, this.canvas);
    this.controls.enableDamping = false; // render only on change: no animation loop on idle
    this.controls.zoomToCursor = true;
    this.controls.addEventListener('change', () => this.requestRender());

    new ResizeObserver(() => this.resize()).observe(host);
    this.resize();
  }

  /**
   * Show a new mesh; ``refit`` moves the camera to the front view (a new image, not a new
   * parameter), and so does a ``frame`` other than the last mesh's. Guides go with the old mesh.
   * ``bounds``: the mesh worker's, else found here. The renderer takes a copy of the arrays (the
   * page keeps its own: the depth under a pixel, the model shown again): ``spare``, the mesh
   * worker's copy, else one made here (cloned or copied on the page, a 273k-vertex mesh's 15 MB
   * took it 30-40 ms).
   */
  setMesh(
    mesh: DecodedMesh,
    { refit, frame = 'model', bounds, spare }: { refit: boolean; frame?: string; bounds?: MeshBounds; spare?: DecodedMesh },
  ): void {
    refit ||= frame !== this.meshFrame;
    this.meshFrame = frame;
    this.hasGuides = false;
    bounds ??= meshBounds(mesh.positions);
    const copy = spare ?? meshCopy(mesh);
    this.send({ type: 'mesh', mesh: copy, bounds }, meshBuffers(copy));
    this.positions = mesh.positions;
    if (refit || !this.centred) this.centre(bounds);
    if (refit) this.recenter();
    this.requestRender();
  }

  /**
   * Show partial models with the mesh, each in its colour (an empty list removes them): a fused
   * model's views where the fusion placed them.
   */
  setParts(meshes: DecodedMesh[], colours: string[]): void {
    const copies = meshes.map(meshCopy);
    this.send({ type: 'parts', meshes: copies, colours }, copies.flatMap(meshBuffers));
    this.partCount = meshes.length;
    this.requestRender();
  }

  setPartsVisible(on: boolean): void {
    this.partsOn = on;
    this.send({ type: 'partsVisible', on });
    this.requestRender();
  }

  /** How many partial models are drawn now (0 when hidden). */
  partsShown(): number {
    return this.partsOn ? this.partCount : 0;
  }

  /** How many vertices the main mesh on screen has. */
  vertexCount(): number {
    return this.positions ? this.positions.length / 3 : 0;
  }

  /** The frame of the mesh on screen ("model", "solid", ...), or "none". */
  get shownFrame(): string {
    return this.positions ? this.meshFrame : 'none';
  }

  /** Lines drawn in the mesh's coordinates until the next mesh (null removes them). */
  setGuides(guides: THREE.Object3D | null): void {
    if (!guides && !this.hasGuides) return;
    this.hasGuides = guides !== null;
    this.send({ type: 'guides', json: guides ? guides.toJSON() : null });
    this.requestRender();
  }

  /** Call ``listener`` after every frame asked for (labels that follow the camera). */
  onRender(listener: () => void): void {
    this.renderListeners.push(listener);
  }

  /** Where a point in the mesh's coordinates is drawn, in CSS pixels of the view; null behind the camera. */
  toScreen(x: number, y: number, z: number): [number, number] | null {
    this.camera.updateMatrixWorld();
    const point = new THREE.Vector3(x, y, z).add(this.modelPosition).project(this.camera);
    if (point.z > 1) return null;
    const rect = this.host.getBoundingClientRect();
    return [((point.x + 1) / 2) * rect.width, ((1 - point.y) / 2) * rect.height];
  }

  clear(): void {
    this.hasGuides = false;
    this.send({ type: 'clear' });
    this.positions = null;
    this.requestRender();
  }

  setLight(light: number[]): void {
    this.send({ type: 'light', light: [...light] });
    this.requestRender();
  }

  /** The photo draped over the model when the texture is on (read only then). */
  setPhoto(url: string): void {
    this.send({ type: 'photo', url: new URL(url, location.href).href });
  }

  setOptions(options: Partial<ViewOptions>): void {
    this.options = { ...this.options, ...options };
    this.send({ type: 'options', options: this.options });
    this.requestRender();
  }

  /** Turn the camera about the target: yaw about the up axis, pitch about the screen's x axis. */
  rotate(yawDegrees: number, pitchDegrees: number): void {
    const target = this.controls.target;
    const offset = this.camera.position.clone().sub(target);
    offset.applyAxisAngle(this.camera.up, THREE.MathUtils.degToRad(yawDegrees));
    const right = new THREE.Vector3().crossVectors(this.camera.up, offset).normalize();
    const pitched = offset.clone().applyAxisAngle(right, THREE.MathUtils.degToRad(-pitchDegrees));
    // stay off the poles, where the orbit would flip
    if (Math.abs(pitched.clone().normalize().dot(this.camera.up)) < 0.985) offset.copy(pitched);
    this.camera.position.copy(target).add(offset);
    this.camera.lookAt(target);
    this.controls.update();
  }

  zoom(factor: number): void {
    const target = this.controls.target;
    const offset = this.camera.position.clone().sub(target).divideScalar(factor);
    const length = THREE.MathUtils.clamp(offset.length(), this.size * 0.05, this.size * 20);
    this.camera.position.copy(target).add(offset.setLength(length));
    this.controls.update();
  }

  /** Front view, the whole model in sight. */
  recenter(): void {
    const fov = THREE.MathUtils.degToRad(this.camera.fov);
    const fitHeight = this.size / 2 / Math.tan(fov / 2);
    const fitWidth = fitHeight / Math.max(this.camera.aspect, 1e-3);
    const distance = 1.12 * Math.max(fitHeight, fitWidth, 1);
    this.controls.target.set(0, 0, 0);
    this.camera.position.set(0, 0, distance);
    this.camera.near = distance / 200;
    this.camera.far = distance * 50;
    this.camera.updateProjectionMatrix();
    this.camera.lookAt(0, 0, 0);
    this.controls.update();
    this.requestRender();
  }

  /**
   * Look at the mesh's centre from ``yawDegrees`` right of and ``pitchDegrees`` above its front
   * (negative: below), as near as lets every corner of its bounding box show within ``fill`` of
   * the view's width and height: the whole of what is shown, as large as it goes, at any aspect.
   */
  fitView(yawDegrees: number, pitchDegrees: number, fill = 0.8): void {
    const yaw = THREE.MathUtils.degToRad(yawDegrees);
    const pitch = THREE.MathUtils.degToRad(pitchDegrees);
    // from the centre toward the camera, and the screen's axes
    const back = new THREE.Vector3(Math.sin(yaw) * Math.cos(pitch), Math.sin(pitch), Math.cos(yaw) * Math.cos(pitch));
    const right = new THREE.Vector3().crossVectors(this.camera.up, back).normalize();
    const up = new THREE.Vector3().crossVectors(back, right);
    const tanY = Math.tan(THREE.MathUtils.degToRad(this.camera.fov) / 2) * fill;
    const tanX = tanY * this.camera.aspect;
    // a corner at distance ``along`` toward the camera, ``x`` and ``y`` off the axis, is in sight
    // from distance d when |x| <= (d - along) tanX and |y| <= (d - along) tanY
    let distance = 0;
    const h = this.halfBox;
    for (const corner of [-1, 1].flatMap((i) => [-1, 1].flatMap((j) => [-1, 1].map((k) => new THREE.Vector3(i * h.x, j * h.y, k * h.z))))) {
      const along = corner.dot(back);
      distance = Math.max(distance, along + Math.abs(corner.dot(right)) / tanX, along + Math.abs(corner.dot(up)) / tanY);
    }
    distance = Math.max(distance, 1e-3);
    this.controls.target.set(0, 0, 0);
    this.camera.position.copy(back).multiplyScalar(distance);
    this.camera.near = distance / 200;
    this.camera.far = distance * 50;
    this.camera.updateProjectionMatrix();
    this.camera.lookAt(0, 0, 0);
    this.controls.update();
    this.requestRender();
  }

  /** Where the camera is, relative to the point it orbits (model units). */
  cameraOffset(): [number, number, number] {
    const offset = this.camera.position.clone().sub(this.controls.target);
    return [offset.x, offset.y, offset.z];
  }

  /** The mesh's z at the vertex nearest pixel (row, col), or null when there is no mesh there. */
  depthAt(row: number, col: number, within = Infinity): number | null {
    const p = this.positions;
    if (!p) return null;
    let best = Infinity;
    let z: number | null = null;
    for (let i = 0; i < p.length; i += 3) {
      const d = (p[i] - col) ** 2 + (p[i + 1] + row) ** 2;
      if (d < best) {
        best = d;
        z = p[i + 2];
      }
    }
    return best <= within * within ? z : null;
  }

  /** Resolves with performance.now() once the renderer has drawn a frame showing the current scene. */
  rendered(): Promise<number> {
    return new Promise((resolve) => {
      this.renderWaiters.push({ id: this.sent + 1, resolve });
      this.requestRender();
    });
  }

  /** Ask for a frame at the page's next animation frame, from the camera then. */
  requestRender(): void {
    if (this.frame) return;
    this.frame = requestAnimationFrame(() => {
      this.frame = 0;
      const { position: p, quaternion: q, fov, aspect, near, far } = this.camera;
      const m = this.modelPosition;
      this.send({
        type: 'frame',
        id: ++this.sent,
        camera: { position: [p.x, p.y, p.z], quaternion: [q.x, q.y, q.z, q.w], fov, aspect, near, far },
        model: [m.x, m.y, m.z],
      });
      this.renderListeners.forEach((listener) => listener());
    });
  }

  // --------------------------------------------------------------------------------------

  private rendered_(reply: RenderReply): void {
    const now = performance.now();
    const done = this.renderWaiters.filter((waiter) => waiter.id <= reply.id);
    this.renderWaiters = this.renderWaiters.filter((waiter) => waiter.id > reply.id);
    done.forEach((waiter) => waiter.resolve(now));
  }

  private centre({ box }: MeshBounds): void {
    const [x0, y0, z0, x1, y1, z1] = box;
    this.size = Math.max(x1 - x0, y1 - y0, z1 - z0, 1);
    this.halfBox.set((x1 - x0) / 2, (y1 - y0) / 2, (z1 - z0) / 2);
    this.modelPosition.set(-(x0 + x1) / 2, -(y0 + y1) / 2, -(z0 + z1) / 2);
    this.centred = true;
  }

  private resize(): void {
    const rect = this.host.getBoundingClientRect();
    if (!rect.width || !rect.height) return;
    this.send({ type: 'size', width: rect.width, height: rect.height, pixelRatio: window.devicePixelRatio || 1 });
    this.camera.aspect = rect.width / rect.height;
    this.camera.updateProjectionMatrix();
    this.requestRender();
  }
}

/**
 * Hand ``canvas`` to the render worker; what to send it. A browser that cannot hand a canvas to a
 * worker gets the same renderer on the page's thread (its frames then block the page while drawn).
 */
function connectRenderer(
  canvas: HTMLCanvasElement,
  reply: (reply: RenderReply) => void,
): (message: RenderMessage, transfer?: Transferable[]) => void {
  if (typeof canvas.transferControlToOffscreen !== 'function') {
    console.warn('this browser cannot draw the 3D view in a worker (no OffscreenCanvas): it is drawn on the page, which may pause while a large model is drawn');
    // the renderer (three.js's WebGLRenderer, its shaders) is loaded only here: the page's own
    // bundle then holds three.js's maths alone, and its first task compiles and runs less
    let scene: RenderScene | null = null;
    const waiting: RenderMessage[] = [];
    void import('./renderScene').then(({ RenderScene }) => {
      scene = new RenderScene(canvas, reply, (draw) => requestAnimationFrame(draw));
      for (const message of waiting.splice(0)) scene.handle(message);
    });
    return (message) => (scene ? scene.handle(message) : void waiting.push(message));
  }
  const offscreen = canvas.transferControlToOffscreen();
  const worker = new Worker(new URL('./renderWorker.ts', import.meta.url), { type: 'module' });
  worker.onmessage = (event: MessageEvent<RenderReply>) => reply(event.data);
  worker.onerror = (event) => {
    // an error drawing the view is the page's: reported as one (and by the tests' page-error checks)
    throw new Error(`the 3D view's renderer failed: ${event.message}`);
  };
  worker.postMessage({ type: 'init', canvas: offscreen }, [offscreen]);
  return (message, transfer = []) => worker.postMessage(message, transfer);
}
