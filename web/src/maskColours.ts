// The mask overlay's colours (RGBA), shared by the page (maskBits.ts paintMask) and the mask worker.

/** An object pixel inside the mask: a light tint. */
export const MASK_FILL = [56, 189, 248, 46] as const;
/** An object pixel on the mask's edge: bright. */
export const MASK_EDGE = [94, 234, 212, 230] as const;
