"""Warp kernels live at module level in the kernel modules, and only those import Warp.

``import crowdstudy`` and every other module of the package stay free of Warp (importing
and initialising it takes seconds): a module that launches kernels imports the kernel
module inside the launching function. Importing a kernel module configures Warp first
(:func:`crowdstudy.warp_runtime.get_warp`), so its kernels compile into the project's
kernel cache whoever launches them.
"""

import ast
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import crowdstudy
from crowdstudy.precompile import KERNEL_MODULES

PACKAGE = Path(crowdstudy.__file__).resolve().parent
#: kernel modules whose kernels a factory function builds (listed with it in KERNEL_MODULES)
FACTORY_MODULES = {name for name, factory in KERNEL_MODULES if factory}


def _python(code: str, **env: str | None) -> str:
    """Run ``code`` in a fresh interpreter (``env``: variables to set, None to unset); its stdout."""
    environ = dict(os.environ)
    for key, value in env.items():
        if value is None:
            environ.pop(key, None)
        else:
            environ[key] = value
    proc = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, env=environ, timeout=300
    )
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def _is_warp_decorator(node: ast.expr) -> bool:
    """``@wp.kernel``, ``@wp.func`` (or called, ``@wp.kernel(...)``)."""
    if isinstance(node, ast.Call):
        node = node.func
    return (
        isinstance(node, ast.Attribute)
        and node.attr in ("kernel", "func")
        and isinstance(node.value, ast.Name)
        and node.value.id == "wp"
    )


def _module_name(path: Path) -> str:
    return ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts)


def test_no_module_but_the_kernel_modules_imports_warp():
    out = _python(f"""
        import importlib, json, pkgutil, sys
        import crowdstudy
        kernel_modules = {sorted(name for name, _ in KERNEL_MODULES)!r}
        imported = []
        for info in pkgutil.walk_packages(crowdstudy.__path__, "crowdstudy."):
            if info.name in kernel_modules or info.name.endswith("__main__"):
                continue
            importlib.import_module(info.name)
            imported.append(info.name)
        print(json.dumps({{"imported": imported, "warp": "warp" in sys.modules}}))
    """)
    res = json.loads(out)
    assert {
        "crowdstudy.body.skinning",
        "crowdstudy.physics",
        "crowdstudy.physics.solver",
        "crowdstudy.physics.collision",
        "crowdstudy.navigation.orca",
        "crowdstudy.metrics.overlap",
    } <= set(res["imported"])
    assert not res["warp"]


def test_kernels_and_funcs_are_defined_at_module_level():
    nested, found = [], set()
    for path in sorted(PACKAGE.rglob("*.py")):
        name = _module_name(path)
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        top = {id(node) for node in tree.body}
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef) and any(_is_warp_decorator(d) for d in node.decorator_list):
                found.add(name)
                if id(node) not in top and name not in FACTORY_MODULES:
                    nested.append(f"{name}.{node.name} (line {node.lineno})")
    assert not nested, "Warp kernels or funcs defined inside a function: " + ", ".join(nested)
    assert found == {name for name, _ in KERNEL_MODULES}


@pytest.mark.parametrize("module", sorted(name for name, factory in KERNEL_MODULES if factory is None))
def test_importing_a_kernel_module_sets_the_project_kernel_cache(module, tmp_path):
    out = _python(
        f"""
        import importlib
        import warp
        importlib.import_module({module!r})
        print(warp.config.kernel_cache_dir)
        print(warp.get_module({module!r}).options["enable_backward"])
    """,
        CROWDSTUDY_CACHE=str(tmp_path),
        WARP_CACHE_PATH=None,
    )
    cache, backward = out.split()
    assert Path(cache).resolve().is_relative_to((tmp_path / "warp-cache").resolve())
    assert backward == "False"
