"""s48 variants for w39/run.py: W = main's defaults; S = the run split joins a frame to the most recent track
it continues (ReconstructSettings.split_runs_recent)."""
VARIANTS = {"W": {}, "S": {"split_runs_recent": True}}
