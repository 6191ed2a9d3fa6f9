#!/bin/bash
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
log=$1; shift
for s in "$@"; do
  until grep -q "wrote $s " /work/b37/gen5.log /work/b37/gen6.log 2>/dev/null; do sleep 10; done
  cd /tmp && PYTHONPATH=/work/main /work/main/.venv/bin/python /work/b37/runxd.py $log $s
done
