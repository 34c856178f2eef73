"""Column lists of the study's CSV files, shared by the stages that write and read them.

``responses.csv`` (written by ``crowdstudy export`` and the server's admin export, read by
``crowdstudy analyze``; the simulated studies of :mod:`crowdstudy.stats.synthetic` have the
same columns): one row per answered study trial (practice trials excluded), sorted by
participant then ``trial_index``, columns :data:`RESPONSE_COLUMNS`:

* ``participant_id``; ``stage`` (the design's stage number) and ``scenario``;
  ``trial_index`` (0-based order in the participant's session);
* the stimulus: ``stimulus_id`` (e.g. ``S1-D3-V2-Ours``), ``density_level``, ``density``
  (characters per m^2), ``viewpoint``, ``method``;
* ``Q1`` .. ``Q6``: the raw Likert answers, 1 .. the design's ``points`` (negative items
  NOT reversed; the analysis reverses them);
* ``rt_ms``: time from the video's start to the answer, milliseconds; ``shown_at`` and
  ``answered_at``: ISO 8601 timestamps (UTC, milliseconds).

The study server's export appends :data:`RESPONSE_QUALITY_COLUMNS` (empty cells where not
recorded): ``video_plays`` (complete plays of the looping video before the answer),
``first_play_ms`` (ms from the trial's display to the first complete play), ``hidden_count``
and ``hidden_ms`` (tab switches during the trial and ms hidden), ``fullscreen_exits``,
``check_answer`` / ``check_value`` (the attention check's answer and the point it asked for).
Readers select the columns they need by name.

``comparisons.csv`` (2AFC trials; ``crowdstudy export`` writes it beside responses.csv
when the design has a ``2afc`` stage; ``crowdstudy analyze`` reads it from there): one row
per answered trial, columns :data:`COMPARISON_COLUMNS` then the quality columns:
``participant_id, stage, scenario, task`` (``2afc``), ``trial_index``, the cell
(``density_level, density, viewpoint``), the two videos (``stimulus_left,
stimulus_right``) and their methods (``method_left, method_right``), ``choice`` (``left``
or ``right``), ``chosen_method`` (the method of the chosen video), ``rt_ms, shown_at,
answered_at``.

``participants.csv`` (``crowdstudy export``): one row per participant, ``participant``,
``status``, ``excluded`` (0/1), ``exclusion_reason`` (``;``-separated rule names) and more
(:data:`crowdstudy.study.quality.PARTICIPANT_COLUMNS`).

``demographics.csv``: one row per participant, columns :data:`DEMOGRAPHIC_COLUMNS`
(``started_at`` and ``completed_at`` ISO 8601; empty cells for what was not given).

Empty cells are missing values; floats are written with ``repr`` (round-trip exact).
"""

from __future__ import annotations

__all__ = [
    "RESPONSE_COLUMNS",
    "DEMOGRAPHIC_COLUMNS",
    "ITEM_COLUMNS",
    "RESPONSE_QUALITY_COLUMNS",
    "COMPARISON_COLUMNS",
]

#: The questionnaire items' columns in the responses file.
ITEM_COLUMNS = ("Q1", "Q2", "Q3", "Q4", "Q5", "Q6")
RESPONSE_COLUMNS = (
    "participant_id",
    "stage",
    "scenario",
    "trial_index",
    "stimulus_id",
    "density_level",
    "density",
    "viewpoint",
    "method",
    *ITEM_COLUMNS,
    "rt_ms",
    "shown_at",
    "answered_at",
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
#: comparisons.csv (2AFC trials), before the quality columns.
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
    "rt_ms",
    "shown_at",
    "answered_at",
)
DEMOGRAPHIC_COLUMNS = ("participant_id", "age", "gender", "started_at", "completed_at", "completion_code")
