#!/bin/bash
# lipgen generate --preset hard (its own nonlinear truth physics), 36 frames, no calibration frames, one worker:
# CPU (user+sys, children included) of the whole command, main and branch alternated.
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 LP_NUM_THREADS=1
for r in 1 2 3; do
  for tree in /work/main /work/wt/tan33; do
    rm -rf /tmp/gt_out
    /usr/bin/time -f "$(basename $tree) round $r cpu %U+%S wall %e" env PYTHONPATH=$tree /work/main/.venv/bin/python -m lipgen generate --out /tmp/gt_out --preset hard --frames 36 --calib-frames 0 --workers 1 > /dev/null 2>>/work/b33/gen_time.err
  done
done
