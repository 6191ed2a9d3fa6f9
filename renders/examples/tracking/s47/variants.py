"""s47 variants for w39/run.py: W = main's defaults; C = the cross-check's continuity judge goes before the
layout (ReconstructSettings.cross_check_continuity)."""
VARIANTS = {"W": {}, "C": {"cross_check_continuity": True}}
