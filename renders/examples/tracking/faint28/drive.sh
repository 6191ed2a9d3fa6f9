#!/bin/bash
# usage: drive.sh VARIANT TREE OUT SET...  (waits until each set's generate has finished)
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 REC_DIR=/work/faint28/rec PYTHONPATH=$2
v=$1; tree=$2; out=$3; shift 3
for s in "$@"; do
  until grep -qs "wrote $s " /work/sets/gen*.log; do sleep 10; done
  /work/main/.venv/bin/python /work/wt/faint/renders/examples/tracking/faint28/run.py $out $v /work/sets/$s
done
