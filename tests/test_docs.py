"""The documentation: a short README, links that resolve, no pointers outside the
repository, and the generators of the reference and results pages (scripts/docs_hooks.py,
scripts/results_pages.py). The site itself is built by `make docs` (mkdocs build --strict),
which takes longer than a test should."""

from __future__ import annotations

import ast
import importlib.util
import json
import os
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
README = ROOT / "README.md"
MAX_README_LINES = 250

# Pointers to files outside the repository: the team's design notes and their folder. The
# raw data folder (../shared/data, read by the motion library's builder and a few tests)
# is a data location and may be named.
FORBIDDEN = [
    re.compile("DESIGN" + r"\.md"),
    re.compile("shared" + r"\s+folder", re.I),
    re.compile(r"\.\./" + "shared" + r"(?!/data)"),
]
SOURCE_DIRS = ("crowdstudy", "paper_figs", "benchmarks", "tests", "scripts")


def _module(name: str):
    path = ROOT / "scripts" / f"{name}.py"
    if str(path.parent) not in sys.path:
        sys.path.insert(0, str(path.parent))
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def hooks():
    return _module("docs_hooks")


@pytest.fixture(scope="module")
def results():
    return _module("results_pages")


def _markdown_files() -> list[Path]:
    return [README, ROOT / "CHANGELOG.md", *sorted(DOCS.rglob("*.md"))]


def _without_code(text: str) -> str:
    text = re.sub(r"^(\s*)(```|~~~).*?^\1\2", "", text, flags=re.M | re.S)  # fenced blocks
    return re.sub(r"`[^`\n]*`", "", text)  # inline code


_LINK_RE = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def _relative_links(path: Path) -> list[str]:
    links = []
    for target in _LINK_RE.findall(_without_code(path.read_text(encoding="utf-8"))):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I) or target.startswith("#"):
            continue  # URLs, mailto:, anchors in the page
        links.append(target.split("#", 1)[0])
    return links


def test_readme_is_short():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= MAX_README_LINES, f"README.md has {len(lines)} lines; at most {MAX_README_LINES}"


def test_relative_links_resolve(hooks, results):
    generated = {DOCS / p for p in hooks.api_pages()} | {DOCS / "reference" / "cli.md"}
    generated |= {DOCS / p for p in results.render_all()}
    broken = []
    for md in _markdown_files():
        for target in _relative_links(md):
            resolved = (md.parent / target).resolve()
            if not resolved.exists() and resolved not in generated:
                broken.append(f"{md.relative_to(ROOT)}: {target}")
    assert not broken, "links to missing files:\n" + "\n".join(broken)


def test_the_link_check_sees_a_broken_link(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("[ok](https://example.org) [gone](missing.md#x) `[code](no.md)` [here](#top)\n")
    assert _relative_links(page) == ["missing.md"]


def _source_files(folder: Path, suffixes: tuple[str, ...]) -> list[Path]:
    """Files under ``folder`` with one of ``suffixes``, leaving out npm and cache folders."""
    out = []
    for top, dirs, files in os.walk(folder):
        dirs[:] = sorted(d for d in dirs if d not in ("node_modules", "__pycache__") and not d.startswith("."))
        out += [Path(top) / f for f in sorted(files) if f.endswith(suffixes)]
    return out


def _docstrings_and_comments(path: Path) -> list[tuple[int, str]]:
    text = path.read_text(encoding="utf-8")
    out = []
    tree = ast.parse(text)
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node, clean=False)
            if doc:
                out.append((getattr(node, "lineno", 1), doc))
    for number, line in enumerate(text.splitlines(), 1):  # comments (and the odd '#' in a string)
        if "#" in line:
            out.append((number, line[line.index("#") :]))
    return out


def _forbidden(text: str) -> list[str]:
    return [m.group(0) for pattern in FORBIDDEN for m in pattern.finditer(text)]


