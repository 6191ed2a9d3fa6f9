"""Experiments that reproduce and extend the thesis's results on synthetic ground truth.

- :mod:`lipgen.experiments.table51`: thesis Table 5.1 (LLSE reconstruction error per DOF from
  partial observations), with the errors against the true surface and the combined model.
- :mod:`lipgen.experiments.normalisation`: the normalisation methods (thesis §3 and the head pose
  of least deformation) on exact world marks of several generated subjects.
"""
