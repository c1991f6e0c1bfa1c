// The orientation inset in the 3D view's corner: the camera-frame axes x, y, z and the
// reconstruction's light as a sun with an arrow along the rays. It turns with the view, so the
// light's direction reads against the axes from any angle, without covering the model.
import * as THREE from 'three';

const AXES: Array<[string, THREE.Vector3, number]> = [
  ['x', new THREE.Vector3(1, 0, 0), 0xf87171],
  ['y', new THREE.Vector3(0, 1, 0), 0x4ade80],
  ['z', new THREE.Vector3(0, 0, 1), 0x60a5fa],
];
const SUN_DISTANCE = 1.15;

/** A canvas of this thread: an OffscreenCanvas where there is one (always in a worker, where the
 * view is drawn: renderScene.ts). */
export function scratchCanvas(width: number, height: number): HTMLCanvasElement | OffscreenCanvas {
  if (typeof OffscreenCanvas !== 'undefined') return new OffscreenCanvas(width, height);
  return Object.assign(document.createElement('canvas'), { width, height });
}

function textSprite(text: string, colour: string): THREE.Sprite {
  const canvas = scratchCanvas(96, 48);
  const ctx = canvas.getContext('2d') as CanvasRenderingContext2D | OffscreenCanvasRenderingContext2D;
  ctx.font = '600 30px system-ui, sans-serif';
  ctx.textAlign = 'center';
  ctx.textBaseline = 'middle';
  ctx.fillStyle = colour;
  ctx.fillText(text, 48, 25);
  const texture = new THREE.CanvasTexture(canvas);
  texture.colorSpace = THREE.SRGBColorSpace;
  const sprite = new THREE.Sprite(new THREE.SpriteMaterial({ map: texture, depthTest: false }));
  sprite.scale.set(0.56, 0.28, 1);
  return sprite;
}

export class Gizmo {
  /** Side of the inset in CSS pixels, and its margin from the corner. */
  static readonly SIZE = 128;
  static readonly MARGIN = 10;
  private readonly scene = new THREE.Scene();
  private readonly camera = new THREE.OrthographicCamera(-1.45, 1.45, 1.45, -1.45, 0.1, 10);
  private readonly light = new THREE.Group();
  private readonly sun = new THREE.Mesh(new THREE.SphereGeometry(0.12, 20, 10), new THREE.MeshBasicMaterial({ color: 0xfde047 }));
  private readonly ray = new THREE.ArrowHelper(new THREE.Vector3(0, 0, -1), new THREE.Vector3(), 1, 0xfde047, 0.26, 0.14);

  constructor() {
    for (const [name, direction, colour] of AXES) {
      this.scene.add(new THREE.ArrowHelper(direction, new THREE.Vector3(), 1, colour, 0.2, 0.1));
      const label = textSprite(name, `#${colour.toString(16).padStart(6, '0')}`);
      label.position.copy(direction).multiplyScalar(1.22);
      this.scene.add(label);
    }
    this.light.add(this.sun, this.ray);
    this.scene.add(this.light);
    this.setLight(new THREE.Vector3(0, 0, 1));
  }

  /** ``direction``: unit vector toward the light (camera frame of the photo). */
  setLight(direction: THREE.Vector3): void {
    const toLight = direction.clone().normalize();
    this.sun.position.copy(toLight).multiplyScalar(SUN_DISTANCE);
    // the arrow starts at the sun and runs the way the light travels, toward the object
    this.ray.position.copy(this.sun.position);
    this.ray.setDirection(toLight.clone().negate());
    this.ray.setLength(SUN_DISTANCE - 0.2, 0.26, 0.14);
  }

  setLightVisible(visible: boolean): void {
    this.light.visible = visible;
  }

  /** Draw the inset over the bottom-left corner, seen from where ``view`` looks. */
  render(renderer: THREE.WebGLRenderer, view: THREE.Camera): void {
    this.camera.quaternion.copy(view.quaternion);
    this.camera.position.set(0, 0, 4).applyQuaternion(view.quaternion);
    const full = renderer.getViewport(new THREE.Vector4());
    const pixelRatio = renderer.getPixelRatio();
    const { SIZE, MARGIN } = Gizmo;
    renderer.autoClear = false;
    renderer.setScissorTest(true);
    renderer.setScissor(MARGIN, MARGIN, SIZE, SIZE);
    renderer.setViewport(MARGIN, MARGIN, SIZE, SIZE);
    // the inset's square cleared (the canvas is transparent there): the model never covers the
    // frame and its label drawn under the canvas
    renderer.clear(true, true, false);
    renderer.render(this.scene, this.camera);
    renderer.setScissorTest(false);
    renderer.setViewport(full.x / pixelRatio, full.y / pixelRatio, full.z / pixelRatio, full.w / pixelRatio);
    renderer.autoClear = true;
  }
}
