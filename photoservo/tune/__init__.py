"""`photoservo tune` (issue 14): Optuna studies over config keys, scored on simulated worlds and
recordings. space (the search space), objectives (what a trial measures), study (storage,
trials, budget), runner (worker processes, stop after the running trial), report (tables, plots).
No argparse here: cli/tune.py is the verb."""
