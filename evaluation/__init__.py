"""Evaluation layer: paired runs of policies and solvers on shared seeds, statistics, reports and experiments.

Sits above ``policies`` (it runs them) and below ``training`` (which evaluates its checkpoints through it):
``episodes`` (one run per (solver, seed), in processes), ``stats`` (paired statistics), ``report`` (tables and
plots), ``compare`` (every baseline on one scenario), ``experiments`` (the sources' experiments as YAML, run;
``experiment_files`` reads them, ``experiment_reports`` writes their tables, plots and docs blocks),
``heldout`` (the learned-policy table on held-out seeds), ``convergence`` (convergence under the scoring options),
``seeds`` (which seed ranges serve which purpose), ``fuzz`` (random configs and invariants), ``acbba_check`` (ACBBA
against synchronous CBBA on random static scenarios) and ``acbba_experiments`` (Johnson's ACBBA figures).
"""
