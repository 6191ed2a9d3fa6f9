"""s45 variants for w39/run.py: W = main's defaults; Q = the cross-check judges in 2-D the disputed frames where
only one run has a pair (ReconstructSettings.cross_check_pairs)."""
VARIANTS = {"W": {}, "Q": {"cross_check_pairs": True}}
