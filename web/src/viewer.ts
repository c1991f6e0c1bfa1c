// The right pane: the reconstructed mesh in three.js.
//
// Positions arrive in the mesh convention of docs/conventions.md, (x, y, z) = (col, -row,
// depth) in pixels, so +z points at the viewer exactly as in the photo. Smooth shading: the
// reconstruction's per-vertex normals are interpolated across each triangle. The viewer's own
// lights ride with the camera (a key light from the upper left, a weak fill), so the relief reads
// from any angle; the reconstruction's light is drawn as an arrow in the corner inset (gizmo.ts).
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import type { DecodedMesh } from './api';
import type { MeshBounds } from './meshWorker';
import { Gizmo } from './gizmo';

export interface ViewOptions {
  wireframe: boolean;
  normalColours: boolean;
  texture: boolean;
  lightArrow: boolean;
}

const BASE_COLOUR = 0xd8d2c8; // warm clay: shading reads better than on pure white

export class Viewer {
  readonly renderer: THREE.WebGLRenderer;
  private readonly scene = new THREE.Scene();
  private readonly camera = new THREE.PerspectiveCamera(32, 1, 0.1, 1e5);
  private readonly controls: OrbitControls;
  private readonly model = new THREE.Group();
  private readonly parts = new THREE.Group(); // partial models placed on a fused one
  private readonly keyLight = new THREE.DirectionalLight(0xffffff, 2.6);
  private readonly fillLight = new THREE.DirectionalLight(0xdfe8ff, 0.6);
  private readonly gizmo = new Gizmo();
  private readonly shaded = new THREE.MeshStandardMaterial({
    color: BASE_COLOUR,
    roughness: 0.9,
    metalness: 0,
    side: THREE.DoubleSide,
    polygonOffset: true, // keeps the wireframe overlay in front of the surface
    polygonOffsetFactor: 1,
    polygonOffsetUnits: 1,
  });
  private readonly normalMaterial = new THREE.MeshBasicMaterial({ vertexColors: true, side: THREE.DoubleSide, polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1 });
  private readonly wireMaterial = new THREE.LineBasicMaterial({ color: 0x0f172a, transparent: true, opacity: 0.45 });
  private surface: THREE.Mesh | null = null;
  private wire: THREE.LineSegments | null = null;
  private texture: THREE.Texture | null = null;
  private textureUrl = '';
  private positions: Float32Array | null = null;
  private size = 1;
  private options: ViewOptions = { wireframe: false, normalColours: false, texture: false, lightArrow: true };
  private frame = 0;
  private renderWaiters: Array<(t: number) => void> = [];
  // what the mesh's coordinates are ("model": pixels; "solid": a print in mm); a mesh in another
  // frame than the last one is always fitted anew (a solid of 80 mm after a model of 1000 px)
  private meshFrame = 'none';
  private guides: THREE.Object3D | null = null; // drawn with the mesh (a solid's measures)
  private readonly renderListeners: Array<() => void> = [];

