// The 3D view's pane around the Viewer (viewer.ts): the model drawn there, whichever mode's (the
// one photo's, the photo set's, the views' fused model with its partial models), the badge that
// says what that model is and the Export menu that follows it, the view's toggles (with the
// image pane's Mask toggle: one set of view settings) and navigation buttons, and the line under
// the view (the mesh's size, the server's time).
import type * as api from './api';
import type { FuseResult, Options, StereoResult } from './api.gen';
import { UNREACHABLE } from './connection';
import { $ } from './dom';
import type { ImagePane } from './imagePane';
import type { MeshBounds } from './meshWorker';
import { statusText, type ModelState } from './modelState';
import type { ViewSettings } from './state';
import { PART_COLOURS } from './viewCards';
import type { Viewer } from './viewer';

export interface ViewerPanelHost {
  /** The badge, the export menu and the dimming follow the shown model's state again. */
  showModelState(): void;
  /** The view settings changed: keep them for a reload. */
  persist(): void;
  /** Export menu: download the model on screen as ``suffix``. */
  exportFormat(suffix: string): void;
}

export class ViewerPanel {
  /** The mesh on screen (any mode's; a print's solid is the Print panel's), or null. */
  mesh: api.DecodedMesh | null = null;

  constructor(
    readonly viewer: Viewer,
    private readonly pane: ImagePane,
    /** What the view shows (wireframe, normals, texture, the light arrow, the mask overlay). */
    public view: ViewSettings,
    private readonly host: ViewerPanelHost,
  ) {}

  /** The Export menu's formats, the toggles and the navigation buttons. */
  bind(options: Options): void {
    const exports = $('export-menu').querySelector('.menu-items')!;
    for (const format of options.formats) {
      const button = document.createElement('button');
      button.dataset.format = format.suffix;
      button.title = `Download the mesh as ${format.suffix}`;
      button.innerHTML = `<span class="format"></span><span class="desc"></span>`;
      button.querySelector('.format')!.textContent = format.suffix;
      button.querySelector('.desc')!.textContent = format.description;
      button.addEventListener('click', () => this.host.exportFormat(format.suffix));
      exports.append(button);
    }
    const toggles: Array<[string, keyof ViewSettings]> = [
      ['wire-toggle', 'wireframe'],
      ['normals-toggle', 'normalColours'],
      ['texture-toggle', 'texture'],
      ['arrow-toggle', 'lightArrow'],
      ['mask-toggle', 'maskOverlay'],
    ];
    for (const [id, key] of toggles) $(id).addEventListener('change', () => this.toggleView(key));
    const nav: Record<string, () => void> = {
      left: () => this.viewer.rotate(-15, 0),
      right: () => this.viewer.rotate(15, 0),
      up: () => this.viewer.rotate(0, 10),
      down: () => this.viewer.rotate(0, -10),
      'zoom-in': () => this.viewer.zoom(1.2),
      'zoom-out': () => this.viewer.zoom(1 / 1.2),
      recenter: () => this.viewer.recenter(),
    };
    for (const button of document.querySelectorAll<HTMLButtonElement>('.nav button')) {
      button.addEventListener('click', () => nav[button.dataset.nav!]());
    }
  }

  // ------------------------------------------------------------------------- view settings

  applyView(): void {
    $<HTMLInputElement>('wire-toggle').checked = this.view.wireframe;
    $<HTMLInputElement>('normals-toggle').checked = this.view.normalColours;
    $<HTMLInputElement>('texture-toggle').checked = this.view.texture;
    $<HTMLInputElement>('arrow-toggle').checked = this.view.lightArrow;
    $<HTMLInputElement>('mask-toggle').checked = this.view.maskOverlay;
    this.viewer.setOptions(this.view);
    this.pane.showMask = this.view.maskOverlay;
    this.pane.redraw();
  }

  toggleView(key: keyof ViewSettings): void {
    this.view = { ...this.view, [key]: !this.view[key] };
    this.applyView();
    this.host.persist();
  }

  // ------------------------------------------------------------------------ the model shown

  /** Show ``mesh`` (the Viewer's options: refit, frame, the mesh worker's bounds and copy). */
  setMesh(mesh: api.DecodedMesh, options: { refit: boolean; bounds?: MeshBounds; spare?: api.DecodedMesh }): void {
    this.mesh = mesh;
    this.viewer.setMesh(mesh, options);
  }

