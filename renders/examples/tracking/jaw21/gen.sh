#!/bin/bash
export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1
for s in "$@"; do
  d=/work/reacq/sets/default_$s
  [ -f $d.done ] && continue
  rm -rf $d
  nice -n 10 /work/main/.venv/bin/lipgen generate --out $d --preset default --seed $s --subject-seed $s --no-progress > $d.log 2>&1 && touch $d.done
done