  constructor(private readonly host: HTMLElement) {
    // a software renderer (SwiftShader: no GPU, or a headless browser) draws multisampling on the
    // CPU, and the page waits for each frame at its commit: 190 ms for the first model without it
    this.renderer = new THREE.WebGLRenderer({ antialias: !softwareGl(), alpha: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(2, window.devicePixelRatio || 1));
    this.renderer.setClearColor(0x000000, 0);
    this.renderer.domElement.className = 'viewer-canvas';
    this.renderer.domElement.tabIndex = 0;
    this.renderer.domElement.setAttribute('aria-label', '3D view: drag to rotate, wheel to zoom, right-drag to pan');
    host.append(this.renderer.domElement);

    this.camera.up.set(0, 1, 0);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.enableDamping = false; // render only on change: no animation loop on idle
    this.controls.zoomToCursor = true;
    this.controls.addEventListener('change', () => this.requestRender());

    this.scene.add(new THREE.HemisphereLight(0xe8eefc, 0x1b1e24, 0.7));
    // lights in the camera's frame (a directional light shines from its position to its target)
    this.keyLight.position.set(-0.5, 0.6, 1);
    this.fillLight.position.set(0.7, -0.2, 0.6);
    for (const light of [this.keyLight, this.fillLight]) {
      this.camera.add(light, light.target);
      light.target.position.set(0, 0, 0);
    }
    this.scene.add(this.camera);
    this.model.add(this.parts);
    this.scene.add(this.model);

    new ResizeObserver(() => this.resize()).observe(host);
    this.resize();
    this.precompile();
  }

  /**
   * Compile the surface's shaders before the first model comes, in parallel where the browser
   * can (KHR_parallel_shader_compile): compiled by the first render instead, they blocked the
   * page for 170 ms in software WebGL.
   */
  private precompile(): void {
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(9), 3));
    geometry.setAttribute('normal', new THREE.BufferAttribute(new Float32Array([0, 0, 1, 0, 0, 1, 0, 0, 1]), 3));
    geometry.setAttribute('uv', new THREE.BufferAttribute(new Float32Array(6), 2));
    const probe = new THREE.Mesh(geometry, this.shaded);
    this.model.add(probe);
    this.renderer
      .compileAsync(this.scene, this.camera)
      .then(() => {
        // one draw with them: a software renderer (SwiftShader) builds its pipeline on the first
        // draw, 200-400 ms that the page then waits for; here, before any model is asked for
        // (the corner gizmo's too, drawn with every model)
        if (this.surface) return;
        this.renderer.render(this.scene, this.camera);
        this.gizmo.render(this.renderer, this.camera);
        this.renderer.clear();
      })
      .catch(() => undefined) // the first render compiles them then
      .finally(() => {
        this.model.remove(probe);
        geometry.dispose();
      });
  }

  /**
   * Show a new mesh; ``refit`` moves the camera to the front view (a new image, not a new
   * parameter), and so does a ``frame`` other than the last mesh's. Guides go with the old mesh.
   */
  setMesh(
    mesh: DecodedMesh,
    { refit, frame = 'model', bounds }: { refit: boolean; frame?: string; bounds?: MeshBounds },
  ): void {
    refit ||= frame !== this.meshFrame;
    this.meshFrame = frame;
    this.setGuides(null);
    const geometry = geometryOf(mesh, bounds);
    const old = this.surface?.geometry;
    if (this.surface) this.model.remove(this.surface);
    if (this.wire) {
      this.model.remove(this.wire);
      this.wire.geometry.dispose();
      this.wire = null;
    }
    old?.dispose();
    this.positions = mesh.positions;
    this.surface = new THREE.Mesh(geometry, this.shaded);
    this.model.add(this.surface);
    this.applyOptions();
    const box = geometry.boundingBox!;
    if (refit || !this.model.userData.centred) this.centre(box);
    if (refit) this.recenter();
    this.requestRender();
  }

  /**
   * Show partial models with the mesh, each in its colour (an empty list removes them): a fused
   * model's views where the fusion placed them. They are drawn a little toward the camera, so
   * that where one lies on the fused surface its colour shows; where none does, the fused one.
   */
  setParts(meshes: DecodedMesh[], colours: string[]): void {
    for (const part of [...this.parts.children] as THREE.Mesh[]) {
      this.parts.remove(part);
      part.geometry.dispose();
      (part.material as THREE.Material).dispose();
    }
    meshes.forEach((mesh, i) => {
      const material = new THREE.MeshStandardMaterial({
        color: colours[i % colours.length],
        roughness: 0.85,
        metalness: 0,
        side: THREE.DoubleSide,
        polygonOffset: true,
        polygonOffsetFactor: -1,
        polygonOffsetUnits: -4 * (i + 1), // a fixed order where two parts overlap: no flicker
      });
      this.parts.add(new THREE.Mesh(geometryOf(mesh), material));
    });
    this.requestRender();
  }

  setPartsVisible(on: boolean): void {
    this.parts.visible = on;
    this.requestRender();
  }

  /** How many partial models are drawn now (0 when hidden). */
  partsShown(): number {
    return this.parts.visible ? this.parts.children.length : 0;
  }

  /** How many vertices the main mesh on screen has. */
  vertexCount(): number {
    return this.positions ? this.positions.length / 3 : 0;
  }

  /** The frame of the mesh on screen ("model", "solid", ...), or "none". */
  get shownFrame(): string {
    return this.surface ? this.meshFrame : 'none';
  }

  /** Lines drawn in the mesh's coordinates until the next mesh (null removes them). */
  setGuides(guides: THREE.Object3D | null): void {
    if (this.guides) {
      this.model.remove(this.guides);
      this.guides.traverse((part) => {
        if (part instanceof THREE.LineSegments) {
          part.geometry.dispose();
          (part.material as THREE.Material).dispose();
        }
      });
    }
    this.guides = guides;
    if (guides) this.model.add(guides);
    this.requestRender();
  }

  /** Call ``listener`` after every frame drawn (labels that follow the camera). */
  onRender(listener: () => void): void {
    this.renderListeners.push(listener);
  }

  /** Where a point in the mesh's coordinates is drawn, in CSS pixels of the view; null behind the camera. */
  toScreen(x: number, y: number, z: number): [number, number] | null {
    this.model.updateMatrixWorld();
    const point = new THREE.Vector3(x, y, z).applyMatrix4(this.model.matrixWorld).project(this.camera);
    if (point.z > 1) return null;
    const rect = this.host.getBoundingClientRect();
    return [((point.x + 1) / 2) * rect.width, ((1 - point.y) / 2) * rect.height];
  }

  clear(): void {
    this.setGuides(null);
    if (this.surface) {
      this.model.remove(this.surface);
      this.surface.geometry.dispose();
      this.surface = null;
    }
    if (this.wire) {
      this.model.remove(this.wire);
      this.wire.geometry.dispose();
      this.wire = null;
    }
    this.positions = null;
    this.requestRender();
  }

  setLight(light: number[]): void {
    this.gizmo.setLight(new THREE.Vector3(light[0], light[1], light[2]));
    this.requestRender();
  }

  setPhoto(url: string): void {
    if (url === this.textureUrl) return;
    this.textureUrl = url;
    this.texture?.dispose();
    this.texture = new THREE.TextureLoader().load(url, () => this.requestRender());
    this.texture.colorSpace = THREE.SRGBColorSpace;
    this.texture.anisotropy = 4;
    if (this.options.texture) this.applyOptions();
  }

  setOptions(options: Partial<ViewOptions>): void {
    this.options = { ...this.options, ...options };
    this.applyOptions();
    this.gizmo.setLightVisible(this.options.lightArrow);
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

  /** Resolves with performance.now() once a frame showing the current scene has been drawn. */
  rendered(): Promise<number> {
    return new Promise((resolve) => {
      this.renderWaiters.push(resolve);
      this.requestRender();
    });
  }

  requestRender(): void {
    if (this.frame) return;
    this.frame = requestAnimationFrame(() => {
      this.frame = 0;
      this.renderer.render(this.scene, this.camera);
      if (this.surface) this.gizmo.render(this.renderer, this.camera);
      this.renderListeners.forEach((listener) => listener());
      const waiters = this.renderWaiters;
      this.renderWaiters = [];
      const now = performance.now();
      waiters.forEach((resolve) => resolve(now));
    });
  }

  // --------------------------------------------------------------------------------------

  private centre(box: THREE.Box3): void {
    const centre = box.getCenter(new THREE.Vector3());
    const extent = box.getSize(new THREE.Vector3());
    this.size = Math.max(extent.x, extent.y, extent.z, 1);
    this.model.position.copy(centre).negate();
    this.model.userData.centred = true;
  }

  private applyOptions(): void {
    const surface = this.surface;
    if (!surface) return;
    const { wireframe, normalColours, texture } = this.options;
    if (normalColours) {
      normalColourAttribute(surface.geometry);
      surface.material = this.normalMaterial;
    } else {
      surface.material = this.shaded;
    }
    // a mesh without texture coordinates (a fused model) is never draped
    const map = texture && this.texture && surface.geometry.getAttribute('uv') ? this.texture : null;
    if (this.shaded.map !== map) {
      this.shaded.map = map;
      this.shaded.color.set(map ? 0xffffff : BASE_COLOUR);
      this.shaded.needsUpdate = true;
    }
    if (wireframe && !this.wire) {
      this.wire = new THREE.LineSegments(new THREE.WireframeGeometry(surface.geometry), this.wireMaterial);
      this.model.add(this.wire);
    } else if (!wireframe && this.wire) {
      this.model.remove(this.wire);
      this.wire.geometry.dispose();
      this.wire = null;
    }
  }

  private resize(): void {
    const rect = this.host.getBoundingClientRect();
    if (!rect.width || !rect.height) return;
    this.renderer.setSize(rect.width, rect.height, true);
    this.camera.aspect = rect.width / rect.height;
    this.camera.updateProjectionMatrix();
    this.requestRender();
  }
}

