"""Regenerate the README's pictures of scenes and render quality: ``make docs-images``.

docs/scenes.png: three rods after 3 s on each scene of mjcf/, through each scene's
camera "main" (320x180 each, four per row, full quality).
docs/render_quality.png: the box scene's demo frame at 960x540 rendered with the
scene's own settings ("full": shadow map 4096, 4x MSAA, reflections) and with
derods' default on software GL ("fast"), side by side, with the CPU time each took.
"""

from __future__ import annotations

import pathlib
import sys
import time

import numpy as np

from derods import scenes
from derods.apps import drop
from derods.viz import output, render

DOCS = pathlib.Path(__file__).resolve().parent


def scene_sheet(out: pathlib.Path) -> None:
    tiles = []
    for scene in scenes.names():
        world = drop.build_world(drop.DropParams(scene=scene, rods=3, n_edges=30))
        world.step(int(round(3.0 / world.model.opt.timestep)))
        cam = render.Camera(world.model, 320, 180, "main", quality="full")
        try:
            tiles.append(cam.render(world.data))
        finally:
            cam.close()
    while len(tiles) % 4:
        tiles.append(np.full_like(tiles[0], 255))
    rows = [np.concatenate(tiles[i:i + 4], axis=1) for i in range(0, len(tiles), 4)]
    output.write_image(out, np.concatenate(rows, axis=0))


def quality_pair(out: pathlib.Path) -> dict:
    world = drop.build_world(drop.DropParams())
    world.step(1500)
    images, costs = [], {}
    for quality in ("full", "fast"):
        cam = render.Camera(world.model, 960, 540, "main", quality=quality)
        try:
            cam.render(world.data)
            t0 = time.process_time()
            for _ in range(5):
                img = cam.render(world.data)
            costs[quality] = (time.process_time() - t0) / 5 * 1000
        finally:
            cam.close()
        images.append(img)
    output.write_image(out, np.concatenate(images, axis=1)[::2, ::2])
    return costs


def main() -> int:
    scene_sheet(DOCS / "scenes.png")
    costs = quality_pair(DOCS / "render_quality.png")
    print("wrote docs/scenes.png, docs/render_quality.png; CPU per 960x540 frame: "
          + ", ".join(f"{k} {v:.0f} ms" for k, v in costs.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
