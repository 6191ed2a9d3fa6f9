#!/bin/bash
# rc.sh TREE TAG SET...
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
tree=$1; tag=$2; shift 2
for s in "$@"; do
  name=$(basename $s)
  rm -rf /work/speed30/rc/$tag/$name; mkdir -p /work/speed30/rc/$tag
  PYTHONPATH=$tree /usr/bin/time -f "$tag $name %U user %e wall" /work/main/.venv/bin/python -m lipgen reconstruct $s --out /work/speed30/rc/$tag/$name.npz --no-progress > /work/speed30/rc/$tag/$name.log 2>&1
  tail -1 /work/speed30/rc/$tag/$name.log
done
