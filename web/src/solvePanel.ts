// The one photo's solves, and the panel over the 3D view that shows a large photo's full solve
// in the background. Every edit sends one reconstruct request (slider drags debounced briefly, one
// at a time); a quick look solved at the mesh's grid (or a coarser one) comes first where the
// image is large enough for it to pay, then the full solve under the same id. A newer request
// aborts the one in flight (ModelRequest, modelState.ts), and a response whose request_id is not
// the newest is dropped, so a stale model never arrives last. A large photo (more than
// Options.limits.large_pixels: a 12 Mpx phone photo) gets its quick look from a downsampled copy,
// then its full solve runs in the background (/api/solves): a progress bar with Cancel, which
// stops it and leaves the quick look shown. Results are parsed and their meshes decoded in a Web
// Worker (meshWorker.ts), so that the page never blocks on a large one.
import * as api from './api';
import type { ImageInfo, ReconstructResult, SolveJob } from './api.gen';
import { NetworkError, UNREACHABLE } from './connection';
import type { Urgency } from './controls';
import { $ } from './dom';
import type { ImagePane } from './imagePane';
import type { MaskTool } from './maskTool';
import type { MeshBounds } from './meshWorker';
import { ModelRequest } from './modelState';
import { forgotten, type Photo } from './photo';
import type { ImageSource } from './sessionTypes';
import { toast } from './toast';
import type { ViewerPanel } from './viewerPanel';

const DRAG_DEBOUNCE_MS = 40;
/** How often a background solve's progress is asked for. */
const PROGRESS_POLL_MS = 250;

/** Timestamps (performance.now()) of the last applied result: where the time went. */
interface Timeline {
  requestId: number;
  changed: number;
  sent: number;
  received: number;
  decoded: number;
  rendered: number;
  /** When the first model of this request was drawn (the preview's, if one came). */
  firstRendered: number;
  /** Whether the last model drawn is the quick look (the full one still to come). */
  preview: boolean;
  serverTimings: Record<string, number>;
}

export interface SolveHost {
  /** The App's busy indicator ("Solving…") on or off, and whether it is on for a solve (any mode's). */
  setSolving(on: boolean): void;
  isSolving(): boolean;
  /** The photo changed (a forgotten one reopened): keep it for a reload. */
  persist(): void;
  /** A fresh id for the same image (by example name, or by re-sending its bytes), or null. */
  reopen(source: ImageSource): Promise<ImageInfo | null>;
  /** A result is drawn: the panel and the image pane show what it found (references, unsure areas). */
  showResult(result: ReconstructResult): void;
}

export class SolvePanel {
  /** A large photo's mask tool is still to ask what its automatic mask is (after the first view). */
  describeMask = false;
  private requestCounter = 0;
  private latestSent = 0;
  private readonly requests: ModelRequest;
  private debounce = 0;
  private changedAt: number | null = null;
  private dragWaiting = false; // a drag moved on while a request was out
  private failureShown: (() => void) | null = null; // takes the last solve failure's message away
  /** The background full solve running now (a large photo's), to cancel. */
  private job: string | null = null;
  private appliedCount = 0;
  private timeline: Timeline | null = null;

  constructor(
    private readonly photo: Photo,
    private readonly viewerPanel: ViewerPanel,
    private readonly pane: ImagePane,
    private readonly maskTool: MaskTool,
    private readonly host: SolveHost,
  ) {
    this.requests = new ModelRequest(photo.model, (on) => host.setSolving(on));
    $('solve-cancel').addEventListener('click', () => void this.cancelJob());
    $('solve-again').addEventListener('click', () => {
      $('solve-progress').hidden = true;
      this.solve();
    });
  }

  /** The id of a request outside the solves (an export), from the same count. */
  nextId(): number {
    return ++this.requestCounter;
  }

  /** Nothing of the photo is solved any more (another mode takes the panes). */
  abort(): void {
    this.requests.abort();
  }

  /**
   * Send the current parameters: at once for a click or a slider's release; during a drag after
   * a short pause, and not while a request is out (the server cannot stop a solve it started,
   * so aborting one per drag step would queue solves nobody waits for): the drag's newest state
   * goes as soon as the answer is in.
   */
  schedule(urgency: Urgency): void {
    if (!this.photo.image) return;
    this.changedAt ??= performance.now();
    clearTimeout(this.debounce);
    if (urgency === 'now') {
      this.dragWaiting = false;
      this.solve();
    } else if (this.host.isSolving()) {
      this.dragWaiting = true;
    } else {
      this.debounce = window.setTimeout(() => this.solve(), DRAG_DEBOUNCE_MS);
    }
  }

