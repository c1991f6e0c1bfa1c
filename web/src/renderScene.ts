// The 3D view's drawing half: the scene (the mesh, partial models, guides, the camera's lights, the
// corner gizmo), its materials and its WebGL renderer. It runs in the render worker
// (renderWorker.ts) on the view's canvas handed over as an OffscreenCanvas, so the page never waits
// for a frame: in software WebGL (SwiftShader) a 273k-vertex model took 200-300 ms a frame, and a
// canvas drawn on the page's thread blocked it that long at each frame's commit. The page's half
// (viewer.ts) keeps the camera and its controls and sends what changes as RenderMessages; where a
// browser cannot hand a canvas to a worker, the page runs this same class itself.
//
// Positions arrive in the mesh convention of docs/conventions.md, (x, y, z) = (col, -row,
// depth) in pixels, so +z points at the viewer exactly as in the photo. Smooth shading: the
// reconstruction's per-vertex normals are interpolated across each triangle. The viewer's own
// lights ride with the camera (a key light from the upper left, a weak fill), so the relief reads
// from any angle; the reconstruction's light is drawn as an arrow in the corner inset (gizmo.ts).
import * as THREE from 'three';
import type { DecodedMesh } from './api';
import type { MeshBounds } from './meshWorker';
import { Gizmo, scratchCanvas } from './gizmo';

export interface ViewOptions {
  wireframe: boolean;
  normalColours: boolean;
  texture: boolean;
  lightArrow: boolean;
}

/** Where the page's camera is: what a frame is drawn from. */
export interface CameraState {
  position: [number, number, number];
  quaternion: [number, number, number, number];
  fov: number;
  aspect: number;
  near: number;
  far: number;
}

/** What the page sends the drawing half, in order. A ``frame`` asks for a frame (the last one
 * asked wins where several come while one is drawn), answered by a ``rendered`` reply. */
export type RenderMessage =
  | { type: 'size'; width: number; height: number; pixelRatio: number }
  | { type: 'mesh'; mesh: DecodedMesh; bounds: MeshBounds }
  | { type: 'clear' }
  | { type: 'parts'; meshes: DecodedMesh[]; colours: string[] }
  | { type: 'partsVisible'; on: boolean }
  | { type: 'guides'; json: unknown }
  | { type: 'light'; light: number[] }
  | { type: 'photo'; url: string }
  | { type: 'options'; options: ViewOptions }
  | { type: 'frame'; id: number; camera: CameraState; model: [number, number, number] };

/** A frame drawn: the last ``frame`` message's id it showed. */
export interface RenderReply {
  type: 'rendered';
  id: number;
}

type Frame = Extract<RenderMessage, { type: 'frame' }>;

const BASE_COLOUR = 0xd8d2c8; // warm clay: shading reads better than on pure white

export class RenderScene {
  private readonly renderer: THREE.WebGLRenderer;
  private readonly scene = new THREE.Scene();
  private readonly camera = new THREE.PerspectiveCamera(32, 1, 0.1, 1e5);
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
  private guides: THREE.Object3D | null = null;
  private texture: THREE.Texture | null = null;
  private photoUrl = '';
  private textureUrl = ''; // the photo the texture is (being) read from
  private options: ViewOptions = { wireframe: false, normalColours: false, texture: false, lightArrow: true };
  private last: Frame | null = null; // the latest frame asked for
  private drawn = true; // whether ``last`` has been drawn

