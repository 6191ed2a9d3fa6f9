"""Scoring a reconstruction against the ground truth, and the report.

* :mod:`~lipgen.evaluate.scoring`: per-stage scores and the Table 5.1 analogue.
* :mod:`~lipgen.evaluate.report`: ``lipgen evaluate``'s report.md, report.json and pictures.
"""

from lipgen.evaluate.scoring import AXES, ROWS, default_test_frames, load_truth, score, split_frames, table51

__all__ = ["default_test_frames", "split_frames", "load_truth", "score", "table51", "ROWS", "AXES"]