  async solve(retried = false): Promise<void> {
    const photo = this.photo;
    if (!photo.image) return;
    clearTimeout(this.debounce);
    const id = ++this.requestCounter;
    this.latestSent = id;
    const changed = this.changedAt ?? performance.now();
    this.changedAt = null;
    await this.requests.run(
      async ({ signal, version }) => {
        $('solve-progress').hidden = true; // a cancelled solve's note goes with the next request
        // ask for a quick look first (the server gives the full result instead where a quick look
        // would not pay), then the full solve; both under this request's id and abort signal
        let firstRendered: number | null = null;
        for (let preview = true; ; preview = false) {
          const sent = performance.now();
          const background = !preview && photo.large();
          const answer = background
            ? await this.solveInBackground(id, signal)
            : await api.reconstructDecoded({ ...photo.request(id), preview }, signal);
          if (answer === null) {
            // cancelled: the quick look stays, said to be one
            if (id === this.latestSent) photo.model.changed('full resolution cancelled: the quick look is shown');
            return;
          }
          const { result, mesh, bounds, spare } = answer;
          // decoded in the worker: received is when it arrived there, decoded when it came back
          const decoded = performance.now();
          const received = decoded - answer.decodeMs;
          if (result.request_id !== this.latestSent) return; // superseded while on the wire
          this.applyResult(result, mesh, { bounds, spare });
          photo.model.arrived(version, !result.preview);
          if (!result.preview) this.outlived();
          if (this.describeMask) {
            this.describeMask = false;
            void this.maskTool.describe();
          }
          const rendered = await this.viewerPanel.viewer.rendered();
          if (id !== this.latestSent) return;
          this.appliedCount += 1;
          firstRendered ??= rendered;
          this.timeline = {
            requestId: id, changed, sent, received, decoded, rendered, firstRendered,
            preview: result.preview, serverTimings: result.timings,
          };
          $('timing').textContent = timingText(result, rendered - changed);
          // a drag that moved on wants its newest state, not this one at full resolution
          if (!result.preview || this.dragWaiting) break;
        }
      },
      async (err, version) => {
        if (err instanceof NetworkError) {
          // the connection's message says so; this solve goes again once the server answers
          photo.model.failed(version, UNREACHABLE);
          return;
        }
        if (err instanceof api.ApiError && err.status === 404 && !retried && photo.source) {
          // the server forgot the image (restarted without its sessions, or its store is full)
          const source = photo.source;
          const name = photo.image?.name ?? source.name;
          let info: ImageInfo | null = null;
          let why = 'this page has no copy to send again: open the image again';
          try {
            info = await this.host.reopen(source);
          } catch (reopenErr) {
            if (reopenErr instanceof NetworkError) return photo.model.failed(version, UNREACHABLE); // away again
            why = `opening it again failed: ${(reopenErr as Error).message}`;
          }
          if (id !== this.latestSent) return;
          if (info) {
            photo.image = info;
            this.pane.setSources(photo.sources());
            this.host.persist();
            toast(`${forgotten(name)}: ${source.kind === 'upload' ? 'sent it again' : 'opened it again'}`, 'info');
            return this.solve(true);
          }
          photo.model.failed(version, `${forgotten(name)}; ${why}`);
          this.failureShown = toast(`${forgotten(name)}; ${why}`);
          return;
        }
        // the old model stays on screen, dimmed and not exportable, until the next change; a model
        // of another image does not: a new image whose first solve failed shows none
        if (photo.result === null) this.viewerPanel.clearModel();
        photo.model.failed(version, err.message);
        this.failureShown = toast(err.message);
      },
      () => {
        // the latest request has ended: a drag that moved on meanwhile sends its newest state
        if (this.dragWaiting) {
          this.dragWaiting = false;
          this.solve();
        }
      },
    );
  }

  /**
   * The full solve of request ``id`` as a background job: its progress shown with Cancel, polled
   * until it ends; the result decoded in the worker, or null if it was cancelled. A newer request
   * (the signal aborted) cancels it on the server too.
   */
  private async solveInBackground(id: number, signal: AbortSignal): Promise<api.Decoded | null> {
    let job = await api.startSolve(this.photo.request(id), signal);
    const jobId = job.job_id;
    const cancel = () => void api.cancelSolve(jobId).catch(() => undefined);
    signal.addEventListener('abort', cancel);
    this.job = jobId;
    try {
      this.showJob(job);
      while (job.state === 'running') {
        await new Promise((resolve) => window.setTimeout(resolve, PROGRESS_POLL_MS));
        signal.throwIfAborted();
        job = await api.solveProgress(jobId, signal);
        if (this.job === jobId) this.showJob(job);
      }
      if (job.state === 'cancelled') return null;
      if (job.state === 'failed') throw new api.ApiError(422, job.detail ?? 'the full-resolution solve failed');
      return await api.solveResult(jobId, signal);
    } finally {
      signal.removeEventListener('abort', cancel);
      if (this.job === jobId) {
        this.job = null;
        $('solve-progress').hidden = true;
      }
    }
  }

