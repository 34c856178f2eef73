"""Results pages of the documentation, generated from benchmark reports.

``crowdstudy bench NAME`` writes ``build/bench/NAME.json`` (:func:`crowdstudy.bench.write_report`:
``rows``, ``command``, ``machine``, ``date``, ``provenance`` and the benchmark's own keys).
The reports to publish are copied into ``docs/results/data/`` (``make results``) and kept
in the repository, so a fresh clone builds the same pages. This script turns each report
into one Markdown page: every table is headed by one line naming the command, the machine
and the date it was measured on.

``make docs`` runs it through the MkDocs hook (``scripts/docs_hooks.py``), which adds the
pages to the site without writing them into ``docs/``. To look at the Markdown alone::

    python scripts/results_pages.py --out build/results-md
"""

from __future__ import annotations

import argparse
import ast
import json
import math
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DATA_DIR = ROOT / "docs" / "results" / "data"
BENCH_DIR = ROOT / "benchmarks"

__all__ = [
    "load_reports",
    "render_report",
    "render_all",
    "heading_line",
    "index_table",
    "page_path",
    "report_table",
]


def load_reports(data_dir: Path = DATA_DIR) -> dict[str, dict]:
    """{report stem: report} for every ``*.json`` in ``data_dir``, sorted by name."""
    reports = {}
    for path in sorted(Path(data_dir).glob("*.json")):
        try:
            report = json.loads(path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: not valid JSON ({exc})") from None
        if not isinstance(report, dict) or not isinstance(report.get("rows"), list):
            raise ValueError(f"{path}: not a benchmark report (no 'rows' list)")
        reports[path.stem] = report
    return reports


def page_path(stem: str) -> str:
    """The page of report ``stem``, relative to the docs folder."""
    return f"results/{stem}.md"


def _fmt(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return ""
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        if value != 0 and abs(value) < 1e-3:
            return f"{value:.3e}"
        if abs(value) >= 1e4:
            return f"{value:.0f}"
        return f"{value:.4g}"
    if isinstance(value, (list, dict)):
        text = json.dumps(value, separators=(", ", ": "), default=str)
        return _cell(text if len(text) <= 120 else text[:117] + "...")
    return _cell(str(value))


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _machine_text(machine) -> str:
    if not isinstance(machine, dict):
        return "machine not recorded"
    cpu = machine.get("cpu") or "unknown CPU"
    cores = machine.get("cores")
    gpus = machine.get("gpus") or []
    gpu = ", ".join(gpus) if gpus else "no GPU"
    text = f"{cpu}, {cores} cores, {gpu}" if cores else f"{cpu}, {gpu}"
    load = machine.get("load_average")
    if isinstance(load, (list, tuple)) and load:
        text += f", load {load[0]:.1f}"
    return text


def heading_line(report: dict) -> str:
    """The one line above each table: command, machine, date."""
    command = report.get("command") or f"crowdstudy bench {report.get('benchmark', '?')} (arguments not recorded)"
    date = str(report.get("date") or "date not recorded")[:10]
    return f"`{_cell(command)}` · {_cell(_machine_text(report.get('machine')))} · {date}"


def _table(rows: list[dict], only: list[str] | None = None) -> list[str]:
    columns: list[str] = []
    for row in rows:
        for key in row if isinstance(row, dict) else {}:
            if key not in columns:
                columns.append(key)
    if only is not None:
        columns = [c for c in only if c in columns]
    if not columns:
        return ["(no rows)"]
    lines = ["| " + " | ".join(_cell(c) for c in columns) + " |", "|" + " --- |" * len(columns)]
    for row in rows:
        lines.append("| " + " | ".join(_fmt(row.get(c)) for c in columns) + " |")
    return lines


def _benchmark_summary(name: str) -> str:
    """The first paragraph of ``benchmarks/NAME.py``'s docstring ('' when there is none)."""
    path = BENCH_DIR / f"{name}.py"
    if not path.is_file():
        return ""
    doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    return " ".join(doc.split("\n\n")[0].split())


_SKIP = {"benchmark", "rows", "command", "machine", "date", "provenance"}


def render_report(stem: str, report: dict) -> str:
    """The Markdown page of one report."""
    name = str(report.get("benchmark") or stem)
    head = heading_line(report)
    out = [f"# Benchmark: {stem}", ""]
    summary = _benchmark_summary(name)
    if summary:
        out += [summary, ""]
    out += [
        "Generated from `docs/results/data/" + stem + ".json`; [how these pages are made](index.md).",
        "",
        "## Rows",
        "",
        head,
        "",
    ]
    out += _table(report["rows"])
    settings = []
    for key, value in report.items():
        if key in _SKIP:
            continue
        rows = _key_rows(value)
        if rows is not None:
            out += ["", f"## {key}", "", head, ""] + _table(rows)
        else:
            settings.append((key, value))
    if settings:
        out += ["", "## Settings", "", head, "", "| key | value |", "| --- | --- |"]
        out += [f"| {_cell(k)} | {_fmt(v)} |" for k, v in settings]
    prov = report.get("provenance") or {}
    versions = prov.get("versions") or {}
    out += ["", "## Provenance", ""]
    out += [f"- git commit: `{prov.get('git_sha', 'unknown')}`", f"- seed: {prov.get('seed')}"]
    if versions:
        out.append("- versions: " + ", ".join(f"{k} {v}" for k, v in sorted(versions.items())))
    machine = report.get("machine")
    if isinstance(machine, dict) and machine.get("platform"):
        out.append(f"- platform: {machine['platform']}, Python {machine.get('python', '?')}")
    return "\n".join(out) + "\n"


def index_table(reports: dict[str, dict]) -> str:
    """A Markdown table of the published reports: page, command, machine, date."""
    if not reports:
        return "No benchmark report is published yet.\n"
    lines = ["| report | command | machine | date |", "| --- | --- | --- | --- |"]
    for stem, rep in reports.items():
        command = rep.get("command") or "not recorded"
        lines.append(
            f"| [{stem}]({stem}.md) | `{_cell(command)}` | {_cell(_machine_text(rep.get('machine')))} | "
            f"{str(rep.get('date') or 'not recorded')[:10]} |"
        )
    return "\n".join(lines) + "\n"


def _key_rows(value) -> list[dict] | None:
    """A report key's value as table rows: a list of dicts as it is, a dict of dicts as one
    row per key (first column empty-named, as on the report's page); None otherwise."""
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        return value
    if isinstance(value, dict) and value and all(isinstance(v, dict) for v in value.values()):
        return [{"": k, **v} for k, v in value.items()]
    return None


def report_table(
    stem: str, key: str, columns: list[str] | None = None, data_dir: Path = DATA_DIR, link: str | None = None
) -> str:
    """One table of a published report, for a hand-written page: the heading line (command,
    machine, date), then the table of the report's ``key`` (``rows`` or any list or dict of
    rows), restricted to ``columns`` in that order (None: all), then a link to the report's
    full page (``link``: its path relative to the including page; None: no link). The
    numbers come from ``docs/results/data/STEM.json`` at build time, so they cannot drift
    from the published report. A missing report, key or column is a ValueError."""
    path = Path(data_dir) / f"{stem}.json"
    if not path.is_file():
        raise ValueError(f"results {stem}: no report {path.name} in {data_dir} (make results RESULTS={stem})")
    report = load_reports(data_dir)[stem]
    rows = _key_rows(report.get(key))
    if rows is None:
        raise ValueError(f"results {stem}: the report has no table {key!r}")
    present = {c for row in rows for c in row}
    unknown = [c for c in columns or [] if c not in present]
    if unknown:
        raise ValueError(f"results {stem} {key}: no column(s) {unknown}")
    if columns is not None and isinstance(report.get(key), dict):
        columns = ["", *columns]  # a dict's rows keep their names
    out = [heading_line(report), "", *_table(rows, columns)]
    if link:
        out += ["", f"All the columns and rows: [{stem}]({link})."]
    return "\n".join(out) + "\n"


def render_all(data_dir: Path = DATA_DIR) -> dict[str, str]:
    """{page path relative to docs/: Markdown} for every report in ``data_dir``."""
    return {page_path(stem): render_report(stem, rep) for stem, rep in load_reports(data_dir).items()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=DATA_DIR, help="folder of reports (default docs/results/data)")
    parser.add_argument("--out", type=Path, required=True, help="folder to write the pages to")
    args = parser.parse_args(argv)
    for rel, text in render_all(args.data).items():
        path = args.out / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
