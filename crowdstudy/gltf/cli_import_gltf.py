"""``crowdstudy import-gltf CHARACTER.glb --out body.json``: a user's skinned character as a
body record (``{"model": "gltf", "path": ...}``), with its joint mapping printed."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from crowdstudy.errors import InvalidInputError


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("input", help="skinned character, .glb or .gltf (Blender, Mixamo, Ready Player Me, VRM)")
    parser.add_argument("--out", required=True, help="output body record .json")
    parser.add_argument("--skin", type=int, default=0, help="which skin of the file (default 0)")
    parser.add_argument("--height", type=float, help="rescale the character to this stature (m)")
    parser.add_argument("--sex", choices=("female", "male"), help="label stored in the record")


def run(args: argparse.Namespace) -> int:
    from crowdstudy.body import load_body
    from crowdstudy.paths import check_output_path

    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise InvalidInputError(f"--out: expected a .json file name, got {args.out!r}")
    check_output_path(out, "--out")
    record = {"model": "gltf", "path": str(Path(args.input).resolve()), "skin": args.skin}
    if args.height is not None:
        record["height"] = args.height
    if args.sex:
        record["sex"] = args.sex
    from crowdstudy.body.gltf_model import read_character

    ch = read_character(record["path"], skin=args.skin, height=args.height)
    body = load_body(record)
    out.write_text(json.dumps(record, indent=2, sort_keys=True) + "\n")
    print(
        f"{args.input}: naming convention {ch.convention}, {body.n_vertices} vertices, "
        f"{len(body.faces)} faces, stature {body.height:.3f} m, texture: {'yes' if ch.texture is not None else 'no'}"
    )
    for name, joint in ch.joint_map.items():
        print(f"  {name:32s} -> {joint}")
    if ch.synthesized:
        print(f"  placed from neighbours: {', '.join(ch.synthesized)}")
    for name, joint in ch.unmapped.items():
        print(f"  {name:32s} -> weights to {joint}")
    print(f"wrote {out}")
    return 0
