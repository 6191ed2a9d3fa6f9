#!/bin/bash
# usage: heldout.sh TREE TAG 'H17_SETTINGS json' 'H18_DOTS json' : hard 59-64 once, main then the frozen candidate per set
tree=$1; tag=$2; s17=$3; s18=$4
ulimit -v 8000000
for s in hard_s59 hard_s60 hard_s61 hard_s62 hard_s63 hard_s64; do
  ./runsets.sh /work/hard18/base HOmain $s >> heldout_main.txt 2>&1
  H17_SETTINGS="$s17" H18_DOTS="$s18" ./runsets.sh $tree $tag $s >> heldout_$tag.txt 2>&1
done