def test_the_pointer_check_sees_docstrings_and_comments(tmp_path):
    design, folder = "DESIGN" + ".md", "../" + "shared"
    source = tmp_path / "mod.py"
    source.write_text(
        f'"""See {design}."""\n\n\ndef f():\n    """In the shared  folder."""\n'
        f'    return "{folder} in a plain string is code"  # {folder}/notes\n'
        f"# the raw takes: {folder}/data/mocap\n"
    )
    hits = [hit for _, text in _docstrings_and_comments(source) for hit in _forbidden(text)]
    assert hits == [design, "shared  folder", folder]


def test_no_pointers_outside_the_repository():
    found = []
    texts: list[tuple[str, str]] = [
        (str(p.relative_to(ROOT)), p.read_text(encoding="utf-8")) for p in _markdown_files()
    ]
    for folder in SOURCE_DIRS:
        for path in _source_files(ROOT / folder, (".py",)):
            if path == Path(__file__).resolve():
                continue
            texts += [(f"{path.relative_to(ROOT)}:{line}", doc) for line, doc in _docstrings_and_comments(path)]
        for path in _source_files(ROOT / folder, (".toml", ".md")):
            texts.append((str(path.relative_to(ROOT)), path.read_text(encoding="utf-8")))
    for where, text in texts:
        found += [f"{where}: {hit!r}" for hit in _forbidden(text)]
    assert not found, "pointers to files outside the repository:\n" + "\n".join(found)


def test_every_column_has_a_meaning(hooks):
    page = DOCS / "reference" / "formats.md"
    expanded, problems = hooks.expand_markers(page.read_text(encoding="utf-8"), "reference/formats.md")
    assert not problems, "\n".join(problems)
    assert "<!-- columns:" not in expanded
    from crowdstudy.schema import RESPONSE_COLUMNS

    for column in RESPONSE_COLUMNS:
        assert f"| `{column}` |" in expanded


def test_a_column_table_reports_drift(hooks):
    table, problems = hooks.column_table(
        "crowdstudy.schema.DEMOGRAPHIC_COLUMNS", "- `age`: years\n- `shoe_size`: EU\n", "x.md"
    )
    assert "| 2 | `age` | years |" in table
    assert any("'participant_id'" in p and "no meaning" in p for p in problems)
    assert any("'shoe_size'" in p for p in problems)


def test_the_meta_table_is_generated_from_the_schema(hooks):
    import typing

    from crowdstudy.scene_meta import SceneMeta

    page = (ROOT / "docs/concepts/crowd-animation.md").read_text(encoding="utf-8")
    expanded, problems = hooks.expand_markers(page, "concepts/crowd-animation.md")
    assert problems == [] and "<!-- meta-keys" not in expanded
    for key in typing.get_type_hints(SceneMeta):
        assert f"`{key}`" in expanded.split("Keys of `meta`")[1].split("\n\n")[1]
    assert "| `stage_distance`, `stage_front` | float | (float, m; concert) how far the stage" in expanded
    # a TypedDict whose keys the module's docstring does not describe: each one reported
    _, drift = hooks.meta_table("crowdstudy.scene_meta.PhysicsMeta", "x.md")
    assert any("'crowd_density'" in p and "no entry" in p for p in drift)


def test_cli_page_covers_every_command(hooks):
    from crowdstudy.cli import COMMANDS

    page = hooks.cli_page()
    for name, _, _ in COMMANDS:
        assert f"\n## {name}\n" in page and f"usage: crowdstudy {name}" in page
    assert "### participants withdraw" in page and "### motion build-library" in page


def test_api_pages_cover_every_subpackage(hooks):
    pages = hooks.api_pages()
    for sub in ("physics", "stats", "body", "render", "study"):
        assert f"::: crowdstudy.{sub}" in pages[f"reference/api/{sub}.md"]
    assert "::: crowdstudy.scene" in pages["reference/api/crowdstudy.md"]


