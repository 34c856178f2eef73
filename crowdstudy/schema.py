"""Column lists of the study's CSV files, shared by the stages that write and read them.

``responses.csv`` (Likert and slider trials; written by ``crowdstudy export`` and the
server's admin export, read by ``crowdstudy analyze``; the simulated studies of
:mod:`crowdstudy.stats.synthetic` have the same columns): one row per answered study trial
(practice trials excluded), sorted by participant then ``trial_index``, columns
:func:`response_columns` of the design's item ids (:data:`RESPONSE_COLUMNS` for the paper's
``Q1`` .. ``Q6``):

* ``participant_id``; ``stage`` (the design's stage number), ``scenario`` and ``task``
  (``likert`` or ``slider``, the stage's task; a file without the column is read as all
  ``likert``: exports of earlier versions keep working); ``trial_index`` (0-based order in
  the participant's session);
* the stimulus: ``stimulus_id`` (e.g. ``S1-D3-V2-Ours``), ``density_level``, ``density``
  (characters per m^2), ``viewpoint``, ``method``;
* one column per questionnaire item, the design's item ids in the design's order (``Q1`` ..
  ``Q6`` for the paper): the raw answers, Likert 1 .. the design's ``points``, slider
  integers 0 .. 100 (negative items NOT reversed; the analysis reverses them);
* ``rt_ms``: time from the video's start to the answer, milliseconds; ``shown_at`` and
  ``answered_at``: ISO 8601 timestamps (UTC, milliseconds).

``comparisons.csv`` (``2afc`` trials, beside ``responses.csv``; written by ``crowdstudy
export`` when the design has a 2afc stage): one row per answered trial, columns
:data:`COMPARISON_COLUMNS`: ``participant_id, stage, scenario, task`` (always ``2afc``),
``trial_index, density_level, density, viewpoint``, the two videos ``stimulus_left,
stimulus_right`` and their methods ``method_left, method_right``, ``choice`` (``left`` or
``right``, the video chosen) and ``chosen_method``, then ``rt_ms, shown_at, answered_at``.

The study server's exports of both files append :data:`RESPONSE_QUALITY_COLUMNS` (empty
cells where not recorded): ``video_plays`` (complete plays of the looping video, or of the
shorter of the two videos of a 2afc trial, before the answer), ``first_play_ms`` (ms from
the trial's display to the first complete play), ``hidden_count`` and ``hidden_ms`` (tab
switches during the trial and ms hidden), ``fullscreen_exits``, ``check_answer`` /
``check_value`` (the attention check's answer and what it asked for: a Likert point; a
slider end, 0 or 100; a 2afc side, ``left`` or ``right``). Readers select the columns they
need by name.

``participants.csv`` (``crowdstudy export``): one row per participant, ``participant``,
``status``, ``excluded`` (0/1), ``exclusion_reason`` (``;``-separated rule names) and more
(:data:`crowdstudy.study.quality.PARTICIPANT_COLUMNS`).

``demographics.csv``: one row per participant, columns :data:`DEMOGRAPHIC_COLUMNS`
(``started_at`` and ``completed_at`` ISO 8601; empty cells for what was not given).

Empty cells are missing values; floats are written with ``repr`` (round-trip exact).
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = [
    "RESPONSE_COLUMNS",
    "DEMOGRAPHIC_COLUMNS",
    "ITEM_COLUMNS",
    "RESPONSE_QUALITY_COLUMNS",
    "COMPARISON_COLUMNS",
    "CHOICES",
    "response_columns",
]

#: The paper's questionnaire items' columns in the responses file.
ITEM_COLUMNS = ("Q1", "Q2", "Q3", "Q4", "Q5", "Q6")
_RESPONSE_HEAD = (
    "participant_id",
    "stage",
    "scenario",
    "task",
    "trial_index",
    "stimulus_id",
    "density_level",
    "density",
    "viewpoint",
    "method",
)
_TIMES = ("rt_ms", "shown_at", "answered_at")


def response_columns(item_ids: Sequence[str] = ITEM_COLUMNS) -> tuple[str, ...]:
    """The columns of ``responses.csv`` for a design whose items are ``item_ids`` (in order)."""
    return (*_RESPONSE_HEAD, *item_ids, *_TIMES)


#: responses.csv of the paper's design (items Q1..Q6).
RESPONSE_COLUMNS = response_columns(ITEM_COLUMNS)
#: The two answers of a 2afc trial: the video on the left or the one on the right.
CHOICES = ("left", "right")
COMPARISON_COLUMNS = (
    "participant_id",
    "stage",
    "scenario",
    "task",
    "trial_index",
    "density_level",
    "density",
    "viewpoint",
    "stimulus_left",
    "stimulus_right",
    "method_left",
    "method_right",
    "choice",
    "chosen_method",
    *_TIMES,
)
RESPONSE_QUALITY_COLUMNS = (
    "video_plays",
    "first_play_ms",
    "hidden_count",
    "hidden_ms",
    "fullscreen_exits",
    "check_answer",
    "check_value",
)
DEMOGRAPHIC_COLUMNS = ("participant_id", "age", "gender", "started_at", "completed_at", "completion_code")
