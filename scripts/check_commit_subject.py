"""Refuse a commit message whose subject line runs past 72 characters (git's commit-msg hook).

The subject is the first line that is neither blank nor a comment (git drops both from the
message). Run by pre-commit on each commit (`.pre-commit-config.yaml`, the `commit-msg`
stage) with the message file's path; prints one line and exits 1 when the subject is too
long, so that the commit stops and the message can be edited.
"""

from __future__ import annotations

import sys
from pathlib import Path

MAX_SUBJECT = 72


def subject_line(message: str) -> str:
    """The message's subject: its first line that is neither blank nor a `#` comment."""
    for line in message.splitlines():
        if line.strip() and not line.startswith("#"):
            return line.rstrip()
    return ""


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: check_commit_subject.py COMMIT_MSG_FILE", file=sys.stderr)
        return 2
    subject = subject_line(Path(argv[0]).read_text(encoding="utf-8"))
    if len(subject) > MAX_SUBJECT:
        print(
            f"commit subject has {len(subject)} characters (at most {MAX_SUBJECT}): "
            "keep it short and put the details in the body",
            file=sys.stderr,
        )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
