// The state of a session's model (one photo, a photo set, the views): the one source the badge by
// the 3D view, the export menu and the dimming of an outdated model are drawn from.
//
//   none       nothing asked, no model of this session on screen
//   computing  a request for the current inputs is out (the model on screen, if any, is older)
//   current    the model on screen was made from the current inputs: it may be exported
//   stale      the inputs changed since the model on screen was made, and no request for them is
//              out yet (a drag's pause, fewer than two views, a view being edited)
//   failed     the server refused or failed the request for the current inputs; message says why
//
// Every change of the inputs bumps a version; a request remembers the version it was sent for,
// so an answer to older inputs can never make the model "current".

import { NetworkError, UNREACHABLE } from './connection';

export type ModelStatus = 'none' | 'computing' | 'current' | 'stale' | 'failed';

export interface ModelStateView {
  status: ModelStatus;
  /** failed: the server's one-line message; stale: what changed. */
  message: string | null;
  /** Whether a model of this session is on screen (perhaps an outdated one). */
  shown: boolean;
  /** The statuses so far, oldest first (the last 100): lets a test see a short-lived state. */
  history: ModelStatus[];
}

const HISTORY = 100;

export class ModelState {
  private state: ModelStatus = 'none';
  private why: string | null = null;
  private shownModel = false;
  private version = 0;
  private readonly log: ModelStatus[] = ['none'];

  constructor(private readonly onChange: () => void) {}

  get status(): ModelStatus {
    return this.state;
  }

  get message(): string | null {
    return this.why;
  }

  get shown(): boolean {
    return this.shownModel;
  }

  view(): ModelStateView {
    return { status: this.state, message: this.why, shown: this.shownModel, history: [...this.log] };
  }

  /** What the model is made from changed: the model on screen no longer matches it. */
  changed(reason = 'parameters changed'): void {
    this.version += 1;
    this.set('stale', reason);
  }

  /** A request for the current inputs goes out; returns the version it is for. */
  computing(): number {
    this.set('computing', null);
    return this.version;
  }

  /** A model made from the inputs of ``version`` is drawn; ``final`` is false for a quick look. */
  arrived(version: number, final = true): void {
    this.shownModel = true;
    if (version !== this.version) {
      this.onChange(); // still stale or computing: the inputs moved on meanwhile
      return;
    }
    this.set(final ? 'current' : 'computing', null);
  }

  /** The request for the inputs of ``version`` was refused or failed: ``message`` says why. */
  failed(version: number, message: string): void {
    if (version !== this.version) return; // about inputs the user has already changed
    this.set('failed', message);
  }

  /** No model of this session on screen any more (another mode took the 3D view). */
  reset(): void {
    this.version += 1;
    this.shownModel = false;
    this.set('none', null);
  }

  private set(status: ModelStatus, message: string | null): void {
    if (status === this.state && message === this.why) return;
    this.state = status;
    this.why = message;
    if (this.log.at(-1) !== status) {
      this.log.push(status);
      if (this.log.length > HISTORY) this.log.shift();
    }
    this.onChange();
  }
}

/**
 * A session's requests for its model, one at a time: a new one aborts the one out, and only the
 * latest one counts. ``run`` makes the model computing and turns the busy indicator on (``busy``:
 * the App's "Solving…", where the session shows it), hands ``work`` the request's abort signal,
 * the version of the inputs it is for and whether it is still the latest, hands its failure to
 * ``failed`` (not an abort's, nor a superseded request's: a newer one is out), and turns the busy
 * indicator off once the latest request has ended (then calls ``done``). The one photo's solves (solvePanel.ts), the
 * photo set's (stereo.ts) and the views' fusions (views.ts) go through it, and the panels' (print,
 * maps) through LatestRequest, its plain form.
 */
export class ModelRequest {
  private inFlight: AbortController | null = null;

  constructor(
    private readonly model: ModelState,
    private readonly busy: (on: boolean) => void = () => undefined,
  ) {}

  /** Abort the request out, if any (its answer is dropped; its end turns the busy indicator off). */
  abort(): void {
    this.inFlight?.abort();
  }

  async run(
    work: (request: { signal: AbortSignal; version: number; latest: () => boolean }) => Promise<void>,
    failed: (err: Error, version: number) => void | Promise<void>,
    done: () => void = () => undefined,
  ): Promise<void> {
    this.inFlight?.abort();
    const controller = new AbortController();
    this.inFlight = controller;
    const latest = () => controller === this.inFlight;
    const version = this.model.computing();
    this.busy(true);
    try {
      await work({ signal: controller.signal, version, latest });
    } catch (err) {
      if ((err as Error).name === 'AbortError' || !latest()) return;
      await failed(err as Error, version);
    } finally {
      if (latest()) {
        this.inFlight = null;
        this.busy(false);
        done();
      }
    }
  }
}

/**
 * A panel's requests for its model, one at a time (a ModelRequest): only the latest one's answer
 * is applied (``apply``) and makes the model current; its failure fails the model with the
 * server's message, shown by ``showError`` unless the server could not be reached (the
 * connection's banner says that). ``render`` redraws the panel when the request has ended.
 */
export class LatestRequest {
  private readonly requests: ModelRequest;
  private counter = 0;

  constructor(
    private readonly model: ModelState,
    private readonly showError: (message: string | null) => void,
    private readonly render: () => void,
  ) {
    this.requests = new ModelRequest(model);
  }

  /** The id of the next request (its ``request_id``). */
  nextId(): number {
    return ++this.counter;
  }

  /** Abort the request out, if any (its answer is dropped). */
  abort(): void {
    this.requests.abort();
  }

  async run<T>(send: (signal: AbortSignal) => Promise<T>, apply: (result: T) => void): Promise<void> {
    try {
      await this.requests.run(
        async ({ signal, version, latest }) => {
          this.showError(null);
          const result = await send(signal);
          if (!latest()) return;
          apply(result);
          this.model.arrived(version);
        },
        (err, version) => {
          const message = err instanceof NetworkError ? UNREACHABLE : err.message;
          this.model.failed(version, message);
          if (!(err instanceof NetworkError)) this.showError(message);
        },
      );
    } finally {
      this.render();
    }
  }
}

/** The badge's words for a state. */
export function statusText(status: ModelStatus, message: string | null): string {
  switch (status) {
    case 'current':
      return 'Up to date';
    case 'computing':
      return 'Computing…';
    case 'stale':
      return `Out of date: ${message ?? 'parameters changed'}`;
    case 'failed':
      return `Failed: ${message ?? 'the server could not make the model'}`;
    default:
      return '';
  }
}
