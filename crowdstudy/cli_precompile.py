"""``crowdstudy precompile``: compile every Warp kernel module once, ahead of use
(:func:`crowdstudy.precompile.precompile`; set-up runs it)."""

from __future__ import annotations

import argparse

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--device", default="cpu", help="Warp device to compile for (default cpu; cuda:0 for a GPU)")
    parser.add_argument("--workers", type=int, default=2, help="modules compiled at once (default 2)")


def run(args: argparse.Namespace) -> int:
    from crowdstudy.precompile import precompile
    from crowdstudy.warp_runtime import get_warp

    res = precompile(args.device, workers=args.workers)
    cache = get_warp().config.kernel_cache_dir
    print(f"precompile: {res['modules']} Warp modules ready on {args.device} in {res['seconds']:.1f} s (cache {cache})")
    return 0
