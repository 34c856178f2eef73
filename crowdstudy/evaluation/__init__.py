"""The correction evaluated on study cells: the acceptance bars of every cell
(:mod:`~crowdstudy.evaluation.acceptance`), what each addition to the paper's method buys
(:mod:`~crowdstudy.evaluation.ablation_run`, :mod:`~crowdstudy.evaluation.ablation_report`),
the large stadium crowds
(:mod:`~crowdstudy.evaluation.stadium`) and the MuJoCo peer on the same scenes
(:mod:`~crowdstudy.evaluation.mujoco_compare`). It sits above the stages it builds on
(design, layout, navigation, motion, physics, metrics); ``crowdstudy bench physics`` and the
tests use it. Its modules import what they need when called, so importing this package
is cheap.
"""
