#!/bin/bash
cd /work/corner19
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
for s in hard_s48 hard_s49 hard_s55 hard_s61 hard_s62 hard_s47 hard_s59; do
  PYTHONPATH=/work/corner19/base nice -n 10 /work/main/.venv/bin/python trackscore.py main $s >> main.txt 2>>log_main.err
done
echo "$(date -u +%H:%M:%S) main7 done" >> main.txt
