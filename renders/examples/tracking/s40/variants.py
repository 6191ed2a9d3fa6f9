# The held-out pair (walk_on became the default after it). On development, "W-sure" started walks only from
# sightings both tracking runs agree on (a setting removed before the freeze), and "W0" was W.
VARIANTS = {"main": dict(walk_on=False), "W": dict(walk_on=True)}
VARIANTS |= {"S5": dict(split_runs=5.0), "S6": dict(split_runs=6.0), "S8": dict(split_runs=8.0)}
VARIANTS |= {"R15": dict(split_runs=5.0, split_runs_ratio=1.5), "R2": dict(split_runs=5.0, split_runs_ratio=2.0),
             "R3": dict(split_runs=5.0, split_runs_ratio=3.0)}