def test_nav_pages_exist(hooks, results):
    nav_files = re.findall(
        r":\s*([\w./-]+\.md)\s*$|^\s*-\s*([\w./-]+\.md)\s*$",
        (ROOT / "mkdocs.yml").read_text(encoding="utf-8"),
        flags=re.M,
    )
    generated = set(hooks.api_pages()) | {"reference/cli.md"} | set(results.render_all())
    missing = [p for pair in nav_files for p in pair if p and not (DOCS / p).is_file() and p not in generated]
    assert nav_files and not missing, f"mkdocs.yml names missing pages: {missing}"


def test_results_tables_are_headed_by_command_machine_and_date(results, tmp_path):
    report = {
        "benchmark": "toy",
        "rows": [{"case": "a", "median_s": 0.0123, "ok": True}],
        "command": "crowdstudy bench toy --n 3",
        "date": "2026-12-07T10:00:00+00:00",
        "machine": {"cpu": "Some CPU", "cores": 2, "gpus": [], "load_average": [1.25, 1.0, 0.5]},
        "provenance": {"git_sha": "abc", "seed": 1},
        "extra_rows": [{"x": 1}],
        "repeat": 5,
    }
    (tmp_path / "toy.json").write_text(json.dumps(report))
    (tmp_path / "old.json").write_text(json.dumps({"benchmark": "old", "rows": [{"x": 1.5}]}))
    pages = results.render_all(tmp_path)
    toy = pages["results/toy.md"].splitlines()
    head = "`crowdstudy bench toy --n 3` · Some CPU, 2 cores, no GPU, load 1.2 · 2026-12-07"
    tables = [i for i, line in enumerate(toy) if line.startswith("| ") and toy[i - 1] == ""]
    assert len(tables) == 3  # rows, extra_rows, settings
    assert all(toy[i - 2] == head for i in tables)
    assert "| a | 0.0123 | yes |" in toy
    assert "arguments not recorded" in pages["results/old.md"] and "machine not recorded" in pages["results/old.md"]


def test_published_reports_have_their_heading(results):
    for rel, text in results.render_all().items():
        assert "not recorded" not in text, f"{rel}: a published report lacks its command, machine or date"


def test_a_page_quotes_a_published_table(results, hooks, tmp_path):
    report = {
        "benchmark": "toy",
        "rows": [{"case": "a", "x": 1.5}],
        "summary": [{"variant": "v", "a_pct": 12.345, "ms_ratio": 0.9}],
        "groups": {"g": {"description": "d", "changes": {"a.b": 0}}},
        "command": "crowdstudy bench toy",
        "date": "2026-12-07T10:00:00+00:00",
        "machine": {"cpu": "Some CPU", "cores": 2, "gpus": []},
    }
    (tmp_path / "toy.json").write_text(json.dumps(report))
    text = results.report_table("toy", "summary", ["ms_ratio", "variant"], data_dir=tmp_path, link="../t.md")
    lines = text.splitlines()
    assert lines[0].startswith("`crowdstudy bench toy` · Some CPU")
    assert lines[2:5] == ["| ms_ratio | variant |", "| --- | --- |", "| 0.9 | v |"]
    assert "[toy](../t.md)" in text
    groups = results.report_table("toy", "groups", ["description"], data_dir=tmp_path).splitlines()
    assert groups[2:5] == ["|  | description |", "| --- | --- |", "| g | d |"]
    for key, columns in (("nothing", None), ("summary", ["b_pct"])):
        with pytest.raises(ValueError, match="toy"):
            results.report_table("toy", key, columns, data_dir=tmp_path)
    with pytest.raises(ValueError, match="make results"):
        results.report_table("absent", "rows", data_dir=tmp_path)
    # the hook leaves an unknown report's marker in place and names the page
    marker = "<!-- results: absent_report summary variant -->"
    expanded, problems = hooks.expand_markers(f"x\n{marker}\n", "concepts/p.md")
    assert marker in expanded and problems and problems[0].startswith("concepts/p.md: results absent_report")