  /** The progress bar of the background solve: stage, share done, seconds so far. */
  private showJob(job: SolveJob): void {
    $('solve-progress').hidden = false;
    $('solve-again').hidden = true;
    $('solve-cancel').hidden = false;
    $('solve-bar').hidden = false;
    $('solve-stage').textContent = `Full resolution: ${job.stage_text}`;
    $<HTMLProgressElement>('solve-bar').value = job.fraction;
    $('solve-percent').textContent = `${Math.round(job.fraction * 100)} % · ${job.elapsed.toFixed(0)} s`;
  }

  /** Cancel: the background solve stops (its worker process ends) and the quick look stays. */
  private async cancelJob(): Promise<void> {
    const jobId = this.job;
    if (!jobId) return;
    this.job = null;
    try {
      await api.cancelSolve(jobId);
    } catch (err) {
      toast((err as Error).message);
    }
    $('solve-progress').hidden = false;
    $('solve-cancel').hidden = true;
    $('solve-bar').hidden = true;
    $('solve-again').hidden = false;
    $('solve-stage').textContent = 'Full resolution cancelled: the quick look is shown';
    $('solve-percent').textContent = '';
  }

  /** ``decoded``: what the mesh worker found with the mesh (its bounds, the renderer's copy). */
  applyResult(result: ReconstructResult, mesh: api.DecodedMesh, decoded: { bounds?: MeshBounds; spare?: api.DecodedMesh } = {}): void {
    this.photo.result = result;
    this.viewerPanel.setMesh(mesh, { refit: this.photo.refitNext, ...decoded });
    this.photo.refitNext = false;
    this.viewerPanel.viewer.setLight(result.light);
    this.viewerPanel.modelShown();
    this.host.showResult(result);
    this.viewerPanel.showDepthInfo(mesh, result.depth_range);
  }

  /** The Print panel's "Show model": the photo's last model in the 3D view again. */
  showModel(): void {
    const { result } = this.photo;
    const mesh = this.viewerPanel.mesh;
    if (result && mesh) this.applyResult(result, mesh);
  }

  /** The last solve's failure is outlived (a model for the current inputs is drawn, or another
   * image opened): its message goes; the badge said the same and now says what holds. */
  outlived(): void {
    this.failureShown?.();
    this.failureShown = null;
  }

  /** Read-only views for the tests and the benchmark (window.shadeform). */
  hook() {
    return {
      lastResult: () => {
        const r = this.photo.result;
        if (!r) return null;
        const mesh = this.viewerPanel.mesh;
        return {
          request_id: r.request_id,
          preview: r.preview,
          /** Whether its JSON was parsed and its mesh decoded in the mesh worker (the page kept no base64). */
          decodedInWorker: r.mesh.positions === '' && mesh !== null && mesh.vertexCount === r.mesh.vertex_count,
          vertex_count: r.mesh.vertex_count,
          triangle_count: r.mesh.triangle_count,
          light: r.light,
          references: r.references,
          depth_range: r.depth_range,
          timings: r.timings,
          info: r.info,
        };
      },
      /** The background full solve's progress bar (a large photo's): shown, its words, the share done. */
      solveProgress: () => ({
        shown: !$('solve-progress').hidden,
        job: this.job,
        text: $('solve-stage').textContent,
        fraction: $<HTMLProgressElement>('solve-bar').value,
        cancellable: !$('solve-cancel').hidden,
      }),
      /** The id of the newest reconstruct request sent. */
      requests: () => this.latestSent,
      /** How many results have been drawn in the 3D view so far. */
      applied: () => this.appliedCount,
      timeline: () => (this.timeline ? { ...this.timeline } : null),
    };
  }
}

function timingText(result: ReconstructResult, total: number): string {
  const server = (result.timings.total ?? 0) * 1000;
  const cached = result.info.cached ? ' (cached solve)' : '';
  if (result.preview && result.info.level) return `quick look (photo ÷ ${result.info.level}) in ${total.toFixed(0)} ms`;
  if (result.preview) return `quick look in ${total.toFixed(0)} ms · refining…`;
  return `server ${server.toFixed(0)} ms${cached} · shown in ${total.toFixed(0)} ms`;
}
