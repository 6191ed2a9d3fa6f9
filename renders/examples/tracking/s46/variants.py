"""s46 variants for w39/run.py: W = main's defaults; R = the cross-check's 3-D judge measures each run's point
against the prediction's spread under the physics prior (ReconstructSettings.cross_check_spread)."""
VARIANTS = {"W": {}, "R": {"cross_check_spread": True}}
