"""The package installs like a library, with the dependencies it imports.

A wheel (not an editable install) put into a fresh virtual environment and run from a
folder outside the source tree finds every resource it needs inside the installed package
(design, consent text, shaders, the questionnaire's front end with jsPsych, licences) and
writes nothing into site-packages.

The temporary environment gets the wheel alone (``pip install --no-deps``); it sees the
heavy dependencies of the project's ``.venv`` through a ``.pth`` line naming .venv's
site-packages (a bare path: .venv's own ``.pth`` files, among them the editable install's
finder, are not run, so the source tree cannot shadow the wheel).

The core dependencies of pyproject.toml are what the runtime imports at module level; every
other third-party import (inside functions) is declared in an extra.
"""

import ast
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import textwrap
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
UI_MODULES = ROOT / "ui" / "node_modules"

# Runs inside the temporary environment, in a folder outside the source tree.
DRIVER = textwrap.dedent(r"""
    import json, sys, warnings
    from pathlib import Path

    import crowdstudy
    from crowdstudy.design import default_design_path, load_design
    from crowdstudy.package_data import read_resource, resource_path
    from crowdstudy.paths import cache_root
    from crowdstudy.render.gpu import shader_source
    from crowdstudy.study.consent import find_consent_file, load_consent_html
    from crowdstudy.study.server import build_config, default_ui_dir

    out = {"file": crowdstudy.__file__, "cache_root": str(cache_root())}
    design = load_design()
    out["design"] = str(default_design_path())
    out["n_stimuli"] = len(design.stimuli())
    out["consent"] = load_consent_html(find_consent_file(None, default_design_path().parent))[:200]
    out["shaders"] = {n: len(shader_source(n)) for n in ("lighting.glsl", "display.glsl", "character.vert",
                                                          "character.frag", "static.vert", "overlap.frag")}
    out["assets"] = read_resource("crowdstudy.body", "ASSETS.md")[:80]
    out["ui_dir"] = str(default_ui_dir())

    # The questionnaire through the installed package: page, own scripts, jsPsych and plugins.
    from starlette.testclient import TestClient
    from crowdstudy.study.app import create_app
    from crowdstudy.study.routes_static import UI_PLUGINS
    from crowdstudy.study.fake_stimuli import write_fake_stimuli
    stim = write_fake_stimuli(Path("stim"), n_files=2, seconds=0.5, width=64, height=36)
    cfg = build_config(stim, db="sqlite:///study.db", admin_token="install-test-token-0123456789")
    out["served_consent"] = cfg.consent_html[:200]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        client = TestClient(create_app(cfg))
    urls = ["/", "/js/study.js", "/js/plugin-video-likert-loop.js", "/css/study.css",
            "/lib/jspsych/dist/index.browser.min.js", "/lib/jspsych/css/jspsych.css"] + \
        [f"/lib/{p}/index.browser.min.js" for p in UI_PLUGINS]
    out["http"] = {u: [client.get(u).status_code, len(client.get(u).content)] for u in urls}
    cfg.store.close()

    # A tiny pipeline: layout, navigation, statistics (no GPU, no rendering).
    from crowdstudy.layout.concert import concert_layout
    from crowdstudy.navigation.corridor import corridor_crowd
    from crowdstudy.stats.synthetic import simulate_responses
    crowd = concert_layout(design, "D1", design.cell_seed(design.stage("stationary"), "D1"))
    out["layout_agents"] = crowd.n_agents
    walk = corridor_crowd(design, "D1", 1, duration=0.2, warm_up=0.1)
    out["walk_shape"] = list(walk.positions.shape)
    responses = simulate_responses(design, 4, seed=0)
    out["responses"] = len(responses)
    print("DRIVER-RESULT " + json.dumps(out))
""")


def _tree(folder: Path) -> dict:
    """Every file and folder under ``folder`` with its size and modification time."""
    entries = {}
    for dirpath, dirnames, filenames in os.walk(folder):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            st = p.lstat()
            entries[str(p.relative_to(folder))] = (st.st_size, st.st_mtime_ns)
    return entries


def _run(cmd, **kwargs):
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, **kwargs)
    assert proc.returncode == 0, f"{cmd} failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc


