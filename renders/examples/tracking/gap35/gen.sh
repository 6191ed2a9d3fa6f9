#!/bin/bash
# usage: gen.sh preset seed...   (hard: 40 frames; default: the preset's own frame count)
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
p=$1; shift
for n in "$@"; do
  if [ "$p" = hard ]; then /work/main/.venv/bin/lipgen generate --preset hard --seed $n --frames 40 --workers 1 --out hard$n
  else /work/main/.venv/bin/lipgen generate --preset default --seed $n --workers 1 --out default$n; fi
done
