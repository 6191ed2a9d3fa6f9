#!/bin/bash
# usage: runsets.sh TREE TAG SET...  (waits for each set's .done; one at a time)
tree=$1; tag=$2; shift 2
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
for s in "$@"; do
  while [ ! -f /work/data/$s/.done ] && ! { [ -f /work/data/gen_59_64.done ] && [[ $s =~ ^hard_s(59|6[0-4])$ ]]; }; do sleep 20; done
  PYTHONPATH=$tree nice -n 10 /work/main/.venv/bin/python /work/hard18/trackscore.py $tag $s 2>>/work/hard18/log_$tag.err
done
