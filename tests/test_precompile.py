"""`crowdstudy precompile` (set-up runs it): every Warp module of the toolkit, and only those,
is compiled into the kernel cache, so no test or first run compiles one."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

import crowdstudy
from crowdstudy.errors import InvalidInputError
from crowdstudy.precompile import KERNEL_MODULES, precompile

PACKAGE = Path(crowdstudy.__file__).resolve().parent


def test_every_module_with_warp_kernels_is_listed():
    found = set()
    for path in PACKAGE.rglob("*.py"):
        if re.search(r"^\s*@wp\.(kernel|func)\b", path.read_text(encoding="utf-8"), flags=re.M):
            found.add(".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts))
    assert found == {name for name, _ in KERNEL_MODULES}


def test_precompile_loads_every_module_into_the_cache():
    from crowdstudy.warp_runtime import get_warp

    wp = get_warp()
    res = precompile("cpu")
    assert res["modules"] == len(KERNEL_MODULES)
    cache = Path(wp.config.kernel_cache_dir)
    for name, _ in KERNEL_MODULES:
        module = wp.get_module(name)
        assert module.execs, name  # loaded on the CPU
        assert not module.options.get("enable_backward", True), name
        # the binary lies in the cache under the module's name and the hash a launch asks for
        digest = module.get_module_hash(1).hex()[:7]
        assert (cache / f"wp_{name}_{digest}").is_dir(), (name, sorted(p.name for p in cache.iterdir()))


def test_precompile_cli_and_bad_arguments():
    proc = subprocess.run(
        [sys.executable, "-m", "crowdstudy", "precompile"], capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stderr
    assert f"{len(KERNEL_MODULES)} Warp modules ready on cpu" in proc.stdout
    with pytest.raises(InvalidInputError, match="workers"):
        precompile("cpu", workers=-1)
    with pytest.raises(InvalidInputError, match="device"):
        precompile("tpu:0")
