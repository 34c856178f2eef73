"""MkDocs hooks that generate the reference and results pages at build time.

Nothing here is written into ``docs/``: the pages are added to the build in memory.

* ``reference/cli.md``: the ``--help`` of every ``crowdstudy`` command, built from
  :data:`crowdstudy.cli.COMMANDS` (each command's module ``configure`` fills a parser, as
  ``crowdstudy COMMAND --help`` does), sub-commands included, and of every benchmark of
  ``crowdstudy bench``.
* ``reference/api/*.md``: one page per subpackage of ``crowdstudy`` (and one for the
  top-level modules), each a mkdocstrings block read statically by griffe.
* ``results/*.md``: one page per benchmark report in ``docs/results/data/``
  (``scripts/results_pages.py``).
* The docstrings' Sphinx roles (``:func:`~crowdstudy.x.f```), which the Google-style
  parser leaves as text, become code, linked to the API page where the name is a full
  ``crowdstudy.`` path (``~`` shows the last part only, as in Sphinx).
* In any page, ``<!-- columns: dotted.path.CONSTANT -->`` followed by a bullet list
  ``- `column`: meaning`` becomes a table of the constant's columns in the code's order
  with those meanings; a column without a meaning, or a meaning for a column the code does
  not have, is a warning (an error under ``mkdocs build --strict``). Likewise
  ``<!-- results: index -->`` becomes the table of published reports, and
  ``<!-- results: STEM KEY [COLUMN,...] -->`` the table ``KEY`` (``rows``, ``summary`` ...)
  of the published report ``STEM`` (:func:`results_pages.report_table`), headed by its
  command, machine and date: a hand-written page quotes measured numbers without typing them.
  ``<!-- meta-keys: dotted.path.TypedDict -->`` becomes the table of a TypedDict's keys,
  types and meanings (from its module's docstring: :func:`meta_table`).

Generation functions are importable (``tests/test_docs.py`` uses them without MkDocs).
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import importlib
import io
import logging
import os
import posixpath
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "crowdstudy"
sys.path.insert(0, str(Path(__file__).resolve().parent))

import results_pages  # noqa: E402  (beside this file)

log = logging.getLogger("mkdocs.hooks.crowdstudy")

HELP_WIDTH = 80
API_INDEX = "reference/api/index.md"
RESULTS_INDEX = "results/index.md"


# ------------------------------------------------------------------ command line


@contextlib.contextmanager
def _columns(width: int):
    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(width)
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = old


def _subparsers(parser: argparse.ArgumentParser) -> list[tuple[str, argparse.ArgumentParser]]:
    out = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            out.extend(action.choices.items())
    return out


def command_helps() -> list[tuple[str, str, list[tuple[str, str]]]]:
    """[(command, its --help, [(sub-command, its --help), ...])] in the order of
    :data:`crowdstudy.cli.COMMANDS`."""
    from crowdstudy.cli import COMMANDS

    out = []
    with _columns(HELP_WIDTH):
        for name, module_name, description in COMMANDS:
            module = importlib.import_module(module_name)
            parser = argparse.ArgumentParser(prog=f"crowdstudy {name}", description=description)
            module.configure(parser)
            subs = [(sub, p.format_help()) for sub, p in _subparsers(parser)]
            out.append((name, parser.format_help(), subs))
    return out


def benchmark_helps() -> list[tuple[str, str]]:
    """[(benchmark, its --help)] of the scripts in ``benchmarks/`` (empty outside a checkout)."""
    from crowdstudy.bench import available, load_benchmark

    out = []
    with _columns(HELP_WIDTH):
        for name in available():
            module = load_benchmark(name)
            buf = io.StringIO()
            with contextlib.redirect_stdout(buf), contextlib.suppress(SystemExit):
                module.main(["--help"])
            out.append((name, buf.getvalue()))
    return out


def cli_page() -> str:
    from crowdstudy.cli import COMMANDS

    lines = [
        "# Command line",
        "",
        "Generated at build time from the parsers of the `crowdstudy` commands: each section "
        "is what `crowdstudy COMMAND --help` prints. Every command reads and writes files, "
        "so the stages can run one at a time; the [getting started](../getting-started.md) "
        "page walks through them in order.",
        "",
        "| command | what it does |",
        "| --- | --- |",
    ]
    lines += [f"| [`{name}`](#{name}) | {text} |" for name, _, text in COMMANDS]
    for name, text, subs in command_helps():
        lines += ["", f"## {name}", "", "```text", text.rstrip(), "```"]
        for sub, sub_text in subs:
            lines += ["", f"### {name} {sub}", "", "```text", sub_text.rstrip(), "```"]
    benches = benchmark_helps()
    if benches:
        lines += [
            "",
            "## Benchmarks (`crowdstudy bench NAME`)",
            "",
            "Each script in `benchmarks/` (a checkout only) takes its own options after its name. "
            "Reports go to `build/bench/NAME.json`; [results](../results/index.md) says how "
            "they become pages.",
        ]
        for name, text in benches:
            lines += ["", f"### bench {name}", "", "```text", text.rstrip(), "```"]
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------ API reference


def _docstring_summary(path: Path) -> str:
    doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    first = doc.strip().split("\n\n")[0]
    return " ".join(first.split())


def subpackages() -> list[str]:
    """The subpackages of ``crowdstudy`` (folders with ``__init__.py``), sorted."""
    return sorted(p.parent.name for p in PACKAGE.glob("*/__init__.py"))


def api_pages() -> dict[str, str]:
    """{page path: Markdown} of the API reference: an index, one page per subpackage and
    one for the top-level modules."""
    pages: dict[str, str] = {}
    index = [
        "# API reference",
        "",
        "Generated from the docstrings by mkdocstrings; griffe reads the sources without "
        "importing them. One page per subpackage, each with the package's public names "
        "first and then every module.",
        "",
        "| page | what it holds |",
        "| --- | --- |",
        f"| [crowdstudy](crowdstudy.md) | {_docstring_summary(PACKAGE / '__init__.py')} "
        "The top-level modules: scene containers, study design, file columns, errors, provenance. |",
    ]
    for name in subpackages():
        summary = _docstring_summary(PACKAGE / name / "__init__.py")
        index.append(f"| [crowdstudy.{name}]({name}.md) | {summary} |")
        pages[f"reference/api/{name}.md"] = "\n".join(
            [
                f"# crowdstudy.{name}",
                "",
                f"::: crowdstudy.{name}",
                "    options:",
                "      show_submodules: true",
                "      heading_level: 2",
                "",
            ]
        )
    top = sorted(p.stem for p in PACKAGE.glob("*.py") if not p.stem.startswith("_"))
    body = [
        "# crowdstudy",
        "",
        "::: crowdstudy",
        "    options:",
        "      show_submodules: false",
        "      heading_level: 2",
        "",
    ]
    for mod in top:
        body += [
            f"::: crowdstudy.{mod}",
            "    options:",
            "      show_root_heading: true",
            "      show_root_full_path: true",
            "      heading_level: 2",
            "",
        ]
    pages["reference/api/crowdstudy.md"] = "\n".join(body)
    pages[API_INDEX] = "\n".join(index) + "\n"
    return pages


# ------------------------------------------------------------------ column tables

_COLUMNS_RE = re.compile(r"^<!-- columns: ([\w.]+) -->\n((?:- `[^`]+`:.*\n(?:  .*\n)*)*)", re.M)
_ITEM_RE = re.compile(r"^- `([^`]+)`:(.*(?:\n  .*)*)", re.M)


def _constant(dotted: str):
    module_name, _, attr = dotted.rpartition(".")
    return getattr(importlib.import_module(module_name), attr)


def column_table(dotted: str, described: str, where: str = "") -> tuple[str, list[str]]:
    """The table of constant ``dotted``'s columns with the meanings of the bullet list
    ``described``; and the problems found (columns without a meaning, meanings of columns
    the constant does not have)."""
    columns = list(_constant(dotted))
    meanings = {m.group(1): " ".join(m.group(2).split()) for m in _ITEM_RE.finditer(described)}
    problems = [f"{where}: column {c!r} of {dotted} has no meaning in the page" for c in columns if c not in meanings]
    problems += [
        f"{where}: the page describes {c!r}, which {dotted} does not have" for c in meanings if c not in columns
    ]
    lines = [f"Columns, in order (`{dotted}`):", "", "| # | column | meaning |", "| --- | --- | --- |"]
    lines += [f"| {i} | `{c}` | {meanings.get(c, '')} |" for i, c in enumerate(columns, 1)]
    return "\n".join(lines) + "\n", problems


# ------------------------------------------------------------------ the keys of meta

_META_RE = re.compile(r"^<!-- meta-keys: ([\w.]+) -->\n", re.M)
#: a key's entry in a module docstring: a line naming the keys, ````a```` (type), then
#: indented lines saying what they mean
_ENTRY_RE = re.compile(r"^(``\w+``.*)\n((?:    .*\n?)+)", re.M)
_ROLE_TEXT_RE = re.compile(r":\w+:`([^`<]+?) <[^`>]+>`")


def _type_name(hint) -> str:
    """A type hint as the page shows it: ``int or None``, ``list[float]``, a TypedDict as a
    link to its API entry."""
    import types
    import typing

    args = typing.get_args(hint)
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return " or ".join(_type_name(a) for a in args)
    if args:
        return f"{typing.get_origin(hint).__name__}[{', '.join(_type_name(a) for a in args)}]"
    if typing.is_typeddict(hint):
        return f":class:`~{hint.__module__}.{hint.__name__}`"
    return "None" if hint is type(None) else getattr(hint, "__name__", str(hint))


def _markdown(rst: str) -> str:
    """Docstring text as Markdown in one table cell: ````x```` -> `x`, roles with a title
    shown by their title (the page's role filter links the rest), ``|`` escaped."""
    text = _ROLE_TEXT_RE.sub(r"`\1`", " ".join(rst.split()))
    return text.replace("``", "`").replace("|", "\\|")


def _plain_type(note: str) -> bool:
    """Whether a docstring's ``(type)`` note says no more than the annotation (no unit)."""
    words = re.sub(r":class:`[^`]+`", "T", note).split()
    return all(w in {"str", "int", "float", "dict", "None", "or", "T"} for w in words)


def meta_table(dotted: str, where: str = "") -> tuple[str, list[str]]:
    """The table of the TypedDict ``dotted``'s keys (in the code's order, keys that share an
    entry in one row), their types (from its annotations) and meanings (from its module's
    docstring, where each key has an entry: a line ````key```` (type, unit), then indented
    text); and the problems found (a key without an entry, an entry for a key the TypedDict
    does not have)."""
    import typing

    typed = _constant(dotted)
    hints = typing.get_type_hints(typed)
    doc = importlib.import_module(typed.__module__).__doc__ or ""
    entries = [(re.findall(r"``(\w+)``", m.group(1)), m.group(1), m.group(2)) for m in _ENTRY_RE.finditer(doc)]
    entry_of = {key: i for i, (keys, _, _) in enumerate(entries) for key in keys}
    problems = [
        f"{where}: key {k!r} of {dotted} has no entry in {typed.__module__}" for k in hints if k not in entry_of
    ]
    problems += [
        f"{where}: {typed.__module__} describes {k!r}, not a key of {dotted}" for k in entry_of if k not in hints
    ]
    rows: dict[object, list[str]] = {}
    for key in hints:
        rows.setdefault(entry_of.get(key, key), []).append(key)
    lines = [f"Keys of `meta` (`{dotted}`):", "", "| key | type | meaning |", "| --- | --- | --- |"]
    for entry, keys in rows.items():
        types = dict.fromkeys(_type_name(hints[k]) for k in keys)
        meaning = ""
        if isinstance(entry, int):
            head, text = entries[entry][1], entries[entry][2]
            note = ", ".join(n for n in re.findall(r"\((.*?)\)(?:,|$)", head) if not _plain_type(n))
            meaning = _markdown(f"({note}) {text}" if note else text)
        cells = (", ".join(f"`{k}`" for k in keys), ", ".join(types), meaning)
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n", problems


_RESULTS_RE = re.compile(r"^<!-- results: ([\w-]+) ([\w-]+)(?: ([\w,]+))? -->$", re.M)


def expand_markers(markdown: str, where: str = "") -> tuple[str, list[str]]:
    """``markdown`` with its column and results markers expanded; the problems found."""
    problems: list[str] = []

    def results(match: re.Match) -> str:
        stem, key, columns = match.group(1), match.group(2), match.group(3)
        link = posixpath.relpath(results_pages.page_path(stem), posixpath.dirname(where) or ".")
        try:
            return results_pages.report_table(stem, key, columns.split(",") if columns else None, link=link)
        except ValueError as exc:
            problems.append(f"{where}: {exc}")
            return match.group(0)

    def columns(match: re.Match) -> str:
        table, found = column_table(match.group(1), match.group(2), where)
        problems.extend(found)
        return table

    def meta_keys(match: re.Match) -> str:
        table, found = meta_table(match.group(1), where)
        problems.extend(found)
        return table

    markdown = _COLUMNS_RE.sub(columns, markdown)
    markdown = _META_RE.sub(meta_keys, markdown)
    markdown = _RESULTS_RE.sub(results, markdown)
    if "<!-- results: index -->" in markdown:
        markdown = markdown.replace("<!-- results: index -->", results_pages.index_table(results_pages.load_reports()))
    return markdown, problems


# ------------------------------------------------------------------ MkDocs events


def generated_pages() -> dict[str, str]:
    pages = {"reference/cli.md": cli_page()}
    pages.update(api_pages())
    pages.update(results_pages.render_all())
    return pages


def _nav_entries(pages: dict[str, str], prefix: str, index: str) -> list:
    entries = [index]
    for path in sorted(p for p in pages if p.startswith(prefix) and p != index):
        title = pages[path].split("\n", 1)[0].lstrip("# ").strip()
        entries.append({title: path})
    return entries


def _expand_nav(nav, pages: dict[str, str]):
    if isinstance(nav, list):
        return [_expand_nav(item, pages) for item in nav]
    if isinstance(nav, dict):
        out = {}
        for title, value in nav.items():
            if value == API_INDEX:
                out[title] = _nav_entries(pages, "reference/api/", API_INDEX)
            elif value == RESULTS_INDEX:
                out[title] = _nav_entries(pages, "results/", RESULTS_INDEX)
            else:
                out[title] = _expand_nav(value, pages)
        return out
    return nav


_PAGES: dict[str, str] = {}


def on_config(config):
    _PAGES.clear()
    _PAGES.update(generated_pages())
    if config.get("nav"):
        config["nav"] = _expand_nav(config["nav"], _PAGES)
    return config


def on_files(files, config):
    from mkdocs.structure.files import File

    for path, text in _PAGES.items():
        if files.get_file_from_path(path) is not None:
            log.warning("%s is generated at build time; remove the file of that name from docs/", path)
            continue
        files.append(File.generated(config, path, content=text))
    return files


_ROLE_RE = re.compile(r":(?:func|class|mod|meth|data|attr|exc|obj|const):\s*<code>(~?)([^<]+)</code>")


def sphinx_roles(html: str) -> str:
    """``:role:<code>~a.b.c</code>`` in rendered HTML -> ``<code>c</code>``, linked (an
    optional autoref, resolved by mkdocs-autorefs) when the name is a full crowdstudy path."""

    def replace(match: re.Match) -> str:
        tilde, name = match.group(1), match.group(2).strip()
        shown = name.rsplit(".", 1)[-1] if tilde else name
        code = f"<code>{shown}</code>"
        if name.startswith("crowdstudy."):
            return f'<autoref identifier="{name}" optional>{code}</autoref>'
        return code

    return _ROLE_RE.sub(replace, html)


def on_page_content(html, page, config, files):
    return sphinx_roles(html)


def on_page_markdown(markdown, page, config, files):
    markdown, problems = expand_markers(markdown, page.file.src_uri)
    for problem in problems:
        log.warning(problem)
    return markdown
