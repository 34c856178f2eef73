"""The stimulus videos a study server shows: the design's stimuli matched to manifest rows.

The render stage writes ``DIR/manifest.json`` (format: :mod:`crowdstudy.render.stimuli`,
"Manifest format"); every stimulus of the design must have a row whose stage, scenario,
density level, viewpoint and method agree with the design, and whose ``file`` is a relative
path to an existing file inside ``DIR``. Video paths come only from here: the server never joins a request value
onto a path.

A practice clip (shown once, before stage 1, answers flagged as practice) is, in order:
an explicit ``practice`` argument (a path relative to ``DIR``), the manifest's optional
``"practice": {"file": ...}`` entry, ``DIR/practice.mp4``, or, failing all, the first stimulus
(``practice_note`` then says so).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

from crowdstudy.design import StudyDesign
from crowdstudy.errors import InvalidInputError
from crowdstudy.study.schedule import check_stimulus_id

__all__ = ["StimulusSet", "load_stimulus_set", "STIMULUS_COLUMNS"]

#: Stimulus metadata the server keeps per stimulus (and the export joins on).
STIMULUS_COLUMNS = ("stimulus_id", "stage", "scenario", "density_level", "density", "viewpoint", "method")


@dataclasses.dataclass(frozen=True)
class StimulusSet:
    """Stimuli of one study.

    rows: {stimulus_id: metadata dict with STIMULUS_COLUMNS (+ "characters")}, design order.
    files: {stimulus_id: absolute Path of the video}.
    practice_file: absolute Path of the practice clip.
    practice_note: non-empty when no dedicated practice clip was found.
    """

    root: Path
    rows: dict[str, dict]
    files: dict[str, Path]
    practice_file: Path
    practice_note: str = ""

    def by_stage(self) -> dict[int, list[str]]:
        """{stage number: stimulus ids of that stage}."""
        out: dict[int, list[str]] = {}
        for sid, row in self.rows.items():
            out.setdefault(int(row["stage"]), []).append(sid)
        return out


def _inside(root: Path, rel, where: str) -> Path:
    if (
        not isinstance(rel, str)
        or not rel
        or rel.startswith(("/", "\\"))
        or "\\" in rel
        or any(part in ("", "..") for part in rel.split("/"))
    ):
        raise InvalidInputError(f"{where}: 'file' must be a relative path inside the stimulus folder, got {rel!r}")
    path = (root / rel).resolve()
    if root not in path.parents:
        raise InvalidInputError(f"{where}: 'file' {rel!r} points outside the stimulus folder {root}")
    if not path.is_file():
        raise InvalidInputError(f"{where}: video file {path} does not exist")
    return path


def _missing_message(manifest_path: Path, design: StudyDesign, missing: list, by_id: dict) -> str:
    """One line naming what the stimulus folder lacks: a method of the design (and the stages,
    with their tasks, that show it), else the first missing videos."""
    have = {row.get("method") for row in by_id.values()}
    lacking = [m for m in design.methods if m not in have and any(m in st.methods for st in design.stages)]
    if lacking:
        m = lacking[0]
        stages = [st for st in design.stages if m in st.methods]
        return (
            f"{manifest_path}: the folder has no video of method {m!r}, which the design {design.source} shows "
            f"in stages {', '.join(str(st.number) for st in stages)} "
            f"({', '.join(sorted({st.task for st in stages}))}); render it with `crowdstudy stimuli`"
        )
    by_stage = {int(sid.split("-")[0][1:]) for sid in missing if sid[1:].split("-")[0].isdigit()}
    tasks = sorted({st.task for st in design.stages if st.number in by_stage})
    return (
        f"{manifest_path}: {len(missing)} stimuli of the design {design.source} have no row "
        f"(first: {', '.join(missing[:3])}; {', '.join(tasks) or 'likert'} videos)"
    )


def load_stimulus_set(stimuli_dir: str | Path, design: StudyDesign, *, practice: str | None = None) -> StimulusSet:
    """Read ``stimuli_dir/manifest.json`` and match it to ``design.stimuli()``."""
    root = Path(stimuli_dir).resolve()
    if not root.is_dir():
        raise InvalidInputError(f"--stimuli: folder {str(stimuli_dir)!r} does not exist")
    manifest_path = root / "manifest.json"
    if not manifest_path.is_file():
        raise InvalidInputError(f"--stimuli: {manifest_path} is missing (run `crowdstudy stimuli` first)")
    try:
        manifest = json.loads(manifest_path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InvalidInputError(f"{manifest_path}: not valid JSON ({exc})") from None
    if not isinstance(manifest, dict) or not isinstance(manifest.get("stimuli"), list):
        raise InvalidInputError(f"{manifest_path}: expected an object with a 'stimuli' list")
    by_id: dict[str, dict] = {}
    for i, row in enumerate(manifest["stimuli"]):
        where = f"{manifest_path}: stimuli[{i}]"
        if not isinstance(row, dict):
            raise InvalidInputError(f"{where} must be an object")
        sid = check_stimulus_id(row.get("stimulus_id"), f"{where}.stimulus_id")
        if sid in by_id:
            raise InvalidInputError(f"{where}: duplicate stimulus_id {sid!r}")
        by_id[sid] = row
    rows: dict[str, dict] = {}
    files: dict[str, Path] = {}
    missing = []
    for stim in design.stimuli():
        row = by_id.get(stim.stimulus_id)
        if row is None:
            missing.append(stim.stimulus_id)
            continue
        where = f"{manifest_path}: stimulus {stim.stimulus_id}"
        expected = {
            "stage": stim.stage,
            "scenario": stim.scenario,
            "density_level": stim.density_level,
            "viewpoint": stim.viewpoint,
            "method": stim.method,
        }
        for key, value in expected.items():
            if row.get(key) != value:
                raise InvalidInputError(f"{where}: {key} is {row.get(key)!r}, the design says {value!r}")
        files[stim.stimulus_id] = _inside(root, row.get("file"), where)
        rows[stim.stimulus_id] = {
            **expected,
            "stimulus_id": stim.stimulus_id,
            "density": float(stim.density),
            "characters": int(stim.n_characters),
        }
    if missing:
        raise InvalidInputError(_missing_message(manifest_path, design, missing, by_id))
    practice_note = ""
    if practice is not None:
        practice_file = _inside(root, practice, "--practice")
    elif isinstance(manifest.get("practice"), dict):
        practice_file = _inside(root, manifest["practice"].get("file"), f"{manifest_path}: practice")
    elif (root / "practice.mp4").is_file():
        practice_file = (root / "practice.mp4").resolve()
    else:
        # No dedicated clip: reuse the first stimulus (the caller warns that it is shown twice).
        first = next(iter(files))
        practice_file, practice_note = files[first], f"no practice clip; reusing stimulus {first}"
    return StimulusSet(root=root, rows=rows, files=files, practice_file=practice_file, practice_note=practice_note)
