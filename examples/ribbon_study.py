"""The ribbon study still, docs/images/ribbon-study.png: one oral arm as a ruffled ribbon
(jellysim.render.ribbons), 0.5 m long, 4 cm wide at the root, hanging in a gentle S from a
point, in the scenes' lights and water; the whole arm (left) and a close-up of its upper part.

    PYTHONPATH=src .venv/bin/python examples/ribbon_study.py [out.png]
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

from jellysim.render import povray
from jellysim.render.frame import Camera, Look
from jellysim.render.ribbons import povray_ribbons, ribbon_mesh

LENGTH, WIDTH, TAPER = 0.5, 0.04, 0.35  # m, m, tip width / root width
RUFFLES, RUFFLE_DEPTH = 80.0, 0.4  # waves per metre, fraction of the width
COLOR = (0.55, 0.25, 0.6)  # linear RGB, a purple jellyfish's arm
LOOK = Look(bell_transparency=0.35, glow=0.3, water_color=(0.03, 0.10, 0.22))
PANEL = (320, 480)  # px, each of the two views
VIEWS = (  # (camera location, look_at), m
    ((0.28, -0.5, -0.2), (0.0, 0.0, -0.25)),
    ((0.1, -0.3, -0.08), (0.0, 0.0, -0.11)),
)


def arm() -> np.ndarray:
    """The centreline (100, 3) m: down from the origin in a gentle S."""
    s = np.linspace(0.0, 1.0, 100)
    return np.stack(
        [0.04 * np.sin(2 * np.pi * s) * (0.3 + s), 0.02 * np.sin(np.pi * s), -LENGTH * s], axis=1
    )


def main(out: Path) -> None:
    mesh = ribbon_mesh(arm(), np.array([1.0, 0.0, 0.0]), WIDTH, TAPER, RUFFLES, RUFFLE_DEPTH, 0.3)
    body = povray_ribbons([mesh], COLOR, LOOK, glow=True)
    draft = povray.QUALITIES["draft"]
    still = Image.new("RGB", (PANEL[0] * len(VIEWS), PANEL[1]))
    with tempfile.TemporaryDirectory() as folder:
        for k, (location, target) in enumerate(VIEWS):
            camera = Camera(np.array(location), np.array(target), angle=38.0)
            scene = Path(folder) / f"view{k}.pov"
            scene.write_text(
                "#version 3.7;\nglobal_settings { assumed_gamma 1.0 max_trace_level 8 }\n"
                + povray.camera_block(camera, PANEL)
                + povray.lights_block(camera, LENGTH, draft)
                + povray.water_block(LOOK.water_color, 6.0 * LENGTH, camera)
                + body,
                encoding="utf-8",
            )
            image = scene.with_suffix(".png")
            povray.render_file(povray.find_povray() or "povray", scene, image, PANEL, draft, 2)
            still.paste(Image.open(image).convert("RGB"), (PANEL[0] * k, 0))
    still.save(out, optimize=True)


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "docs/images/ribbon-study.png"))
