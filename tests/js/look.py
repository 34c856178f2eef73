"""Render one frame of a glTF export in Chromium with three.js, beside crowdstudy's own render
of the same frame from the same camera (for looking, not a test).

    python tests/js/look.py ANIM.npz OUT_DIR [--frame 150] [--view V3 | --eye X,Y,Z --target X,Y,Z --fov 30]
                            [--width 1280 --height 720] [--glb FILE.glb]

Writes OUT_DIR/crowd.glb, OUT_DIR/threejs.png, OUT_DIR/crowdstudy.png and
OUT_DIR/side_by_side.png (three.js left, crowdstudy right). With ``--glb`` three.js shows
that file (a corrected glTF crowd, ``crowdstudy correct IN.glb OUT.glb``) instead of an
export of ANIM (its import, ``crowdstudy import-crowd``, for crowdstudy's side).
"""

from __future__ import annotations

import argparse
import functools
import http.server
import shutil
import threading
from pathlib import Path

import numpy as np

from crowdstudy.body.gltf_container import Z_UP_TO_Y_UP
from crowdstudy.gltf.export import export_gltf
from crowdstudy.scene import CrowdAnimation

JS = Path(__file__).resolve().parent
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--headless",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--no-first-run",
]


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("anim")
    ap.add_argument("out", type=Path)
    ap.add_argument("--frame", type=int, default=150)
    ap.add_argument("--view", default="V3")
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--height", type=int, default=720)
    ap.add_argument("--eye", help="free camera position x,y,z (toolkit metres) instead of --view")
    ap.add_argument("--target", help="free camera target x,y,z (toolkit metres)")
    ap.add_argument("--fov", type=float, default=30.0, help="free camera vertical field of view (deg)")
    ap.add_argument("--glb", type=Path, help="show this glTF file in three.js instead of an export of ANIM")
    args = ap.parse_args()
    from PIL import Image
    from playwright.sync_api import sync_playwright

    from crowdstudy.render.renderer import CrowdRenderer

    anim = CrowdAnimation.load(args.anim)
    args.out.mkdir(parents=True, exist_ok=True)
    if args.glb:
        shutil.copy(args.glb, args.out / "crowd.glb")
    else:
        export_gltf(anim, args.out / "crowd.glb")
    with CrowdRenderer(anim, width=args.width, height=args.height) as r:
        view = args.view
        if args.eye:
            from crowdstudy.render.camera import Camera

            view = Camera(
                eye=tuple(float(x) for x in args.eye.split(",")),
                target=tuple(float(x) for x in args.target.split(",")),
                fov=args.fov,
            )
        cam = r.set_view(view)
        ours = r.render(args.frame)
    Image.fromarray(ours).save(args.out / "crowdstudy.png")
    eye = Z_UP_TO_Y_UP @ np.asarray(cam.eye)
    target = Z_UP_TO_Y_UP @ np.asarray(cam.target)

    (args.out / "node_modules").unlink(missing_ok=True)
    (args.out / "node_modules").symlink_to(JS / "node_modules")
    shutil.copy(JS / "gltf_page.html", args.out / "index.html")
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Quiet, directory=str(args.out)))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path="/usr/bin/chromium", args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": args.width, "height": args.height})
            page.goto(f"http://127.0.0.1:{server.server_address[1]}/index.html")
            page.wait_for_function("window.crowdReady === true", timeout=30000)
            print(page.evaluate("crowd.load('crowd.glb')"))
            page.evaluate(
                "([t, e, g, f, w, h]) => crowd.render(t, e, g, f, w, h)",
                [
                    args.frame / anim.fps + anim.meta.get("imported", {}).get("time_start", 0.0),
                    eye.tolist(),
                    target.tolist(),
                    cam.fov,
                    args.width,
                    args.height,
                ],
            )
            page.screenshot(path=str(args.out / "threejs.png"))
            browser.close()
    finally:
        server.shutdown()
        (args.out / "node_modules").unlink(missing_ok=True)
    a = np.asarray(Image.open(args.out / "threejs.png").convert("RGB"))
    Image.fromarray(np.concatenate([a, ours], axis=1)).save(args.out / "side_by_side.png")
    print(f"camera {args.view}: eye {cam.eye}, target {cam.target}, fov {cam.fov}")


if __name__ == "__main__":
    main()
