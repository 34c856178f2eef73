"""``crowdstudy import-crowd FILE.glb|FILE.usda --out anim.npz``: every skinned, animated
character of a glTF or USD (UsdSkel) file as one CrowdAnimation
(:mod:`crowdstudy.interchange.gltf_crowd`, :mod:`crowdstudy.body.usd_stage`). Prints what
was found and, per character, the mapping table: each physics joint's source joint and how
it was found (name table, topology, ``--map``), then the joints that map to none."""

from __future__ import annotations

import argparse

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "input",
        help="glTF file (.glb, .gltf) with skinned or rigid-parts animated characters, or a USD file "
        "(.usd, .usda, .usdc) with UsdSkel characters",
    )
    parser.add_argument("--out", required=True, help="CrowdAnimation .npz to write")
    parser.add_argument(
        "--fps",
        type=float,
        default=None,
        help="resample to FPS (default: the file's key rate; USD: its time samples' rate)",
    )
    parser.add_argument(
        "--animation",
        action="append",
        default=None,
        metavar="NAME",
        help="animation to import, by name or index (repeatable; default: all)",
    )
    parser.add_argument(
        "--map",
        default=None,
        metavar="FILE.json",
        help='joints to force: {"left_knee": "LowerLeg.L", ...} (physics joint: source joint name or index)',
    )


def run(args: argparse.Namespace) -> int:
    from crowdstudy.body.rig_map import read_overrides
    from crowdstudy.errors import InvalidInputError
    from crowdstudy.interchange.gltf_crowd import read_crowd
    from crowdstudy.paths import check_output_path

    out = check_output_path(args.out, "--out")
    if out.suffix.lower() != ".npz":
        raise InvalidInputError(f"--out: expected a .npz file, got {str(out)!r}")
    overrides = read_overrides(args.map) if args.map else None
    crowd = read_crowd(args.input, fps=args.fps, animations=args.animation, overrides=overrides)
    print(crowd.report())
    crowd.anim.save(out)
    print(f"wrote {out}: {crowd.anim.n_characters} characters, {crowd.anim.n_frames} frames at {crowd.anim.fps:g} fps")
    return 0