  /** A photo set's model, its albedo draped on it. */
  showStereo(result: StereoResult, mesh: api.DecodedMesh, refit: boolean): void {
    this.setMesh(mesh, { refit });
    this.viewer.setLight(result.light);
    this.viewer.setPhoto(`data:image/png;base64,${result.albedo_png}`);
    this.modelShown();
    this.showDepthInfo(mesh, result.depth_range);
    $('timing').textContent = `server ${((result.timings.total ?? 0) * 1000).toFixed(0)} ms${result.info.cached ? ' (cached solve)' : ''}`;
  }

  /** The views' fused model, with each view's partial model (shown or not: ``showParts``). */
  showFused(result: FuseResult, fused: api.DecodedMesh, parts: api.DecodedMesh[], refit: boolean, showParts: boolean): void {
    this.setMesh(fused, { refit });
    this.viewer.setParts(parts, PART_COLOURS);
    this.viewer.setPartsVisible(showParts);
    this.viewer.setLight(result.views[0].light); // the object frame is the first view's camera frame
    this.modelShown();
    $('mesh-info').textContent =
      `${fused.vertexCount.toLocaleString()} vertices · ${fused.triangleCount.toLocaleString()} triangles · ` +
      `fused from ${result.views.length} views${result.watertight ? '' : ' · NOT closed'}`;
    $('timing').textContent = `server ${((result.timings.total ?? 0) * 1000).toFixed(0)} ms${result.info.cached ? ' (fused model reused)' : ''}`;
  }

  /** The line under the view for a model of depth ``low`` … ``high`` px. */
  showDepthInfo(mesh: api.DecodedMesh, [low, high]: number[]): void {
    $('mesh-info').textContent =
      `${mesh.vertexCount.toLocaleString()} vertices · ${mesh.triangleCount.toLocaleString()} triangles · ` +
      `depth ${low.toFixed(1)} … ${high.toFixed(1)} px`;
  }

  /** A model is on screen: the 3D view's controls are on (the exports follow the model's state). */
  modelShown(): void {
    $('view-empty').hidden = true;
    $('view-host').classList.add('has-model');
  }

  /** No model on screen (a new mode's comes): the 3D view is empty, the exports off. */
  clearModel(): void {
    this.mesh = null;
    this.viewer.clear();
    this.viewer.setParts([], PART_COLOURS);
    $('view-empty').hidden = false;
    $('view-host').classList.remove('has-model');
    $('mesh-info').textContent = '';
    $('timing').textContent = '';
    this.host.showModelState();
  }

  /**
   * Everything that tells what the model on screen is, from its ModelState alone: the badge,
   * the export menu (only a current model may be exported: the file would otherwise not be what
   * is shown, or the server would refuse it) and the dimming of a model that is not current.
   */
  showState({ status, message }: ModelState): void {
    const onScreen = $('view-host').classList.contains('has-model');
    const badge = $('model-badge');
    badge.hidden = status === 'none';
    badge.dataset.status = status;
    badge.textContent = statusText(status, message);
    const waiting = status === 'failed' && message === UNREACHABLE;
    badge.title = waiting
      ? 'The model shown is an older one: it is made again once the server answers'
      : status === 'failed' ? 'The model shown is an older one: change a setting to try again' : '';
    $('view-host').dataset.modelStatus = status;
    $('view-host').classList.toggle('outdated', onScreen && status !== 'current');
    const exportable = onScreen && status === 'current';
    const button = $<HTMLButtonElement>('export-button');
    button.disabled = !exportable;
    button.title = exportable
      ? 'Download the current mesh in one of the library\'s formats'
      : 'Export is off until the model on screen is up to date with the settings';
    if (!exportable) $('export-menu').classList.remove('open');
  }

  /** The badge's words, or null while it is hidden (the test hook's). */
  badge(): string | null {
    return $('model-badge').hidden ? null : $('model-badge').textContent;
  }

  /** Read-only views for the tests (window.shadeform). */
  hook() {
    return {
      depthAt: (row: number, col: number) => this.viewer.depthAt(row, col),
      // resolves once the render worker has drawn the scene as it is now (a screenshot waits on it)
      rendered: () => this.viewer.rendered(),
      cameraOffset: () => this.viewer.cameraOffset(),
      mesh: () =>
        this.mesh && {
          positions: Array.from(this.mesh.positions),
          normals: Array.from(this.mesh.normals),
          uvs: this.mesh.uvs ? Array.from(this.mesh.uvs) : [],
          indices: Array.from(this.mesh.indices),
        },
    };
  }
}
