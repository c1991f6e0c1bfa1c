// The one photo's panels: the image pane (its tools, what it shows, the regions, references and
// mask drawn on it) with the mask tool, the side panel of parameters (controls.ts), and the
// group that adds the photo to the views or says which view is being edited. Their edits change
// the photo's settings (Photo.params), which the App keeps and the solves send (solvePanel.ts).
import type { Options, ReconstructResult } from './api.gen';
import { Panel, type Urgency } from './controls';
import { $, showMessage } from './dom';
import { ImagePane, type Display, type Tool } from './imagePane';
import { MaskTool } from './maskTool';
import type { Photo } from './photo';
import type { Axis, Params, Region } from './sessionTypes';
import { download, regionsDocument } from './state';
import { toast } from './toast';
import { readUnsure, type Unsure } from './unsure';
import type { ViewsSession } from './views';

export interface PhotoPanelHost {
  /** Send the settings: at once, or after a drag's pause (solvePanel.ts). */
  schedule(urgency: Urgency): void;
  /** The settings changed: keep them for a reload (and in the view being edited). */
  persist(): void;
}

export class PhotoPanel {
  readonly pane: ImagePane;
  readonly maskTool: MaskTool;
  // built in the app's second task (App.create), with the views
  private panel!: Panel;
  private views!: ViewsSession;

  constructor(
    private readonly photo: Photo,
    private readonly host: PhotoPanelHost,
  ) {
    this.pane = new ImagePane($('image-host'), {
      regions: (regions, final) => this.regionsEdited(regions, final),
      references: (refs) => this.change({ references: refs }, 'now'),
      selection: () => this.showRegions(),
      hover: (pixel) => ($('pixel').textContent = pixel ? `row ${pixel.row}, col ${pixel.col}` : ''),
      hint: (text) => ($('hint').textContent = text),
      notice: (text) => this.notice(text),
    });
    this.maskTool = new MaskTool({
      image: () => photo.image && { id: photo.image.image_id, width: photo.image.width, height: photo.image.height, channel: photo.params.channel },
      changed: (png, refit) => {
        photo.refitNext ||= refit;
        this.change({ mask: png }, 'now');
      },
      cleared: () => photo.model.changed('the mask was cleared: paint or outline the object'),
      show: (mask, dirty) => this.pane.setMask(mask, dirty),
      redraw: () => this.pane.redraw(),
      hint: (text) => {
        if (this.pane.tool === 'mask') $('hint').textContent = text;
      },
      download: (blob, filename) => download(blob, filename),
      stem: () => photo.stem(),
      notice: (text) => this.notice(text),
    });
    this.pane.maskEditor = this.maskTool;
  }

  /** The parameter panel; ``views``: where Add this photo as a view adds it. */
  buildControls(options: Options, views: ViewsSession): void {
    this.views = views;
    this.panel = new Panel(options, {
      change: (patch, urgency) => this.change(patch, urgency),
      axis: (axis) => this.setAxis(axis),
      selectRegion: (i) => this.pane.select(i),
      removeRegion: (i) => this.pane.removeRegion(i),
      removeReference: (i) => this.change({ references: this.photo.params.references.filter((_, k) => k !== i) }, 'now'),
      clearReferences: () => this.change({ references: [] }, 'now'),
      drawRegion: () => this.setTool('polygon'),
      editReferences: () => this.setTool('reference'),
      editMask: () => this.setTool('mask'),
      loadRegions: () => $<HTMLInputElement>('file-regions').click(),
      saveRegions: () => this.saveRegions(),
      clearRegions: () => this.regionsEdited([], true),
      markUnsure: (i) => this.markUnsure(i),
    });
  }

  /** The image pane's toolbar (tools, what it shows, Fit) and Add this photo as a view. */
  bind(): void {
    for (const button of document.querySelectorAll<HTMLButtonElement>('#tools button')) {
      button.addEventListener('click', () => this.setTool(button.dataset.tool as Tool));
    }
    $<HTMLSelectElement>('display').addEventListener('change', (event) => {
      this.pane.display = (event.target as HTMLSelectElement).value as Display;
      this.pane.redraw();
    });
    $('fit-image').addEventListener('click', () => this.pane.fit());
  }

  /** What the panel shows of the settings. */
  show(params: Params): void {
    this.panel.show(params);
  }

  // ------------------------------------------------------------------------- editing

  change(patch: Partial<Params>, urgency: Urgency): void {
    const photo = this.photo;
    const before = photo.params;
    photo.params = { ...photo.params, ...structuredClone(patch) };
    if (photo.image) photo.model.changed();
    this.panel.show(photo.params);
    if ('references' in patch) this.showReferences();
    if (patch.channel !== undefined && patch.channel !== before.channel) this.maskTool.channelChanged();
    if (photo.image && (patch.channel !== undefined || patch.filter !== undefined)) {
      if (patch.channel !== before.channel || JSON.stringify(patch.filter) !== JSON.stringify(before.filter)) {
        this.pane.setSources(photo.sources());
      }
    }
    this.host.persist();
    this.host.schedule(urgency);
  }

