#!/bin/bash
# usage: runwhen.sh LOG TAG SET...  : run each set once its generate log says "wrote SET"
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
log=$1; tag=$2; shift 2
for s in "$@"; do
  until grep -q "wrote $s " /work/b37/gen3.log /work/b37/gen4.log 2>/dev/null; do sleep 10; done
  cd /tmp && PYTHONPATH=/work/main /work/main/.venv/bin/python /work/b37/run.py $log $tag $s
done
