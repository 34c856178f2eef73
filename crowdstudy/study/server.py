"""Assemble a study server from files: design, stimulus folder, consent text, database."""

from __future__ import annotations

import json
import os
import secrets
from pathlib import Path

from crowdstudy.design import default_design_path, load_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.package_data import resource_path

__all__ = ["build_config", "default_ui_dir", "ADMIN_TOKEN_ENV"]

ADMIN_TOKEN_ENV = "CROWDSTUDY_ADMIN_TOKEN"


def default_ui_dir() -> Path:
    """The questionnaire's front end shipped in the package (``crowdstudy/study/ui``: in a
    checkout, the link to the top-level ``ui/``; in a wheel, copies of its files)."""
    return resource_path("crowdstudy.study", "ui")


def _design_path(stimuli_dir: Path, design) -> Path:
    if design is not None:
        return Path(design)
    try:
        recorded = json.loads((stimuli_dir / "manifest.json").read_text(encoding="utf-8")).get("design")
    except (OSError, ValueError, AttributeError):
        recorded = None
    if isinstance(recorded, str) and recorded:
        for candidate in (Path(recorded), stimuli_dir / recorded):
            if candidate.is_file():
                return candidate
    return default_design_path()


def build_config(
    stimuli: str | Path,
    *,
    design: str | Path | None = None,
    db: str | None = None,
    consent: str | Path | None = None,
    practice: str | None = None,
    admin_token: str | None = None,
    completion_code: str | None = None,
    redirect_url: str | None = None,
    ui_dir: str | Path | None = None,
    online: str | Path | None = None,
    media_dir: str | Path | None = None,
    media_url: str | None = None,
):
    """A :class:`~crowdstudy.study.app.StudyConfig` from files.

    design: the study TOML (default: the one recorded in the manifest, else stimuli/study.toml);
    db: SQLAlchemy URL (default ``sqlite:///study.db`` in the working directory);
    consent: Markdown file (default: ``consent.md`` beside the design, in the stimulus
    folder, or the toolkit's ``crowdstudy/study/consent.md``); admin_token: default from the
    ``CROWDSTUDY_ADMIN_TOKEN`` environment variable, else random; online: the data-quality
    TOML (default: the design's ``[online]`` table, else ``online.toml`` beside the design, else
    the toolkit's defaults); media_dir /
    media_url: publish the videos there under opaque names / the URL prefix they are served
    from (:mod:`crowdstudy.study.media`).
    """
    from crowdstudy.study.app import StudyConfig
    from crowdstudy.study.consent import find_consent_file, load_consent_html
    from crowdstudy.study.quality import load_online_config, online_config
    from crowdstudy.study.stimulus_set import load_stimulus_set
    from crowdstudy.study.storage import StudyStore

    stimuli_dir = Path(stimuli)
    design_obj = load_design(_design_path(stimuli_dir, design))
    stim = load_stimulus_set(stimuli_dir, design_obj, practice=practice)
    consent_file = find_consent_file(consent, Path(design_obj.source).parent, stimuli_dir, default_design_path().parent)
    token = admin_token or os.environ.get(ADMIN_TOKEN_ENV) or secrets.token_urlsafe(24)
    if len(token) < 16:
        raise InvalidInputError("--admin-token must be at least 16 characters")
    if redirect_url is not None and not redirect_url.startswith(("https://", "http://")):
        raise InvalidInputError(f"--redirect-url must be an http(s) URL, got {redirect_url!r}")
    if completion_code is not None and not (0 < len(completion_code) <= 128 and completion_code.isprintable()):
        raise InvalidInputError("--completion-code must be 1-128 printable characters")
    if media_url is not None and not (
        media_url.startswith("/") and not media_url.startswith("//") or media_url.startswith(("https://", "http://"))
    ):
        raise InvalidInputError(f"--media-url must be a path such as /media or an http(s) URL, got {media_url!r}")
    beside = Path(design_obj.source).parent / "online.toml"
    if online is not None:
        online_cfg = load_online_config(online)
    elif design_obj.online is not None:  # the design's own [online] table
        online_cfg = online_config(design_obj.online, design_obj.source)
    elif beside.is_file():
        online_cfg = load_online_config(beside)
    else:
        online_cfg = load_online_config()
    consent_html = load_consent_html(consent_file)
    store = StudyStore(db or "sqlite:///study.db")
    return StudyConfig(
        design=design_obj,
        stimuli=stim,
        store=store,
        consent_html=consent_html,
        admin_token=token,
        ui_dir=Path(ui_dir) if ui_dir else default_ui_dir(),
        completion_code=completion_code,
        redirect_url=redirect_url,
        online=online_cfg,
        media_dir=Path(media_dir) if media_dir is not None else None,
        media_url=media_url,
    )