  regionsEdited(regions: Region[], final: boolean): void {
    const photo = this.photo;
    photo.params = { ...photo.params, concave: { regions: structuredClone(regions) } };
    if (photo.image) photo.model.changed('regions changed');
    this.showRegions();
    if (final) {
      this.host.persist();
      this.host.schedule('now');
    }
  }

  /** Make the shown result's ``index``-th unsure area a concave region with its suggested axis. */
  private markUnsure(index: number): void {
    const area = this.pane.unsure[index];
    if (!area) return;
    const region: Region = { polygon: area.polygon.map(([x, y]): [number, number] => [x, y]), axis: area.axis };
    const regions = [...this.photo.params.concave.regions, region];
    this.pane.setRegions(regions);
    this.regionsEdited(regions, true);
  }

  showUnsure(areas: Unsure[]): void {
    this.pane.setUnsure(areas);
    this.panel.showUnsure(areas, this.photo.params.concave.regions);
  }

  /** A regions file's regions replace the photo's. */
  loadRegions(regions: Region[]): void {
    this.pane.setRegions(regions);
    this.pane.select(null);
    this.regionsEdited(regions, true);
    toast(`Loaded ${regions.length} region${regions.length === 1 ? '' : 's'}`, 'info');
  }

  saveRegions(): void {
    const text = JSON.stringify(regionsDocument(this.photo.params.concave.regions), null, 2);
    download(new Blob([text + '\n'], { type: 'application/json' }), `${this.photo.stem()}.regions.json`);
  }

  setAxis(axis: Axis): void {
    this.pane.newAxis = axis;
    const selected = this.pane.selection;
    if (selected !== null) this.pane.setAxis(selected, axis);
    this.showRegions();
    this.pane.redraw();
  }

  setTool(tool: Tool): void {
    this.pane.setTool(tool);
    for (const button of document.querySelectorAll<HTMLButtonElement>('#tools button')) {
      button.classList.toggle('on', button.dataset.tool === tool);
    }
  }

  showRegions(): void {
    this.panel.showRegions(this.photo.params.concave.regions, this.pane.selection, this.pane.newAxis);
    this.panel.showUnsure(this.pane.unsure, this.photo.params.concave.regions);
  }

  showReferences(): void {
    const used = this.photo.result?.references ?? [];
    this.pane.setReferences(this.photo.params.references, used);
    this.panel.showReferences(this.photo.params.references, used);
  }

  /** A message over the image about what its tool refused; null takes it away. */
  notice(text: string | null): void {
    showMessage('image-notice', text);
  }

  /** A result is drawn: its mask, the references it used, what the panel says of it, its unsure areas. */
  showResult(result: ReconstructResult | null): void {
    if (result === null) {
      this.panel.showResult(null);
      return;
    }
    if (result.mask_png) this.maskTool.solvedWith(result.mask_png); // a large photo's quick look has none
    this.showReferences();
    this.panel.showResult(result);
    // a quick look may leave the areas out: keep the last ones until a result says
    if (!result.preview || 'unsure' in result.info) this.showUnsure(readUnsure(result.info));
  }

  // ------------------------------------------------------------------- the views' group

  /** The photo open now, with its settings, becomes one more view. */
  addView(): void {
    const { image, source, params } = this.photo;
    if (!image || !source) return void toast('Open a photo first, then add it as a view');
    const angle = this.views.nextAngle();
    const index = this.views.add({ image, source, angle, params });
    toast(`Added as view ${index + 1} at ${angle}° — Views fuses the views into one model`, 'info');
  }

  /** The single-photo panel says which view is being edited, and offers to go back. */
  showEditing(): void {
    const index = this.views.editing;
    const view = index === null ? undefined : this.views.views[index];
    $('view-editing').hidden = !view;
    $('view-add-row').hidden = !!view;
    $('view-add-group').hidden = !this.photo.image; // nothing to add or edit before a photo is open
    if (view) $('view-editing-name').textContent = `view ${index! + 1} (${view.image.name}, ${view.angle}°)`;
  }

  /** Read-only views for the tests (window.shadeform). */
  hook() {
    return {
      /** The message over the image about what its tool refused, or null. */
      notice: () => ($('image-notice').hidden ? null : $('image-notice').textContent),
      pagePoint: (x: number, y: number) => this.pane.pagePoint(x, y),
      /** The unsure areas outlined on the image (the newest result's). */
      unsure: () => structuredClone(this.pane.unsure),
      /** The mask tool: whose mask is shown (user or automatic), its pixels, note, error. */
      mask: () => this.maskTool.state(),
      /** Whether pixel (row, col) is object in the mask the pane shows. */
      maskAt: (row: number, col: number) => this.maskTool.at(row, col),
    };
  }
}