def test_front_end_is_one_folder_linked_into_the_package():
    """The questionnaire lives in the top-level ui/; the package's study/ui is a link to it
    (so git holds one copy of each file, and the package finds it)."""
    from crowdstudy.study.server import default_ui_dir

    link = ROOT / "crowdstudy" / "study" / "ui"
    assert link.is_symlink() and link.resolve() == (ROOT / "ui").resolve()
    assert default_ui_dir().resolve() == (ROOT / "ui").resolve()
    for name in ("package.json", "package-lock.json", "index.html", "README.md"):
        assert (ROOT / "ui" / name).is_file(), name
    tracked = subprocess.run(
        ["git", "ls-files", "-s", "crowdstudy/study/ui", "ui"], cwd=ROOT, capture_output=True, text=True
    )
    if tracked.returncode != 0:
        pytest.skip("not a git checkout")
    entries = [line.split(None, 3) for line in tracked.stdout.splitlines()]
    in_package = [(mode, path) for mode, _, _, path in entries if path.startswith("crowdstudy/")]
    assert in_package == [("120000", "crowdstudy/study/ui")], tracked.stdout  # the link alone, no copies
    assert any(path == "ui/package.json" for *_, path in entries), tracked.stdout


@pytest.mark.slow
def test_wheel_installs_and_runs_outside_the_tree(tmp_path):
    try:
        import setuptools
    except ImportError:  # pragma: no cover
        pytest.skip("setuptools is not installed (pip install -e '.[dev]')")
    if int(setuptools.__version__.split(".")[0]) < 77:
        pytest.skip(f"building the wheel offline needs setuptools>=77 (have {setuptools.__version__}); run make setup")
    if not (UI_MODULES / "jspsych" / "dist" / "index.browser.min.js").is_file():
        pytest.skip("the questionnaire's npm packages are not installed; run make setup")

    # 1. Build the wheel from a clean copy of the sources (setuptools' build/ and egg-info
    #    stay out of the working tree, and stale build/lib files cannot leak into it).
    src = tmp_path / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(ROOT / name, src / name)
    shutil.copytree(ROOT / "crowdstudy", src / "crowdstudy", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    dist = tmp_path / "dist"
    _run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "-q",
            "--no-deps",
            "--no-build-isolation",
            "--no-index",
            "-w",
            str(dist),
            str(src),
        ]
    )
    wheels = list(dist.glob("crowdstudy-*.whl"))
    assert len(wheels) == 1, wheels

    # 2. A fresh environment with the wheel alone, then a bare path to .venv's packages.
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)])
    python = venv / "bin" / "python"
    _run(
        [
            sys.executable,
            "-m",
            "pip",
            "--python",
            str(python),
            "install",
            "-q",
            "--no-deps",
            "--no-index",
            str(wheels[0]),
        ]
    )
    site = Path(_run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip())
    deps = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (site / "zz_crowdstudy_test_deps.pth").write_text("".join(f"{d}\n" for d in sorted(deps)))
    installed = site / "crowdstudy"
    assert (installed / "study" / "ui" / "node_modules" / "jspsych" / "dist" / "index.browser.min.js").is_file()
    assert not (installed / "study" / "ui" / "node_modules" / "jspsych" / "src").exists(), (
        "only the files the page loads should ship from node_modules"
    )
    # Every data file of the source package ships (shaders, Markdown, TOML, the motion
    # library's .npz/.json ...): a new kind of file needs a package-data pattern.
    data = [
        p.relative_to(src / "crowdstudy")
        for p in (src / "crowdstudy").rglob("*")
        if p.is_file() and p.suffix not in (".py", ".pyc") and "node_modules" not in p.parts
    ]
    assert any(p.name == "study.toml" for p in data)
    missing = [str(p) for p in data if not (installed / p).is_file()]
    assert not missing, f"data files missing from the wheel (add them to package-data in pyproject.toml): {missing}"
    before = _tree(site)

    # 3. Run from a folder outside the tree, caches in a temporary per-user cache folder.
    work, home, cache = tmp_path / "work", tmp_path / "home", tmp_path / "cache"
    for d in (work, home):
        d.mkdir()
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("PYTHONPATH", "CROWDSTUDY_CACHE", "XDG_CACHE_HOME", "VIRTUAL_ENV", "PYTHONHOME")
    }
    env.update(
        HOME=str(home),
        CROWDSTUDY_CACHE=str(cache),
        MPLBACKEND="Agg",
        PYTHONNOUSERSITE="1",
        PATH=f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}",
    )
    # Warp's compiled kernels are keyed by their source: reuse the test session's cache.
    env["WARP_CACHE_PATH"] = os.environ.get("WARP_CACHE_PATH", str(cache / "warp-cache"))

    helptext = _run([str(venv / "bin" / "crowdstudy"), "--help"], cwd=work, env=env).stdout
    assert "serve" in helptext and "layout" in helptext
    _run([str(venv / "bin" / "crowdstudy"), "layout", "--density", "D1", "--out", "lay/d1.npz"], cwd=work, env=env)
    assert (work / "lay" / "d1.npz").is_file()
    proc = _run([str(python), "-c", DRIVER], cwd=work, env=env)
    line = [x for x in proc.stdout.splitlines() if x.startswith("DRIVER-RESULT ")][-1]
    res = json.loads(line.split(" ", 1)[1])

    # The imported crowdstudy is the installed wheel, not the source tree.
    assert Path(res["file"]).resolve().is_relative_to(installed.resolve()), res["file"]
    assert not Path(res["file"]).resolve().is_relative_to(ROOT.resolve())
    for key in ("design", "ui_dir"):
        assert Path(res[key]).resolve().is_relative_to(installed.resolve()), (key, res[key])
    assert res["cache_root"] == str(cache)
    assert res["n_stimuli"] == 60
    assert "consent" in res["consent"].lower() and res["served_consent"] == res["consent"]
    assert all(n > 0 for n in res["shaders"].values()), res["shaders"]
    assert res["assets"].strip()
    assert all(code == 200 and size > 0 for code, size in res["http"].values()), res["http"]
    assert res["layout_agents"] > 0 and res["walk_shape"][1] > 0 and res["responses"] > 0

    # Nothing was written into the environment's site-packages (the installed package
    # included): outputs went to the working folder, caches to the cache folder.
    after = _tree(site)
    added = sorted(set(after) - set(before))
    changed = sorted(k for k in set(before) & set(after) if before[k] != after[k])
    assert not added and not changed, f"written into site-packages: added {added[:10]}, changed {changed[:10]}"
    assert (work / "study.db").is_file()


