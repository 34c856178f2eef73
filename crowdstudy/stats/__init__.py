"""Statistics of the perceptual study: from exported responses to the paper's tables,
figures and APA summary.

- :mod:`~crowdstudy.stats.scoring`: validate responses.csv, reverse negative items,
  item-pair reliability, composites, per participant x cell means.
- :mod:`~crowdstudy.stats.anova`: ``rm_anova`` for any number of within factors, with
  Mauchly's test, Greenhouse-Geisser / Huynh-Feldt and partial / generalized eta squared
  (matched to R's afex).
- :mod:`~crowdstudy.stats.posthoc`: ``pairwise`` comparisons as emmeans' multivariate
  model, Tukey / Bonferroni / Holm.
- :mod:`~crowdstudy.stats.effects`: confidence-interval critical values, d_z / g_av with
  intervals; :mod:`~crowdstudy.stats.contrasts`: simple effects (emmeans' joint_tests) and
  polynomial contrasts; :mod:`~crowdstudy.stats.robust`: mixed model (incomplete
  participants kept) and rank tests of Method.
- :mod:`~crowdstudy.stats.assumptions`: Shapiro-Wilk and Q-Q plots of residuals per cell.
- :mod:`~crowdstudy.stats.report`, :mod:`~crowdstudy.stats.figures`: table formats, APA
  text, paper-style figures.
- :mod:`~crowdstudy.stats.pipeline`: ``analyze`` (what ``crowdstudy analyze`` runs) as
  load -> ``compute`` -> write; :mod:`~crowdstudy.stats.options`: its settings
  (``AnalysisOptions``); :mod:`~crowdstudy.stats.results`: what it computes;
  :mod:`~crowdstudy.stats.summary`, :mod:`~crowdstudy.stats.writers`: summary.md, the
  tables, figures and analysis.json.
- :mod:`~crowdstudy.stats.inputs`: reading responses.csv, its sidecar and participants.csv.
- :mod:`~crowdstudy.stats.synthetic`, :mod:`~crowdstudy.stats.power`,
  :mod:`~crowdstudy.stats.pilot`: simulated participants, Monte-Carlo power, the
  simulation model fitted to pilot responses.

Each public name has one import path, its module (``from crowdstudy.stats.anova import
rm_anova``); importing this package imports nothing heavy.
"""

__all__: list[str] = []
