#!/bin/bash
# usage: gen.sh PRESET SEED...   -> lips/PRESET_SEED/{dataset,recon.npz}
L=${LIPGEN:-lipgen}   # (default 2: reconstruct exited 3 on a never-accepted marker; marked done by hand)
export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1
p=$1; shift
for s in "$@"; do
  d=lips/${p}_$s
  [ -f $d/.done ] && continue
  rm -rf $d; mkdir -p $d
  sub=""; [ "$p" != easy ] && sub="--subject-seed $s"
  nice -n 10 $L generate --out $d/dataset --preset $p --seed $s $sub --no-progress > $d/gen.log 2>&1 &&
  nice -n 10 $L reconstruct $d/dataset --out $d/recon.npz --no-progress > $d/rec.log 2>&1 && touch $d/.done
done
