"""Regenerate every figure of the paper: runs each ``paper_figs/fig*.py`` in turn.

.venv/bin/python paper_figs/make_all.py            # full configuration (``make figures``)
.venv/bin/python paper_figs/make_all.py --quick    # small configuration
.venv/bin/python paper_figs/make_all.py fig4_damping fig_runtime   # a selection
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def scripts() -> list[Path]:
    return sorted(p for p in HERE.glob("fig*.py") if p.stem != "figstyle")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("names", nargs="*", help="figure scripts to run (default: all)")
    parser.add_argument("--quick", action="store_true", help="small, fast configuration")
    args = parser.parse_args(argv)
    chosen = scripts()
    if args.names:
        known = {p.stem: p for p in chosen}
        unknown = [n for n in args.names if n not in known]
        if unknown:
            parser.error(f"unknown figure script(s) {', '.join(unknown)}; available: {', '.join(known)}")
        chosen = [known[n] for n in args.names]
    failed = []
    for script in chosen:
        t0 = time.perf_counter()
        print(f"== {script.stem} ==", flush=True)
        cmd = [sys.executable, str(script)] + (["--quick"] if args.quick else [])
        if subprocess.run(cmd).returncode != 0:
            failed.append(script.stem)
        print(f"   ({time.perf_counter() - t0:.1f} s)", flush=True)
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    print(f"all {len(chosen)} figures written to {HERE / 'out'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
