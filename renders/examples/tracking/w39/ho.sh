#!/bin/bash
# ho.sh OUT SET... : each set scored (main, W) once its tracking is in the cache
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=/work/wt/w39
cd /work/b39
out=$1; shift
for s in "$@"; do
  while [ ! -f cache/$s.second.pkl ] || ! grep -q "cached $s\$" log_cache_ho.txt; do sleep 20; done
  /work/main/.venv/bin/python run.py $out main,W $s >> log_ho.txt 2>&1
done
