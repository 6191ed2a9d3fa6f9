"""Experiments that reproduce and extend the thesis's results on synthetic ground truth.

- :mod:`lipgen.experiments.table51`: thesis Table 5.1 (LLSE reconstruction error per DOF from
  partial observations), with the errors against the true surface and the combined model.
"""
