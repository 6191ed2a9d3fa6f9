#!/bin/bash
cd /work/corner19
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
for s in hard_s51 hard_s53 hard_s57 hard_s60 hard_s74 hard_s75 default_s8; do
  PYTHONPATH=/work/corner19/base nice -n 10 /work/main/.venv/bin/python trackscore.py main $s >> main.txt 2>>log_main.err
done
echo "$(date -u +%H:%M:%S) main14 done" >> main.txt
