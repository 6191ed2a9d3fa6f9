VARIANTS = {"W": dict(walk_on=True)}
