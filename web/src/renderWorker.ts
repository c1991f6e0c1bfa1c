// The render worker: draws the 3D view on the canvas the page hands it (an OffscreenCanvas), so a
// frame that takes hundreds of milliseconds (a large model in software WebGL) never blocks the
// page. The scene is renderScene.ts's; the first message brings the canvas, the rest are its
// RenderMessages, in the order the page sent them.
import { RenderScene, type RenderMessage, type RenderReply } from './renderScene';

const scope = globalThis as unknown as {
  onmessage: unknown;
  postMessage: (message: RenderReply) => void;
  requestAnimationFrame?: (draw: () => void) => number;
};
// a worker's requestAnimationFrame follows the display where the browser has one (Chromium)
const nextFrame = scope.requestAnimationFrame ? (draw: () => void) => scope.requestAnimationFrame!(draw) : (draw: () => void) => setTimeout(draw, 0);
let scene: RenderScene | null = null;

scope.onmessage = (event: MessageEvent<{ type: 'init'; canvas: OffscreenCanvas } | RenderMessage>) => {
  const message = event.data;
  if (message.type === 'init') scene = new RenderScene(message.canvas, (reply) => scope.postMessage(reply), nextFrame);
  else scene?.handle(message);
};
