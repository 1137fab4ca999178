"""The ODE-solver study of a trained CNODE: its own stage (``quadfdi solvers``, docs/solvers.md).

One job per module:

- ``settings``: a way of solving a CNODE (``Setting``), the reference, the grid of ``[solvers]``;
- ``study``: solve test windows one at a time with each setting, compare with the reference;
- ``matching``: the cheapest fixed setting that matches each adaptive one;
- ``matrix``: CNODEs trained with several solvers and controls, each deployed with each;
- ``report``: markdown and findings in words; ``report_section``/``headline``/``load_records``
  for the run report and bench (JSON only, no torch);
- ``plots``: the figures; ``files``: where the outputs live (``runs/<name>/solvers/``, figures in
  ``runs/<name>/figures/``);
- ``run``: ``study_run``, ``matrix_run``, ``render`` (typed settings, never argv); ``cli``: the command.

The model variants it solves (step-average control, knot restarts) are training's: ``models.variants``.
This package imports ``core``, ``sim`` and ``train``; no stage imports it except through
``solverstudy.report`` (bench and the app layer read its JSON).
"""
