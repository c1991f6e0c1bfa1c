"""Pictures of results, drawn with numpy and Pillow alone (no OpenGL): a shaded view of a mesh
and the side-by-side summary the demo writes."""

from __future__ import annotations

import math

import numpy as np

PANEL = 360  # side of each panel of result.png, pixels
BACKGROUND = np.array([24, 24, 28], dtype=np.uint8)
CLAY = np.array([0.86, 0.80, 0.70])


def result_picture(image: np.ndarray, normals: np.ndarray, mesh) -> np.ndarray:
    """Input photo, normal map and a shaded 3D view side by side, with captions: (H, W, 3) uint8."""
    from PIL import Image

    height, width = image.shape
    scale = PANEL / max(height, width)
    size = (max(1, round(width * scale)), max(1, round(height * scale)))

    photo = np.repeat((np.clip(image, 0, 1) * 255).round().astype(np.uint8)[..., None], 3, axis=2)
    shown = np.where(np.isnan(normals), -1.0, normals)  # off the object: black
    normal_rgb = ((shown + 1.0) * 127.5).round().clip(0, 255).astype(np.uint8)
    panels = [
        (np.asarray(Image.fromarray(photo).resize(size, Image.Resampling.LANCZOS)), "input photo"),
        (np.asarray(Image.fromarray(normal_rgb).resize(size, Image.Resampling.NEAREST)), "recovered normals"),
        (render_mesh(mesh, PANEL, PANEL), "3D mesh, turned 20° and tilted back 35°"),
    ]
    return compose(panels)


def compose(panels: list[tuple[np.ndarray, str]]) -> np.ndarray:
    from PIL import Image, ImageDraw, ImageFont

    gap, caption = 16, 34
    height = max(p.shape[0] for p, _ in panels)
    width = sum(p.shape[1] for p, _ in panels) + gap * (len(panels) + 1)
    canvas = Image.new("RGB", (width, height + caption + gap), tuple(int(v) for v in BACKGROUND))
    draw = ImageDraw.Draw(canvas)
    try:
        font = ImageFont.load_default(size=18)
    except TypeError:  # Pillow without FreeType sizes
        font = ImageFont.load_default()
    x = gap
    for pixels, text in panels:
        top = gap + (height - pixels.shape[0]) // 2
        canvas.paste(Image.fromarray(pixels), (x, top))
        text_width = draw.textlength(text, font=font)
        draw.text(
            (x + (pixels.shape[1] - text_width) / 2, gap + height + 6), text, fill=(225, 225, 225), font=font
        )
        x += pixels.shape[1] + gap
    return np.asarray(canvas)


def rotation(tilt_deg: float, turn_deg: float) -> np.ndarray:
    """Turn about the vertical axis by ``turn``, then tip the top away from the viewer by ``tilt``."""
    a, b = math.radians(turn_deg), math.radians(-tilt_deg)
    turn = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    tip = np.array([[1, 0, 0], [0, math.cos(b), -math.sin(b)], [0, math.sin(b), math.cos(b)]])
    return tip @ turn


def render_mesh(
    mesh, height: int, width: int, *, tilt_deg: float = 35.0, turn_deg: float = -20.0
) -> np.ndarray:
    """A shaded view of a mesh, drawn with numpy alone: (height, width, 3) uint8.

    The mesh is turned (see :func:`rotation`) and projected orthographically; every triangle is
    sampled densely enough to leave no gap between samples (barycentric grids sized by its
    longest projected edge), each sample takes the interpolated vertex normal (the area-weighted
    normal of the triangles around the vertex: the shape of the mesh itself, as smooth shading
    shows it), and a z-buffer keeps the nearest sample per pixel. Shading is Lambertian from a
    key light at the upper left and a weaker fill light at the right, two-sided (back faces are
    lit as if facing the viewer), plus some ambient light.
    """
    turn_and_tilt = rotation(tilt_deg, turn_deg)
    vertices = (mesh.vertices - (mesh.vertices.min(0) + mesh.vertices.max(0)) / 2) @ turn_and_tilt.T
    # shade the surface the mesh really has: area-weighted normals of its triangles
    a, b, c = (vertices[mesh.faces[:, k]] for k in range(3))
    face_normals = np.cross(b - a, c - a)
    vertex_normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(vertex_normals, mesh.faces[:, k], face_normals)
    margin = 0.06
    extent = np.ptp(vertices[:, :2], axis=0).clip(1e-9)
    scale = (1 - 2 * margin) * min(width / extent[0], height / extent[1])
    # screen: column right, row down
    screen = np.column_stack([vertices[:, 0] * scale + width / 2, -vertices[:, 1] * scale + height / 2])

    corners = screen[mesh.faces]  # (F, 3, 2)
    edges = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    samples_per_edge = np.clip(np.ceil(edges * 1.5).astype(int) + 1, 2, 256)

    pixel_ids, depths, sample_normals = [], [], []
    for k in np.unique(samples_per_edge):
        faces = mesh.faces[samples_per_edge == k]
        i, j = np.nonzero(np.add.outer(np.arange(k), np.arange(k)) <= k - 1)
        weights = np.column_stack([i, j, k - 1 - i - j]) / (k - 1)  # (S, 3) barycentric
        xy = np.einsum("sv,fvd->fsd", weights, screen[faces]).reshape(-1, 2)
        z = np.einsum("sv,fv->fs", weights, vertices[faces, 2]).ravel()
        n = np.einsum("sv,fvd->fsd", weights, vertex_normals[faces]).reshape(-1, 3)
        col, row = np.floor(xy[:, 0]).astype(int), np.floor(xy[:, 1]).astype(int)
        inside = (row >= 0) & (row < height) & (col >= 0) & (col < width)
        pixel_ids.append((row * width + col)[inside])
        depths.append(z[inside])
        sample_normals.append(n[inside])
    pixel_ids = np.concatenate(pixel_ids)
    depths = np.concatenate(depths)
    sample_normals = np.concatenate(sample_normals)

    # z-buffer: the nearest sample (largest z) of each pixel
    order = np.argsort(-depths, kind="stable")
    first = np.unique(pixel_ids[order], return_index=True)[1]
    winners = order[first]
    n = sample_normals[winners]
    n /= np.linalg.norm(n, axis=1, keepdims=True).clip(1e-12)
    n[n[:, 2] < 0] *= -1  # two-sided
    key = np.array([-0.62, 0.50, 0.60])  # upper left, raking enough to show relief
    fill = np.array([0.70, -0.10, 0.70])  # weaker, from the right: the dark side keeps its shape
    shade = 0.10 + 0.84 * np.clip(n @ (key / np.linalg.norm(key)), 0, 1)
    shade += 0.12 * np.clip(n @ (fill / np.linalg.norm(fill)), 0, 1)

    picture = np.tile(BACKGROUND, (height * width, 1)).astype(np.float64)
    picture[pixel_ids[winners]] = 255 * shade[:, None] * CLAY
    return picture.reshape(height, width, 3).round().clip(0, 255).astype(np.uint8)
