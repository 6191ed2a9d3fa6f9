#!/bin/bash
cd /work/collapse19
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
for s in hard_s65 hard_s66 hard_s67 hard_s68 hard_s69 hard_s70; do
  PYTHONPATH=/work/collapse19/base nice -n 10 /work/main/.venv/bin/python trackscore.py HOmain $s 2>>log_HOmain.err
  H17_SETTINGS='{"first_frame_floor": 0.7}' PYTHONPATH=/work/collapse19/cand nice -n 10 /work/main/.venv/bin/python trackscore.py HOC07 $s 2>>log_HOC07.err
done