def _canonical(name: str) -> str:
    return name.lower().replace("_", "-").replace(".", "-")


def _third_party_imports() -> dict[str, tuple[set[str], set[str]]]:
    """{top-level module: (modules importing it at module level, modules importing it anywhere)}."""
    found: dict[str, tuple[set[str], set[str]]] = {}
    for path in sorted((ROOT / "crowdstudy").rglob("*.py")):
        if "node_modules" in path.parts:
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        top_level = set(map(id, tree.body))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split(".")[0]
                if top in sys.stdlib_module_names or top in ("crowdstudy", "__future__"):
                    continue
                module_level, anywhere = found.setdefault(top, (set(), set()))
                anywhere.add(str(path.relative_to(ROOT)))
                if id(node) in top_level:
                    module_level.add(str(path.relative_to(ROOT)))
    return found


def test_dependencies_match_the_imports():
    from importlib.metadata import packages_distributions

    from packaging.requirements import Requirement

    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    core = {_canonical(Requirement(r).name) for r in project["dependencies"]}
    declared = set(core)
    for reqs in project["optional-dependencies"].values():
        for r in map(Requirement, reqs):
            declared.add(_canonical(r.name))
            declared.update(_canonical(e) for e in r.extras)  # dask[distributed] -> distributed
    assert not core & {"pingouin", "statsmodels", "httpx", "pytest", "playwright"}, core

    dists = packages_distributions()
    for module, (module_level, anywhere) in _third_party_imports().items():
        names = {_canonical(d) for d in dists.get(module, [module])}
        assert names & declared, f"{module} (imported by {sorted(anywhere)[:3]}) is not declared in pyproject.toml"
        if module_level:
            assert names & core, (
                f"{module} is imported at module level by {sorted(module_level)[:3]} but is "
                f"not a core dependency (import it inside the function, or make it core)"
            )
