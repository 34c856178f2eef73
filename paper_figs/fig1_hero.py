"""Paper Fig. 1: the concert crowd, a hero frame (Ours, 1920x1080).

The study's densest concert cell (D5: 60 dancers on the 9 m^2 floor, the design's cell
seed) after the physics correction, rendered at full HD from the stage's side, a little
above the crowd, so the dancers face the camera. The sidecar holds the frame, the camera,
and the mesh overlap (litres per character) of that frame, Baseline and Ours. The
animations are those of ``fig5_frames.py`` (same cache).

    .venv/bin/python paper_figs/fig1_hero.py            # 1 s clip, the last frame, 1920x1080
    .venv/bin/python paper_figs/fig1_hero.py --quick    # 0.4 s clip, 1920x1080
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from fig5_frames import cell_animations  # noqa: E402
from figstyle import out_path  # noqa: E402

#: the camera: beside the stage (+y), above the dancers' heads, looking down at the crowd (m)
EYE, TARGET = (2.2, 4.6, 2.6), (0.0, 0.0, 1.0)
WIDTH, HEIGHT = 1920, 1080


def main(argv=None) -> int:
    from figstyle import figure_args

    args = figure_args(__doc__.splitlines()[0], argv)
    import json

    from PIL import Image

    from crowdstudy.design import load_design
    from crowdstudy.metrics.overlap import overlap_volume
    from crowdstudy.provenance import provenance
    from crowdstudy.render.camera import free_camera
    from crowdstudy.render.renderer import CrowdRenderer

    design = load_design()
    duration = 0.4 if args.quick else 1.0
    base, ours = cell_animations(design, "D5", duration, args.refresh)
    frame = ours.n_frames - 1
    with CrowdRenderer(ours, design=design, width=WIDTH, height=HEIGHT) as r:
        r.set_view(free_camera(EYE, TARGET, fov=42.0))
        image = r.render(frame)
    path = out_path("fig1_hero", args)
    Image.fromarray(image).save(path)
    litres = {
        m: 1000.0 * float(overlap_volume(a, resolution=0.02, frames=[frame]).mean)
        for m, a in (("Baseline", base), ("Ours", ours))
    }
    info = {
        "figure": path.name,
        "provenance": provenance(design.seed),
        "level": "D5",
        "characters": ours.n_characters,
        "method": "Ours",
        "frame": frame,
        "width": WIDTH,
        "height": HEIGHT,
        "camera": {"eye": EYE, "target": TARGET, "fov": 42.0},
        "overlap_litres_per_character": litres,
        "pixel_std": float(np.std(image)),
    }
    path.with_suffix(".json").write_text(json.dumps(info, indent=2, default=str))
    print(f"wrote {path}")
    print(f"  overlap at frame {frame}: Baseline {litres['Baseline']:.3f} L, Ours {litres['Ours']:.3f} L per character")
    return 0


if __name__ == "__main__":
    sys.exit(main())
