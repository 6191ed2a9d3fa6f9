#!/bin/bash
# usage: runsets.sh TREE TAG SET...  (one at a time)
tree=$1; tag=$2; shift 2
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
for s in "$@"; do
  PYTHONPATH=$tree nice -n 10 /work/main/.venv/bin/python /work/collapse19/trackscore.py $tag $s 2>>/work/collapse19/log_$tag.err
done
