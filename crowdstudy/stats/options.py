"""The settings of ``crowdstudy analyze`` as one frozen value (:class:`AnalysisOptions`).

The closed sets are ``typing.Literal`` types; :class:`AnalysisOptions` checks every value
when it is made, so a bad setting fails before any response is read, with an
:class:`~crowdstudy.errors.InvalidInputError` naming the option.

>>> AnalysisOptions(adjust="holm", stages=[1]).stages
(1,)
"""

from __future__ import annotations

import dataclasses
from typing import Literal, get_args

from crowdstudy.errors import InvalidInputError

__all__ = ["AnalysisOptions", "Correction", "Adjust", "EffectSize", "Missing", "ErrorBars", "StarsRule"]

#: Greenhouse-Geisser: where Mauchly's p < alpha (the paper's rule), always (afex's default), never.
Correction = Literal["auto", "always", "never"]
#: Post hoc p-value adjustment.
Adjust = Literal["tukey", "bonferroni", "holm"]
#: Effect size quoted in the APA text (both are in the tables).
EffectSize = Literal["np2", "ng2"]
#: A participant without every cell: error, or listwise deletion.
Missing = Literal["raise", "drop"]
#: Figure error bars: standard deviation, standard error, 95% confidence interval.
ErrorBars = Literal["sd", "se", "ci95"]
#: Figure stars for Method: in every cell, or only where the ANOVA's Method effect (or an
#: interaction with Method) is significant.
StarsRule = Literal["always", "omnibus"]

_CHOICES = {
    "correction": Correction,
    "adjust": Adjust,
    "effsize": EffectSize,
    "missing": Missing,
    "error_bars": ErrorBars,
    "stars": StarsRule,
}


@dataclasses.dataclass(frozen=True)
class AnalysisOptions:
    """How :func:`~crowdstudy.stats.pipeline.analyze` runs and what it writes.

    - ``correction``, ``alpha``, ``effsize``, ``missing``: as
      :func:`~crowdstudy.stats.anova.rm_anova` (``correction`` here by name: ``"always"``
      is rm_anova's ``True``, ``"never"`` its ``False``).
    - ``adjust``: post hoc adjustment; ``level``: confidence level of the intervals.
    - ``composites``, ``stages``: subsets (None: all; stages by number, each must be a
      stage of the design). Lists are accepted and stored as tuples.
    - ``robustness``: also fit the mixed model (all participants, incomplete ones too) and
      run the ordinal (signed-rank / sign) checks of the Method effect.
    - ``stars``: ``"always"`` draws the per-cell Method stars, ``"omnibus"`` only where
      the ANOVA's Method effect or an interaction with Method is significant.
    - ``figures``: write the figures (tables only when False); ``error_bars``: what the
      figures' error bars show; ``figure_note``: text appended to every figure title.
    """

    correction: Correction = "auto"
    alpha: float = 0.05
    effsize: EffectSize = "np2"
    missing: Missing = "raise"
    adjust: Adjust = "tukey"
    level: float = 0.95
    composites: tuple[str, ...] | None = None
    stages: tuple[int, ...] | None = None
    robustness: bool = True
    stars: StarsRule = "always"
    figures: bool = True
    error_bars: ErrorBars = "sd"
    figure_note: str = ""

    def __post_init__(self) -> None:
        for name, kind in _CHOICES.items():
            value = getattr(self, name)
            allowed = get_args(kind)
            if value not in allowed:
                raise InvalidInputError(f"{name} must be {' or '.join(map(repr, allowed))}, got {value!r}")
        for name in ("alpha", "level"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < 1:
                raise InvalidInputError(f"{name} must be in (0, 1), got {value!r}")
        for name in ("composites", "stages"):
            value = getattr(self, name)
            if value is not None:
                if isinstance(value, (str, int)):
                    raise InvalidInputError(f"{name} must be a list, got {value!r}")
                object.__setattr__(self, name, tuple(value))

    @property
    def anova_correction(self) -> Literal["auto"] | bool:
        """``correction`` as :func:`~crowdstudy.stats.anova.rm_anova` takes it (and as the
        summary and analysis.json state it): ``"auto"``, ``True`` or ``False``."""
        return {"auto": "auto", "always": True, "never": False}[self.correction]

    def settings(self) -> dict:
        """The settings analysis.json records."""
        return {
            "correction": self.anova_correction,
            "alpha": self.alpha,
            "effsize": self.effsize,
            "adjust": self.adjust,
            "missing": self.missing,
            "stars": self.stars,
            "level": self.level,
        }