  /**
   * ``canvas``: the view's (an OffscreenCanvas in the render worker); ``reply``: how a drawn frame
   * is told; ``nextFrame``: the thread's requestAnimationFrame.
   */
  constructor(
    canvas: HTMLCanvasElement | OffscreenCanvas,
    private readonly reply: (reply: RenderReply) => void,
    private readonly nextFrame: (draw: () => void) => void,
  ) {
    // a software renderer (SwiftShader: no GPU, or a headless browser) draws multisampling on the
    // CPU: 190 ms more for the first model with it
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: !softwareGl(), alpha: true, preserveDrawingBuffer: true });
    this.renderer.setClearColor(0x000000, 0);
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
    this.precompile();
  }

  handle(message: RenderMessage): void {
    switch (message.type) {
      case 'size':
        this.renderer.setPixelRatio(Math.min(2, message.pixelRatio || 1));
        this.renderer.setSize(message.width, message.height, false); // the page sizes the canvas's box
        return;
      case 'mesh':
        return this.setMesh(message.mesh, message.bounds);
      case 'clear':
        return this.clear();
      case 'parts':
        return this.setParts(message.meshes, message.colours);
      case 'partsVisible':
        this.parts.visible = message.on;
        return;
      case 'guides':
        return this.setGuides(message.json === null ? null : new THREE.ObjectLoader().parse(message.json));
      case 'light':
        this.gizmo.setLight(new THREE.Vector3(message.light[0], message.light[1], message.light[2]));
        return;
      case 'photo':
        this.photoUrl = message.url;
        if (this.options.texture) this.loadTexture();
        return;
      case 'options':
        this.options = message.options;
        if (this.options.texture) this.loadTexture();
        this.applyOptions();
        this.gizmo.setLightVisible(this.options.lightArrow);
        return;
      case 'frame':
        this.last = message;
        return this.schedule();
    }
  }

  /**
   * Compile the surface's shaders before the first model comes, in parallel where the browser
   * can (KHR_parallel_shader_compile): compiled by the first render instead, they took 170 ms in
   * software WebGL.
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
        // draw, 200-400 ms; here, before any model is asked for (the corner gizmo's too)
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

  private schedule(): void {
    if (!this.drawn) return;
    this.drawn = false;
    this.nextFrame(() => this.draw());
  }

  private draw(): void {
    this.drawn = true;
    const frame = this.last;
    if (!frame) return;
    const { camera, model } = frame;
    this.camera.position.fromArray(camera.position);
    this.camera.quaternion.fromArray(camera.quaternion);
    Object.assign(this.camera, { fov: camera.fov, aspect: camera.aspect, near: camera.near, far: camera.far });
    this.camera.updateProjectionMatrix();
    this.model.position.fromArray(model);
    this.renderer.render(this.scene, this.camera);
    if (this.surface) this.gizmo.render(this.renderer, this.camera);
    this.reply({ type: 'rendered', id: frame.id });
  }

  private setMesh(mesh: DecodedMesh, bounds: MeshBounds): void {
    this.setGuides(null);
    const old = this.surface?.geometry;
    if (this.surface) this.model.remove(this.surface);
    this.removeWire();
    old?.dispose();
    this.surface = new THREE.Mesh(geometryOf(mesh, bounds), this.shaded);
    this.model.add(this.surface);
    this.applyOptions();
  }

  private clear(): void {
    this.setGuides(null);
    if (this.surface) {
      this.model.remove(this.surface);
      this.surface.geometry.dispose();
      this.surface = null;
    }
    this.removeWire();
  }

  private removeWire(): void {
    if (!this.wire) return;
    this.model.remove(this.wire);
    this.wire.geometry.dispose();
    this.wire = null;
  }

  /** Each partial model in its colour, drawn a little toward the camera, so that where one lies on
   * the fused surface its colour shows; where none does, the fused one. */
  private setParts(meshes: DecodedMesh[], colours: string[]): void {
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
  }

  private setGuides(guides: THREE.Object3D | null): void {
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
  }

  /** The photo as a texture, read when first shown (a 12 Mpx photo is 48 MB decoded): fetched and
   * decoded off the page's thread, flipped as WebGL's texture coordinates want it. */
  private loadTexture(): void {
    const url = this.photoUrl;
    if (!url || url === this.textureUrl) return;
    this.textureUrl = url;
    fetch(url)
      .then((response) => response.blob())
      .then((blob) => createImageBitmap(blob, { imageOrientation: 'flipY' }))
      .then((bitmap) => {
        if (url !== this.textureUrl) return bitmap.close();
        if (this.texture) {
          (this.texture.image as ImageBitmap).close();
          this.texture.dispose();
        }
        this.texture = new THREE.Texture(bitmap);
        this.texture.flipY = false; // flipped when decoded: an ImageBitmap is never flipped on upload
        this.texture.colorSpace = THREE.SRGBColorSpace;
        this.texture.anisotropy = 4;
        this.texture.needsUpdate = true;
        this.applyOptions();
        this.schedule(); // the last frame again, draped
      })
      .catch(() => {
        if (url === this.textureUrl) this.textureUrl = ''; // tried again when next shown
      });
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
    // a mesh without texture coordinates (a fused model) is never draped; nor is another photo's
    const current = this.texture && this.textureUrl === this.photoUrl ? this.texture : null;
    const map = texture && current && surface.geometry.getAttribute('uv') ? current : null;
    if (this.shaded.map !== map) {
      this.shaded.map = map;
      this.shaded.color.set(map ? 0xffffff : BASE_COLOUR);
      this.shaded.needsUpdate = true;
    }
    if (wireframe && !this.wire) {
      this.wire = new THREE.LineSegments(new THREE.WireframeGeometry(surface.geometry), this.wireMaterial);
      this.model.add(this.wire);
    } else if (!wireframe) {
      this.removeWire();
    }
  }
}

/** The geometry of a decoded mesh: its arrays as they are; its bounds when known (from the mesh
 * worker: a loop over every vertex less), else computed here. */
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
  const gl = scratchCanvas(1, 1).getContext('webgl2') as WebGL2RenderingContext | null;
  if (!gl) return false;
  const info = gl.getExtension('WEBGL_debug_renderer_info');
  const renderer = info ? String(gl.getParameter(info.UNMASKED_RENDERER_WEBGL)) : String(gl.getParameter(gl.RENDERER));
  gl.getExtension('WEBGL_lose_context')?.loseContext();
  return /swiftshader|llvmpipe|software/i.test(renderer);
}