/** The geometry of a decoded mesh: its arrays as they are; its bounds from the mesh worker when
 * it found them (a loop over every vertex less on the page's thread), else computed here. */
function geometryOf(mesh: DecodedMesh, bounds?: MeshBounds): THREE.BufferGeometry {
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(mesh.positions, 3));
  geometry.setAttribute('normal', new THREE.BufferAttribute(mesh.normals, 3));
  if (mesh.uvs) geometry.setAttribute('uv', new THREE.BufferAttribute(mesh.uvs, 2));
  geometry.setIndex(new THREE.BufferAttribute(mesh.indices, 1));
  if (bounds) {
    const [x0, y0, z0, x1, y1, z1] = bounds.box;
    geometry.boundingBox = new THREE.Box3(new THREE.Vector3(x0, y0, z0), new THREE.Vector3(x1, y1, z1));
    const [cx, cy, cz, radius] = bounds.sphere;
    geometry.boundingSphere = new THREE.Sphere(new THREE.Vector3(cx, cy, cz), radius);
  } else {
    geometry.computeBoundingBox();
    geometry.computeBoundingSphere();
  }
  return geometry;
}

/** Per-vertex colours (n + 1) / 2: the OpenGL normal-map convention the library writes. */
function normalColourAttribute(geometry: THREE.BufferGeometry): void {
  if (geometry.getAttribute('color')) return;
  const normals = geometry.getAttribute('normal');
  const colours = new Float32Array(normals.count * 3);
  const colour = new THREE.Color();
  for (let i = 0; i < normals.count; i++) {
    // a normal-map file's bytes are shown as sRGB: convert so the view shows the same colours
    colour.setRGB((normals.getX(i) + 1) / 2, (normals.getY(i) + 1) / 2, (normals.getZ(i) + 1) / 2, THREE.SRGBColorSpace);
    colours.set([colour.r, colour.g, colour.b], 3 * i);
  }
  geometry.setAttribute('color', new THREE.BufferAttribute(colours, 3));
}

/** Whether WebGL runs in software (SwiftShader, llvmpipe): read from a throwaway context. */
function softwareGl(): boolean {
  const gl = document.createElement('canvas').getContext('webgl2');
  if (!gl) return false;
  const info = gl.getExtension('WEBGL_debug_renderer_info');
  const renderer = info ? String(gl.getParameter(info.UNMASKED_RENDERER_WEBGL)) : String(gl.getParameter(gl.RENDERER));
  gl.getExtension('WEBGL_lose_context')?.loseContext();
  return /swiftshader|llvmpipe|software/i.test(renderer);
}
