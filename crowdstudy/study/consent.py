"""The informed-consent text: a Markdown file in the study folder, shown as HTML.

Only a small, safe subset of Markdown is understood (``#`` headings, paragraphs, ``-``/``*``
bullet lists, ``1.`` numbered lists, ``**bold**``, ``*italic*``); everything else is text,
HTML-escaped, so the file cannot inject markup or scripts into the page.
"""

from __future__ import annotations

import html
import re
from pathlib import Path

from crowdstudy.errors import InvalidInputError

__all__ = ["markdown_to_html", "load_consent_html", "find_consent_file"]

_BOLD = re.compile(r"\*\*(.+?)\*\*")
_ITALIC = re.compile(r"(?<![*\w])\*(?!\s)(.+?)(?<!\s)\*(?![*\w])")


def _inline(text: str) -> str:
    text = html.escape(text, quote=True)
    text = _BOLD.sub(r"<strong>\1</strong>", text)
    return _ITALIC.sub(r"<em>\1</em>", text)


def markdown_to_html(text: str) -> str:
    """Convert the supported Markdown subset to HTML (see the module docstring)."""
    out: list[str] = []
    para: list[str] = []
    list_tag: str | None = None

    def flush_para():
        if para:
            out.append(f"<p>{_inline(' '.join(para))}</p>")
            para.clear()

    def close_list():
        nonlocal list_tag
        if list_tag:
            out.append(f"</{list_tag}>")
            list_tag = None

    for raw in text.splitlines():
        line = raw.strip()
        heading = re.match(r"(#{1,4})\s+(.*)", line)
        bullet = re.match(r"[-*]\s+(.*)", line)
        number = re.match(r"\d+[.)]\s+(.*)", line)
        if not line:
            flush_para()
            close_list()
        elif heading:
            flush_para()
            close_list()
            level = len(heading.group(1)) + 1  # the page has its own <h1>
            out.append(f"<h{level}>{_inline(heading.group(2))}</h{level}>")
        elif bullet or number:
            flush_para()
            tag = "ul" if bullet else "ol"
            if list_tag != tag:
                close_list()
                out.append(f"<{tag}>")
                list_tag = tag
            item = bullet or number  # one of them matched (the branch's condition)
            if item is not None:
                out.append(f"<li>{_inline(item.group(1))}</li>")
        elif list_tag and raw.startswith((" ", "\t")) and out:
            out[-1] = out[-1][:-5] + " " + _inline(line) + "</li>"
        else:
            close_list()
            para.append(line)
    flush_para()
    close_list()
    return "\n".join(out)


def find_consent_file(explicit: str | Path | None, *folders: Path) -> Path:
    """``explicit`` if given (must exist), else the first ``consent.md`` in ``folders``."""
    if explicit is not None:
        path = Path(explicit)
        if not path.is_file():
            raise InvalidInputError(f"--consent: file {str(explicit)!r} does not exist")
        return path
    for folder in folders:
        candidate = Path(folder) / "consent.md"
        if candidate.is_file():
            return candidate
    raise InvalidInputError("no consent text: put a consent.md beside the study design or pass --consent FILE")


def load_consent_html(path: str | Path) -> str:
    """Read a consent Markdown file and return its HTML."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InvalidInputError(f"--consent: cannot read {path} as UTF-8 text ({exc})") from None
    if not text.strip():
        raise InvalidInputError(f"--consent: {path} is empty")
    return markdown_to_html(text)
