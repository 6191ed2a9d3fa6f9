VARIANTS = {"W": {}, "R15": dict(split_runs=5.0, split_runs_ratio=1.5),
            "P1": dict(split_runs=5.0, split_runs_ratio=1.5, split_runs_spread=1.0),
            "P2": dict(split_runs=5.0, split_runs_ratio=1.5, split_runs_spread=2.0)}
