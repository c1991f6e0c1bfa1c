// Whether the server answers. A request that fails at the network level (fetch rejects: the
// server was stopped or is restarting; an HTTP error status is an answer, not this) makes the
// connection "lost": a message that stays says so, and `/api/options` is polled, one request at
// a time, 2 s after the failure and then backing off to 10 s, until the server answers. Any
// answer (the poll's or another request's) makes it "online" again: the message gives way to
// "Reconnected to the server" and the listeners run (the App sends the open mode's last solve
// again, so the model becomes current without the user doing anything).
import { toast } from './toast';

export type ConnectionState = 'online' | 'lost';

/** A model's failure while the server is away (a session's ModelState message): the App looks
 * for it on reconnecting to know which solve to send again. */
export const UNREACHABLE = 'server not reachable (retrying…)';

const LOST_MESSAGE = 'Lost the connection to the server; retrying…';
const FIRST_WAIT_MS = 2000;
const LONGEST_WAIT_MS = 10_000;
// a server that takes the connection but does not answer (still starting) is tried again later
const POLL_TIMEOUT_MS = 5000;

/** A request that never reached the server; its message is for a toast about what was not done. */
export class NetworkError extends Error {
  constructor() {
    super('Not done: the server is not reachable (stopped or restarting?); try again once it is back');
    this.name = 'NetworkError';
  }
}

let state: ConnectionState = 'online';
let takeBack: (() => void) | null = null;
let polling = false;
let outages = 0;
const listeners: Array<() => void> = [];

export function connectionState(): ConnectionState {
  return state;
}

/** Run ``listener`` each time the server answers again after being lost. */
export function onReconnect(listener: () => void): void {
  listeners.push(listener);
}

/** ``fetch``, telling the connection how it went. An abort is the caller's and stays an AbortError. */
export async function send(input: string, init?: RequestInit): Promise<Response> {
  let response: Response;
  try {
    response = await fetch(input, init);
  } catch (err) {
    if ((err as Error).name === 'AbortError') throw err;
    lost();
    throw new NetworkError();
  }
  reached();
  return response;
}

/** A request made in a worker (the mesh worker's fetch) never reached the server: the error to
 * throw, the connection told, as :func:`send` tells it. */
export function unreachable(): NetworkError {
  lost();
  return new NetworkError();
}

/** A request made in a worker was answered: the connection is online. */
export function answered(): void {
  reached();
}

function lost(): void {
  if (state === 'lost') return;
  state = 'lost';
  outages += 1;
  takeBack = toast(LOST_MESSAGE);
  void poll();
}

function reached(): void {
  if (state === 'online') return;
  state = 'online';
  takeBack?.();
  takeBack = null;
  toast('Reconnected to the server', 'info');
  for (const listener of listeners) listener();
}

/** Ask the server until it answers: never two polls at once, so no storm of requests. */
async function poll(): Promise<void> {
  if (polling) return;
  polling = true;
  try {
    let outage = outages;
    let wait = FIRST_WAIT_MS;
    while (state === 'lost') {
      if (outage !== outages) [outage, wait] = [outages, FIRST_WAIT_MS]; // lost again meanwhile: start over
      await new Promise((resolve) => window.setTimeout(resolve, wait));
      if (state !== 'lost') break;
      try {
        await fetch('/api/options', { cache: 'no-store', signal: AbortSignal.timeout(POLL_TIMEOUT_MS) });
        reached();
      } catch {
        wait = Math.min(LONGEST_WAIT_MS, wait * 1.5);
      }
    }
  } finally {
    polling = false;
  }
}
