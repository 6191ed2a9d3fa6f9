#!/bin/bash
# usage: ho.sh TAG VARIANTS SET...   (held-out rows to /work/b38/ho_TAG.jsonl)
cd /work/wt/g38
export PYTHONPATH=/work/wt/g38 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
.venv/bin/python /work/b38/run.py /work/b38/ho_$1.jsonl $2 "${@:3}" > /work/b38/ho_$1.log 2>&1
